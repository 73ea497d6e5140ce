"""Parameter table, dataclasses and parameter files (INTERFACES.md "Parameters")."""
import os
import pathlib

import pytest

from road_force_estimator.core.parameters import (
    GRAVITY_MPS2, PARAMETERS, ObserverParameters, SimulatorParameters, VehicleParameters,
    load_params_file, validate_parameter)

REPO = pathlib.Path(__file__).resolve().parents[2]
CONTRACT_NAMES = """
vehicle.sprung_mass vehicle.roll_inertia vehicle.track_width vehicle.cg_height_above_roll_axis
vehicle.unsprung_mass vehicle.suspension_stiffness vehicle.suspension_damping
vehicle.tire_stiffness vehicle.tire_damping vehicle.static_load
observer.lipschitz_deflection observer.lipschitz_roll observer.discretization
observer.profile_cutoff_wavelength observer.latency
simulator.rate simulator.speed simulator.duration simulator.road simulator.noise.deflection
simulator.noise.roll simulator.seed simulator.tire_envelope_length simulator.gnss.rate
simulator.gnss.start_latitude simulator.gnss.start_longitude simulator.gnss.heading
""".split()


def test_every_contract_name_is_declared_with_description_and_range():
    names = {spec.name for spec in PARAMETERS}
    assert set(CONTRACT_NAMES) <= names
    for spec in PARAMETERS:
        assert spec.description
        if spec.kind != 'string':
            assert spec.low <= min(spec.default if isinstance(spec.default, list)
                                   else [spec.default])


def test_model_md_defaults():
    v = VehicleParameters()
    assert (v.sprung_mass_kg, v.roll_inertia_kgm2, v.track_width_m, v.cg_height_m) == (
        5000.0, 3000.0, 2.0, 0.8)
    assert v.unsprung_mass_kg == (450.0, 450.0)
    assert v.suspension_stiffness_npm == (400e3, 400e3)
    assert v.tire_stiffness_npm == (1000e3, 1000e3)
    assert v.half_track_m == 1.0
    # F_c,i = (M/2 + m_i) g, computed by hand: (2500 + 450) * 9.80665
    assert v.static_load_n == pytest.approx((28929.6175, 28929.6175))
    assert VehicleParameters(static_load_setting_n=(30000.0, 0.0)).static_load_n[0] == 30000.0
    assert VehicleParameters(static_load_setting_n=(30000.0, 0.0)).static_load_n[1] == (
        pytest.approx(2950 * GRAVITY_MPS2))


def test_bad_values_are_refused_with_name_value_and_range():
    with pytest.raises(ValueError, match=r'vehicle\.sprung_mass = -5.*\[100, 100000\] kg'):
        VehicleParameters(sprung_mass_kg=-5.0)
    with pytest.raises(ValueError, match=r'vehicle\.unsprung_mass.*\[left, right\]'):
        VehicleParameters(unsprung_mass_kg=(450.0,))
    with pytest.raises(ValueError, match=r'observer\.discretization = .rk9.*euler'):
        ObserverParameters(discretization='rk9')
    with pytest.raises(ValueError, match=r'simulator\.rate = nan'):
        SimulatorParameters(rate_hz=float('nan'))
    with pytest.raises(ValueError, match=r'simulator\.seed.*integer'):
        validate_parameter('simulator.seed', 1.5)
    with pytest.raises(ValueError, match=r'unknown parameter'):
        validate_parameter('vehicle.mass', 1.0)


def test_default_params_file_matches_the_table_and_round_trips(tmp_path):
    values = load_params_file(REPO / 'config' / 'road_force_estimator.yaml')
    assert set(values) == {spec.name for spec in PARAMETERS}
    for spec in PARAMETERS:
        expected = tuple(spec.default) if spec.kind == 'double_pair' else spec.default
        assert values[spec.name] == expected, spec.name
    sim = SimulatorParameters.from_parameters(values)
    assert SimulatorParameters.from_parameters(sim.to_parameters()) == sim


def test_params_file_errors_name_the_file_and_parameter(tmp_path):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('/**:\n  ros__parameters:\n    vehicle:\n      track_width: 9.0\n')
    with pytest.raises(ValueError, match=r'bad\.yaml.*vehicle\.track_width = 9\.0'):
        load_params_file(bad)
    node_only = tmp_path / 'node.yaml'
    node_only.write_text('observer:\n  ros__parameters:\n    observer:\n      latency: 0.01\n')
    assert load_params_file(node_only, node_names=('observer',)) == {'observer.latency': 0.01}
    with pytest.raises(ValueError, match='no "/\\*\\*: ros__parameters:" section'):
        load_params_file(node_only)
    with pytest.raises(ValueError, match='cannot read'):
        load_params_file(tmp_path / 'missing.yaml')


def _params_file(tmp_path, text):
    path = tmp_path / 'p.yaml'
    path.write_text(text)
    return path


def test_yaml_alias_bomb_is_refused_at_once(tmp_path):
    """A 1 KB "billion laughs" file: refused by its first alias, never expanded."""
    lines = ['a0: &a0 [x, x, x, x, x, x, x, x, x, x]']
    lines += [f'a{i}: &a{i} [' + ', '.join([f'*a{i - 1}'] * 10) + ']' for i in range(1, 9)]
    path = _params_file(tmp_path, '\n'.join(lines) + '\n/**:\n  ros__parameters: *a8\n')
    assert path.stat().st_size < 1500
    with pytest.raises(ValueError, match=r'line 2: YAML alias \*a0 refused'):
        load_params_file(path)


def test_duplicate_key_is_refused_naming_both_lines(tmp_path):
    path = _params_file(tmp_path, '/**:\n  ros__parameters:\n    vehicle:\n'
                                  '      sprung_mass: 5000.0\n      sprung_mass: 6000.0\n')
    with pytest.raises(ValueError, match=r"line 5: key 'sprung_mass' given twice "
                                         r'\(first on line 4\)'):
        load_params_file(path)


def test_a_params_file_must_be_a_regular_file(tmp_path):
    fifo = tmp_path / 'fifo.yaml'
    os.mkfifo(fifo)
    with pytest.raises(ValueError, match='not a regular file'):
        load_params_file(fifo)
    with pytest.raises(ValueError, match='not a regular file'):
        load_params_file('/dev/zero')
    with pytest.raises(ValueError, match='not a regular file'):
        load_params_file(tmp_path)


def test_offline_commands_refuse_an_alias_bomb_in_one_line(tmp_path):
    """estimate_bag and simulate_bag refuse the file before reading anything else (exit 1)."""
    import subprocess
    import sys

    lines = ['a0: &a0 [x, x, x, x, x, x, x, x, x, x]']
    lines += [f'a{i}: &a{i} [' + ', '.join([f'*a{i - 1}'] * 10) + ']' for i in range(1, 9)]
    bomb = _params_file(tmp_path, '\n'.join(lines) + '\n/**:\n  ros__parameters: *a8\n')
    bindir = pathlib.Path(sys.executable).parent
    for argv in (['simulate_bag', '--road', 'iso8608:C:seed=1', '--speed', '20', '--rate',
                  '100', '--duration', '1', '--params-file', str(bomb), '--output',
                  str(tmp_path / 'drive')],
                 ['estimate_bag', str(tmp_path / 'none'), '--params-file', str(bomb),
                  '--output', str(tmp_path / 'est')]):
        run = subprocess.run([str(bindir / argv[0]), *argv[1:]], capture_output=True,
                             text=True, timeout=120)
        assert run.returncode in (1, 2), (argv[0], run.stderr)
        assert 'YAML alias' in run.stderr and 'Traceback' not in run.stderr, run.stderr
        assert len(run.stderr.strip().splitlines()) == 1, run.stderr


@pytest.mark.parametrize('preset, latency_s', [('rollover_warning', 0.0),
                                               ('load_monitoring', 0.01),
                                               ('road_survey', 0.01)])
def test_presets_load_and_change_only_what_they_say(preset, latency_s):
    values = load_params_file(REPO / 'config' / f'{preset}.yaml')
    assert values['observer.latency'] == latency_s
    observer = ObserverParameters.from_parameters(values)
    assert observer.latency_s == latency_s
    assert VehicleParameters.from_parameters(values) == VehicleParameters()
