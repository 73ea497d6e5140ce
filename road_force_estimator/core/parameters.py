"""Parameters: the one table of names, defaults, units and ranges, and the frozen dataclasses.

Names are those of ``../shared/design/INTERFACES.md`` (``vehicle.*``, ``observer.*``,
``simulator.*``); defaults are those of ``MODEL.md``. Nodes declare their ROS parameters
from :data:`PARAMETERS`; offline commands read the same ``/**: ros__parameters:`` files with
:func:`load_params_file`. Every value is validated once, when a dataclass is built: a bad value
raises :class:`ValueError` naming the parameter, the value, the unit and the valid range.

This module imports no ROS package (the core stays ROS-free).
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields
import math
from pathlib import Path
import stat
from typing import Any, Mapping

import yaml

from road_force_estimator.core import ros_yaml

__all__ = [
    'ParameterSpec', 'PARAMETERS', 'SPECS', 'GRAVITY_MPS2',
    'VehicleParameters', 'ObserverParameters', 'SimulatorParameters',
    'validate_parameter', 'check_spec', 'parse_override', 'load_params_file',
    'read_params_document', 'defaults', 'MAX_PARAMS_FILE_BYTES',
    'ARTICULATED_PARAMETERS', 'ARTICULATED_SPECS', 'AXLE_FIELDS', 'AXLE_DEFAULTS',
    'axle_parameter_name', 'split_axle_name', 'axle_spec', 'spec_of',
]

GRAVITY_MPS2 = 9.80665


@dataclass(frozen=True)
class ParameterSpec:
    """One parameter of the contract.

    ``kind`` is ``'double'``, ``'double_pair'`` (``[left, right]``), ``'integer'`` or
    ``'string'``; ``low``/``high`` bound every element (inclusive), ``choices`` a string.
    """

    name: str
    kind: str
    default: Any
    unit: str
    description: str
    low: float = -math.inf
    high: float = math.inf
    choices: tuple[str, ...] = ()

    def range_text(self) -> str:
        if self.kind == 'string':
            return 'one of ' + ', '.join(self.choices) if self.choices else 'any string'
        return f'[{self.low:g}, {self.high:g}] {self.unit}'.rstrip()


def _p(name, kind, default, unit, description, low=-math.inf, high=math.inf, choices=()):
    return ParameterSpec(name, kind, default, unit, description, low, high, tuple(choices))


# The one place where defaults live (MODEL.md "Parameters", INTERFACES.md "Parameters").
PARAMETERS: tuple[ParameterSpec, ...] = (
    _p('vehicle.sprung_mass', 'double', 5000.0, 'kg',
       'sprung mass carried by the front axle', 100.0, 1e5),
    _p('vehicle.roll_inertia', 'double', 3000.0, 'kg m^2',
       'roll inertia of the sprung mass about the roll axis', 10.0, 1e6),
    _p('vehicle.track_width', 'double', 2.0, 'm', 'front axle track width', 0.5, 4.0),
    _p('vehicle.cg_height_above_roll_axis', 'double', 0.8, 'm',
       'height of the sprung-mass centre of gravity above the roll axis', 0.0, 5.0),
    _p('vehicle.unsprung_mass', 'double_pair', [450.0, 450.0], 'kg',
       'unsprung mass per side [left, right]', 1.0, 1e4),
    _p('vehicle.suspension_stiffness', 'double_pair', [400e3, 400e3], 'N/m',
       'suspension stiffness per side [left, right]', 1e3, 1e8),
    _p('vehicle.suspension_damping', 'double_pair', [15e3, 15e3], 'N s/m',
       'suspension damping per side [left, right]', 0.0, 1e7),
    _p('vehicle.tire_stiffness', 'double_pair', [1000e3, 1000e3], 'N/m',
       'tire vertical stiffness per side [left, right]', 1e4, 1e9),
    _p('vehicle.tire_damping', 'double_pair', [0.0, 0.0], 'N s/m',
       'tire vertical damping per side [left, right]', 0.0, 1e6),
    _p('vehicle.static_load', 'double_pair', [0.0, 0.0], 'N',
       'static wheel load per side [left, right]; 0 = (M/2 + m_i) g', 0.0, 1e7),
    _p('vehicle.deflection_reference', 'string', 'equilibrium', '',
       'where the deflection sensors read from: "equilibrium" = static equilibrium under '
       'vehicle.static_load; "zero_load" = a mechanical zero (the observer estimates the '
       'static loads and the payload from the readings, MODEL.md "Measurements")',
       choices=('equilibrium', 'zero_load')),
    _p('vehicle.deflection_zero_load', 'double_pair', [0.0, 0.0], 'N',
       'sprung load per side [left, right] at which each deflection sensor reads 0 under '
       'zero_load; 0 = the spring unloaded', 0.0, 1e7),
    _p('vehicle.leaf_spring_friction', 'double_pair', [0.0, 0.0], 'N',
       'inter-leaf (Coulomb) friction force per spring [left, right], smoothed as '
       'F_f tanh(dq / v_f) with v_f = 0.01 m/s; 0 = none (plant and observer alike)', 0.0, 1e5),
    _p('vehicle.sensor_time_constant', 'double_pair', [0.0, 0.0], 's',
       'first-order lag of the sensors [deflection, roll]; 0 = none (plant and observer '
       'alike)', 0.0, 0.1),
    _p('vehicle.roll_sensor', 'string', 'ideal', '',
       'what the roll sensors read, the measurement model of the observer (the plant: '
       'simulator.roll_sensor): "ideal" = phi; "pendulum" = an inclinometer, phi + a_y / g '
       '(articulated with the tractor IMU: a row on the a_y state of each unit; without it, '
       'and on the front axle, read as phi: docs/sensors.md); "gyro" = an integrated rate '
       'gyro, read as phi (its drift is no state)',
       choices=('ideal', 'pendulum', 'gyro')),
    # The whole vehicle and the friction that sticks (MODEL.md "The whole vehicle", "What the
    # model leaves out"); the articulated model's own names are in ARTICULATED_PARAMETERS.
    _p('vehicle.model', 'string', 'front_axle', '',
       'the vehicle model: "front_axle" = the 4-DOF roll-plane front axle (MODEL.md); '
       '"articulated" = the tractor and semi-trailer with every axle (vehicle.axles)',
       choices=('front_axle', 'articulated')),
    _p('vehicle.leaf_spring_friction_model', 'string', 'tanh', '',
       'law of the leaf-spring friction: "tanh" = -F_f tanh(dq / v_f) (no stick); "stick" = '
       'the elastic-plastic (Jenkins) element, a spring k_f in series with a Coulomb slider '
       'F_f (MODEL.md "Friction that sticks"; the plant simulates it, the observer carries '
       "each slider from its spring's measured deflection)", choices=('tanh', 'stick')),
    _p('vehicle.leaf_spring_friction_velocity', 'double', 0.01, 'm/s',
       'smoothing velocity v_f of the tanh friction law -F_f tanh(dq / v_f)', 1e-4, 1.0),
    _p('vehicle.leaf_spring_friction_stiffness', 'double', 8.0, '',
       'stiffness k_f of the stick element before it slips, per unit suspension stiffness '
       '(k_f = this x k; the leaf pack: about 5-10)', 0.1, 100.0),
    _p('observer.lipschitz_deflection', 'double', 3000.0, 'm/s^3',
       'Lipschitz constant L of the deflection differentiators (bound on |dddq|)', 1e-3, 1e9),
    _p('observer.lipschitz_roll', 'double', 200.0, 'rad/s^3',
       'Lipschitz constant L of the roll differentiator (bound on |dddphi|)', 1e-6, 1e9),
    _p('observer.discretization', 'string', 'model', '',
       'observer: "model" = the Kalman unknown-input observer on the paper\'s model (with an '
       'optional sliding-mode injection, observer.sliding_mode_gain; the default); "euler" '
       '(the paper\'s explicit scheme), "taylor", "implicit", "filtering" (Levant and Livne\'s '
       'filtering differentiators) = the differentiator chain with that scheme',
       choices=('euler', 'taylor', 'implicit', 'model', 'filtering')),
    _p('observer.profile_cutoff_wavelength', 'double', 100.0, 'm',
       'long-wavelength cutoff of the body-heave integration (profile high-pass)', 5.0, 1e4),
    _p('observer.latency', 'double', 0.0, 's',
       'delay of the published estimate behind the newest input sample', 0.0, 1.0),
    _p('observer.sliding_mode_gain', 'double', 0.0, '',
       'weight of the sliding-mode (Levant) injection of the model observer, weighted down '
       'by the noise level; 0 = off (the default: the Kalman unknown-input observer alone; '
       'python -m bench.studies.sliding_mode_events measures it)', 0.0, 10.0),
    _p('observer.noise.deflection', 'double', 0.0, 'm',
       'deflection sensor noise std for the model observer; 0 = estimate online', 0.0, 0.1),
    _p('observer.noise.roll', 'double', 0.0, 'rad',
       'roll sensor noise std for the model observer; 0 = estimate online', 0.0, 0.1),
    _p('observer.road_roughness', 'double', 0.0, 'm^3',
       'ISO 8608 Gd(n0) of the road for the model observer; 0 = estimate online', 0.0, 1.0),
    _p('observer.road_correlation_length', 'double', 0.0, 'm',
       'correlation length of the road velocity under the tire (tire envelope) of the model '
       'observer; 0 = scheduled on the noise level', 0.0, 20.0),
    _p('observer.rollover_cutoff_frequency', 'double', 2.0, 'Hz',
       'low-pass cutoff of the quasi-static LTR for rollover warnings (below the wheel hop)',
       0.05, 50.0),
    _p('observer.distance_source', 'string', 'auto', '',
       'travelled distance: "speed" = the integral of /vehicle/twist; "gnss" = the speed '
       'times the odometer scale estimated from /fix (estimation.odometer; offline mode of '
       'estimate_bag and estimate_fleet); "auto" = gnss when the drive has fixes that '
       'give the scale to 0.2 % (the report says how many and how good), else speed (and '
       'speed online)', choices=('auto', 'speed', 'gnss')),
    _p('observer.innovation_gate', 'double', 6.0, '',
       'innovation gate of the model observer: a channel whose innovation lies beyond this '
       'many standard deviations of its predicted spread is not fed to the filter (a spike; '
       'counted per sensor); 0 = off', 0.0, 1000.0),
    _p('observer.friction_velocity_fit', 'integer', 1, '',
       'offline: 1 = fit v_f of the tanh leaf-spring friction (vehicle.leaf_spring_friction_'
       'velocity x 0.5-2) by the likelihood of the innovations of the online observer over the '
       'first 20 s (estimation.friction_fit; the front axle not under zero_load, the whole '
       'vehicle one v_f for every spring); 0 = the v_f of the file', 0, 1),
    _p('observer.fault_stuck_time', 'double', 0.05, 's',
       'a sensor whose reading has not changed (by more than observer.fault_stuck_tolerance) '
       'for this long while every other sensor moved is flagged stuck (estimation.sensor_health)',
       0.01, 1000.0),
    _p('observer.fault_stuck_tolerance', 'double', 0.0, 'm or rad',
       'largest change between samples that counts as no change for the stuck flag (0 = '
       'exact repeats)', 0.0, 0.1),
    _p('observer.fault_drift_window', 'double', 6.0, 's',
       'window of the momentum balance whose mean force flags a drifting deflection sensor '
       '(estimation.sensor_health)', 1.0, 1000.0),
    _p('observer.fault_drift_offset', 'double', 2e-4, 'm',
       'deflection offset the momentum balance must show for a drifting-sensor flag; 0 = '
       'drift detection off', 0.0, 0.1),
    _p('simulator.rate', 'double', 1000.0, 'Hz', 'output sample rate of the plant', 10.0, 1e5),
    _p('simulator.speed', 'double', 20.0, 'm/s', 'vehicle speed (constant)', 0.1, 60.0),
    _p('simulator.speed_profile', 'string', '', '',
       'varying speed: "" = constant simulator.speed, or a CSV path with the header '
       'time_s,speed_mps (linearly interpolated, speed >= 0: stops allowed)'),
    _p('simulator.duration', 'double', 60.0, 's',
       'simulated time; the drive also stops at the end of the road profile', 0.0, 1e6),
    _p('simulator.road', 'string', 'iso8608:C:seed=1', '',
       'road source: "iso8608:<A-H>[:seed=N]", a path to an LPA bag, CSV or ERD profile, or '
       '"topic" (the profile as it arrives on /lpa/left and /lpa/right)'),
    _p('simulator.noise.deflection', 'double', 1e-5, 'm',
       'standard deviation of the deflection sensor noise', 0.0, 0.1),
    _p('simulator.noise.roll', 'double', 1e-4, 'rad',
       'standard deviation of the roll sensor noise', 0.0, 0.1),
    _p('simulator.seed', 'integer', 1, '', 'seed of the sensor noise', 0, 2**31 - 1),
    _p('simulator.tire_envelope_length', 'double', 0.25, 'm',
       'moving-average length of the tire envelope; 0 = point contact', 0.0, 2.0),
    _p('simulator.gnss.rate', 'double', 10.0, 'Hz', 'rate of /fix; 0 = no /fix', 0.0, 100.0),
    _p('simulator.gnss.start_latitude', 'double', 48.1486, 'deg',
       'WGS84 latitude of the start of the route', -90.0, 90.0),
    _p('simulator.gnss.start_longitude', 'double', 17.1077, 'deg',
       'WGS84 longitude of the start of the route', -180.0, 180.0),
    _p('simulator.gnss.heading', 'double', 0.0, 'deg',
       'route heading, clockwise from north', -360.0, 360.0),
    _p('simulator.gnss.noise', 'double', 0.0, 'm',
       'standard deviation of the white position noise of /fix, per horizontal axis', 0.0,
       100.0),
    _p('simulator.speed_scale_error', 'double', 0.0, '',
       'odometer error: the published /vehicle/twist speed is (1 + e) times the true one '
       '(the route and /fix stay true)', -0.2, 0.2),
    # Plant-only effects (MODEL.md "What the model leaves out"): never told the observer.
    _p('simulator.spring_progression', 'double', 0.0, '1/m',
       'progressive springs (plant only): the spring force k q (1 + p max(-q, 0)), the '
       'stiffness rising by k p per metre of compression; 0 = linear springs', 0.0, 1000.0),
    _p('simulator.bump_stop_clearance', 'double', 0.05, 'm',
       'compression from static equilibrium at which the bump stops engage (plant only)',
       0.001, 1.0),
    _p('simulator.bump_stop_stiffness', 'double', 0.0, 'N/m',
       'bump-stop stiffness (plant only): the force k_b (-q - clearance) beyond the '
       'clearance; 0 = no bump stops', 0.0, 1e9),
    _p('simulator.sensor_scale_error.deflection', 'double_pair', [0.0, 0.0], '',
       'relative scale error of the deflection sensors [left, right] (plant only: reading '
       '(1 + e) q + offset)', -0.5, 0.5),
    _p('simulator.sensor_scale_error.roll', 'double', 0.0, '',
       'relative scale error of the roll sensor (plant only)', -0.5, 0.5),
    _p('simulator.sensor_offset.deflection', 'double_pair', [0.0, 0.0], 'm',
       'offset of the deflection sensors [left, right] (plant only)', -0.1, 0.1),
    _p('simulator.sensor_offset.roll', 'double', 0.0, 'rad',
       'offset of the roll sensor (plant only)', -0.1, 0.1),
    _p('simulator.stamp_jitter', 'double', 0.0, 's',
       'stamp jitter (plant only): each stamp moved by a uniform draw in [-j, +j] (the '
       'samples stay at their true time); below half a sample period; 0 = none', 0.0, 0.01),
    _p('simulator.leaf_spring_friction_start', 'double', 0.0, '',
       'stick friction (plant only): the force each slider holds at the start, per unit F_f, '
       '> 0 upward on the body (a truck loaded while parked: its springs read F_f less per '
       'spring than they carry); 0 = none; needs vehicle.leaf_spring_friction_model = stick',
       -1.0, 1.0),
    _p('simulator.lateral_profile', 'string', '', '',
       'lateral acceleration a_y (> 0 to the left): "" = none; "curve:start=T,ramp=R,'
       'hold=H,ay=A" (a curve entered and left over R s, held H s); or a CSV path with the '
       'header time_s,lateral_accel_mps2 (linearly interpolated, 0 outside it)'),
    _p('simulator.sensor_faults', 'string', '', '',
       'sensor faults (plant only), ";"-separated, each KIND@CHANNEL:KEY=VALUE,...: '
       '"spikes@C:count=N,size=S[,start=T0,end=T1]" (N samples off by +-S), '
       '"stuck@C:start=T,duration=D" (the reading held), "drift@C:rate=R[,start=T]" (an '
       'offset growing R per s); C = a /suspension/deflections joint name; "" = none'),
    _p('simulator.roll_sensor', 'string', 'ideal', '',
       'roll-sensor physics (plant only): "ideal" = phi; "pendulum" = an inclinometer reading '
       'phi + a_y / g; "gyro" = an integrated rate gyro reading phi plus its drift',
       choices=('ideal', 'pendulum', 'gyro')),
    _p('simulator.roll_gyro_drift', 'double', 0.0, 'rad/s',
       'roll_sensor = gyro: bias of the rate, the angle drifting by this per second', -0.01,
       0.01),
    _p('simulator.roll_gyro_random_walk', 'double', 0.0, 'rad/s^0.5',
       'roll_sensor = gyro: angle random walk (white rate noise) of the integrated angle', 0.0,
       0.01),
    _p('simulator.road_crossfall', 'double', 0.0, 'rad',
       'road crossfall or bank (plant only): the road plane tilted by this angle, > 0 = the '
       'left wheel path higher (the roll angle takes it, the deflections do not)', -0.15,
       0.15),
)

SPECS: dict[str, ParameterSpec] = {spec.name: spec for spec in PARAMETERS}

# The articulated model's names (INTERFACES.md "The whole vehicle"; defaults: MODEL.md's
# European 5-axle 40 t combination, config/tractor_semitrailer.yaml). Kinds 'string_list'
# and 'bool' as well as those above.
_BODY = (
    ('mass', 'kg', 'mass of the sprung body', 100.0, 1e5, 6500.0, 29000.0),
    ('cg_position', 'm', 'centre of gravity, distance behind the front axle', -5.0, 60.0, 1.1,
     8.6),
    ('pitch_inertia', 'kg m^2', 'pitch inertia about the centre of gravity', 10.0, 1e8,
     20000.0, 450000.0),
    ('roll_inertia', 'kg m^2', 'roll inertia about the roll axis', 10.0, 1e7, 4000.0, 35000.0),
    ('cg_height', 'm', 'height of the centre of gravity above the ground (braking pitch)', 0.0,
     5.0, 1.1, 2.0),
    ('cg_height_above_roll_axis', 'm', 'height of the centre of gravity above the roll axis',
     0.0, 5.0, 0.6, 1.4),
)
ARTICULATED_PARAMETERS: tuple[ParameterSpec, ...] = (
    _p('vehicle.axles', 'string_list', ['front', 'drive', 'trailer_1', 'trailer_2',
                                        'trailer_3'], '',
       'names of the axles, front first: the per-axle names vehicle.axle.<name>.* and '
       'simulator.axle.<name>.* are declared from it'),
    *(_p(f'vehicle.{body}.{name}', 'double', (tractor, trailer)[i], unit, f'{body}: {text}',
         low, high)
      for i, body in enumerate(('tractor', 'trailer'))
      for name, unit, text, low, high, tractor, trailer in _BODY),
    _p('vehicle.fifth_wheel.position', 'double', 3.2, 'm',
       'fifth wheel (kingpin), distance behind the front axle', 0.0, 60.0),
    _p('vehicle.fifth_wheel.vertical_stiffness', 'double', 5e7, 'N/m',
       'vertical stiffness of the fifth wheel coupling', 1e4, 1e10),
    _p('vehicle.fifth_wheel.vertical_damping', 'double', 1e5, 'N s/m',
       'vertical damping of the fifth wheel coupling', 0.0, 1e8),
    _p('vehicle.fifth_wheel.roll_stiffness', 'double', 3e6, 'N m/rad',
       'roll stiffness between tractor and trailer at the fifth wheel', 0.0, 1e9),
    _p('vehicle.fifth_wheel.roll_damping', 'double', 3e4, 'N m s/rad',
       'roll damping between tractor and trailer at the fifth wheel', 0.0, 1e8),
    _p('vehicle.trailer_roll_sensor', 'bool', True, '',
       'the trailer has a roll-angle sensor (trailer_roll in /suspension/deflections)'),
    _p('vehicle.tractor_imu', 'bool', False, '',
       'the tractor has an IMU at its centre of gravity (/imu/tractor: a_x, a_y, vertical '
       'acceleration + g, roll, pitch and yaw rates)'),
    _p('simulator.noise.imu_acceleration', 'double', 0.05, 'm/s^2',
       'standard deviation of the IMU accelerometer noise, per axis', 0.0, 10.0),
    _p('simulator.noise.imu_rate', 'double', 0.002, 'rad/s',
       'standard deviation of the IMU gyro noise, per axis', 0.0, 1.0),
)
ARTICULATED_SPECS: dict[str, ParameterSpec] = {s.name: s for s in ARTICULATED_PARAMETERS}

#: Per-axle fields: ``vehicle.axle.<name>.<field>`` and ``simulator.axle.<name>.<field>``:
#: (prefix, field, kind, unit, description, low, high, whole-vehicle name giving the default
#: or None). An axle's values default to MODEL.md's table for the names of
#: :data:`AXLE_DEFAULTS`; any other axle gives them (body and position always).
AXLE_FIELDS = (
    ('vehicle', 'body', 'string', '', 'the body carrying the axle: "tractor" or "trailer"',
     None, None, None),
    ('vehicle', 'position', 'double', 'm', 'distance behind the front axle', 0.0, 60.0, None),
    ('vehicle', 'mass', 'double', 'kg', 'mass of the whole axle with its wheels', 10.0, 1e4,
     None),
    ('vehicle', 'roll_inertia', 'double', 'kg m^2', 'roll inertia of the axle', 1.0, 1e5,
     None),
    ('vehicle', 'spring_half_track', 'double', 'm', 'half the spring track s', 0.1, 2.0, None),
    ('vehicle', 'wheel_half_track', 'double', 'm', 'half the wheel track w (dual tires lumped)',
     0.1, 2.0, None),
    ('vehicle', 'suspension_stiffness', 'double_pair', 'N/m',
     'suspension stiffness per side [left, right]', 1e3, 1e8, None),
    ('vehicle', 'suspension_damping', 'double_pair', 'N s/m',
     'suspension damping per side [left, right]', 0.0, 1e7, None),
    ('vehicle', 'auxiliary_roll_stiffness', 'double', 'N m/rad',
     'auxiliary roll stiffness kphi between body and axle (anti-roll bar, axle torsion)', 0.0,
     1e9, None),
    ('vehicle', 'tire_stiffness', 'double_pair', 'N/m',
     'tire vertical stiffness per side [left, right] (duals lumped)', 1e4, 1e9, None),
    ('vehicle', 'tire_damping', 'double_pair', 'N s/m',
     'tire vertical damping per side [left, right]', 0.0, 1e6, None),
    ('vehicle', 'roll_centre_height', 'double', 'm', 'roll centre height above the ground',
     0.0, 3.0, None),
    ('vehicle', 'wheel_radius', 'double', 'm', 'wheel radius (height of the axle centre)', 0.1,
     1.5, None),
    ('vehicle', 'static_load', 'double_pair', 'N',
     'static wheel load per side [left, right]; 0 = from the statics of the spring system',
     0.0, 1e7, None),
    ('vehicle', 'instrumented', 'bool', '',
     'the axle has deflection sensors (<axle>_left_suspension, <axle>_right_suspension)', None,
     None, None),
    ('vehicle', 'deflection_zero_load', 'double_pair', 'N',
     'sprung load per side at which each deflection sensor reads 0 under zero_load', 0.0, 1e7,
     'vehicle.deflection_zero_load'),
    ('vehicle', 'leaf_spring_friction', 'double_pair', 'N',
     'inter-leaf friction force per spring [left, right]; 0 = none', 0.0, 1e5,
     'vehicle.leaf_spring_friction'),
    ('vehicle', 'sensor_time_constant', 'double', 's',
     "first-order lag of the axle's deflection sensors (plant and observer alike)", 0.0, 0.1,
     'vehicle.sensor_time_constant'),
    ('simulator', 'spring_progression', 'double', '1/m',
     'progressive springs of the axle (plant only), see simulator.spring_progression', 0.0,
     1000.0, 'simulator.spring_progression'),
    ('simulator', 'bump_stop_clearance', 'double', 'm',
     'bump-stop clearance of the axle (plant only)', 0.001, 1.0, 'simulator.bump_stop_clearance'),
    ('simulator', 'bump_stop_stiffness', 'double', 'N/m',
     'bump-stop stiffness of the axle (plant only); 0 = none', 0.0, 1e9,
     'simulator.bump_stop_stiffness'),
    ('simulator', 'sensor_scale_error', 'double_pair', '',
     "relative scale error of the axle's deflection sensors [left, right] (plant only)", -0.5,
     0.5, 'simulator.sensor_scale_error.deflection'),
    ('simulator', 'sensor_offset', 'double_pair', 'm',
     "offset of the axle's deflection sensors [left, right] (plant only)", -0.1, 0.1,
     'simulator.sensor_offset.deflection'),
)
_AXLE_FIELD = {(f[0], f[1]): f for f in AXLE_FIELDS}

#: MODEL.md's defaults of the 5-axle combination's axles, by name.
_FRONT = dict(body='tractor', position=0.0, mass=900.0, roll_inertia=600.0,
              spring_half_track=0.45, wheel_half_track=1.02,
              suspension_stiffness=(400e3, 400e3), suspension_damping=(15e3, 15e3),
              auxiliary_roll_stiffness=0.2e6, tire_stiffness=(1000e3, 1000e3),
              roll_centre_height=0.5, wheel_radius=0.5)
_DRIVE = dict(body='tractor', position=3.7, mass=1400.0, roll_inertia=800.0,
              spring_half_track=0.5, wheel_half_track=0.92,
              suspension_stiffness=(450e3, 450e3), suspension_damping=(20e3, 20e3),
              auxiliary_roll_stiffness=0.5e6, tire_stiffness=(2000e3, 2000e3),
              roll_centre_height=0.7, wheel_radius=0.5)
_TRAILER = dict(body='trailer', mass=800.0, roll_inertia=450.0, spring_half_track=0.65,
                wheel_half_track=1.02, suspension_stiffness=(450e3, 450e3),
                suspension_damping=(15e3, 15e3), auxiliary_roll_stiffness=0.8e6,
                tire_stiffness=(1800e3, 1800e3), roll_centre_height=0.6, wheel_radius=0.45)
_COMMON = dict(tire_damping=(0.0, 0.0), static_load=(0.0, 0.0), instrumented=True)
AXLE_DEFAULTS: dict[str, dict[str, Any]] = {
    'front': {**_FRONT, **_COMMON}, 'drive': {**_DRIVE, **_COMMON},
    **{f'trailer_{i + 1}': {**_TRAILER, 'position': x, **_COMMON}
       for i, x in enumerate((9.6, 10.91, 12.22))},
}


def axle_parameter_name(prefix: str, axle: str, name: str) -> str:
    """``<prefix>.axle.<axle>.<name>`` (prefix ``vehicle`` or ``simulator``)."""
    return f'{prefix}.axle.{axle}.{name}'


def split_axle_name(name: str) -> tuple[str, str, str] | None:
    """``(prefix, axle, field)`` of a per-axle parameter name, or None."""
    parts = name.split('.')
    if len(parts) == 4 and parts[1] == 'axle' and (parts[0], parts[3]) in _AXLE_FIELD:
        return parts[0], parts[2], parts[3]
    return None


def axle_spec(prefix: str, axle: str, field_name: str,
              whole: Mapping[str, Any] | None = None) -> ParameterSpec:
    """The spec of one per-axle parameter; its default is MODEL.md's for a default axle
    name, else the whole-vehicle parameter's (``whole``: given values by name, else the
    table's default), else None (to be given)."""
    _, _, kind, unit, text, low, high, parent = _AXLE_FIELD[(prefix, field_name)]
    default = AXLE_DEFAULTS.get(axle, {}).get(field_name)
    if default is None and parent is not None:
        default = (whole or {}).get(parent, SPECS[parent].default)
        if field_name == 'sensor_time_constant':
            default = default[0]          # [deflection, roll]: the deflection sensors' lag
    if default is None and field_name == 'instrumented':
        default = True
    if default is None and field_name in ('tire_damping', 'static_load'):
        default = (0.0, 0.0)
    if isinstance(default, tuple):
        default = list(default)
    low = -math.inf if low is None else low
    high = math.inf if high is None else high
    choices = ('tractor', 'trailer') if field_name == 'body' else ()
    return ParameterSpec(axle_parameter_name(prefix, axle, field_name), kind, default, unit,
                         f'axle {axle}: {text}', low, high, choices)


def spec_of(name: str) -> ParameterSpec | None:
    """The spec of any parameter name: the shared table's, the articulated model's, or a
    per-axle one (for any axle name: whether ``vehicle.axles`` lists it is checked when the
    vehicle is built, :func:`.articulated_parameters.check_axle_names`); None if none."""
    spec = SPECS.get(name) or ARTICULATED_SPECS.get(name)
    if spec is not None:
        return spec
    parts = split_axle_name(name)
    if parts is None or not parts[1].isidentifier():
        return None
    return axle_spec(parts[0], parts[1], parts[2])


def defaults(prefix: str = '') -> dict[str, Any]:
    """Default values by dotted name, optionally only those starting with ``prefix``."""
    return {s.name: s.default for s in PARAMETERS if s.name.startswith(prefix)}


def validate_parameter(name: str, value: Any) -> Any:
    """Return ``value`` checked and normalised for parameter ``name``.

    Raises
    ------
    ValueError
        Unknown name, wrong type or out of range; the message names the parameter, the value
        and the valid range.
    """
    spec = spec_of(name)
    if spec is None:
        raise ValueError(f'unknown parameter {name!r}')
    return check_spec(spec, value)


def check_spec(spec: ParameterSpec, value: Any) -> Any:
    """Return ``value`` checked and normalised for ``spec`` (kinds 'string', 'integer',
    'double', 'double_pair'): the one rule for the shared table and the nodes' own
    parameters.

    Raises
    ------
    ValueError
        Wrong type or out of range; the message names the parameter, the value and the range.
    """
    bad = f'{spec.name} = {value!r}'
    if spec.kind == 'bool':
        if not isinstance(value, bool):
            raise ValueError(f'{bad}: expected true or false')
        return value
    if spec.kind == 'string_list':
        if isinstance(value, (str, bytes)) or not hasattr(value, '__iter__') or not all(
                isinstance(v, str) for v in value):
            raise ValueError(f'{bad}: expected a list of strings')
        return tuple(value)
    if spec.kind == 'string':
        if not isinstance(value, str):
            raise ValueError(f'{bad}: expected a string ({spec.range_text()})')
        if spec.choices and value not in spec.choices:
            raise ValueError(f'{bad}: must be {spec.range_text()}')
        return value
    if spec.kind == 'integer':
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f'{bad}: expected an integer in {spec.range_text()}')
        if not spec.low <= value <= spec.high:
            raise ValueError(f'{bad} is out of range {spec.range_text()}')
        return int(value)
    if spec.kind == 'double_pair':
        if isinstance(value, (str, bytes)) or not hasattr(value, '__len__') or len(value) != 2:
            raise ValueError(f'{bad}: expected [left, right], each in {spec.range_text()}')
        return tuple(_check_double(spec, v, bad) for v in value)
    if spec.kind == 'double':
        return _check_double(spec, value, bad)
    raise ValueError(f'{bad}: unsupported parameter kind {spec.kind!r}')


def _check_double(spec: ParameterSpec, value: Any, bad: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f'{bad}: expected a number in {spec.range_text()}')
    value = float(value)
    if not math.isfinite(value) or not spec.low <= value <= spec.high:
        raise ValueError(f'{bad} is out of range {spec.range_text()}')
    return value


def _param(name: str, *, quiet_default: bool = False):
    """A dataclass field whose default and validation come from :data:`SPECS`.

    ``quiet_default``: :meth:`_FromParameters.to_parameters` leaves the parameter out while it
    has its default (parameters added later, so that what earlier versions wrote, e.g. the
    parameters recorded in a bag, stays byte-identical).
    """
    spec = SPECS[name]
    default = tuple(spec.default) if spec.kind == 'double_pair' else spec.default
    return field(default=default, metadata={'param': name, 'quiet_default': quiet_default})


class _FromParameters:
    """Build from / export to dotted parameter names; validate every field once."""

    def __post_init__(self) -> None:
        for f in fields(self):
            name = f.metadata.get('param')
            if name is not None:
                object.__setattr__(self, f.name, validate_parameter(name, getattr(self, f.name)))
        self._check()

    def _check(self) -> None:
        """Cross-field checks (overridden where needed)."""

    @classmethod
    def from_parameters(cls, values: Mapping[str, Any]):
        """Build from a mapping of dotted names (others ignored); missing names take defaults."""
        kwargs = {f.name: values[f.metadata['param']] for f in fields(cls)
                  if 'param' in f.metadata and f.metadata['param'] in values}
        return cls(**kwargs)

    def to_parameters(self, *, every: bool = False) -> dict[str, Any]:
        """Dotted names to values (pairs as lists, as in a parameter file); the ``quiet_default``
        ones at their defaults only with ``every``."""
        out = {}
        for f in fields(self):
            if 'param' in f.metadata:
                v = getattr(self, f.name)
                if not every and f.metadata.get('quiet_default') and v == f.default:
                    continue
                out[f.metadata['param']] = list(v) if isinstance(v, tuple) else v
        return out


@dataclass(frozen=True)
class VehicleParameters(_FromParameters):
    """Roll-plane half tractor, front axle (MODEL.md). Index 0 = left, 1 = right; SI units."""

    sprung_mass_kg: float = _param('vehicle.sprung_mass')
    roll_inertia_kgm2: float = _param('vehicle.roll_inertia')
    track_width_m: float = _param('vehicle.track_width')
    cg_height_m: float = _param('vehicle.cg_height_above_roll_axis')
    unsprung_mass_kg: tuple[float, float] = _param('vehicle.unsprung_mass')
    suspension_stiffness_npm: tuple[float, float] = _param('vehicle.suspension_stiffness')
    suspension_damping_nspm: tuple[float, float] = _param('vehicle.suspension_damping')
    tire_stiffness_npm: tuple[float, float] = _param('vehicle.tire_stiffness')
    tire_damping_nspm: tuple[float, float] = _param('vehicle.tire_damping')
    static_load_setting_n: tuple[float, float] = _param('vehicle.static_load')
    deflection_reference: str = _param('vehicle.deflection_reference', quiet_default=True)
    deflection_zero_load_n: tuple[float, float] = _param('vehicle.deflection_zero_load',
                                                         quiet_default=True)
    leaf_spring_friction_n: tuple[float, float] = _param('vehicle.leaf_spring_friction',
                                                         quiet_default=True)
    sensor_time_constant_s: tuple[float, float] = _param('vehicle.sensor_time_constant',
                                                         quiet_default=True)
    roll_sensor: str = _param('vehicle.roll_sensor', quiet_default=True)
    leaf_spring_friction_model: str = _param('vehicle.leaf_spring_friction_model',
                                             quiet_default=True)
    leaf_spring_friction_velocity_mps: float = _param('vehicle.leaf_spring_friction_velocity',
                                                      quiet_default=True)
    leaf_spring_friction_stiffness_ratio: float = _param(
        'vehicle.leaf_spring_friction_stiffness', quiet_default=True)

    @property
    def half_track_m(self) -> float:
        """s = T/2: lever arm of each suspension about the roll axis (m)."""
        return 0.5 * self.track_width_m

    @property
    def static_load_n(self) -> tuple[float, float]:
        """Static wheel loads F_c,i (N): the setting, or (M/2 + m_i) g where it is 0."""
        return tuple(
            setting if setting > 0.0 else (0.5 * self.sprung_mass_kg + m) * GRAVITY_MPS2
            for setting, m in zip(self.static_load_setting_n, self.unsprung_mass_kg))

    @property
    def zero_load(self) -> bool:
        """True when the deflections are read from a mechanical zero
        (``vehicle.deflection_reference: zero_load``)."""
        return self.deflection_reference == 'zero_load'

    @property
    def deflection_offset_m(self) -> tuple[float, float]:
        """What a sensor adds to the extension from equilibrium (m), per side: 0 under
        ``equilibrium``; under ``zero_load`` ``-(F_s,i - F_0,i) / k_i`` with the static
        sprung load ``F_s,i = F_c,i - m_i g`` (MODEL.md "Measurements", q_meas = q + offset)."""
        if not self.zero_load:
            return (0.0, 0.0)
        return tuple(-(fc - m * GRAVITY_MPS2 - f0) / k for fc, m, f0, k in zip(
            self.static_load_n, self.unsprung_mass_kg, self.deflection_zero_load_n,
            self.suspension_stiffness_npm))


@dataclass(frozen=True)
class ObserverParameters(_FromParameters):
    """Settings of the estimator (differentiator and reconstruction)."""

    lipschitz_deflection_mps3: float = _param('observer.lipschitz_deflection')
    lipschitz_roll_radps3: float = _param('observer.lipschitz_roll')
    discretization: str = _param('observer.discretization')
    profile_cutoff_wavelength_m: float = _param('observer.profile_cutoff_wavelength')
    latency_s: float = _param('observer.latency')
    sliding_mode_gain: float = _param('observer.sliding_mode_gain')
    noise_deflection_m: float = _param('observer.noise.deflection')
    noise_roll_rad: float = _param('observer.noise.roll')
    road_roughness_m3: float = _param('observer.road_roughness')
    road_correlation_length_m: float = _param('observer.road_correlation_length')
    rollover_cutoff_frequency_hz: float = _param('observer.rollover_cutoff_frequency')
    distance_source: str = _param('observer.distance_source')
    innovation_gate: float = _param('observer.innovation_gate', quiet_default=True)
    friction_velocity_fit: int = _param('observer.friction_velocity_fit',
                                         quiet_default=True)
    fault_stuck_time_s: float = _param('observer.fault_stuck_time', quiet_default=True)
    fault_stuck_tolerance: float = _param('observer.fault_stuck_tolerance', quiet_default=True)
    fault_drift_window_s: float = _param('observer.fault_drift_window', quiet_default=True)
    fault_drift_offset_m: float = _param('observer.fault_drift_offset', quiet_default=True)


@dataclass(frozen=True)
class SimulatorParameters(_FromParameters):
    """Settings of the plant simulator (sensor noise, road, drive, GNSS)."""

    rate_hz: float = _param('simulator.rate')
    speed_mps: float = _param('simulator.speed')
    speed_profile: str = _param('simulator.speed_profile')
    duration_s: float = _param('simulator.duration')
    road: str = _param('simulator.road')
    noise_deflection_m: float = _param('simulator.noise.deflection')
    noise_roll_rad: float = _param('simulator.noise.roll')
    seed: int = _param('simulator.seed')
    tire_envelope_length_m: float = _param('simulator.tire_envelope_length')
    gnss_rate_hz: float = _param('simulator.gnss.rate')
    gnss_start_latitude_deg: float = _param('simulator.gnss.start_latitude')
    gnss_start_longitude_deg: float = _param('simulator.gnss.start_longitude')
    gnss_heading_deg: float = _param('simulator.gnss.heading')
    gnss_noise_m: float = _param('simulator.gnss.noise')
    speed_scale_error: float = _param('simulator.speed_scale_error')
    spring_progression_per_m: float = _param('simulator.spring_progression')
    bump_stop_clearance_m: float = _param('simulator.bump_stop_clearance')
    bump_stop_stiffness_npm: float = _param('simulator.bump_stop_stiffness')
    sensor_scale_error_deflection: tuple[float, float] = _param(
        'simulator.sensor_scale_error.deflection')
    sensor_scale_error_roll: float = _param('simulator.sensor_scale_error.roll')
    sensor_offset_deflection_m: tuple[float, float] = _param('simulator.sensor_offset.deflection')
    sensor_offset_roll_rad: float = _param('simulator.sensor_offset.roll')
    stamp_jitter_s: float = _param('simulator.stamp_jitter')
    leaf_spring_friction_start: float = _param('simulator.leaf_spring_friction_start',
                                               quiet_default=True)
    lateral_profile: str = _param('simulator.lateral_profile', quiet_default=True)
    sensor_faults: str = _param('simulator.sensor_faults', quiet_default=True)
    roll_sensor: str = _param('simulator.roll_sensor', quiet_default=True)
    roll_gyro_drift_radps: float = _param('simulator.roll_gyro_drift', quiet_default=True)
    roll_gyro_random_walk: float = _param('simulator.roll_gyro_random_walk', quiet_default=True)
    road_crossfall_rad: float = _param('simulator.road_crossfall', quiet_default=True)

    def _check(self) -> None:
        if self.stamp_jitter_s >= 0.5 / self.rate_hz:
            raise ValueError(f'simulator.stamp_jitter = {self.stamp_jitter_s!r} s must be below '
                             f'half the sample period ({0.5 / self.rate_hz:g} s at '
                             f'simulator.rate = {self.rate_hz:g} Hz): stamps would reorder')


def _flatten(tree: Mapping[str, Any], prefix: str = '') -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in tree.items():
        name = f'{prefix}{key}'
        if isinstance(value, Mapping):
            out.update(_flatten(value, name + '.'))
        else:
            out[name] = value
    return out


#: A parameter file larger than this is refused (the package's own file is ~5 KB).
MAX_PARAMS_FILE_BYTES = 1 << 20


def read_params_document(path: str | Path) -> Any:
    """The YAML document of a parameter file, read safely.

    Refused with a :class:`ValueError` naming the file (and the line where there is one): an
    unreadable or non-regular file, one over :data:`MAX_PARAMS_FILE_BYTES`, invalid YAML, an
    alias (``*name``: ROS 2 parameter files have none, and nested aliases expand
    exponentially: the "billion laughs" bomb), or a key given twice in one mapping. Values are
    read as a node reads them (:mod:`.ros_yaml`: rcl's rules, ``1.1e6`` a double, ``0x10`` an
    integer, quoted text a string), so that what a node accepts the offline commands accept.
    """
    path = Path(path)
    try:
        info = path.stat()
        if not stat.S_ISREG(info.st_mode):
            raise ValueError(f'parameter file {path} is not a regular file')
        if info.st_size > MAX_PARAMS_FILE_BYTES:
            raise ValueError(f'parameter file {path} is larger than '
                             f'{MAX_PARAMS_FILE_BYTES} bytes: not a parameter file')
        text = path.read_text()
    except OSError as exc:
        raise ValueError(f'cannot read parameter file {path}: {exc.strerror}') from None
    except UnicodeDecodeError:
        raise ValueError(f'parameter file {path} is not UTF-8 text') from None
    try:
        return ros_yaml.load(text)   # the values rcl's parser gives a node
    except yaml.YAMLError as exc:
        raise ValueError(f'parameter file {path} is not valid YAML: {exc}') from None
    except ValueError as exc:
        if str(exc).startswith('parameter file'):
            raise
        raise ValueError(f'parameter file {path}, {exc}') from None


def parse_override(text: str) -> tuple[str, Any]:
    """``NAME:=VALUE`` (``-p``, as ``--ros-args -p``) -> ``(name, validated value)``; VALUE is
    read as rcl reads a ``-p`` value (:mod:`.ros_yaml`: ``20``, ``1e-5``, ``[1, 2]``, ``ekf``).

    Raises
    ------
    ValueError
        No ``:=``, an unknown name, or a bad value (as :func:`load_params_file` says it).
    """
    name, sep, value_text = text.partition(':=')
    name = name.strip()
    if not sep or not name:
        raise ValueError(f'-p {text!r}: expected NAME:=VALUE')
    try:   # rcl reads a -p value as a YAML document of its own, by the same rules
        value = ros_yaml.load(value_text) if value_text.strip() else ''
    except (yaml.YAMLError, ValueError):
        value = value_text
    try:
        return name, validate_parameter(name, value)
    except ValueError as exc:
        raise ValueError(f'-p {text}: {exc}') from None


def load_params_file(path: str | Path, node_names: tuple[str, ...] = ()) -> dict[str, Any]:
    """Read a ROS 2 parameter file into ``{dotted name: validated value}``.

    Sections ``/**`` and any of ``node_names`` (with or without a leading ``/``) are merged in
    file order; nested keys or dotted keys are both accepted. Unknown names and bad values raise
    :class:`ValueError` naming the file and the parameter.
    """
    path = Path(path)
    doc = read_params_document(path)
    if not isinstance(doc, Mapping):
        raise ValueError(f'parameter file {path}: expected "/**: ros__parameters:" at the top')
    wanted = {'/**', '**'} | {n for name in node_names for n in (name, '/' + name.lstrip('/'))}
    values: dict[str, Any] = {}
    found = False
    for section, body in doc.items():
        if section not in wanted:
            continue
        if not isinstance(body, Mapping) or not isinstance(body.get('ros__parameters'), Mapping):
            raise ValueError(f'parameter file {path}: section {section!r} has no ros__parameters')
        found = True
        for name, value in _flatten(body['ros__parameters']).items():
            if name.startswith('use_sim_time') or name.startswith('qos_overrides'):
                continue
            try:
                values[name] = validate_parameter(name, value)
            except ValueError as exc:
                raise ValueError(f'parameter file {path}: {exc}') from None
    if not found:
        raise ValueError(f'parameter file {path}: no "/**: ros__parameters:" section')
    return values
