"""ROS parameters of the nodes: descriptors, start-up refusals, vetted live sets."""
import math
import pathlib
import re

import pytest
import rclpy
from rcl_interfaces.msg import ParameterType
from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter

from road_force_estimator.core.parameters import (
    PARAMETERS, ObserverParameters, VehicleParameters, load_params_file)
from road_force_estimator.ros.ros_parameters import (
    ParameterError, ParameterGuard, check_value, declare, local_spec, specs_with_prefix)

REPO = pathlib.Path(__file__).resolve().parents[2]
OBSERVER_SPECS = specs_with_prefix('vehicle.', 'observer.')


def build(values):
    return VehicleParameters.from_parameters(values), ObserverParameters.from_parameters(values)


def make_node(context, overrides=()):
    return Node('params_under_test', context=context,
                parameter_overrides=[Parameter(k, value=v) for k, v in overrides])


def test_every_parameter_is_declared_with_type_unit_and_range(ros_context):
    node = make_node(ros_context)
    try:
        values = declare(node, PARAMETERS)
        assert set(values) == {s.name for s in PARAMETERS}
        types = {'double': ParameterType.PARAMETER_DOUBLE,
                 'double_pair': ParameterType.PARAMETER_DOUBLE_ARRAY,
                 'integer': ParameterType.PARAMETER_INTEGER,
                 'string': ParameterType.PARAMETER_STRING}
        for spec in PARAMETERS:
            d = node.describe_parameter(spec.name)
            assert d.type == types[spec.kind], spec.name
            assert spec.description in d.description
            assert (f'({spec.unit})' in d.description) == bool(spec.unit), spec.name
            if spec.kind in ('double', 'double_pair'):
                (r,) = d.floating_point_range
                assert (r.from_value, r.to_value) == (spec.low, spec.high)
            elif spec.kind == 'integer':
                (r,) = d.integer_range
                assert (r.from_value, r.to_value) == (spec.low, spec.high)
            elif spec.choices:
                assert all(c in d.additional_constraints for c in spec.choices)
            # Declared defaults are the table's defaults.
            got = node.get_parameter(spec.name).value
            assert (list(got) if spec.kind == 'double_pair' else got) == spec.default
    finally:
        node.destroy_node()


@pytest.mark.parametrize('name, value, pattern', [
    ('vehicle.track_width', 10.0, r'vehicle\.track_width = 10\.0 is out of range \[0\.5, 4\] m'),
    ('vehicle.track_width', 'wide', r"vehicle\.track_width = 'wide': expected a number"),
    ('vehicle.unsprung_mass', [450.0, 450.0, 1.0], r'vehicle\.unsprung_mass = .*\[left, right\]'),
    ('vehicle.tire_stiffness', [1e6, -1.0], r'vehicle\.tire_stiffness = .*-1\.0.*\[10000, 1e\+09'),
    ('observer.discretization', 'rk9', r"observer\.discretization = 'rk9'.*euler, taylor"),
    ('observer.latency', math.nan, r'observer\.latency = nan is out of range \[0, 1\] s'),
])
def test_bad_start_up_value_is_refused_naming_it(ros_context, name, value, pattern):
    node = make_node(ros_context, [(name, value)])
    try:
        with pytest.raises(ParameterError, match=pattern):
            ParameterGuard(node, OBSERVER_SPECS, build)
    finally:
        node.destroy_node()


def test_integer_for_a_double_is_taken_as_the_double(ros_context):
    node = make_node(ros_context, [('vehicle.track_width', 3),
                                   ('vehicle.unsprung_mass', [400, 500])])
    try:
        guard = ParameterGuard(node, OBSERVER_SPECS, build)
        vehicle, _ = guard.config
        assert vehicle.track_width_m == 3.0 and isinstance(vehicle.track_width_m, float)
        assert vehicle.unsprung_mass_kg == (400.0, 500.0)
        assert node.get_parameter('vehicle.track_width').type_ == Parameter.Type.DOUBLE
        result, = node.set_parameters([Parameter('observer.latency', value=0)])
        assert result.successful, result.reason
        assert guard.config[1].latency_s == 0.0
    finally:
        node.destroy_node()


def test_live_set_is_vetted_and_a_refusal_leaves_the_running_config(ros_context):
    node = make_node(ros_context)
    applied = []
    try:
        guard = ParameterGuard(node, OBSERVER_SPECS, build, applied.append)
        before = guard.config
        refused = [
            ('vehicle.track_width', 5.0, r'vehicle\.track_width = 5\.0 .*\[0\.5, 4\] m'),
            ('vehicle.track_width', 'x', r"vehicle\.track_width = 'x'.*\[0\.5, 4\] m"),
            ('vehicle.suspension_damping', [1.0, 2e7], r'suspension_damping = .*\[0, 1e\+07\]'),
            ('vehicle.unsprung_mass', 3.0, r'vehicle\.unsprung_mass = 3\.0.*\[left, right\]'),
            ('observer.discretization', 'rk9', r"observer\.discretization = 'rk9'"),
        ]
        for name, value, pattern in refused:
            result, = node.set_parameters([Parameter(name, value=value)])
            assert not result.successful
            assert re.search(pattern, result.reason), result.reason
        assert guard.config == before and applied == []
        assert node.get_parameter('vehicle.track_width').value == 2.0
        # A good set in the same batch as a bad one is refused with it (atomic).
        result = node.set_parameters_atomically([
            Parameter('observer.lipschitz_roll', value=80.0),
            Parameter('observer.discretization', value='rk9')])
        assert not result.successful and guard.config == before
        result, = node.set_parameters([Parameter('observer.discretization', value='euler')])
        assert result.successful
        assert applied == [guard.config]
        assert guard.config[1].discretization == 'euler' and guard.config[0] == before[0]
        assert len(guard.refusals) == len(refused) + 1
    finally:
        node.destroy_node()


def test_every_refused_live_set_is_counted_and_named(ros_context):
    """Refusals rclpy makes itself (undeclared name, range, type) are counted and named too."""
    node = make_node(ros_context)
    try:
        guard = ParameterGuard(node, OBSERVER_SPECS, build)
        refused = [
            ('vehicle.sprung_mas', 5000.0, r'vehicle\.sprung_mas: no such parameter'),
            ('vehicle.track_width', 5.0, r'track_width = 5\.0'),
            ('vehicle.track_width', -1.0, r'track_width = -1\.0'),
            ('vehicle.track_width', 'x', r"track_width = 'x'"),
            ('vehicle.track_width', True, r'track_width = True'),
            ('observer.latency', 9.0, r'observer\.latency = 9\.0'),
            ('vehicle.unsprung_mass', [1.0], r'unsprung_mass'),
            ('vehicle.unsprung_mass', [-1.0, 2.0], r'unsprung_mass'),
            ('observer.discretization', 'rk9', r"discretization = 'rk9'"),
        ]
        for k, (name, value, pattern) in enumerate(refused, 1):
            result, = node.set_parameters_atomically([Parameter(name, value=value)]),
            assert not result.successful, name
            assert re.search(pattern, result.reason), result.reason
            assert len(guard.refusals) == k, (name, guard.refusals)
            assert re.search(pattern, guard.refusals[-1])
        # A good set afterwards is not refused by a leftover of the refused ones.
        result = node.set_parameters_atomically([Parameter('vehicle.track_width', value=2.2)])
        assert result.successful and guard.config[0].track_width_m == 2.2
        assert len(guard.refusals) == len(refused)
    finally:
        node.destroy_node()


def test_read_only_parameters_refuse_live_sets_naming_them(ros_context):
    node = make_node(ros_context)
    try:
        guard = ParameterGuard(node, specs_with_prefix('simulator.'), dict, read_only=True)
        result, = node.set_parameters([Parameter('simulator.rate', value=500.0)])
        assert not result.successful and 'simulator.rate' in result.reason
        assert guard.values['simulator.rate'] == 1000.0
        assert len(guard.refusals) == 1 and 'simulator.rate is read-only' in guard.refusals[0]
    finally:
        node.destroy_node()


def test_node_local_parameters():
    topics = local_spec('topics', 'string_list', ['/a'], '', 'topics to record')
    assert check_value(topics, ['/a', '/b']) == ('/a', '/b')
    with pytest.raises(ValueError, match=r"topics = \['/a', 3\]: expected a list of strings"):
        check_value(topics, ['/a', 3])
    factor = local_spec('realtime_factor', 'double', 1.0, '', 'speed-up', 0.01, 1000.0)
    assert check_value(factor, 2) == 2.0
    with pytest.raises(ValueError, match=r'realtime_factor = 0\.0 is out of range \[0\.01, 1000'):
        check_value(factor, 0.0)
    with pytest.raises(ValueError, match='unknown parameter kind'):
        local_spec('x', 'complex', 0, '', 'x')


def test_params_file_through_rcl_matches_the_offline_reader():
    """The ROS parameter file parsed by rcl (C) gives the values parameters.py (PyYAML) reads."""
    path = REPO / 'config' / 'road_force_estimator.yaml'
    context = Context()
    rclpy.init(context=context, args=['--ros-args', '--params-file', str(path)])
    node = Node('observer', context=context)
    try:
        values = declare(node, PARAMETERS)
        offline = load_params_file(path)
        assert set(offline) <= set(values)
        for name, value in offline.items():
            assert values[name] == value, name
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def test_bad_params_file_value_is_refused_naming_it(tmp_path):
    path = tmp_path / 'bad.yaml'
    path.write_text('/**:\n  ros__parameters:\n    vehicle:\n      tire_damping: [0.0, -5.0]\n'
                    '    observer:\n      latency: 0.5\n')
    context = Context()
    rclpy.init(context=context, args=['--ros-args', '--params-file', str(path)])
    node = Node('observer', context=context)
    try:
        with pytest.raises(ParameterError, match=r'tire_damping = .*-5\.0.*\[0, 1e\+06\]'):
            ParameterGuard(node, OBSERVER_SPECS, build)
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)


@pytest.mark.parametrize('body, unknown', [
    ('    vehicle:\n      sprung_mas: 5200.0\n', 'vehicle.sprung_mas'),
    ('    observer.latencyy: 0.01\n', 'observer.latencyy'),
])
def test_a_typo_key_in_a_params_file_is_refused_at_start(tmp_path, body, unknown):
    path = tmp_path / 'typo.yaml'
    path.write_text('/**:\n  ros__parameters:\n' + body)
    context = Context()
    rclpy.init(context=context, args=['--ros-args', '--params-file', str(path)])
    node = Node('observer', context=context)
    try:
        with pytest.raises(ParameterError, match=re.escape(unknown) + '.*no such parameter'):
            ParameterGuard(node, OBSERVER_SPECS, build)
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def test_shared_and_ros_keys_are_not_typos(ros_context):
    """The shared file's other sections (simulator.*), node-local names of the nodes and
    ROS's own keys start a node that does not use them."""
    node = make_node(ros_context, [('simulator.rate', 500.0), ('realtime_factor', 2.0),
                                   ('use_sim_time', True)])
    try:
        guard = ParameterGuard(node, OBSERVER_SPECS, build)
        assert guard.config[1] == ObserverParameters()
    finally:
        node.destroy_node()


def test_observer_process_refuses_a_typo_in_one_line(tmp_path):
    from node_harness import finish, run_main

    path = tmp_path / 'typo.yaml'
    path.write_text('/**:\n  ros__parameters:\n    vehicle:\n      sprung_mas: 5200.0\n')
    code, _, err = finish(run_main('observer', '--ros-args', '--params-file', str(path)))
    assert code == 1
    assert 'vehicle.sprung_mas' in err and 'no such parameter' in err and 'Traceback' not in err
