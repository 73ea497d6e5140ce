"""plant_simulator node: topics, exact stamps, ground truth, end of drive, parameters, main().

Nodes spin in the test process (fresh rclpy context per test); main() runs in a subprocess.
"""
import math
import signal

import numpy as np
import pytest
from rclpy.parameter import Parameter

from node_harness import Collector, close, finish, make_executor, run_main
from road_force_estimator.interfaces import DEFLECTION_JOINTS
from road_force_estimator.ros.messages import stamp_to_ns
from road_force_estimator.core.parameters import GRAVITY_MPS2
from road_force_estimator.core.plant import simulate
from road_force_estimator.ros.plant_simulator import PlantSimulator
from road_force_estimator.ros.ros_parameters import ParameterError
from road_force_estimator.core.sensors import SensorModel
from ros_helpers import spin_until

TRUTH = ['/ground_truth/wheel_load/left', '/ground_truth/wheel_load/right',
         '/ground_truth/road_profile/left', '/ground_truth/road_profile/right']
TOPICS = ['/suspension/deflections', '/vehicle/twist', *TRUTH, '/fix', '/diagnostics']
WGS84_A, WGS84_E2 = 6378137.0, 6.69437999014e-3


def drive(context, timeout_s=30.0, **params):
    """Run a plant_simulator with ``params`` to its end; (node, collector) after delivery."""
    params.setdefault('start_nodes', ['collector'])      # the test's collector starts it
    overrides = [Parameter(k.replace('__', '.'), value=v) for k, v in params.items()]
    collector = Collector(context, TOPICS)
    plant = PlantSimulator(context=context, parameter_overrides=overrides)
    executor = make_executor(context, collector, plant)
    try:
        assert spin_until(executor, lambda: plant.finished, timeout_s), 'drive did not end'
        n = plant.k
        assert spin_until(executor, lambda: all(collector.count(t) >= n for t in TOPICS[:6]),
                          10.0), {t: collector.count(t) for t in TOPICS}
        assert spin_until(executor, lambda: any(
            s.values and dict((v.key, v.value) for v in s.values).get('finished') == 'true'
            for m in collector.messages['/diagnostics'] for s in m.status), 10.0)
    finally:
        close(executor, plant, collector)
    return plant, collector


def test_samples_stamps_frames_and_ground_truth(ros_context):
    plant, col = drive(ros_context, simulator__duration=0.4, simulator__road='iso8608:C:seed=3')
    n = 401  # floor(0.4 s * 1000 Hz) + 1
    assert plant.k == n
    stamps = col.stamps('/suspension/deflections')
    assert len(stamps) == n
    # Simulated sample times: start + k / rate, exactly, on every topic.
    assert [s - stamps[0] for s in stamps] == [k * 1_000_000 for k in range(n)]
    for topic in TOPICS[1:6]:
        assert col.stamps(topic) == stamps, topic
    defl = col.messages['/suspension/deflections']
    assert all(list(m.name) == list(DEFLECTION_JOINTS) and m.header.frame_id == 'base_link'
               for m in defl)
    assert {m.twist.linear.x for m in col.messages['/vehicle/twist']} == {20.0}
    loads = np.array([[m.wrench.force.z for m in col.messages[t]] for t in TRUTH[:2]]).T
    assert {m.header.frame_id for m in col.messages[TRUTH[0]]} == {'front_left_wheel'}
    assert {m.header.frame_id for m in col.messages[TRUTH[1]]} == {'front_right_wheel'}
    points = [col.messages[t] for t in TRUTH[2:]]
    assert {m.point.y for m in points[0]} == {1.0} and {m.point.y for m in points[1]} == {-1.0}
    assert {m.header.frame_id for m in points[0] + points[1]} == {'road'}
    # The node publishes the plant core's samples unchanged (same road, same settings).
    traj = simulate(plant.plant.vehicle, plant.road, speed_mps=20.0, rate_hz=1000.0,
                    duration_s=0.4, tire_envelope_m=0.25)
    np.testing.assert_array_equal(loads, traj.wheel_load_n)
    np.testing.assert_array_equal([m.point.x for m in points[0]], traj.distance_m)
    np.testing.assert_array_equal(np.array([[m.point.z for m in p] for p in points]).T,
                                  traj.road_m)
    q_meas, roll_meas = SensorModel(deflection_std_m=1e-5, roll_std_rad=1e-4, seed=1).measure(
        traj.q_m, traj.roll_rad)
    np.testing.assert_array_equal([m.position[:2] for m in defl], q_meas)
    np.testing.assert_array_equal([m.position[2] for m in defl], roll_meas)
    # Distance: v t (20 m/s), independently of the core.
    np.testing.assert_allclose(traj.distance_m - traj.distance_m[0],
                               20.0 * np.arange(n) / 1000.0, atol=1e-9)


def test_fix_follows_the_straight_route(ros_context):
    plant, col = drive(ros_context, simulator__duration=0.5, simulator__road='flat:length=50',
                       simulator__gnss__rate=10.0, realtime_factor=2.0)
    fixes = col.messages['/fix']
    assert len(fixes) == 6  # t = 0, 0.1, ..., 0.5 s
    t = np.array([(stamp_to_ns(f.header.stamp) - col.stamps('/vehicle/twist')[0]) * 1e-9
                  for f in fixes])
    np.testing.assert_allclose(t, np.arange(6) * 0.1, atol=1e-9)
    # Heading 0 (north): the latitude grows by v t / M, M the WGS84 meridian radius there.
    lat0 = 48.1486
    m = WGS84_A * (1 - WGS84_E2) / (1 - WGS84_E2 * math.sin(math.radians(lat0)) ** 2) ** 1.5
    np.testing.assert_allclose([f.latitude for f in fixes],
                               lat0 + np.degrees(20.0 * t / m), rtol=0, atol=1e-9)
    assert {f.longitude for f in fixes} == {17.1077}
    # A fix, from GPS (an unset status reads as -2, "unknown", in Jazzy).
    assert {(f.status.status, f.status.service) for f in fixes} == {(0, 1)}


def test_odometer_error_and_fix_noise(ros_context):
    """simulator.speed_scale_error: the twist reads (1 + e) v, the distance stays v t;
    simulator.gnss.noise: the fixes of the noise-free run plus FixNoise's numbers (the
    simulate_bag path, same seed)."""
    from road_force_estimator.core.gnss import FixNoise
    params = dict(simulator__duration=0.5, simulator__road='flat:length=50',
                  simulator__gnss__rate=10.0, realtime_factor=2.0)
    _, clean = drive(ros_context, **params)
    _, col = drive(ros_context, simulator__speed_scale_error=0.015,
                   simulator__gnss__noise=2.5, **params)
    assert {m.twist.linear.x for m in col.messages['/vehicle/twist']} == {20.0 * 1.015}
    assert [m.point.x for m in col.messages[TRUTH[2]]] == \
        [m.point.x for m in clean.messages[TRUTH[2]]]
    lat, lon = FixNoise(2.5, 1).apply([f.latitude for f in clean.messages['/fix']],
                                      [f.longitude for f in clean.messages['/fix']])
    assert [f.latitude for f in col.messages['/fix']] == list(lat)
    assert [f.longitude for f in col.messages['/fix']] == list(lon)


def test_flat_road_gives_static_loads_and_the_noise_asked_for(ros_context):
    plant, col = drive(ros_context, simulator__duration=1.0, simulator__road='flat:length=100',
                       simulator__rate=500.0, simulator__noise__deflection=1e-4,
                       simulator__noise__roll=1e-3, simulator__seed=7, realtime_factor=4.0)
    assert plant.k == 501
    # Static loads by hand: (M/2 + m) g = (2500 + 450) kg * g on each wheel.
    for topic in TRUTH[:2]:
        np.testing.assert_allclose([m.wrench.force.z for m in col.messages[topic]],
                                   2950.0 * GRAVITY_MPS2, rtol=1e-9)
    for topic in TRUTH[2:]:
        assert {m.point.z for m in col.messages[topic]} == {0.0}
    pos = np.array([m.position for m in col.messages['/suspension/deflections']])
    # At equilibrium the measurements are the noise alone: its std within 15 % (n = 501).
    np.testing.assert_allclose(pos.std(axis=0), [1e-4, 1e-4, 1e-3], rtol=0.15)
    assert np.all(np.abs(pos.mean(axis=0)) < 3 * np.array([1e-4, 1e-4, 1e-3]) / math.sqrt(501))


def test_drive_stops_at_the_end_of_the_road(ros_context):
    plant, col = drive(ros_context, simulator__duration=10.0, simulator__road='flat:length=3')
    # The 0.25 m tire envelope leaves [0.125, 2.875] m: 2.75 m at 20 m/s = 0.1375 s at 1 kHz.
    assert plant.k == 138 and col.count('/suspension/deflections') == 138
    assert max(m.point.x for m in col.messages[TRUTH[2]]) <= 2.875


@pytest.mark.parametrize('name, value, pattern', [
    ('simulator.rate', 5.0, r'simulator\.rate = 5\.0 is out of range \[10, 100000\] Hz'),
    ('simulator.road', 'iso8608:Z', r"simulator\.road = 'iso8608:Z'"),
    ('simulator.road', '/no/such/profile.csv', r"simulator\.road = '/no/such/profile\.csv'"),
    ('vehicle.suspension_stiffness', [4e5], r'vehicle\.suspension_stiffness = \[400000\.0\]'),
    ('realtime_factor', 0.0, r'realtime_factor = 0\.0 is out of range'),
])
def test_bad_start_up_parameter_is_refused_naming_it(ros_context, name, value, pattern):
    with pytest.raises(ParameterError, match=pattern):
        PlantSimulator(context=ros_context, parameter_overrides=[Parameter(name, value=value)])


def test_live_set_is_refused_naming_the_parameter(ros_context):
    plant = PlantSimulator(context=ros_context)
    try:
        result, = plant.set_parameters([Parameter('simulator.speed', value=10.0)])
        assert not result.successful and 'simulator.speed' in result.reason
        assert plant.sim.speed_mps == 20.0
    finally:
        plant.destroy_node()


def test_main_exits_cleanly_when_the_drive_ends():
    code, _, err = finish(run_main('plant_simulator', '--ros-args', '-p',
                                   'simulator.duration:=0.3', '-p', 'realtime_factor:=3.0',
                                   '-p', 'start_timeout:=0.5'))
    assert code == 0, err
    assert 'drive finished after 301 samples' in err


def test_main_exits_cleanly_on_sigint_mid_drive(ros_context):
    process = run_main('plant_simulator', '--ros-args', '-p',
                       'start_timeout:=0.5')  # 60 s by default
    collector = Collector(ros_context, ['/vehicle/twist'])
    executor = make_executor(ros_context, collector)
    try:
        assert spin_until(executor, lambda: collector.count('/vehicle/twist') > 10, 30.0)
    finally:
        close(executor, collector)
    process.send_signal(signal.SIGINT)
    code, _, err = finish(process, 30.0)
    assert code == 0 and 'Traceback' not in err, err


def test_main_refuses_a_bad_parameter_with_one_line(tmp_path):
    code, _, err = finish(run_main('plant_simulator', '--ros-args', '-p',
                                   'simulator.speed:=99.0'))
    assert code == 1
    assert err.strip().splitlines() == [
        'plant_simulator: refused simulator.speed = 99.0 is out of range [0.1, 60] m/s']
    bad = tmp_path / 'bad.yaml'
    bad.write_text('/**:\n  ros__parameters:\n    simulator:\n      rate: [1\n')
    code, _, err = finish(run_main('plant_simulator', '--ros-args', '--params-file', str(bad)))
    assert code == 1 and 'Traceback' not in err and 'params file' in err


def test_the_drive_waits_for_a_subscriber_on_the_measurements(ros_context):
    plant = PlantSimulator(context=ros_context, parameter_overrides=[
        Parameter('simulator.duration', value=0.2), Parameter('start_timeout', value=60.0),
        Parameter('start_nodes', value=['collector'])])
    executor = make_executor(ros_context, plant)
    collector = None
    try:
        # Nobody listens: nothing is simulated nor published (a bounded look, not a sleep).
        assert not spin_until(executor, lambda: plant.k > 0, 1.0)
        collector = Collector(ros_context, TOPICS)
        executor.add_node(collector)
        assert spin_until(executor, lambda: plant.finished, 30.0)
        assert spin_until(executor, lambda: all(collector.count(t) >= plant.k
                                                for t in TOPICS[:6]), 10.0)
    finally:
        close(executor, plant, *([collector] if collector else []))
    # Every sample from the first one on reached the subscriber.
    stamps = collector.stamps('/suspension/deflections')
    assert len(stamps) == plant.k == 201
    assert stamps[0] == plant.start_ns


def test_main_starts_after_start_timeout_without_a_subscriber():
    code, _, err = finish(run_main('plant_simulator', '--ros-args', '-p',
                                   'simulator.duration:=0.1', '-p', 'start_timeout:=0.5'))
    assert code == 0, err
    assert ('no observer on /suspension/deflections, observer on /vehicle/twist after 0.5 s '
            '(start_timeout): starting the drive anyway') in err
    assert 'drive finished after 101 samples' in err


def test_a_drive_recorded_from_the_nodes_has_every_sample_and_coordinates(ros_context,
                                                                          tmp_path):
    """plant_simulator + bag_recorder (started together): the bag holds every sample from
    the first on and every fix, and estimate_bag gives coordinates on every segment."""
    from road_force_estimator.bagio import read_drive_bag
    from road_force_estimator.ros.bag_recorder import BagRecorder
    from road_force_estimator.tools.estimate_bag import main as estimate_bag

    bag = tmp_path / 'drive'
    recorder = BagRecorder(context=ros_context, parameter_overrides=[
        Parameter('output', value=str(bag))])
    plant = PlantSimulator(context=ros_context, parameter_overrides=[
        Parameter('simulator.duration', value=4.0), Parameter('simulator.speed', value=25.0),
        Parameter('simulator.road', value='iso8608:C:seed=3'),
        Parameter('start_nodes', value=['bag_recorder'])])
    executor = make_executor(ros_context, recorder, plant)
    try:
        assert spin_until(executor, lambda: plant.finished, 60.0)
        assert spin_until(executor, lambda: recorder.counts['/suspension/deflections']
                          >= plant.k, 20.0)
        recorder.stop()                  # what is queued, written; the bag closed
    finally:
        recorder.close()
        close(executor, plant, recorder)
    drive = read_drive_bag(bag)
    assert len(drive.stamps_ns) == plant.k == 4001
    assert drive.stamps_ns[0] == plant.start_ns
    assert len(drive.fixes.stamps_ns) == 41 and not drive.rejected.get('/fix')
    code = estimate_bag([str(bag), '--output', str(tmp_path / 'est'), '--no-figures',
                         '--no-progress', '--segment-length', '20'])
    assert code == 0
    rows = (tmp_path / 'est' / 'report' / 'segments.csv').read_text().splitlines()
    header = rows[0].split(',')
    assert len(rows) - 1 == 5
    for row in rows[1:]:
        values = dict(zip(header, row.split(',')))
        assert all(math.isfinite(float(values[k])) for k in ('start_lat', 'start_lon',
                                                             'end_lat', 'end_lon')), row


def first_stamp_said(collector) -> int | None:
    """The plant's /diagnostics: the stamp of its first sample on the measurements."""
    for msg in collector.messages['/diagnostics']:
        for status in msg.status:
            values = {v.key: v.value for v in status.values}
            if 'first_stamp_ns:/suspension/deflections' in values:
                assert values['first_stamp_ns:/vehicle/twist'] == values[
                    'first_stamp_ns:/suspension/deflections']
                return int(values['first_stamp_ns:/suspension/deflections'])
    return None


def test_the_drive_waits_for_the_observer_not_for_any_subscriber(ros_context):
    """Issue 29: a recorder (any subscriber) no longer starts the drive; the node that reads
    the measurements (``start_nodes``, default observer) does, and the plant says in its
    /diagnostics the stamp of its first sample."""
    plant = PlantSimulator(context=ros_context, parameter_overrides=[
        Parameter('simulator.duration', value=0.2), Parameter('start_timeout', value=60.0)])
    recorder_like = Collector(ros_context, TOPICS, name='bag_recorder')
    executor = make_executor(ros_context, plant, recorder_like)
    observer = None
    try:
        assert spin_until(executor, lambda: plant.deflections_pub.get_subscription_count()
                          >= 1, 30.0)
        assert not spin_until(executor, lambda: plant.k > 0, 1.5)      # a bounded look
        observer = Collector(ros_context, ['/suspension/deflections', '/vehicle/twist'],
                             name='observer')
        executor.add_node(observer)
        assert spin_until(executor, lambda: plant.finished, 30.0)
        assert spin_until(executor, lambda: observer.count('/suspension/deflections')
                          >= plant.k and first_stamp_said(recorder_like) is not None, 10.0)
    finally:
        close(executor, plant, recorder_like, *([observer] if observer else []))
    assert observer.stamps('/suspension/deflections')[0] == plant.start_ns
    assert first_stamp_said(recorder_like) == plant.start_ns


def test_start_subscribers_counts_whoever_subscribes(ros_context):
    plant = PlantSimulator(context=ros_context, parameter_overrides=[
        Parameter('simulator.duration', value=0.1), Parameter('start_timeout', value=60.0),
        Parameter('start_subscribers', value=2)])
    first = Collector(ros_context, TOPICS, name='one')
    executor = make_executor(ros_context, plant, first)
    second = None
    try:
        assert spin_until(executor, lambda: plant.deflections_pub.get_subscription_count()
                          >= 1, 30.0)
        assert not spin_until(executor, lambda: plant.k > 0, 1.0)
        second = Collector(ros_context, TOPICS, name='two')
        executor.add_node(second)
        assert spin_until(executor, lambda: plant.finished, 30.0)
    finally:
        close(executor, plant, first, *([second] if second else []))
    assert plant.k == 101
