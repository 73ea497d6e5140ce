"""The friction v_f an offline estimate took, in its report (``report.json``
``friction_velocity``, a line in ``report.md``) and on estimate_bag's stderr: the fitted one
(estimation.friction_fit) against the file's, in one block and in pieces.

Truth: the plant's tanh friction velocity (core/plant.py, its friction checked against solve_ivp
in test/core/test_friction.py; the drive of test/estimation/test_friction_velocity_fit.py, where
the fit finds the plant's 0.005 m/s); the file always states 0.01 m/s.
"""
from dataclasses import replace
import json

import numpy as np
import pytest

from road_force_estimator.bagio import BagWriter, drive_blocks
from road_force_estimator.core.parameters import VehicleParameters
from road_force_estimator.core.plant import simulate
from road_force_estimator.core.road import iso8608_profile
from road_force_estimator.core.sensors import SensorModel
from road_force_estimator.interfaces import DEFLECTION_JOINTS
from road_force_estimator.pipeline import plan
from road_force_estimator.tools import estimate_bag

import bag_samples

PLANT_VF, FILE_VF = 0.005, 0.01
FRICTION = ['-p', 'vehicle.leaf_spring_friction:=[1500.0, 1500.0]',
            '-p', 'vehicle.sensor_time_constant:=[0.003, 0.003]',
            '-p', f'vehicle.leaf_spring_friction_velocity:={FILE_VF}']
LINE = 'Leaf-spring friction v_f'


@pytest.fixture(scope='module')
def drive(tmp_path_factory):
    """test_friction_velocity_fit's drive as a bag: the plant at 20 m/s, 1 kHz, 12 s over
    class C (seed 4) with 1.5 kN of tanh friction per spring, v_f 0.005 m/s, read by sensors
    with a 3 ms lag and noise; the twist at 100 Hz."""
    plant = replace(VehicleParameters(), leaf_spring_friction_n=(1500.0, 1500.0),
                    sensor_time_constant_s=(0.003, 0.003),
                    leaf_spring_friction_velocity_mps=PLANT_VF)
    tr = simulate(plant, iso8608_profile('C', 300.0, seed=4), speed_mps=20.0, rate_hz=1000.0,
                  duration_s=12.0, tire_envelope_m=0.25)
    q, phi = SensorModel(deflection_std_m=1e-5, roll_std_rad=1e-4, seed=5,
                         time_constant_s=plant.sensor_time_constant_s,
                         rate_hz=1000.0).measure(tr.q_m, tr.roll_rad)
    stamps = bag_samples.BASE_NS + np.round(tr.t_s * 1e9).astype(np.int64)
    folder = tmp_path_factory.mktemp('friction') / 'drive'
    with BagWriter(folder) as bag:
        bag.add_topic('/vehicle/twist', 'geometry_msgs/msg/TwistStamped', 'sensor_data')
        bag.add_topic('/suspension/deflections', 'sensor_msgs/msg/JointState', 'sensor_data')
        for k, s in enumerate(stamps.tolist()):
            if k % 10 == 0:
                bag.write('/vehicle/twist', s, bag_samples.twist(s, 20.0))
            bag.write('/suspension/deflections', s, bag_samples.joint_state(
                s, DEFLECTION_JOINTS, [q[k, 0], q[k, 1], phi[k]]))
    return folder


def _run(drive, out, args, capsys):
    """estimate_bag offline: (report.json, report.md, stderr)."""
    code = estimate_bag.main([str(drive), '--output', str(out), '--mode', 'offline',
                              '--no-figures', '--no-progress', *args])
    assert code == 0
    err = capsys.readouterr().err
    report = out / 'report'
    md = (report / 'report.md').read_text()
    return json.loads((report / 'report.json').read_text()), md, err


def _line(md: str) -> str:
    lines = [a for a in md.splitlines() if LINE in a]
    assert len(lines) == 1, lines
    return lines[0]


def test_the_report_states_the_fitted_v_f_and_the_files(drive, tmp_path, capsys):
    js, md, err = _run(drive, tmp_path / 'fit', FRICTION, capsys)
    fv = js['friction_velocity']
    assert fv['taken_mps'] == pytest.approx(PLANT_VF)        # the plant's
    assert fv['file_mps'] == FILE_VF and fv['fitted'] and fv['changed']
    line = _line(md)
    assert '0.005 m/s fitted from the drive' in line and "the file's 0.01" in line
    assert 'vehicle.leaf_spring_friction_velocity' in line
    notes = [a for a in err.splitlines() if 'friction v_f' in a]
    assert len(notes) == 1 and '0.005 m/s fitted' in notes[0] and '0.01 m/s' in notes[0]


def test_with_the_fit_off_the_report_states_the_files(drive, tmp_path, capsys):
    js, md, err = _run(drive, tmp_path / 'off',
                       [*FRICTION, '-p', 'observer.friction_velocity_fit:=0'], capsys)
    fv = js['friction_velocity']
    assert (fv['taken_mps'], fv['file_mps'], fv['fitted'], fv['changed']) == (
        FILE_VF, FILE_VF, False, False)
    assert 'observer.friction_velocity_fit is 0' in fv['reason']
    assert "0.01 m/s, the file's (not fitted: observer.friction_velocity_fit is 0)" in _line(md)
    assert 'friction v_f' not in err


def test_without_friction_in_the_file_no_v_f(drive, tmp_path, capsys):
    js, md, err = _run(drive, tmp_path / 'none', [], capsys)
    assert 'friction_velocity' not in js
    assert LINE not in md and 'friction v_f' not in err


def test_online_no_v_f(drive, tmp_path, capsys):
    code = estimate_bag.main([str(drive), '--output', str(tmp_path / 'on'), '--mode',
                              'online', '--no-figures', '--no-progress', *FRICTION])
    assert code == 0
    js = json.loads((tmp_path / 'on' / 'report' / 'report.json').read_text())
    assert 'friction_velocity' not in js


def test_in_pieces_the_same_v_f_is_reported(drive, tmp_path, monkeypatch):
    """The drive in blocks (pipeline.blocks, the offline stream) states the one block's."""
    vehicle, observer = estimate_bag.load_parameters(None, FRICTION[1::2])
    one = estimate_bag.run(drive, tmp_path / 'one', vehicle=vehicle, observer=observer,
                           mode='offline', figures=False)
    monkeypatch.setattr(plan, 'STREAM_MIN_SAMPLES', 1)
    monkeypatch.setattr(drive_blocks, 'BLOCK_SAMPLES', 5000)
    many = estimate_bag.run(drive, tmp_path / 'many', vehicle=vehicle, observer=observer,
                            mode='offline', figures=False)
    assert not hasattr(many.estimates, 'wheel_load_n')          # went in blocks
    assert one.summary['friction_velocity']['taken_mps'] == pytest.approx(PLANT_VF)
    assert many.summary['friction_velocity'] == one.summary['friction_velocity']
    assert _line((tmp_path / 'many' / 'report' / 'report.md').read_text()) == \
        _line((tmp_path / 'one' / 'report' / 'report.md').read_text())


def test_the_whole_vehicles_report_states_its_fitted_v_f(tmp_path, capsys, monkeypatch):
    """A 5-axle drive (simulate_bag, 6 s of class C, 1.5 kN of tanh friction per spring, the
    plant's v_f 0.02 m/s: test_whole_vehicle_friction_fit's) and the file's 0.01: its section
    states the plant's 0.02, fitted, in one block and in pieces; the front axle's (the package
    defaults: no friction) no v_f."""
    import pathlib
    import subprocess
    import sys

    config = pathlib.Path(__file__).resolve().parents[2] / 'config' / 'tractor_semitrailer.yaml'
    text = config.read_text(encoding='utf-8')
    assert text.count('leaf_spring_friction: [0.0, 0.0]') == 1
    params = tmp_path / 'friction.yaml'
    params.write_text(text.replace('leaf_spring_friction: [0.0, 0.0]',
                                   'leaf_spring_friction: [1500.0, 1500.0]'), encoding='utf-8')
    bag = tmp_path / 'drive'
    sim = subprocess.run([str(pathlib.Path(sys.executable).parent / 'simulate_bag'),
                          '--params-file', str(params), '-p',
                          'vehicle.leaf_spring_friction_velocity:=0.02', '--road',
                          'iso8608:C:seed=11', '--speed', '20', '--rate', '1000', '--duration',
                          '6', '--gnss-rate', '0', '--no-progress', '--output', str(bag)],
                         capture_output=True, text=True, timeout=300)
    assert sim.returncode == 0, sim.stderr
    one, md, err = _run(bag, tmp_path / 'one', ['--params-file', str(params)], capsys)
    assert 'friction_velocity' not in one
    fv = one['whole_vehicle_estimate']['friction_velocity']
    assert fv['taken_mps'] == pytest.approx(0.02)                # the plant's
    assert fv['file_mps'] == FILE_VF and fv['fitted'] and fv['changed']
    assert '0.02 m/s fitted from the drive' in _line(md)
    notes = [a for a in err.splitlines() if 'friction v_f' in a]
    assert len(notes) == 1 and "the whole vehicle's" in notes[0] and '0.02 m/s' in notes[0]
    monkeypatch.setattr(plan, 'STREAM_MIN_SAMPLES', 1)
    monkeypatch.setattr(drive_blocks, 'BLOCK_SAMPLES', 2500)
    from road_force_estimator.pipeline import whole_vehicle as stage
    spilled, offline = [], stage._offline                 # the stage in pieces
    monkeypatch.setattr(stage, '_offline', lambda *a, **k: spilled.append(1) or offline(*a, **k))
    many, md_many, _ = _run(bag, tmp_path / 'many', ['--params-file', str(params)], capsys)
    assert spilled
    assert many['whole_vehicle_estimate']['friction_velocity'] == fv
    assert _line(md_many) == _line(md)


def test_the_fleet_table_gets_the_v_f_taken(drive, tmp_path):
    """estimate_fleet's table (fleet_outputs.fleet_table, from each drive's report as
    fleet_drives.report_counts reads it): ``friction_velocity_mps`` the plant's 0.005 on every
    row of the drive whose file states friction, NaN on the other's; no such column in a
    fleet without it."""
    from road_force_estimator.tools.fleet_drives import (
        DriveOutcome, read_segments_csv, report_counts)
    from road_force_estimator.tools.fleet_outputs import FRICTION_COLUMN, fleet_table

    outcomes = []
    for name, args in (('fit', FRICTION[1::2]), ('none', [])):
        vehicle, observer = estimate_bag.load_parameters(None, args)
        r = estimate_bag.run(drive, tmp_path / name, vehicle=vehicle, observer=observer,
                             mode='offline', figures=False, segment_length_m=50.0)
        table = read_segments_csv(tmp_path / name / 'report' / 'segments.csv')
        outcomes.append(DriveOutcome(name, 'processed', table=table,
                                     **report_counts(r.summary)))
    table = fleet_table(outcomes)
    rows = table['drive'] == 'fit'
    assert rows.sum() >= 4 and (~rows).sum() >= 4
    np.testing.assert_allclose(table[FRICTION_COLUMN][rows], PLANT_VF)
    assert np.isnan(table[FRICTION_COLUMN][~rows]).all()
    assert FRICTION_COLUMN not in fleet_table(outcomes[1:])

