"""calibrate_vehicle: end to end over bags written by simulate_bag (200 Hz, 12 s)."""
import json

import numpy as np
import pytest

from road_force_estimator.bagio import read_drive_bag, write_drive_bag
from road_force_estimator.core.parameters import (
    ObserverParameters, VehicleParameters, load_params_file, read_params_document)
from road_force_estimator.core.road import RoadProfile
from road_force_estimator.core.road_files import road_from_source, write_csv_profile
from road_force_estimator.tools import calibrate_vehicle, simulate_bag

pytestmark = pytest.mark.slow   # `pytest -m 'not slow'` skips it; scripts/test runs it

TRUCK = """/**:
  ros__parameters:
    vehicle:
      sprung_mass: 6300.0
      roll_inertia: 3900.0
      track_width: 2.1
      unsprung_mass: [380.0, 520.0]
      suspension_stiffness: [330000.0, 470000.0]
      suspension_damping: [18000.0, 11000.0]
      tire_stiffness: [800000.0, 1250000.0]
    simulator:
      noise:
        deflection: 0.0
        roll: 0.0
"""
NOMINAL = """/**:
  ros__parameters:
    vehicle:
      sprung_mass: 5000.0
      track_width: 2.1
      roll_inertia: 3000.0
    observer:
      latency: 0.01
"""


@pytest.fixture(scope='module')
def files(tmp_path_factory):
    root = tmp_path_factory.mktemp('calib')
    road = road_from_source('iso8608:C:seed=7', length_m=400.0)
    write_csv_profile(root / 'road.csv', road)
    write_csv_profile(root / 'survey.csv', RoadProfile(road.distance_m + 30.0, road.elevation_m))
    (root / 'truck.yaml').write_text(TRUCK)
    (root / 'nominal.yaml').write_text(NOMINAL)
    code = simulate_bag.main(['--road', str(root / 'road.csv'), '--speed', '20', '--rate', '200',
                              '--duration', '12', '--params-file', str(root / 'truck.yaml'),
                              '--output', str(root / 'drive'), '--no-ground-truth',
                              '--gnss-rate', '0', '--no-progress'])
    assert code == 0
    return root


def _run(files, *extra, drive='drive', profile='survey.csv', output='out/calib.yaml'):
    return calibrate_vehicle.main([str(files / drive), '--profile', str(files / profile),
                                   '--output', str(files / output), '--no-progress', '--force',
                                   *extra])


@pytest.fixture(scope='module')
def calibrated(files):
    truck = VehicleParameters.from_parameters(load_params_file(files / 'truck.yaml'))
    left, right = truck.static_load_n
    code = _run(files, '--params-file', str(files / 'nominal.yaml'), '--static-load',
                str(left), str(right), '--hold', 'vehicle.track_width', '--no-figures',
                '-p', 'vehicle.sprung_mass:=5500.0')
    assert code == 0
    return files / 'out' / 'calib.yaml', truck


def test_output_round_trips_with_every_key_and_the_fit(calibrated):
    path, truck = calibrated
    values = load_params_file(path)
    doc = read_params_document(path)
    assert values['observer.latency'] == 0.01                       # kept from the input
    assert doc['/**']['ros__parameters']['vehicle']['track_width'] == 2.1   # held: unchanged
    vehicle = VehicleParameters.from_parameters(values)
    assert vehicle.sprung_mass_kg == pytest.approx(truck.sprung_mass_kg, rel=2e-3)
    assert vehicle.tire_stiffness_npm == pytest.approx(truck.tire_stiffness_npm, rel=2e-3)
    assert vehicle.static_load_n == pytest.approx(truck.static_load_n)
    report = json.loads((path.parent / 'calib_report' / 'calibration.json').read_text())
    assert report['scale_known'] and report['alignment']['correlation'] > 0.8
    # the gravity moment M g h sin(phi) (issue 19) makes the CG height act: fitted
    assert 'vehicle.cg_height_above_roll_axis' not in report['not_identifiable']
    assert vehicle.cg_height_m == pytest.approx(truck.cg_height_m, rel=2e-2)
    md = (path.parent / 'calib_report' / 'calibration.md').read_text()
    assert '95 % interval' in md and 'Alignment' in md


def test_output_starts_the_observer_node(calibrated):
    rclpy = pytest.importorskip('rclpy')
    from rclpy.context import Context
    from rclpy.node import Node

    from road_force_estimator.ros.ros_parameters import ParameterGuard, specs_with_prefix

    path, truck = calibrated
    context = Context()
    rclpy.init(context=context, args=['--ros-args', '--params-file', str(path)])
    node = Node('observer', context=context)
    try:
        guard = ParameterGuard(node, specs_with_prefix('vehicle.', 'observer.'),
                               lambda v: (VehicleParameters.from_parameters(v),
                                          ObserverParameters.from_parameters(v)))
        vehicle, observer = guard.config
        assert vehicle == VehicleParameters.from_parameters(load_params_file(path))
        assert observer.latency_s == 0.01
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def test_without_static_load_says_masses_up_to_a_factor(files, capsys):
    assert _run(files, '--output', str(files / 'free.yaml'), '--no-figures') == 0
    err = capsys.readouterr().err
    assert 'known only up to a common factor' in err
    report = json.loads((files / 'free_report' / 'calibration.json').read_text())
    assert not report['scale_known']


def _one_line_error(capsys, code):
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1 and len(err) == 1 and 'Traceback' not in err[0], err
    return err[0]


def test_other_road_is_refused_in_one_line(files, capsys):
    other = road_from_source('iso8608:C:seed=99', length_m=400.0)
    write_csv_profile(files / 'other.csv', RoadProfile(other.distance_m + 30.0,
                                                       other.elevation_m))
    line = _one_line_error(capsys, _run(files, profile='other.csv', output='x.yaml'))
    assert 'does not match the survey' in line


def test_bad_inputs_one_line_each(files, capsys):
    road = road_from_source(str(files / 'survey.csv'))
    keep = (road.distance_m < 150.0) | (road.distance_m > 160.0)
    write_csv_profile(files / 'gappy.csv', RoadProfile(road.distance_m[keep],
                                                       road.elevation_m[keep]))
    assert 'gap of' in _one_line_error(capsys, _run(files, profile='gappy.csv', output='g.yaml'))
    line = _one_line_error(capsys, _run(files, '--start-offset', '5000', output='n.yaml'))
    assert 'no overlap' in line
    drive = read_drive_bag(files / 'drive')
    n = 500                                            # 2.5 s
    traj = type('T', (), {'t_s': (drive.stamps_ns[:n] - drive.stamps_ns[0]) * 1e-9,
                          'distance_m': 20.0 * (drive.stamps_ns[:n] - drive.stamps_ns[0]) * 1e-9})
    write_drive_bag(files / 'short', traj, drive.q_m[:n], drive.roll_rad[:n], speed_mps=20.0,
                    ground_truth=False, overwrite=True)
    line = _one_line_error(capsys, _run(files, drive='short', output='s.yaml'))
    assert 'too short' in line and 'at least' in line
    assert calibrate_vehicle.main(['x', '--output', 'y']) == 2                 # no --profile
    capsys.readouterr()
    line = _one_line_error(capsys, _run(files, '--free', 'vehicle.sprung_mass', output='f.yaml'))
    assert '--free vehicle.sprung_mass' in line and 'vehicle.leaf_spring_friction' in line


def test_drive_with_missing_samples_calibrates_on_the_good_ones(files, capsys):
    """Samples the reader rejected are missing rows of the drive: the fit runs through them.
    (write_drive_bag refuses non-finite values; the reader's own rejections are covered in
    test/estimation/test_calibration.py with the arrays it returns.)"""
    drive = read_drive_bag(files / 'drive')
    keep = np.ones(drive.stamps_ns.size, bool)
    keep[700:710] = False
    traj = type('T', (), {'stamps_ns': drive.stamps_ns[keep]})
    write_drive_bag(files / 'holes', traj, drive.q_m[keep], drive.roll_rad[keep],
                    speed_mps=20.0, ground_truth=False, overwrite=True)
    assert _run(files, '--no-figures', drive='holes', output='h.yaml') == 0
    assert '(10 missing or rejected)' in capsys.readouterr().err


def _copy_with_nan_deflections(src, dst, bad):
    """The bag ``src`` again with the deflection messages of index ``bad`` set to NaN (the
    rosbags writer: ours refuses non-finite values)."""
    from rosbags.rosbag2 import Reader, StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    with Reader(src) as reader, Writer(dst, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conns = {c.id: w.add_connection(c.topic, c.msgtype, typestore=store)
                 for c in reader.connections}
        k = 0
        for conn, t, data in reader.messages():
            if conn.topic == '/suspension/deflections':
                if k in bad:
                    msg = store.deserialize_cdr(data, conn.msgtype)
                    msg.position = np.full(len(msg.position), np.nan)
                    data = store.serialize_cdr(msg, conn.msgtype)
                k += 1
            w.write(conns[conn.id], t, data)


def test_drive_with_rejected_samples_calibrates_on_the_good_ones(files, calibrated, capsys):
    """Deflections the reader rejects (non-finite) are left out; the fit is unchanged."""
    _copy_with_nan_deflections(files / 'drive', files / 'nans', set(range(800, 812)))
    capsys.readouterr()
    path, truck = calibrated
    left, right = truck.static_load_n
    assert _run(files, '--params-file', str(files / 'nominal.yaml'), '--static-load',
                str(left), str(right), '--hold', 'vehicle.track_width', '--no-figures',
                '-p', 'vehicle.sprung_mass:=5500.0', drive='nans', output='nans.yaml') == 0
    err = capsys.readouterr().err
    assert '(12 missing or rejected; 12 messages rejected by the reader' in err
    vehicle = VehicleParameters.from_parameters(load_params_file(files / 'nans.yaml'))
    # as the clean drive's calibration (test_output_round_trips_with_every_key_and_the_fit)
    assert vehicle.sprung_mass_kg == pytest.approx(truck.sprung_mass_kg, rel=2e-3)
    assert vehicle.suspension_stiffness_npm == pytest.approx(truck.suspension_stiffness_npm,
                                                             rel=2e-3)


def test_a_held_fitted_parameter_is_written_unchanged(files, capsys):
    """--hold of a parameter the fit frees otherwise: the output has the input file's value
    (not the truth's 3900, not a fit) and the report names it held."""
    assert _run(files, '--params-file', str(files / 'nominal.yaml'), '--hold',
                'vehicle.roll_inertia', '--no-figures', output='held.yaml') == 0
    capsys.readouterr()
    doc = read_params_document(files / 'held.yaml')
    assert doc['/**']['ros__parameters']['vehicle']['roll_inertia'] == 3000.0
    report = json.loads((files / 'held_report' / 'calibration.json').read_text())
    rows = {p['name']: p for p in report['parameters']}
    assert rows['vehicle.roll_inertia']['status'] == 'held'
    assert rows['vehicle.sprung_mass']['status'] == 'fitted'


@pytest.mark.parametrize('args, line', [
    (['--search-range', '0'], '--search-range 0: must be > 0 m'),
    (['--min-correlation', '1.5'], '--min-correlation 1.5: a correlation, in (-1, 1]'),
    (['--static-load', '30000', '-5'], '--static-load 30000 -5: wheel loads, > 0 N'),
    (['--search-range', 'nan'], "argument --search-range: 'nan': must be a finite number"),
])
def test_numbers_that_cannot_work_are_a_bad_command_line(tmp_path, capsys, args, line):
    """Issue 28: every numeric option checked against what can work, non-finite refused."""
    from road_force_estimator.tools.calibrate_vehicle import main
    code = main([str(tmp_path / 'drive'), '--profile', 'iso8608:C', '--output',
                 str(tmp_path / 'out.yaml'), *args])
    assert (code, capsys.readouterr().err) == (2, f'calibrate_vehicle: error: {line}\n')
