"""One parameter reader (issue 29): a file reads the same in a node (rcl's YAML parser, through
rclpy) and in every offline command (core.ros_yaml through core.parameters).

The reference is rcl itself: rclpy hands a node the values rcl_yaml_param_parser made of the
file; the tests read the same file both ways and compare type and value.
"""
from __future__ import annotations

import dataclasses
import math
import pathlib

import pytest
import rclpy
from rclpy.context import Context
from rclpy.node import Node

from road_force_estimator.core import ros_yaml
from road_force_estimator.core.parameters import load_params_file, parse_override
from road_force_estimator.ros.observer import Observer
from road_force_estimator.ros.plant_simulator import PlantSimulator
from road_force_estimator.ros.ros_parameters import ParameterError
from road_force_estimator.tools import calibrate_vehicle, estimate_bag, simulate_bag

REPO = pathlib.Path(__file__).resolve().parents[2]
CONFIGS = sorted((REPO / 'config').glob('*.yaml'))
# Scalars whose reading differs between YAML 1.1 (PyYAML) and rcl, and the usual ones.
SCALARS = ['1.1e6', '1e-05', '5', '010', '0x1A', '08', '1_000', '~', 'null', 'yes', 'y', 'N',
           'inf', '.inf', '-.Inf', 'nan', 'Infinity', '1e999', '1e-400', '0x1p3', '5.', '.5',
           '+5', '1:20', "'5'", '"1e6"', '!!str 5', '!!float 5', '99999999999999999999',
           '-0x10', '1.5E+3', '+.5', '-5e-3', '0', '-0', '0.0', 'off', 'On', 'abc', '0b101',
           '1e', '0x1.8p1', '12abc', '[1.1e6, 1.08e6]', '[1, 2]', '[a, b]', '[true, false]']
# A vehicle file as users write it: exponents without a dot, integers for doubles.
NUMBERS_FILE = """/**:
  ros__parameters:
    vehicle:
      sprung_mass: 5200
      roll_inertia: 3.1e3
      tire_stiffness: [1.1e6, 1.08e6]
      suspension_stiffness: [400000, 410000]
      suspension_damping: [1.5e4, 1.6E+4]
    observer:
      lipschitz_deflection: 3e3
      latency: 1e-2
    simulator:
      rate: 1e3
      duration: 2
      noise:
        deflection: 1e-05
      seed: 0x10
"""


def params_file(tmp_path, text: str) -> pathlib.Path:
    path = tmp_path / 'params.yaml'
    path.write_text(text)
    return path


def rcl_context(*ros_args: str) -> Context:
    context = Context()
    rclpy.init(args=['test', '--ros-args', *ros_args], context=context)
    return context


def same(a, b) -> bool:
    if isinstance(a, (list, tuple)) or hasattr(a, 'tolist'):
        return isinstance(b, list) and len(a) == len(b) and all(map(same, list(a), b))
    nan = isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b)
    return type(a) is type(b) and (a == b or nan)


def test_every_scalar_reads_as_rcl_reads_it(tmp_path):
    text = '/**:\n  ros__parameters:\n' + ''.join(f'    k{i}: {v}\n' for i, v in
                                                  enumerate(SCALARS))
    path = params_file(tmp_path, text)
    context = rcl_context('--params-file', str(path))
    node = Node('reader', context=context, allow_undeclared_parameters=True,
                automatically_declare_parameters_from_overrides=True)
    try:
        ours = ros_yaml.load(text)['/**']['ros__parameters']
        for i, scalar in enumerate(SCALARS):
            rcl = node.get_parameter(f'k{i}').value
            assert same(rcl, ours[f'k{i}']), (scalar, rcl, ours[f'k{i}'])
        # YAML 1.1 reads these differently: the point of the reader
        assert ours['k0'] == 1.1e6 and ours['k1'] == 1e-05 and ours['k3'] == 8
        assert ours['k6'] == '1_000' and ours['k7'] == '~' and ours['k10'] is True
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def test_a_minus_p_value_reads_as_rcl_reads_it():
    for value in ('1.1e6', '[1.1e6, 1.08e6]', '0x10', '1e-05', 'yes', "'2.0'"):
        context = rcl_context('-p', f'k:={value}')
        node = Node('reader', context=context, allow_undeclared_parameters=True,
                    automatically_declare_parameters_from_overrides=True)
        try:
            assert same(node.get_parameter('k').value, ros_yaml.load(value)), value
        finally:
            node.destroy_node()
            rclpy.try_shutdown(context=context)


def node_configs(path: pathlib.Path):
    """(observer's (vehicle, observer), plant's (vehicle, simulator)) as the nodes read
    ``path``."""
    out = []
    for cls in (Observer, PlantSimulator):
        context = rcl_context('--params-file', str(path))
        node = cls(context=context)
        try:
            out.append(node.params.config[:2])
        finally:
            node.destroy_node()
            rclpy.try_shutdown(context=context)
    return out


def offline_configs(path: pathlib.Path, *overrides: str):
    """The same through every offline command's own reading function."""
    p_args = [a for o in overrides for a in ('-p', o)]
    estimator = estimate_bag.load_parameters(str(path), list(overrides))
    sim_args = simulate_bag.build_parser().parse_args(
        ['--road', 'flat', '--params-file', str(path), *p_args, '--output', 'unused'])
    plant = simulate_bag.parameters_from(sim_args)
    cal_args = calibrate_vehicle.build_parser().parse_args(
        ['drive', '--profile', 'flat', '--params-file', str(path), *p_args,
         '--output', 'unused.yaml'])
    values, _ = calibrate_vehicle._parameters(cal_args)
    return estimator, plant, values


def _articulated(path: pathlib.Path) -> bool:
    return load_params_file(path).get('vehicle.model') == 'articulated'


FRONT_AXLE = [p.name for p in CONFIGS if not _articulated(p)]
ARTICULATED = [p.name for p in CONFIGS if _articulated(p)]


@pytest.mark.parametrize('name', ARTICULATED)
def test_an_articulated_file_reads_the_same_in_the_plant_node_and_simulate_bag(name):
    """``vehicle.model: articulated``: the plant node, the observer node, simulate_bag and
    estimate_bag build the same vehicle (the whole vehicle's estimator in both)."""
    from road_force_estimator.core.articulated_setup import ArticulatedDrive
    path = REPO / 'config' / name
    context = rcl_context('--params-file', str(path))
    try:
        node = PlantSimulator(context=context)
        drive, simulator = node.params.config[:2]
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    args = simulate_bag.build_parser().parse_args(
        ['--road', 'flat', '--params-file', str(path), '--output', 'unused'])
    offline = ArticulatedDrive.from_values(simulate_bag.parameter_mapping(args))
    assert offline.vehicle == drive.vehicle
    assert offline.sim == dataclasses.replace(simulator, road='flat')
    context = rcl_context('--params-file', str(path))
    try:
        node = Observer(context=context)
        assert node.whole.params.config[0] == drive.vehicle
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    assert estimate_bag.load_parameters(str(path), [])[0] == drive.vehicle


@pytest.mark.parametrize('name', FRONT_AXLE + ['numbers.yaml'])
def test_every_config_file_reads_the_same_in_the_nodes_and_the_offline_commands(
        tmp_path, name):
    path = REPO / 'config' / name if name != 'numbers.yaml' else params_file(
        tmp_path, NUMBERS_FILE)
    (observer_vehicle, observer), (plant_vehicle, simulator) = node_configs(path)
    estimator, plant, calibration_values = offline_configs(path)
    assert estimator == (observer_vehicle, observer)      # estimate_bag and estimate_fleet
    # simulate_bag (its --road, required, replaces simulator.road)
    assert plant == (plant_vehicle, dataclasses.replace(simulator, road='flat'))
    wanted = {**observer_vehicle.to_parameters(every=True), **observer.to_parameters(
        every=True)}
    got = {k: (list(v) if isinstance(v, tuple) else v) for k, v in calibration_values.items()}
    assert {k: got[k] for k in got if k in wanted} == {k: wanted[k] for k in got if k in wanted}
    if name == 'numbers.yaml':
        assert observer_vehicle.tire_stiffness_npm == (1.1e6, 1.08e6)
        assert observer_vehicle.sprung_mass_kg == 5200.0 and simulator.seed == 16
        assert simulator.noise_deflection_m == 1e-05 and observer.latency_s == 0.01


def test_overrides_read_the_same_in_a_node_and_offline(tmp_path):
    path = REPO / 'config' / 'road_force_estimator.yaml'
    override = 'vehicle.tire_stiffness:=[1.1e6, 1.08e6]'
    context = rcl_context('--params-file', str(path), '-p', override)
    node = Observer(context=context)
    try:
        config = node.params.config
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    estimator, _, _ = offline_configs(path, override)
    assert estimator == config and config[0].tire_stiffness_npm == (1.1e6, 1.08e6)
    assert parse_override(override) == ('vehicle.tire_stiffness', (1.1e6, 1.08e6))


@pytest.mark.parametrize('line, node_words, words', [
    # rcl refuses the file itself; a quoted number is text for both
    ('tire_stiffness: [1000000, 1.08e6]', 'Sequence should be of same type', 'same type'),
    ('sprung_mass: "5000"', "sprung_mass = '5000': expected a number",
     "sprung_mass = '5000': expected a number"),
])
def test_what_a_node_refuses_the_offline_commands_refuse(tmp_path, line, node_words, words):
    path = params_file(tmp_path, f'/**:\n  ros__parameters:\n    vehicle:\n      {line}\n')
    with pytest.raises((ParameterError, RuntimeError), match=node_words):
        node_configs(path)
    with pytest.raises(ValueError, match=words):
        estimate_bag.load_parameters(str(path))
