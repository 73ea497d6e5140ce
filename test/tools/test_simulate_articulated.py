"""simulate_bag and estimate_bag with the articulated truck (INTERFACES.md "The whole
vehicle"): the drive bag read by the mcap library (independent of the package's reader) and
rosbags, the truth against the test's own statics, a front-axle tool reading the drive, and
the one-line refusals."""
import json
from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest

from articulated_reference import G, defaults, statics
from road_force_estimator import bagio
from road_force_estimator.tools.estimate_bag import main as estimate_bag
from road_force_estimator.tools.simulate_bag import main as simulate_bag

REPO = Path(__file__).resolve().parents[2]
CONFIG = REPO / 'config' / 'tractor_semitrailer.yaml'
FRONT = REPO / 'config' / 'road_force_estimator.yaml'
BIN = Path(sys.executable).parent


def decoded_messages(bag: Path):
    """(topic, message) of every record of the bag's MCAP files, decoded by the mcap library
    and mcap-ros2-support (not the package's reader)."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    for path in sorted(bag.glob('*.mcap')):
        with open(path, 'rb') as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            for _, channel, _, msg in reader.iter_decoded_messages(log_time_order=False):
                yield channel.topic, msg


def run(main, argv, capsys):
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.fixture(scope='module')
def drive(tmp_path_factory):
    """A 4 s drive of the default combination with the IMU, a stop and a curve."""
    folder = tmp_path_factory.mktemp('articulated')
    speed = folder / 'speed.csv'
    speed.write_text('time_s,speed_mps\n0,15\n1,15\n3,9\n')
    bag = folder / 'drive'
    run_ = subprocess.run([str(BIN / 'simulate_bag'), '--params-file', str(CONFIG), '--road',
                           'iso8608:C:seed=3', '--rate', '500', '--duration', '4',
                           '-p', 'vehicle.tractor_imu:=true',
                           '-p', f'simulator.speed_profile:={speed}',
                           '-p', 'simulator.lateral_profile:=curve:start=0.5,ramp=1,hold=1,ay=2',
                           '-p', 'simulator.sensor_faults:=spikes@trailer_1_left_suspension:'
                                 'count=4,size=5e-4',
                           '--output', str(bag)], capture_output=True, text=True, timeout=300)
    assert run_.returncode == 0, run_.stderr
    return bag, run_.stderr


def test_the_bag_holds_the_contract_s_topics_read_by_mcap(drive):
    bag, err = drive
    assert '5 axles, 40.20 t' in err
    msgs = {}
    for topic, msg in decoded_messages(bag):
        msgs.setdefault(topic, []).append(msg)
    n = 4 * 500 + 1
    for topic in ('/vehicle/twist', '/suspension/deflections', '/imu/tractor',
                  '/ground_truth/wheel_load/left', '/ground_truth/wheel_load/right',
                  '/ground_truth/road_profile/left', '/ground_truth/road_profile/right',
                  '/ground_truth/wheel_loads', '/ground_truth/load_transfer_ratios'):
        assert len(msgs[topic]) == n, topic
    names = list(msgs['/suspension/deflections'][0].name)
    assert names == [f'{a}_{s}_suspension' for a in ('front', 'drive', 'trailer_1',
                                                     'trailer_2', 'trailer_3')
                     for s in ('left', 'right')] + ['tractor_roll', 'trailer_roll']
    wheels = msgs['/ground_truth/wheel_loads']
    assert list(wheels[0].name)[:2] == ['front_left_wheel', 'front_right_wheel']
    assert all(len(m.position) == 0 and len(m.velocity) == 0 and len(m.effort) == 10
               for m in wheels[:5])
    loads = np.array([m.effort for m in wheels])
    # the front axle's contract topics carry the front axle's wheels
    left = np.array([m.wrench.force.z for m in msgs['/ground_truth/wheel_load/left']])
    np.testing.assert_array_equal(left, loads[:, 0])
    road = msgs['/ground_truth/road_profile/left']
    assert all(m.point.y == 1.02 for m in road) and road[0].header.frame_id == 'road'
    # the static loads the drive was simulated with: the test's own statics (MODEL.md's
    # combination); the wheel loads carry the weight on average
    ref = statics(defaults())
    custom = bagio.bag_custom_data(bag)
    static = np.array(json.loads(custom['road_force_estimator.static_wheel_loads_n']))
    np.testing.assert_allclose(static.reshape(5, 2).sum(1), ref['wheel'], rtol=1e-9)
    assert np.mean(loads.sum(1)) == pytest.approx(40200 * G, rel=1e-2)   # the road's slopes
    assert custom['road_force_estimator.vehicle_model'] == 'articulated'
    imu = msgs['/imu/tractor']
    assert imu[0].header.frame_id == 'base_link' and imu[0].orientation_covariance[0] == -1.0
    assert np.mean([m.linear_acceleration.z for m in imu]) == pytest.approx(G, abs=0.05)
    braking = [m.linear_acceleration.x for k, m in enumerate(imu) if 1.2 * 500 < k < 2.8 * 500]
    assert np.mean(braking) == pytest.approx(-3.0, abs=0.01)
    ltr = msgs['/ground_truth/load_transfer_ratios']
    assert list(ltr[0].name) == ['tractor', 'trailer', 'combination']
    in_curve = [m.velocity[1] for m in ltr[int(1.8 * 500):int(2.4 * 500)]]
    assert np.mean(in_curve) > 0.2                       # a left curve: the trailer's right
    faults = json.loads(bagio.bag_custom_data(bag)['road_force_estimator.sensor_faults'])
    assert faults[0]['channel'] == 'trailer_1_left_suspension' and len(faults[0]['samples']) == 4


def test_rosbags_reads_every_connection(drive):
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore
    bag, _ = drive
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        counts = {c.topic: 0 for c in reader.connections}
        for conn, _, raw in reader.messages():
            reader.deserialize(raw, conn.msgtype)
            counts[conn.topic] += 1
    assert counts['/imu/tractor'] == 2001 and counts['/ground_truth/wheel_loads'] == 2001


def test_a_front_axle_tool_reads_the_front_axle_and_says_so(drive, tmp_path, capsys):
    bag, _ = drive
    d = bagio.read_drive_bag(bag)
    assert len(d.stamps_ns) == 2001 and not d.rejected
    assert 'front_left_suspension, front_right_suspension, tractor_roll' in d.notes[0]
    code, out, err = run(estimate_bag, [bag, '--params-file', FRONT, '--output',
                                        tmp_path / 'est', '--no-figures', '--no-progress'],
                         capsys)
    assert code == 0, err
    assert 'note: an articulated drive (5 instrumented axles): the front axle estimated' in err
    report = (tmp_path / 'est' / 'report' / 'report.md').read_text()
    assert '## The whole vehicle (ground truth)' in report
    rows = (tmp_path / 'est' / 'report' / 'axles.csv').read_text().splitlines()
    assert rows[0].startswith('wheel,axle,body,static_load_n') and len(rows) == 11
    static = np.array([float(r.split(',')[3]) for r in rows[1:]])
    np.testing.assert_allclose(static.reshape(5, 2).sum(1), statics(defaults())['wheel'],
                               rtol=1e-9)
    summary = json.loads((tmp_path / 'est' / 'report' / 'report.json').read_text())
    assert summary['whole_vehicle']['gross_weight_t'] == pytest.approx(40.2, abs=1e-9)
    assert summary['whole_vehicle']['units']['trailer']['max_abs_ltr_quasi_static'] > 0.2


def test_an_articulated_parameter_file_estimates_the_whole_vehicle(drive, tmp_path, capsys):
    bag, _ = drive
    code, _, err = run(estimate_bag, [bag, '--params-file', CONFIG, '--output',
                                      tmp_path / 'est', '--no-figures', '--no-progress'],
                       capsys)
    assert code == 0, err
    assert 'note: the whole vehicle estimated (5 axles, 2001 samples)' in err
    summary = json.loads((tmp_path / 'est' / 'report' / 'report.json').read_text())
    assert len(summary['whole_vehicle_estimate']['wheels']) == 10


def test_a_drive_without_front_axle_sensors_is_refused_by_a_front_axle_tool(tmp_path, capsys):
    code, _, err = run(simulate_bag, ['--params-file', CONFIG, '--duration', 0.5, '--rate', 200,
                                      '-p', 'vehicle.axle.front.instrumented:=false',
                                      '--output', tmp_path / 'd', '--gnss-rate', 0], capsys)
    assert code == 0, err
    code, _, err = run(estimate_bag, [tmp_path / 'd', '--output', tmp_path / 'est',
                                      '--no-progress'], capsys)
    assert code == 1 and err.count('\n') == 1
    assert 'front axle has no deflection sensors' in err


@pytest.mark.parametrize('overrides, message', [
    (['vehicle.axle.trailer_4.mass:=800.0'], "no axle 'trailer_4' in vehicle.axles"),
    (['vehicle.axle.drive.body:=dolly'], "vehicle.axle.drive.body = 'dolly': must be one of"),
    (['vehicle.axle.trailer_1.position:=3.0', 'vehicle.axle.drive.position:=2.0'],
     'a trailer axle must be behind the kingpin'),
    (['vehicle.trailer.cg_position:=14.0'], 'the vehicle cannot stand: the kingpin would pull'),
    (['vehicle.track_width:=2.0'], 'a parameter of the front-axle model, refused'),
])
def test_simulate_bag_refuses_in_one_line(overrides, message, tmp_path, capsys):
    argv = ['--params-file', CONFIG, '--duration', 0.2, '--output', tmp_path / 'd']
    for o in overrides:
        argv += ['-p', o]
    code, _, err = run(simulate_bag, argv, capsys)
    assert code == 1 and err.count('\n') == 1 and message in err, err
    assert not (tmp_path / 'd').exists()


def test_a_front_axle_drive_refuses_the_articulated_names(tmp_path, capsys):
    code, _, err = run(simulate_bag, ['--duration', 0.2, '-p', 'vehicle.tractor.mass:=7000.0',
                                      '--output', tmp_path / 'd'], capsys)
    assert code == 1 and 'vehicle.tractor.mass: a parameter of vehicle.model: articulated' in err
