"""plant_simulator with vehicle.model: articulated: every sample recorded from the first, the
numbers simulate_bag writes for the same drive, live LPA replay driving every axle, one-line
refusals at start; the observer reading an articulated truck's deflections."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rclpy.parameter import Parameter

from node_harness import Collector, close, finish, make_executor, run_main
from road_force_estimator import bagio
from road_force_estimator.bagio.articulated_drive import read_articulated_truth
from road_force_estimator.core.parameters import load_params_file
from road_force_estimator.core.road import iso8608_profile
from road_force_estimator.ros.plant_simulator import PlantSimulator
from road_force_estimator.ros.ros_parameters import ParameterError
from road_force_estimator.tools.simulate_bag import main as simulate_bag
from ros_helpers import spin_until
from test_live_road import write_lpa_with_rosbags

REPO = Path(__file__).resolve().parents[2]
CONFIG = REPO / 'config' / 'tractor_semitrailer.yaml'
TRUTH = ['/suspension/deflections', '/ground_truth/wheel_loads',
         '/ground_truth/load_transfer_ratios', '/ground_truth/wheel_load/left',
         '/ground_truth/road_profile/right', '/vehicle/twist']


def overrides(**extra):
    """The articulated file as start-up values (what --params-file gives a node)."""
    values = load_params_file(CONFIG)
    values.update(extra)
    return [Parameter(n, value=list(v) if isinstance(v, tuple) else v)
            for n, v in values.items()]


def test_a_recorded_drive_has_every_sample_and_the_numbers_of_simulate_bag(ros_context,
                                                                         tmp_path):
    """plant_simulator at 1 kHz with 5 axles and the IMU + bag_recorder, started together: the
    bag holds every sample from the first, the same readings and truth as simulate_bag."""
    from road_force_estimator.ros.bag_recorder import BagRecorder

    bag = tmp_path / 'drive'
    recorder = BagRecorder(context=ros_context, parameter_overrides=[
        Parameter('output', value=str(bag))])
    plant = PlantSimulator(context=ros_context, parameter_overrides=overrides(**{
        'simulator.duration': 3.0, 'simulator.road': 'iso8608:C:seed=3',
        'vehicle.tractor_imu': True, 'start_nodes': ['bag_recorder']}))
    executor = make_executor(ros_context, recorder, plant)
    try:
        assert spin_until(executor, lambda: plant.finished, 60.0)
        assert spin_until(executor, lambda: all(recorder.counts[t] >= plant.k for t in
                                                (*TRUTH, '/imu/tractor')), 20.0)
        recorder.stop()                  # what is queued, written; the bag closed
    finally:
        recorder.close()
        close(executor, plant, recorder)
    assert plant.k == 3001
    assert simulate_bag(['--params-file', str(CONFIG), '--road', 'iso8608:C:seed=3',
                         '--duration', '3', '-p', 'vehicle.tractor_imu:=true',
                         '--output', str(tmp_path / 'ref'), '--no-progress']) == 0
    got, ref = bagio.read_drive_bag(bag), bagio.read_drive_bag(tmp_path / 'ref')
    assert len(got.stamps_ns) == 3001 and got.stamps_ns[0] == plant.start_ns
    # a bag without simulate_bag's custom_data: the first axle of the message is read
    assert 'the first axle of the message' in got.notes[0]
    np.testing.assert_array_equal(got.q_m, ref.q_m)
    np.testing.assert_array_equal(got.roll_rad, ref.roll_rad)
    t_got, t_ref = read_articulated_truth(bag), read_articulated_truth(tmp_path / 'ref')
    assert t_got.wheel_names == t_ref.wheel_names and len(t_got.wheel_names) == 10
    np.testing.assert_array_equal(t_got.wheel_load_n, t_ref.wheel_load_n)
    np.testing.assert_array_equal(t_got.unit_ltr, t_ref.unit_ltr)
    np.testing.assert_array_equal(got.truth.road_m, ref.truth.road_m)
    imu_got = bagio.read_topic_columns(bag, {'/imu/tractor': 'sensor_msgs/msg/Imu'})
    imu_ref = bagio.read_topic_columns(tmp_path / 'ref', {'/imu/tractor': 'sensor_msgs/msg/Imu'})
    for path in ('linear_acceleration.z', 'angular_velocity.x'):
        np.testing.assert_array_equal(imu_got['/imu/tractor'].column(path)[0],
                                      imu_ref['/imu/tractor'].column(path)[0])


def test_live_lpa_replay_drives_every_axle_as_simulate_bag(ros_context, tmp_path):
    """simulator.road: topic: a bag_player replays an LPA bag; every axle drives the paths as
    they arrive, the drive ends with the profile: the numbers of simulate_bag over the bag."""
    lpa = tmp_path / 'lpa'
    write_lpa_with_rosbags(lpa, iso8608_profile('C', 40.0, seed=5))
    assert simulate_bag(['--params-file', str(CONFIG), '--road', str(lpa), '--duration', '60',
                         '--rate', '500', '--output', str(tmp_path / 'ref'),
                         '--no-progress']) == 0
    ref = bagio.read_drive_bag(tmp_path / 'ref')
    collector = Collector(ros_context, TRUTH)
    plant = PlantSimulator(context=ros_context, parameter_overrides=overrides(**{
        'simulator.road': 'topic', 'simulator.duration': 60.0, 'simulator.rate': 500.0,
        'road_timeout': 0.5}))
    player = run_main('bag_player', str(lpa), '--wait', '30')
    executor = make_executor(ros_context, collector, plant)
    try:
        assert spin_until(executor, lambda: plant.finished, 60.0), plant.k
        assert spin_until(executor, lambda: all(collector.count(t) >= plant.k for t in TRUTH),
                          10.0)
    finally:
        close(executor, plant, collector)
    code, _, err = finish(player, 30.0)
    assert code == 0, err
    n = len(ref.stamps_ns)
    assert plant.k == n == collector.count('/suspension/deflections') > 500
    loads = np.array([m.effort for m in collector.messages['/ground_truth/wheel_loads']])
    np.testing.assert_allclose(loads, read_articulated_truth(tmp_path / 'ref').wheel_load_n,
                               rtol=1e-9, atol=1e-9)
    defl = np.array([m.position for m in collector.messages['/suspension/deflections']])
    np.testing.assert_allclose(defl[:, :2], ref.q_m, atol=1e-12)


@pytest.mark.parametrize('extra, message', [
    ({'vehicle.axle.trailer_4.mass': 800.0}, "no axle 'trailer_4' in vehicle.axles"),
    ({'vehicle.axle.drive.body': 'dolly'}, "vehicle.axle.drive.body = 'dolly'"),
    ({'vehicle.sprung_mass': 5000.0}, 'a parameter of the front-axle model'),
    ({'vehicle.trailer.cg_position': 14.0}, 'the kingpin would pull'),
])
def test_a_bad_articulated_vehicle_is_refused_at_start_in_one_line(ros_context, extra,
                                                                   message):
    with pytest.raises(ParameterError, match=message) as err:
        PlantSimulator(context=ros_context, parameter_overrides=overrides(**extra))
    assert '\n' not in str(err.value)


def test_the_observer_reads_an_articulated_truck_s_front_axle_and_says_so():
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState

    from road_force_estimator.ros.wire import Wire

    names = ['front_left_suspension', 'front_right_suspension', 'drive_left_suspension',
             'drive_right_suspension', 'tractor_roll', 'trailer_roll']
    msg = JointState(name=names, position=[0.001, 0.002, 0.003, 0.004, 0.01, 0.02])
    msg.header.stamp.sec = 5
    wire = Wire()
    said = []
    wire.on_note = said.append
    for _ in range(3):
        stamp, q, phi = wire.read_deflections(serialize_message(msg))
    assert (stamp, q, phi) == (5_000_000_000, (0.001, 0.002), 0.01)
    assert len(said) == 1 and 'front_left_suspension, front_right_suspension, tractor_roll' in \
        said[0]


def test_bag_player_plays_an_articulated_drive_with_its_topics(ros_context, tmp_path):
    """bag_player replays simulate_bag's articulated drive: every message of the new topics
    (the IMU with the sensor-data QoS, the truth reliable), values as written."""
    assert simulate_bag(['--params-file', str(CONFIG), '--duration', '0.5', '--rate', '500',
                         '-p', 'vehicle.tractor_imu:=true', '--output', str(tmp_path / 'd'),
                         '--no-progress']) == 0
    topics = [*TRUTH, '/imu/tractor']
    collector = Collector(ros_context, topics)
    player = run_main('bag_player', str(tmp_path / 'd'), '--wait', '30', '--topics', *topics)
    executor = make_executor(ros_context, collector)
    try:
        assert spin_until(executor, lambda: all(collector.count(t) >= 251 for t in topics),
                          60.0), {t: collector.count(t) for t in topics}
    finally:
        close(executor, collector)
    code, _, err = finish(player, 30.0)
    assert code == 0, err
    truth = read_articulated_truth(tmp_path / 'd')
    np.testing.assert_array_equal(
        [m.effort for m in collector.messages['/ground_truth/wheel_loads']], truth.wheel_load_n)
    assert collector.messages['/imu/tractor'][0].linear_acceleration.z > 9.0
