"""Parameters of the tractor and semi-trailer (``vehicle.model: articulated``, MODEL.md "The
whole vehicle"): axles, bodies, fifth wheel, as frozen dataclasses validated once.

Names are INTERFACES.md's ("The whole vehicle"): ``vehicle.axles`` lists the axles front first;
``vehicle.axle.<name>.*`` and ``simulator.axle.<name>.*`` are declared from it
(:func:`axle_specs`), with MODEL.md's defaults for the axles ``front``, ``drive`` and
``trailer_1..3`` and, for the per-axle forms of a whole-vehicle effect (friction, zero load,
sensor lag, progressive springs, sensor scale and offset), the whole-vehicle value. Any other
axle gives its values in the parameter file: a 6x4 tractor or a tandem trailer is a file, no
code. Every refusal is one line naming the parameter (:class:`ValueError`).

This module imports no ROS package (the core stays ROS-free).
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, Iterable, Mapping

from road_force_estimator.core.parameters import (
    ARTICULATED_SPECS, AXLE_FIELDS, SPECS, ParameterSpec, axle_parameter_name, axle_spec,
    check_spec, split_axle_name)

__all__ = ['AxleParameters', 'BodyParameters', 'FifthWheelParameters', 'ArticulatedParameters',
           'FRONT_AXLE_NAMES', 'vehicle_model', 'check_model_names', 'axle_specs',
           'given_names']

BODIES = ('tractor', 'trailer')

#: The front-axle model's names, refused with ``vehicle.model: articulated`` (INTERFACES.md),
#: each with what to use instead.
FRONT_AXLE_NAMES = {
    'vehicle.sprung_mass': 'vehicle.tractor.mass and vehicle.trailer.mass',
    'vehicle.roll_inertia': 'vehicle.tractor.roll_inertia and vehicle.trailer.roll_inertia',
    'vehicle.track_width': 'vehicle.axle.<name>.spring_half_track and .wheel_half_track',
    'vehicle.cg_height_above_roll_axis': 'vehicle.tractor.cg_height_above_roll_axis',
    'vehicle.unsprung_mass': 'vehicle.axle.<name>.mass',
    'vehicle.suspension_stiffness': 'vehicle.axle.<name>.suspension_stiffness',
    'vehicle.suspension_damping': 'vehicle.axle.<name>.suspension_damping',
    'vehicle.tire_stiffness': 'vehicle.axle.<name>.tire_stiffness',
    'vehicle.tire_damping': 'vehicle.axle.<name>.tire_damping',
    'vehicle.static_load': 'vehicle.axle.<name>.static_load',
}


@dataclass(frozen=True)
class AxleParameters:
    """One beam axle (MODEL.md): SI units, per-side pairs [left, right]."""

    name: str
    body: str                                   #: 'tractor' or 'trailer'
    position_m: float                           #: xi_j, behind the front axle
    mass_kg: float                              #: m_j, the whole axle
    roll_inertia_kgm2: float                    #: I_a,j
    spring_half_track_m: float                  #: s_j
    wheel_half_track_m: float                   #: w_j
    suspension_stiffness_npm: tuple[float, float]
    suspension_damping_nspm: tuple[float, float]
    auxiliary_roll_stiffness_nmprad: float      #: kphi_j
    tire_stiffness_npm: tuple[float, float]
    tire_damping_nspm: tuple[float, float]
    roll_centre_height_m: float                 #: h_rc,j above the ground
    wheel_radius_m: float                       #: rho_j
    static_load_setting_n: tuple[float, float]  #: 0 = from the statics
    instrumented: bool
    deflection_zero_load_n: tuple[float, float]
    leaf_spring_friction_n: tuple[float, float]
    sensor_time_constant_s: float               #: lag of the deflection sensors
    spring_progression_per_m: float             #: plant only
    bump_stop_clearance_m: float                #: plant only
    bump_stop_stiffness_npm: float              #: plant only
    sensor_scale_error: tuple[float, float]     #: plant only
    sensor_offset_m: tuple[float, float]        #: plant only


#: AxleParameters field -> (prefix, parameter field).
_AXLE_MAP = {
    'body': ('vehicle', 'body'), 'position_m': ('vehicle', 'position'),
    'mass_kg': ('vehicle', 'mass'), 'roll_inertia_kgm2': ('vehicle', 'roll_inertia'),
    'spring_half_track_m': ('vehicle', 'spring_half_track'),
    'wheel_half_track_m': ('vehicle', 'wheel_half_track'),
    'suspension_stiffness_npm': ('vehicle', 'suspension_stiffness'),
    'suspension_damping_nspm': ('vehicle', 'suspension_damping'),
    'auxiliary_roll_stiffness_nmprad': ('vehicle', 'auxiliary_roll_stiffness'),
    'tire_stiffness_npm': ('vehicle', 'tire_stiffness'),
    'tire_damping_nspm': ('vehicle', 'tire_damping'),
    'roll_centre_height_m': ('vehicle', 'roll_centre_height'),
    'wheel_radius_m': ('vehicle', 'wheel_radius'),
    'static_load_setting_n': ('vehicle', 'static_load'),
    'instrumented': ('vehicle', 'instrumented'),
    'deflection_zero_load_n': ('vehicle', 'deflection_zero_load'),
    'leaf_spring_friction_n': ('vehicle', 'leaf_spring_friction'),
    'sensor_time_constant_s': ('vehicle', 'sensor_time_constant'),
    'spring_progression_per_m': ('simulator', 'spring_progression'),
    'bump_stop_clearance_m': ('simulator', 'bump_stop_clearance'),
    'bump_stop_stiffness_npm': ('simulator', 'bump_stop_stiffness'),
    'sensor_scale_error': ('simulator', 'sensor_scale_error'),
    'sensor_offset_m': ('simulator', 'sensor_offset'),
}


@dataclass(frozen=True)
class BodyParameters:
    """A sprung body, tractor or trailer (MODEL.md), SI units."""

    name: str
    mass_kg: float                              #: M_b
    cg_position_m: float                        #: xi_b, behind the front axle
    pitch_inertia_kgm2: float                   #: I_y,b
    roll_inertia_kgm2: float                    #: I_x,b
    cg_height_m: float                          #: H_b above the ground
    cg_height_above_roll_axis_m: float          #: h_b


_BODY_MAP = {'mass_kg': 'mass', 'cg_position_m': 'cg_position',
             'pitch_inertia_kgm2': 'pitch_inertia', 'roll_inertia_kgm2': 'roll_inertia',
             'cg_height_m': 'cg_height',
             'cg_height_above_roll_axis_m': 'cg_height_above_roll_axis'}


@dataclass(frozen=True)
class FifthWheelParameters:
    """The fifth wheel (kingpin) coupling, SI units."""

    position_m: float                           #: xi_5, behind the front axle
    vertical_stiffness_npm: float               #: k_5
    vertical_damping_nspm: float                #: c_5
    roll_stiffness_nmprad: float                #: kphi_5
    roll_damping_nmsprad: float                 #: cphi_5


_FIFTH_MAP = {'position_m': 'position', 'vertical_stiffness_npm': 'vertical_stiffness',
              'vertical_damping_nspm': 'vertical_damping',
              'roll_stiffness_nmprad': 'roll_stiffness', 'roll_damping_nmsprad': 'roll_damping'}


@dataclass(frozen=True)
class ArticulatedParameters:
    """The whole vehicle: axles front first, the two bodies, the fifth wheel and the settings
    shared by every axle. Build with :meth:`from_parameters` (every check there)."""

    axles: tuple[AxleParameters, ...]
    tractor: BodyParameters
    trailer: BodyParameters
    fifth_wheel: FifthWheelParameters
    trailer_roll_sensor: bool = True
    tractor_imu: bool = False
    deflection_reference: str = 'equilibrium'
    leaf_spring_friction_model: str = 'tanh'
    leaf_spring_friction_velocity_mps: float = 0.01
    leaf_spring_friction_stiffness_ratio: float = 8.0
    roll_time_constant_s: float = 0.0           #: lag of the roll sensors
    #: what the roll sensors read, the observer's measurement model (``vehicle.roll_sensor``)
    roll_sensor: str = 'ideal'

    @property
    def axle_names(self) -> tuple[str, ...]:
        return tuple(a.name for a in self.axles)

    @property
    def zero_load(self) -> bool:
        """True when the deflections are read from a mechanical zero."""
        return self.deflection_reference == 'zero_load'

    @property
    def spring_friction_n(self) -> tuple[float, ...]:
        """Every spring's friction F_f (N), axle by axle, left then right."""
        return tuple(f for a in self.axles for f in a.leaf_spring_friction_n)

    def body(self, name: str) -> BodyParameters:
        return self.tractor if name == 'tractor' else self.trailer

    @classmethod
    def from_parameters(cls, values: Mapping[str, Any],
                        given: Iterable[str] | None = None) -> ArticulatedParameters:
        """Build from ``{dotted name: value}``; names missing take their defaults.

        ``given``: the names the user gave (default: the keys of ``values``), checked with
        :func:`check_model_names`.

        Raises
        ------
        ValueError
            One line naming the parameter: a name of the front-axle model, an axle that
            ``vehicle.axles`` does not list, a value out of range or not given, a body that
            is not tractor or trailer, axles out of order, a trailer axle ahead of the
            kingpin.
        """
        values = dict(values)
        check_model_names(values if given is None else given, {**values,
                                                                'vehicle.model': 'articulated'})
        axles = tuple(_axle(name, values) for name in _axle_list(values))
        _check_layout(axles, values)

        def pick(prefix: str, table: Mapping[str, str]) -> dict[str, Any]:
            return {f: _value(f'{prefix}.{p}', values) for f, p in table.items()}

        tau = _value('vehicle.sensor_time_constant', values)
        return cls(axles=axles,
                   tractor=BodyParameters('tractor', **pick('vehicle.tractor', _BODY_MAP)),
                   trailer=BodyParameters('trailer', **pick('vehicle.trailer', _BODY_MAP)),
                   fifth_wheel=FifthWheelParameters(**pick('vehicle.fifth_wheel', _FIFTH_MAP)),
                   trailer_roll_sensor=_value('vehicle.trailer_roll_sensor', values),
                   tractor_imu=_value('vehicle.tractor_imu', values),
                   deflection_reference=_value('vehicle.deflection_reference', values),
                   leaf_spring_friction_model=_value('vehicle.leaf_spring_friction_model',
                                                     values),
                   leaf_spring_friction_velocity_mps=_value(
                       'vehicle.leaf_spring_friction_velocity', values),
                   leaf_spring_friction_stiffness_ratio=_value(
                       'vehicle.leaf_spring_friction_stiffness', values),
                   roll_time_constant_s=tau[1],
                   roll_sensor=_value('vehicle.roll_sensor', values))

    def to_parameters(self) -> dict[str, Any]:
        """Every parameter of the vehicle by dotted name (pairs as lists), as a file has them:
        ``from_parameters(to_parameters())`` gives the same vehicle."""
        out: dict[str, Any] = {'vehicle.model': 'articulated',
                               'vehicle.axles': list(self.axle_names)}
        for axle in self.axles:
            for f, (prefix, name) in _AXLE_MAP.items():
                out[axle_parameter_name(prefix, axle.name, name)] = _plain(getattr(axle, f))
        for body in (self.tractor, self.trailer):
            for f, name in _BODY_MAP.items():
                out[f'vehicle.{body.name}.{name}'] = getattr(body, f)
        for f, name in _FIFTH_MAP.items():
            out[f'vehicle.fifth_wheel.{name}'] = getattr(self.fifth_wheel, f)
        out.update({'vehicle.trailer_roll_sensor': self.trailer_roll_sensor,
                    'vehicle.tractor_imu': self.tractor_imu,
                    'vehicle.deflection_reference': self.deflection_reference,
                    'vehicle.leaf_spring_friction_model': self.leaf_spring_friction_model,
                    'vehicle.leaf_spring_friction_velocity':
                        self.leaf_spring_friction_velocity_mps,
                    'vehicle.leaf_spring_friction_stiffness':
                        self.leaf_spring_friction_stiffness_ratio,
                    'vehicle.sensor_time_constant': [0.0, self.roll_time_constant_s]})
        if self.roll_sensor != 'ideal':     # (added later: what earlier files wrote stays)
            out['vehicle.roll_sensor'] = self.roll_sensor
        return out


def _plain(value):
    return list(value) if isinstance(value, tuple) else value


def _spec(name: str) -> ParameterSpec:
    return SPECS.get(name) or ARTICULATED_SPECS[name]


def _value(name: str, values: Mapping[str, Any]) -> Any:
    """A shared or articulated parameter: the given value (checked), else the default."""
    spec = _spec(name)
    value = values.get(name, spec.default)
    return check_spec(spec, tuple(value) if isinstance(value, list) else value)


def _axle_list(values: Mapping[str, Any]) -> tuple[str, ...]:
    names = _value('vehicle.axles', values)
    if not names:
        raise ValueError('vehicle.axles = []: the vehicle needs at least one axle per body')
    for name in names:
        if not name.isidentifier():
            raise ValueError(f'vehicle.axles: {name!r} is not a valid axle name (letters, '
                             'digits and _, not starting with a digit)')
    if len(set(names)) != len(names):
        twice = sorted({n for n in names if names.count(n) > 1})
        raise ValueError(f'vehicle.axles: {", ".join(twice)} listed twice')
    return names


def _axle(name: str, values: Mapping[str, Any]) -> AxleParameters:
    out: dict[str, Any] = {}
    for f, (prefix, pname) in _AXLE_MAP.items():
        key = axle_parameter_name(prefix, name, pname)
        spec = axle_spec(prefix, name, pname, values)
        value = values.get(key, spec.default)
        if value is None:
            raise ValueError(f'{key}: not given (axle {name!r} has no default values: only '
                             "front, drive and trailer_1..3 have MODEL.md's; give its body, "
                             'position, mass, roll_inertia, half tracks, stiffnesses, damping, '
                             'roll centre height and wheel radius)')
        out[f] = check_spec(spec, tuple(value) if isinstance(value, list) else value)
    return AxleParameters(name=name, **out)


def _check_layout(axles: tuple[AxleParameters, ...], values: Mapping[str, Any]) -> None:
    """Axles front first, the first one at 0 on the tractor, tractor axles before trailer
    axles, every trailer axle behind the kingpin, at least one axle per body."""
    first = axles[0]
    if first.body != 'tractor' or first.position_m != 0.0:
        raise ValueError(f'vehicle.axle.{first.name}: the first axle of vehicle.axles is the '
                         f"tractor's front axle at position 0 m (got body {first.body!r}, "
                         f'position {first.position_m:g} m)')
    for a, b in zip(axles, axles[1:]):
        if not b.position_m > a.position_m:
            raise ValueError(f'vehicle.axle.{b.name}.position = {b.position_m:g} m: axles go '
                             f'front first, behind {a.name} at {a.position_m:g} m')
        if a.body == 'trailer' and b.body == 'tractor':
            raise ValueError(f'vehicle.axle.{b.name}.body = tractor: behind the trailer axle '
                             f"{a.name} (the tractor's axles come first)")
    kingpin = _value('vehicle.fifth_wheel.position', values)
    for a in axles:
        if a.body == 'trailer' and not a.position_m > kingpin:
            raise ValueError(f'vehicle.axle.{a.name}.position = {a.position_m:g} m: a trailer '
                             f'axle must be behind the kingpin (vehicle.fifth_wheel.position '
                             f'= {kingpin:g} m)')
    if not any(a.body == 'trailer' for a in axles):
        raise ValueError('vehicle.axles: no axle has body trailer (the semi-trailer needs one)')


def vehicle_model(values: Mapping[str, Any]) -> str:
    """``vehicle.model`` of a parameter mapping (its default when missing)."""
    return _value('vehicle.model', values)


def given_names(names: Iterable[str]) -> list[str]:
    """The names that matter to :func:`check_model_names` (vehicle.* and simulator.*)."""
    return [n for n in names if n.startswith(('vehicle.', 'simulator.'))]


def check_model_names(given: Iterable[str], values: Mapping[str, Any]) -> None:
    """Refuse a given name that the vehicle model of ``values`` does not have.

    With ``front_axle``: the articulated model's names (``vehicle.axles``,
    ``vehicle.tractor.*``, per-axle names...). With ``articulated``: the front-axle model's
    (:data:`FRONT_AXLE_NAMES`, naming what to use) and a per-axle name of an axle that
    ``vehicle.axles`` does not list.

    Raises
    ------
    ValueError
        One line naming the first such parameter.
    """
    model = vehicle_model(values)
    names = sorted(given_names(given))
    if model == 'front_axle':
        for name in names:
            if name in ARTICULATED_SPECS or split_axle_name(name) is not None:
                raise ValueError(f'{name}: a parameter of vehicle.model: articulated (this '
                                 'vehicle is front_axle; set vehicle.model: articulated)')
        return
    axles = _axle_list(values)
    for name in names:
        if name in FRONT_AXLE_NAMES:
            raise ValueError(f'{name}: a parameter of the front-axle model, refused with '
                             f'vehicle.model: articulated: use {FRONT_AXLE_NAMES[name]}')
        parts = split_axle_name(name)
        if parts is not None and parts[1] not in axles:
            raise ValueError(f'{name}: no axle {parts[1]!r} in vehicle.axles '
                             f'({", ".join(axles)})')


def axle_specs(values: Mapping[str, Any]) -> tuple[ParameterSpec, ...]:
    """The per-axle specs of the axles ``vehicle.axles`` lists in ``values`` (defaults: see
    :func:`.parameters.axle_spec`; the whole-vehicle values taken from ``values``), for the
    nodes to declare."""
    out = []
    for name in _axle_list(values):
        for prefix, pname, *_ in AXLE_FIELDS:
            out.append(axle_spec(prefix, name, pname, values))
    return tuple(out)


def _check_fields() -> None:
    """Every AxleParameters field is mapped (import-time consistency)."""
    names = {f.name for f in fields(AxleParameters)} - {'name'}
    if names != set(_AXLE_MAP) or len(_AXLE_MAP) != len(AXLE_FIELDS):
        raise RuntimeError('articulated_parameters: _AXLE_MAP and AXLE_FIELDS disagree')


_check_fields()
