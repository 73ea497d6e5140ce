"""simulate_bag: the drive bag it writes against independent references.

References: the plant run directly (road_force_estimator.core.plant.simulate) and the sensor model
with the same seed, the profile the bundled LPA bags were made from, WGS84 geometry written
here (meridian radius), and the parameter precedence of INTERFACES.md (defaults < file <
command line).
"""
import importlib.util
from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest

from road_force_estimator import bagio
from road_force_estimator.core.parameters import VehicleParameters
from road_force_estimator.core.plant import simulate
from road_force_estimator.core.road import iso8608_profile
from road_force_estimator.core.sensors import SensorModel
from road_force_estimator.tools.simulate_bag import build_parser, main

REPO = Path(__file__).resolve().parents[2]
BAGS = REPO / 'bags'
EXE = Path(sys.executable).parent / 'simulate_bag'

WGS84_A = 6378137.0
WGS84_E2 = (1.0 / 298.257223563) * (2.0 - 1.0 / 298.257223563)


def run(argv, capsys):
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_parser_has_the_interface_options():
    args = build_parser().parse_args(['--road', 'iso8608:C', '--speed', '20', '--rate', '1000',
                                      '--duration', '3', '--params-file', 'p.yaml',
                                      '--output', 'd'])
    assert (args.road, args.speed, args.rate, args.duration, args.params_file, args.output) == (
        'iso8608:C', 20.0, 1000.0, 3.0, 'p.yaml', 'd')


class TestDriveBag:
    def test_measurements_and_truth_equal_the_plant_and_the_sensors(self, tmp_path, capsys):
        code, _, err = run(['--road', 'iso8608:C:seed=4', '--speed', 15, '--rate', 500,
                            '--duration', 3, '--seed', 8, '--noise-deflection', 2e-5,
                            '--noise-roll', 3e-4, '--output', tmp_path / 'd'], capsys)
        assert code == 0, err
        assert err.count('\n') == 1 and 'wrote' in err
        d = bagio.read_drive_bag(tmp_path / 'd')
        # The same drive, run here directly: road of the length the command asks for.
        vehicle = VehicleParameters()
        road = iso8608_profile('C', 15 * 3 + 2 * 0.25 + 1.0, seed=4)
        tr = simulate(vehicle, road, speed_mps=15.0, rate_hz=500.0, duration_s=3.0,
                      tire_envelope_m=0.25)
        q, phi = SensorModel(deflection_std_m=2e-5, roll_std_rad=3e-4, seed=8).measure(
            tr.q_m, tr.roll_rad)
        assert len(d.stamps_ns) == 3 * 500 + 1
        np.testing.assert_array_equal(d.stamps_ns - d.stamps_ns[0],
                                      np.round(tr.t_s * 1e9).astype(np.int64))
        np.testing.assert_array_equal(d.q_m, q)
        np.testing.assert_array_equal(d.roll_rad, phi)
        np.testing.assert_array_equal(d.speed_mps, 15.0)
        np.testing.assert_array_equal(d.truth.wheel_load_n, tr.wheel_load_n)
        np.testing.assert_array_equal(d.truth.road_m, tr.road_m)
        np.testing.assert_array_equal(d.truth.distance_m, tr.distance_m)
        assert d.rejected_total == 0 and not d.issues
        # The noise really has the asked standard deviation.
        assert np.std(d.q_m - tr.q_m) == pytest.approx(2e-5, rel=0.05)

    def test_gnss_fixes_on_the_straight_route(self, tmp_path, capsys):
        code, _, err = run(['--road', 'flat:length=100', '--speed', 20, '--rate', 200,
                            '--duration', 2, '--gnss-rate', 5, '--output', tmp_path / 'd'],
                           capsys)
        assert code == 0, err
        f = bagio.read_drive_bag(tmp_path / 'd').fixes
        assert len(f.stamps_ns) == 2 * 5 + 1           # a fix at the start of each period
        assert np.all(np.diff(f.stamps_ns) == 200_000_000)
        # Default route: from (48.1486, 17.1077) heading north at 20 m/s.
        assert f.latitude_deg[0] == 48.1486 and np.all(f.longitude_deg == 17.1077)
        lat = np.radians(0.5 * (f.latitude_deg[1:] + f.latitude_deg[:-1]))
        meridian = WGS84_A * (1 - WGS84_E2) / (1 - WGS84_E2 * np.sin(lat) ** 2) ** 1.5
        step = np.radians(np.diff(f.latitude_deg)) * meridian
        np.testing.assert_allclose(step, 20.0 * 0.2, rtol=1e-6)

    def test_lateral_acceleration_bends_the_route_to_the_left(self, tmp_path, capsys):
        code, _, err = run(['--road', 'flat:length=200', '--speed', 20, '--rate', 200,
                            '--duration', 4, '--lateral-acceleration', '2@1',
                            '--noise-deflection', 0, '--noise-roll', 0,
                            '--output', tmp_path / 'd'], capsys)
        assert code == 0, err
        d = bagio.read_drive_bag(tmp_path / 'd')
        lon = d.fixes.longitude_deg
        t = (d.fixes.stamps_ns - d.fixes.stamps_ns[0]) * 1e-9
        assert np.all(lon[t < 0.95] == 17.1077)             # straight before the step
        assert lon[-1] < 17.1077 - 1e-5                     # heading north, turning left: west
        assert '2@1' in d.custom_data['road_force_estimator.lateral_acceleration']
        # The roll responds to the lateral acceleration (flat road: nothing else moves it).
        assert abs(d.roll_rad[-1]) > 1e-3 and np.all(d.roll_rad[t_index(d, 0.9)] == 0.0)

    def test_parameter_precedence_file_then_command_line(self, tmp_path, capsys):
        params = tmp_path / 'p.yaml'
        params.write_text('/**:\n  ros__parameters:\n    simulator:\n      speed: 10.0\n'
                          '      rate: 250.0\n      duration: 1.0\n      road: "flat:length=60"\n'
                          '      noise:\n        deflection: 0.0\n        roll: 0.0\n'
                          '      gnss:\n        rate: 0.0\n')
        code, _, err = run(['--params-file', params, '--speed', 12, '--output',
                            tmp_path / 'd'], capsys)
        assert code == 0, err
        d = bagio.read_drive_bag(tmp_path / 'd')
        assert np.all(d.speed_mps == 12.0)                  # command line wins
        assert len(d.stamps_ns) == 251                      # rate and duration from the file
        assert d.fixes is None                              # gnss.rate 0: no /fix
        assert np.all(d.q_m == 0.0) and np.all(d.roll_rad == 0.0)   # flat, no noise

    def test_lpa_bag_road_and_no_ground_truth(self, tmp_path, capsys):
        code, _, err = run(['--road', BAGS / 'lpa_iso8608_b', '--speed', 20, '--rate', 500,
                            '--duration', 2, '--output', tmp_path / 'd'], capsys)
        assert code == 0, err
        d = bagio.read_drive_bag(tmp_path / 'd')
        # The bag holds the profile it was made from (bags/README.md): the truth is that road,
        # enveloped over 0.25 m, under the tire.
        road = iso8608_profile('B', 1000.0, seed=21, dx_m=0.1, band_cpm=(0.02, 2.0))
        expect = road.enveloped(0.25).elevation_at(d.truth.distance_m)
        np.testing.assert_allclose(d.truth.road_m, expect, rtol=0, atol=1e-12)
        code, _, err = run(['--road', BAGS / 'lpa_iso8608_b', '--speed', 20, '--rate', 500,
                            '--duration', 1, '--no-ground-truth', '--output', tmp_path / 'm'],
                           capsys)
        assert code == 0, err
        m = bagio.read_drive_bag(tmp_path / 'm')
        assert m.truth is None and len(m.stamps_ns) == 501

    def test_a_road_shorter_than_the_drive_cuts_it(self, tmp_path, capsys):
        code, _, err = run(['--road', 'flat:length=30', '--speed', 20, '--rate', 100,
                            '--duration', 5, '--output', tmp_path / 'd'], capsys)
        assert code == 0
        assert 'road ends' in err
        d = bagio.read_drive_bag(tmp_path / 'd')
        assert 100 < len(d.stamps_ns) < 160 and d.truth.distance_m[-1] <= 30.0

    def test_two_runs_give_identical_bags(self, tmp_path, capsys):
        argv = ['--road', 'iso8608:D:seed=2', '--speed', 25, '--rate', 400, '--duration', 1]
        assert run(argv + ['--output', tmp_path / 'a' / 'd'], capsys)[0] == 0
        assert run(argv + ['--output', tmp_path / 'b' / 'd'], capsys)[0] == 0
        for name in ('d_0.mcap', 'metadata.yaml'):
            assert (tmp_path / 'a' / 'd' / name).read_bytes() == (
                tmp_path / 'b' / 'd' / name).read_bytes()


def t_index(d, t_s):
    return slice(0, int(np.searchsorted((d.stamps_ns - d.stamps_ns[0]) * 1e-9, t_s)))


class TestBadInput:
    @pytest.mark.parametrize('argv, code, text', [
        (['--road', 'iso8608:C', '--speed', '100', '--rate', '100'], 1, 'simulator.speed'),
        (['--road', 'no/such/road.csv', '--speed', '10', '--rate', '100'], 1, 'road source'),
        (['--road', 'iso8608:Z', '--speed', '10', '--rate', '100'], 1, 'Z'),
        (['--road', 'flat', '--speed', 'fast', '--rate', '100'], 2, '--speed'),
        (['--road', 'flat', '--lateral-acceleration', 'x'], 2, '--lateral-acceleration'),
        (['--road', 'flat', '--params-file', '/no/such/file.yaml'], 1, 'parameter file'),
    ])
    def test_one_line_and_a_nonzero_exit(self, tmp_path, capsys, argv, code, text):
        got, _, err = run(argv + ['--output', tmp_path / 'd'], capsys)
        assert got == code
        assert err.count('\n') == 1 and text in err and 'Traceback' not in err
        assert not (tmp_path / 'd').exists()

    def test_missing_output_and_existing_output(self, tmp_path, capsys):
        assert run(['--road', 'flat'], capsys)[0] == 2
        argv = ['--road', 'flat:length=20', '--speed', 10, '--rate', 100, '--duration', 0.5,
                '--output', tmp_path / 'd']
        assert run(argv, capsys)[0] == 0
        code, _, err = run(argv, capsys)
        assert code == 1 and 'exists' in err
        assert 'use --force' in err and 'overwrite=True' not in err   # no Python-API hint
        assert run(argv + ['--force'], capsys)[0] == 0

    def test_help_shows_the_defaults_and_p_overrides_the_file(self, tmp_path, capsys):
        text = ' '.join(build_parser().format_help().split())
        for option in ('speed, m/s (default 20.0)', 'sample rate, Hz (default 1000.0)',
                       "(default 'iso8608:C:seed=1')", 'standard deviation, m (default 1e-05)',
                       '-p NAME:=VALUE'):
            assert option in text, option
        f = tmp_path / 'p.yaml'
        f.write_text('/**:\n  ros__parameters:\n    simulator.speed: 12.0\n'
                     '    simulator.rate: 100.0\n')
        from road_force_estimator.tools.simulate_bag import parameters_from
        args = build_parser().parse_args(['--params-file', str(f), '-p', 'simulator.speed:=8',
                                          '--output', 'x'])
        _, sim = parameters_from(args)
        assert sim.speed_mps == 8.0 and sim.rate_hz == 100.0
        args = build_parser().parse_args(['-p', 'simulator.speed:=8', '--speed', '9', '-o', 'x'])
        assert parameters_from(args)[1].speed_mps == 9.0              # the option comes last
        code, _, err = run(['--road', 'flat', '-p', 'simulator.sped:=8', '--output',
                            tmp_path / 'd'], capsys)
        assert code == 1 and "unknown parameter 'simulator.sped'" in err


def test_bundled_bags_are_reproducible(tmp_path):
    spec = importlib.util.spec_from_file_location('make_sample_bags',
                                                  BAGS / 'make_sample_bags.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.main(['--output', str(tmp_path)]) == 0
    for folder, _, _ in module.BAGS:
        (bundled,) = (BAGS / folder).glob('*.mcap')
        assert (tmp_path / folder / bundled.name).read_bytes() == bundled.read_bytes()
        profile = bagio.read_lpa_bag(BAGS / folder)
        assert profile.length_m >= 1000.0
    total = sum(p.stat().st_size for p in BAGS.rglob('*') if p.is_file())
    assert total < 5e6


def test_installed_executable(tmp_path):
    assert EXE.is_file(), f'{EXE}: run scripts/setup'
    ok = subprocess.run([str(EXE), '--road', 'flat:length=30', '--speed', '10', '--rate', '100',
                         '--duration', '1', '--output', str(tmp_path / 'd')],
                        capture_output=True, text=True, timeout=120)
    assert ok.returncode == 0, ok.stderr
    assert len(bagio.read_drive_bag(tmp_path / 'd').stamps_ns) == 101
    bad = subprocess.run([str(EXE), '--road', 'flat', '--rate', '0', '--output',
                          str(tmp_path / 'e')], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 1 and bad.stderr.count('\n') == 1 and 'simulator.rate' in bad.stderr


def test_speed_profile_brakes_stops_and_pulls_away(tmp_path, capsys):
    # simulator.speed_profile (INTERFACES.md): a CSV time_s,speed_mps; /vehicle/twist, the
    # distance and /fix follow it, and standing still the route does not move.
    csv = tmp_path / 'speed.csv'
    csv.write_text('time_s,speed_mps\n0,10\n1,10\n2,0\n3,0\n4,5\n')
    code, _, err = run(['--road', 'flat:length=100', '--rate', 200, '--duration', 4,
                        '--gnss-rate', 5, '-p', f'simulator.speed_profile:={csv}',
                        '--output', tmp_path / 'd'], capsys)
    assert code == 0, err
    d = bagio.read_drive_bag(tmp_path / 'd')
    t = (d.stamps_ns - d.stamps_ns[0]) * 1e-9
    np.testing.assert_allclose(d.speed_mps, np.interp(t, [0, 1, 2, 3, 4], [10, 10, 0, 0, 5]),
                               atol=1e-12)
    f = d.fixes
    ft = (f.stamps_ns - d.stamps_ns[0]) * 1e-9
    still = (ft >= 2.0) & (ft <= 3.0)
    assert still.sum() >= 5
    assert np.ptp(f.latitude_deg[still]) == 0.0
    # 10 m in the first second, 5 m braking, 2.5 m pulling away: 17.5 m north in all
    lat = np.radians(f.latitude_deg[-1])
    meridian = WGS84_A * (1 - WGS84_E2) / (1 - WGS84_E2 * np.sin(lat) ** 2) ** 1.5
    travelled = np.radians(f.latitude_deg[-1] - f.latitude_deg[0]) * meridian
    assert travelled == pytest.approx(17.5, rel=1e-3)


def test_truck_effects_reach_the_bag(tmp_path, capsys):
    # Friction and bump stops in the plant, a 3 ms deflection lag, a scale error and an offset
    # on the roll, stamp jitter: the bag against the plant and the sensor model run here.
    code, _, err = run(['--road', 'iso8608:C:seed=4', '--speed', 15, '--rate', 500,
                        '--duration', 2, '--seed', 8, '--output', tmp_path / 'd',
                        '-p', 'vehicle.leaf_spring_friction:=[1500.0, 1000.0]',
                        '-p', 'vehicle.sensor_time_constant:=[0.003, 0.0]',
                        '-p', 'simulator.bump_stop_stiffness:=2e6',
                        '-p', 'simulator.bump_stop_clearance:=0.005',
                        '-p', 'simulator.sensor_scale_error.roll:=0.02',
                        '-p', 'simulator.sensor_offset.roll:=0.001',
                        '-p', 'simulator.stamp_jitter:=5e-5'], capsys)
    assert code == 0, err
    d = bagio.read_drive_bag(tmp_path / 'd')
    from road_force_estimator.core.vehicle_model import SpringOptions
    vehicle = VehicleParameters(leaf_spring_friction_n=(1500.0, 1000.0),
                                sensor_time_constant_s=(0.003, 0.0))
    road = iso8608_profile('C', 15 * 2 + 2 * 0.25 + 1.0, seed=4)
    tr = simulate(vehicle, road, speed_mps=15.0, rate_hz=500.0, duration_s=2.0,
                  tire_envelope_m=0.25, springs=SpringOptions(0.0, 0.005, 2e6))
    sensor = SensorModel(deflection_std_m=1e-5, roll_std_rad=1e-4, seed=8,
                         time_constant_s=(0.003, 0.0), rate_hz=500.0,
                         scale_error=(0.0, 0.0, 0.02), offset=(0.0, 0.0, 0.001),
                         stamp_jitter_s=5e-5)
    q, phi = sensor.measure(tr.q_m, tr.roll_rad)
    np.testing.assert_array_equal(d.q_m, q)
    np.testing.assert_array_equal(d.roll_rad, phi)
    np.testing.assert_array_equal(d.truth.wheel_load_n, tr.wheel_load_n)
    # the stamps moved by the documented draws (within +-50 us), the samples did not
    expect = np.round((tr.t_s + sensor.stamp_offsets_s(tr.t_s.size)) * 1e9).astype(np.int64)
    np.testing.assert_array_equal(d.stamps_ns - d.stamps_ns[0] + expect[0], expect)
    offsets_ns = expect - np.round(tr.t_s * 1e9).astype(np.int64)
    assert np.max(np.abs(offsets_ns)) <= 50_000 and np.std(offsets_ns) > 20_000


@pytest.mark.parametrize('argv, what', [
    (['--duration', '1e6', '--rate', '1e5'], 'a synthetic road of 2e+07 m'),
    (['--duration', '1e4', '--rate', '1e5'], '1000000001 samples (10000 s at 100000 Hz)')])
def test_a_drive_that_cannot_fit_in_memory_is_refused_before_it_starts(tmp_path, capsys,
                                                                      monkeypatch, argv, what):
    """Issue 28: --duration 1e6 --rate 1e5 failed late with a MemoryError. The memory
    available is made 8 GB here (the machine's own varies)."""
    from road_force_estimator.tools import cli
    monkeypatch.setattr(cli, 'available_memory', lambda: 8e9)
    code, out, err = run(['--road', 'iso8608:C', '--speed', '20', *argv, '--output',
                          tmp_path / 'huge', '--no-progress'], capsys)
    assert (code, out) == (1, '')
    assert err.startswith(f'simulate_bag: {what} would need about ')
    assert err.endswith(' GB of memory, more than the 8 GB available: shorten --duration or '
                        'lower --rate\n') and err.count('\n') == 1
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize('option', ['--speed', '--rate', '--duration', '--noise-deflection',
                                    '--gnss-rate'])
def test_non_finite_options_are_refused(tmp_path, capsys, option):
    code, out, err = run(['--road', 'flat', option, 'nan', '--output', tmp_path / 'x'], capsys)
    assert code == 2 and err == (f"simulate_bag: error: argument {option}: 'nan': must be a "
                                 'finite number\n')
