"""ROS 2 parameters of the nodes: declared from :data:`.parameters.PARAMETERS`, vetted when set.

Every parameter a node uses is declared with a ``ParameterDescriptor`` (description with the unit
and the range, the type, a ``FloatingPointRange``/``IntegerRange`` where it is bounded) and read
once into the core's frozen dataclasses. One rule decides what a good value is: the dataclasses
of :mod:`.parameters` (or :func:`check_value` for node-local parameters), whose ``ValueError``
names the parameter, the value and the range.

* At start-up (:func:`declare`), values given with ``-p`` or ``--params-file`` are checked before
  they are declared: a bad one raises :class:`ParameterError` with that message (the node's
  ``main`` prints it and exits non-zero). An integer given for a double (``-p x:=2``) is taken as
  that double; rclpy alone would refuse it with a message that names the type, not the value.
* Live sets (:class:`ParameterGuard`): an on-set callback builds a candidate configuration from
  the current values and the new ones; a bad value is refused with
  ``SetParametersResult(successful=False, reason=<parameter, value, range>)`` and the running
  configuration is untouched; a good one is applied by a post-set callback. rclpy checks the
  descriptor (type, range) before any on-set callback and words its own refusals
  (``Parameter <name> out of range Min: .., Max: .., value: ..``, which names all three); a value
  of the wrong type is caught earlier, in a pre-set callback, so that its refusal names it too.

Array parameters (``[left, right]`` pairs) carry the element range in their descriptor for
``ros2 param describe``; rclpy checks ranges of scalars only, so the pairs are checked here.
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass
import math
import sys
from typing import Any, Callable, Iterable, Mapping, Sequence

import rclpy
from rcl_interfaces.msg import (
    FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult)
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.utilities import remove_ros_args

from road_force_estimator.core.articulated_parameters import axle_specs, check_model_names
from road_force_estimator.core.parameters import (
    ARTICULATED_PARAMETERS, PARAMETERS, SPECS, ParameterSpec, check_spec, spec_of,
    validate_parameter)

__all__ = [
    'ParameterError', 'NODE_LOCAL_NAMES', 'local_spec', 'specs_with_prefix', 'descriptor',
    'check_value', 'declare', 'refuse_unknown_names', 'ParameterGuard', 'init_ros',
    'articulated_names', 'articulated_specs', 'articulated_requested',
]

# Parameter kinds of parameters.ParameterSpec, plus node-local ones ('string_list', 'bool').
_TYPES = {
    'double': Parameter.Type.DOUBLE,
    'double_pair': Parameter.Type.DOUBLE_ARRAY,
    'integer': Parameter.Type.INTEGER,
    'string': Parameter.Type.STRING,
    'string_list': Parameter.Type.STRING_ARRAY,
    'bool': Parameter.Type.BOOL,
}


class ParameterError(ValueError):
    """A parameter value refused at start-up; the message names the parameter, value and range."""


#: Node-local parameters (INTERFACES.md: not in the shared files), by node. A key of a
#: parameter file that is neither one of these, nor in the shared table, nor a ROS one
#: (``use_sim_time``, ``qos_overrides.*``) is a typo and refused at start.
NODE_LOCAL_NAMES = {
    'plant_simulator': ('realtime_factor', 'start_timeout', 'road_timeout', 'start_nodes',
                        'start_subscribers'),
    'bag_recorder': ('topics', 'output'),
}
_ROS_NAMES = ('use_sim_time', 'start_type_description_service')


def _known_name(name: str, node_specs: Mapping[str, ParameterSpec]) -> bool:
    return (name in node_specs or name in SPECS or name in _ROS_NAMES
            or name.startswith('qos_overrides.')
            or any(name in names for names in NODE_LOCAL_NAMES.values()))


def refuse_unknown_names(node: Node, specs: Iterable[ParameterSpec]) -> None:
    """Refuse a start-up value (``-p``, ``--params-file``, ``parameter_overrides``) whose name
    is no parameter at all (a typo such as ``vehicle.sprung_mas``): rclpy alone ignores it.

    Raises
    ------
    ParameterError
        Naming the node and the unknown names.
    """
    node_specs = {s.name: s for s in specs}
    overrides = getattr(node, '_parameter_overrides', None) or {}
    unknown = sorted(n for n in overrides if not _known_name(n, node_specs))
    other = [n for n in unknown if spec_of(n) is not None]   # the articulated model's names
    if other and len(other) == len(unknown):
        raise ParameterError(f'{node.get_name()}: refused {", ".join(other[:3])}'
                             f'{", ..." if len(other) > 3 else ""}: parameters of '
                             'vehicle.model: articulated, which this node does not model')
    if unknown:
        raise ParameterError(f'{node.get_name()}: refused {", ".join(unknown)}: no such '
                             'parameter (a typo?); the parameters are listed by --help')


def local_spec(name: str, kind: str, default: Any, unit: str, description: str,
               low: float = -math.inf, high: float = math.inf,
               choices: Sequence[str] = ()) -> ParameterSpec:
    """A node-local parameter (not in the shared table), e.g. the recorder's ``topics``."""
    if kind not in _TYPES:
        raise ValueError(f'{name}: unknown parameter kind {kind!r}')
    return ParameterSpec(name, kind, default, unit, description, low, high, tuple(choices))


def _range_text(spec: ParameterSpec) -> str:
    if spec.kind == 'string_list':
        return 'a list of strings'
    if spec.kind == 'bool':
        return 'true or false'
    return spec.range_text()


def specs_with_prefix(*prefixes: str) -> tuple[ParameterSpec, ...]:
    """The shared parameters whose names start with one of ``prefixes`` (e.g. ``'vehicle.'``)."""
    return tuple(s for s in PARAMETERS if s.name.startswith(prefixes))


def articulated_names(*prefixes: str) -> tuple[ParameterSpec, ...]:
    """The articulated model's whole-vehicle names (``vehicle.axles``, ``vehicle.tractor.*``,
    ...) whose names start with one of ``prefixes``: declared beside the shared ones by a node
    that models ``vehicle.model: articulated`` (the per-axle ones: :func:`articulated_specs`)."""
    return tuple(s for s in ARTICULATED_PARAMETERS if s.name.startswith(prefixes))


def articulated_requested(node: Node) -> bool:
    """True when the start-up values of ``node`` (``-p``, ``--params-file``,
    ``parameter_overrides``) set ``vehicle.model: articulated``."""
    given = getattr(node, '_parameter_overrides', None) or {}
    p = given.get('vehicle.model')
    return p is not None and p.value == 'articulated'


def articulated_specs(node: Node) -> tuple[ParameterSpec, ...]:
    """The per-axle specs of an articulated vehicle given at start (``vehicle.model:
    articulated`` among the start-up values: the axles of ``vehicle.axles``, defaults from
    the whole-vehicle values given), else none. The plant_simulator and the observer declare
    the same (``vehicle.axle.<name>.*`` and ``simulator.axle.<name>.*``).

    Raises
    ------
    ParameterError
        A name the vehicle does not have (one line, naming the node).
    """
    if not articulated_requested(node):
        return ()
    overrides = {n: p.value for n, p in node._parameter_overrides.items()}
    try:
        values = {n: validate_parameter(n, v) for n, v in overrides.items()
                  if n.startswith(('vehicle.', 'simulator.'))}
        check_model_names(values, values)
        return axle_specs(values)
    except ValueError as exc:
        raise ParameterError(f'{node.get_name()}: refused {exc}') from None


def descriptor(spec: ParameterSpec, *, read_only: bool = False) -> ParameterDescriptor:
    """The ROS descriptor of ``spec``: type, description with unit and range, numeric range."""
    unit = f' ({spec.unit})' if spec.unit else ''
    d = ParameterDescriptor(
        name=spec.name, type=_TYPES[spec.kind].value, read_only=read_only,
        description=f'{spec.description}{unit}; valid: {_range_text(spec)}')
    if spec.kind == 'double_pair':
        d.additional_constraints = f'[left, right], each in {spec.range_text()}'
    elif spec.choices:
        d.additional_constraints = spec.range_text()
    if spec.kind in ('double', 'double_pair') and (math.isfinite(spec.low)
                                                  or math.isfinite(spec.high)):
        d.floating_point_range = [FloatingPointRange(
            from_value=float(spec.low), to_value=float(spec.high), step=0.0)]
    elif spec.kind == 'integer' and math.isfinite(spec.low) and math.isfinite(spec.high):
        d.integer_range = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high),
                                        step=0)]
    return d


def _coerce(spec: ParameterSpec, value: Any) -> Any:
    """Integers where doubles are expected become doubles; arrays become lists."""
    if spec.kind == 'double' and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if spec.kind in ('double_pair', 'string_list') and not isinstance(value, (str, bytes)):
        try:
            items = list(value)
        except TypeError:
            return value
        if spec.kind == 'double_pair':
            return [float(v) if isinstance(v, int) and not isinstance(v, bool) else v
                    for v in items]
        return items
    return value


def check_value(spec: ParameterSpec, value: Any) -> Any:
    """Return ``value`` checked and normalised for ``spec``.

    Raises
    ------
    ValueError
        Wrong type or out of range; the message names the parameter, the value and the range.
    """
    value = _coerce(spec, value)
    bad = f'{spec.name} = {value!r}'
    if spec.kind == 'string_list':
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise ValueError(f'{bad}: expected a list of strings')
        return tuple(value)
    if spec.kind == 'bool':
        if not isinstance(value, bool):
            raise ValueError(f'{bad}: expected true or false')
        return value
    return check_spec(spec, value)


def _ros_value(spec: ParameterSpec, value: Any):
    """The value to declare: a Python value of the declared type, or the type for ``[]``.

    rclpy infers a type from the value, and an empty list would be taken for a byte array.
    """
    if isinstance(value, (tuple, list)):
        return list(value) if value else _TYPES[spec.kind]
    return value


def declare(node: Node, specs: Iterable[ParameterSpec], *,
            read_only: bool = False) -> dict[str, Any]:
    """Declare ``specs`` on ``node``; return ``{name: checked value}``.

    Values given at start-up (``-p``, ``--params-file``, ``parameter_overrides``) are checked
    with :func:`check_value` before they are declared. A spec without a default (None) and
    without a start-up value is declared unset (its value None: the node's build refuses it
    by name).

    Raises
    ------
    ParameterError
        A start-up value is refused; the message names the node, parameter, value and range.
    """
    # rclpy keeps the start-up values here (no public accessor); without it, rclpy's own checks
    # still refuse a bad value and the message below names the parameter.
    overrides = getattr(node, '_parameter_overrides', None) or {}
    values: dict[str, Any] = {}
    for spec in specs:
        value = spec.default
        if spec.name in overrides:
            value = overrides[spec.name].value
        elif value is None:     # no default (an axle's value that must be given): unset
            node.declare_parameter(spec.name, _TYPES[spec.kind], descriptor(
                spec, read_only=read_only))
            values[spec.name] = None
            continue
        try:
            value = check_value(spec, value)
            declared = node.declare_parameter(
                spec.name, _ros_value(spec, value), descriptor(spec, read_only=read_only),
                ignore_override=spec.name in overrides)
            values[spec.name] = value if declared.value is None else check_value(
                spec, declared.value)
        except (ValueError, InvalidParameterValueException,
                InvalidParameterTypeException) as exc:
            raise ParameterError(f'{node.get_name()}: refused {exc}') from None
    return values


@dataclass
class _Pending:
    values: dict[str, Any]
    config: Any


class ParameterGuard:
    """Declared parameters of one node, their built configuration, and the vetting of live sets.

    Parameters
    ----------
    node : rclpy.node.Node
        The node that owns the parameters.
    specs : iterable of ParameterSpec
        What to declare (:func:`specs_with_prefix`, :func:`local_spec`).
    build : callable(values: dict) -> config
        Builds the node's configuration (e.g. core dataclasses) from ``{name: value}``; raises
        ``ValueError`` naming the parameter for a value or combination it refuses.
    apply : callable(config) -> None, optional
        Called after a live set succeeded, with the new configuration.
    read_only : bool
        Declare every parameter read-only (live sets refused by rclpy, naming the parameter).

    Attributes
    ----------
    values : dict
        Current ``{name: checked value}``.
    config
        Current result of ``build(values)``.
    refusals : list of str
        Reasons of the live sets refused so far (newest last; for diagnostics).

    Raises
    ------
    ParameterError
        A start-up value is refused (by :func:`declare` or by ``build``).
    """

    def __init__(self, node: Node, specs: Iterable[ParameterSpec],
                 build: Callable[[Mapping[str, Any]], Any],
                 apply: Callable[[Any], None] | None = None, *, read_only: bool = False):
        self._node = node
        self._specs = {s.name: s for s in specs}
        self._build = build
        self._apply = apply
        refuse_unknown_names(node, self._specs.values())
        self._read_only = read_only
        self.values = declare(node, self._specs.values(), read_only=read_only)
        try:
            self.config = build(self.values)
        except ValueError as exc:
            raise ParameterError(f'{node.get_name()}: refused {exc}') from None
        self.refusals: list[str] = []
        self._type_errors: list[str] = []
        self._pending: _Pending | None = None
        node.add_pre_set_parameters_callback(self.pre_set_callback)
        node.add_on_set_parameters_callback(self.on_set_callback)
        node.add_post_set_parameters_callback(self.post_set_callback)

    def pre_set_callback(self, params: list[Parameter]) -> list[Parameter]:
        """Coerce integers given for doubles; hold a set that will be refused for a named,
        counted refusal.

        rclpy refuses an undeclared name ("undeclared parameter(s): []": it names none), a
        wrong type and a value outside the descriptor's range itself, before any on-set
        callback, so those refusals were neither counted nor all named. Such a parameter is
        replaced by the current value of a declared one (which passes rclpy's checks) and
        refused by :meth:`on_set_callback` with a message that names it. A read-only node's
        sets are refused by rclpy (naming the parameter); they are counted here.
        """
        self._type_errors = []
        out = []
        for p in params:
            reason = self._early_refusal(p)
            if reason is None:
                spec = self._specs[p.name]
                value = p.value if p.type_ == _TYPES[spec.kind] else _coerce(spec, p.value)
                out.append(Parameter(p.name, _TYPES[spec.kind], value))
                continue
            if self._read_only:   # rclpy refuses it (read-only); count it here
                self._refuse(reason)
                out.append(p)
            else:
                self._type_errors.append(reason)
                name = p.name if p.name in self._specs else next(iter(self._specs))
                out.append(self._node.get_parameter(name))
        return out

    def _early_refusal(self, p: Parameter) -> str | None:
        """Why rclpy would refuse ``p`` before the on-set callback (None: it would not)."""
        spec = self._specs.get(p.name)
        if spec is None:
            return f'{p.name}: no such parameter of {self._node.get_name()}'
        if self._read_only:
            return f'{p.name} is read-only: restart {self._node.get_name()} to change it'
        value = p.value if p.type_ == _TYPES[spec.kind] else _coerce(spec, p.value)
        if not _TYPES[spec.kind].check(value):
            try:
                check_value(spec, p.value)
            except ValueError as exc:
                return str(exc)
            return f'{p.name} = {p.value!r}: expected {_range_text(spec)}'
        try:
            check_value(spec, value)
        except ValueError as exc:
            return str(exc)
        return None

    def _refuse(self, reason: str) -> SetParametersResult:
        self.refusals.append(reason)
        self._node.get_logger().warning(f'parameter set refused: {reason}')
        return SetParametersResult(successful=False, reason=reason)

    def on_set_callback(self, params: list[Parameter]) -> SetParametersResult:
        """Build a candidate configuration; refuse (naming the value) if it cannot be built."""
        self._pending = None
        if self._type_errors:
            reasons, self._type_errors = self._type_errors, []
            return self._refuse('; '.join(reasons))
        candidate = dict(self.values)
        try:
            for p in params:
                spec = self._specs.get(p.name)
                if spec is not None:
                    candidate[p.name] = check_value(spec, p.value)
            config = self._build(candidate)
        except ValueError as exc:
            return self._refuse(str(exc))
        self._pending = _Pending(candidate, config)
        return SetParametersResult(successful=True)

    def post_set_callback(self, params: list[Parameter]) -> None:
        """Adopt the vetted candidate and hand it to ``apply``."""
        pending, self._pending = self._pending, None
        if pending is None or not any(p.name in self._specs for p in params):
            return
        self.values, self.config = pending.values, pending.config
        if self._apply is not None:
            self._apply(pending.config)


def init_ros(prog: str, description: str, specs: Iterable[ParameterSpec],
             args: Sequence[str] | None, **init_kwargs) -> None:
    """Start a node's process: ``--help`` (listing its parameters), then ``rclpy.init``.

    Arguments outside ``--ros-args`` other than ``--help`` are a usage error (``SystemExit(2)``,
    as argparse makes it). ``args`` is what ``main(args)`` received: ``None`` for
    ``sys.argv``, else a full argv (program name first), as ``rclpy.init(args=...)`` takes it;
    ``init_kwargs`` go to ``rclpy.init``.

    Raises
    ------
    ParameterError
        rcl refuses the ROS arguments (e.g. a params file that is not valid YAML); one line.
    """
    argv = list(sys.argv if args is None else args)
    lines = [f'  {s.name} ({_range_text(s)}): {s.description}' for s in specs]
    parser = argparse.ArgumentParser(
        prog=prog, description=description.replace('``', ''),
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog='ROS arguments: --ros-args [-p NAME:=VALUE]... [--params-file FILE]\n'
               'parameters:\n' + '\n'.join(lines))
    try:
        plain = remove_ros_args(argv)
    except Exception as exc:  # rcl refuses bad ROS arguments or an unreadable params file
        raise ParameterError(f'{prog}: {exc}') from None
    parser.parse_args(plain[1:])
    try:
        rclpy.init(args=argv, **init_kwargs)
    except Exception as exc:  # rcl's RCLError
        raise ParameterError(f'{prog}: {exc}') from None
