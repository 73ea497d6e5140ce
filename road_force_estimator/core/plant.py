"""The plant simulator core: the roll-plane model driven over a road, the ground truth.

A fixed-step classical Runge-Kutta (RK4) integrates the equations of
:mod:`road_force_estimator.core.vehicle_model` with ``substeps`` steps per output sample. The
vehicle drives at a constant speed v: the tire is at distance ``x = x0 + v t`` and the road
under it is the profile linearly interpolated in distance; its rate, which only the tire
damping sees, is ``du/dt = v * (slope of the interpolated segment)``. The drive starts at the
quasi-static equilibrium on the road under it (:meth:`VehicleModel.equilibrium`), so there is
no start-up transient, and stops at the end of the road (never extrapolated).

:class:`Plant` gives one sample per :meth:`Plant.step` (for the plant_simulator node);
:func:`simulate` gives the same samples as arrays (:class:`Trajectory`), with the same numbers.
Pure Python floats on the per-sample path: numpy on 8-element vectors would be slower.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
import math
from typing import Callable

import numpy as np

from road_force_estimator.core.friction import Sliders
from road_force_estimator.core.parameters import VehicleParameters
from road_force_estimator.core.road import RoadProfile
from road_force_estimator.core.sampled_plant import (
    STABLE_LAMBDA_H, SampledPlant, checked_rates, checked_substeps)
from road_force_estimator.core.speed_profile import speed_knots
from road_force_estimator.core.vehicle_model import SpringOptions, VehicleModel

__all__ = ['Plant', 'PlantSample', 'Trajectory', 'simulate', 'default_substeps',
           'MAX_SUBSTEP_S']

#: Longest RK4 step the automatic choice allows (s): 4 substeps at 1 kHz. Checked against
#: scipy's solve_ivp on ISO 8608 roads (test_plant.py, report): the integration error of the
#: dynamic tire force stays far below the sensor-noise and estimator errors.
MAX_SUBSTEP_S = 2.5e-4

#: Samples whose road and lateral acceleration are prepared at once (the numbers do not
#: depend on it).
_CHUNK_SAMPLES = 512

# Flat per-sample record: (field, width). Width 2 = [left, right].
_LAYOUT = (
    ('t_s', 1), ('distance_m', 1), ('q_m', 2), ('dq_mps', 2), ('roll_rad', 1),
    ('roll_rate_radps', 1), ('body_heave_m', 1), ('body_heave_rate_mps', 1),
    ('wheel_heave_m', 2), ('wheel_heave_rate_mps', 2), ('road_m', 2), ('road_rate_mps', 2),
    ('suspension_force_n', 2), ('tire_force_dynamic_n', 2), ('wheel_load_n', 2),
    ('lateral_accel_mps2', 1), ('body_accel_mps2', 1), ('roll_accel_radps2', 1),
    ('wheel_accel_mps2', 2),
)
_COLUMNS = {}
_col = 0
for _name, _width in _LAYOUT:
    _COLUMNS[_name] = (_col, _width)
    _col += _width
_NCOLS = _col


@dataclass(frozen=True)
class PlantSample:
    """The plant's ground truth at one output sample (SI units; per-side arrays [left, right]).

    Signs: z up, phi > 0 when the left side goes up, q > 0 when the suspension extends,
    forces > 0 upward (tire force on the wheel, suspension force on the body).
    """

    t_s: float                          #: time since the start (s)
    distance_m: float                   #: distance along the road (m)
    q_m: np.ndarray                     #: suspension extensions q_i (m), (2,)
    dq_mps: np.ndarray                  #: their rates (m/s), (2,)
    roll_rad: float                     #: phi (rad)
    roll_rate_radps: float              #: dphi/dt (rad/s)
    body_heave_m: float                 #: z_s (m)
    body_heave_rate_mps: float          #: dz_s/dt (m/s)
    wheel_heave_m: np.ndarray           #: z_ui (m), (2,)
    wheel_heave_rate_mps: np.ndarray    #: dz_ui/dt (m/s), (2,)
    road_m: np.ndarray                  #: road under each tire u_i (the enveloped road) (m)
    road_rate_mps: np.ndarray           #: du_i/dt = v * slope (m/s), (2,)
    suspension_force_n: np.ndarray      #: F_bi, on the body (N), (2,)
    tire_force_dynamic_n: np.ndarray    #: dF_i >= -F_c,i (N), (2,)
    wheel_load_n: np.ndarray            #: F_n,i = F_c,i + dF_i >= 0 (N), (2,)
    lateral_accel_mps2: float           #: a_y applied (m/s^2, > 0 to the left)
    body_accel_mps2: float              #: dd z_s (m/s^2)
    roll_accel_radps2: float            #: dd phi (rad/s^2)
    wheel_accel_mps2: np.ndarray        #: dd z_ui (m/s^2), (2,)

    @property
    def lift_off(self) -> np.ndarray:
        """True for a wheel whose tire has lifted off (zero load), (2,)."""
        return self.wheel_load_n <= 0.0

    @classmethod
    def _from_row(cls, row: tuple[float, ...]) -> PlantSample:
        values = {}
        for name, (col, width) in _COLUMNS.items():
            values[name] = row[col] if width == 1 else np.array(row[col:col + width])
        return cls(**values)


@dataclass(frozen=True)
class Trajectory:
    """:class:`PlantSample` fields as arrays over samples: (n,) or (n, 2); sample 0 is the
    equilibrium at t = 0.

    Attributes beyond the samples: ``rate_hz``, ``speed_mps``, ``substeps``, ``completed``
    (the requested duration was simulated) and ``stop_reason`` (why it stopped: the duration,
    or the end of the road, where the trajectory is truncated).
    """

    t_s: np.ndarray
    distance_m: np.ndarray
    q_m: np.ndarray
    dq_mps: np.ndarray
    roll_rad: np.ndarray
    roll_rate_radps: np.ndarray
    body_heave_m: np.ndarray
    body_heave_rate_mps: np.ndarray
    wheel_heave_m: np.ndarray
    wheel_heave_rate_mps: np.ndarray
    road_m: np.ndarray
    road_rate_mps: np.ndarray
    suspension_force_n: np.ndarray
    tire_force_dynamic_n: np.ndarray
    wheel_load_n: np.ndarray
    lateral_accel_mps2: np.ndarray
    body_accel_mps2: np.ndarray
    roll_accel_radps2: np.ndarray
    wheel_accel_mps2: np.ndarray
    rate_hz: float = 0.0
    speed_mps: float = 0.0
    substeps: int = 0
    completed: bool = True
    stop_reason: str = ''

    def __len__(self) -> int:
        return int(self.t_s.size)

    @property
    def lift_off(self) -> np.ndarray:
        """True where a tire has lifted off (zero load), (n, 2)."""
        return self.wheel_load_n <= 0.0

    def sample(self, i: int) -> PlantSample:
        """Sample ``i`` as a :class:`PlantSample`."""
        values = {}
        for f in fields(PlantSample):
            a = getattr(self, f.name)[i]
            values[f.name] = np.array(a) if np.ndim(a) else float(a)
        return PlantSample(**values)

    @classmethod
    def _from_rows(cls, rows: list, **meta) -> Trajectory:
        data = np.array(rows, dtype=np.float64).reshape(-1, _NCOLS)
        values = {}
        for name, (col, width) in _COLUMNS.items():
            values[name] = data[:, col].copy() if width == 1 else data[:, col:col + width].copy()
        return cls(**values, **meta)


def default_substeps(rate_hz: float, max_substep_s: float = MAX_SUBSTEP_S) -> int:
    """RK4 substeps per sample so that the step is at most ``max_substep_s``."""
    return max(1, int(math.ceil(1.0 / (rate_hz * max_substep_s) - 1e-9)))


class Plant(SampledPlant):
    """The plant, one output sample at a time.

    Parameters
    ----------
    vehicle : VehicleParameters
    road : RoadProfile
        The road; with ``tire_envelope_m`` > 0 the plant drives on
        ``road.enveloped(tire_envelope_m)`` (see :attr:`road`).
    speed_mps : float
        Constant speed v (m/s), > 0 (the nominal speed with a ``speed_profile``).
    speed_profile : (time_s, speed_mps) arrays, optional
        A varying speed (``simulator.speed_profile``): knots from t = 0, speeds >= 0 (stops
        allowed), linearly interpolated, held after the last knot. The distance is its exact
        integral: at v = 0 the road under the tires does not move.
    rate_hz : float
        Output sample rate (Hz), > 0.
    substeps : int, optional
        RK4 steps per sample; default :func:`default_substeps` (step <= 0.25 ms). A step too
        long for RK4's stability on the model's fastest pole is refused.
    lateral_acceleration : None, float or callable
        a_y (m/s^2, > 0 to the left): None = 0, a constant, or ``f(t_s) -> float`` evaluated
        at every RK4 stage time.
    start_m : float, optional
        Distance where the drive starts (default: the road's start).
    tire_envelope_m : float
        Tire enveloping length (m), see :meth:`RoadProfile.enveloped`; 0 = the road as given.
    springs : SpringOptions, optional
        Plant-only progressive springs and bump stops (``simulator.spring_progression``,
        ``simulator.bump_stop_*``); None = linear springs. The leaf-spring friction of
        ``vehicle.leaf_spring_friction`` acts in every case (:class:`.VehicleModel`), in the
        law of ``vehicle.leaf_spring_friction_model``.
    crossfall_rad : float
        The road plane's cross slope (``simulator.road_crossfall``, rad, > 0 = the left wheel
        path higher): each tire's road ``+- (T/2) tan(crossfall)``; 0 = none.
    friction_start : float
        Stick friction only (``simulator.leaf_spring_friction_start``): the force each slider
        holds at the start per unit F_f (> 0 upward on the body); 0 = none. With stick
        friction the sliders advance after every RK4 step (:class:`.friction.Sliders`).

    Notes
    -----
    The first :meth:`step` returns sample 0, the equilibrium at t = 0; each later call
    advances one sample period ``1 / rate_hz`` with ``substeps`` RK4 steps. Stage times are
    ``t_j = j / (2 * substeps * rate_hz)``; the road and a_y there are prepared in blocks
    (results do not depend on the blocking).
    """

    def __init__(self, vehicle: VehicleParameters, road: RoadProfile, *, speed_mps: float,
                 rate_hz: float, substeps: int | None = None,
                 lateral_acceleration: float | Callable[[float], float] | None = None,
                 start_m: float | None = None, tire_envelope_m: float = 0.0,
                 speed_profile: tuple | None = None,
                 springs: SpringOptions | None = None, friction_start: float = 0.0,
                 crossfall_rad: float = 0.0) -> None:
        speed_mps, rate_hz = checked_rates(road, speed_mps, rate_hz)
        self.model = VehicleModel(vehicle, springs)
        self.vehicle = vehicle
        self.friction_start = float(friction_start)
        rise = vehicle.half_track_m * math.tan(float(crossfall_rad))
        #: the crossfall's rise of each tire's road (m), [left, right]
        self.crossfall_m = (rise, -rise)
        if self.friction_start and not self.model.sticks:
            raise ValueError(f'simulator.leaf_spring_friction_start = {self.friction_start:g}: '
                             'needs vehicle.leaf_spring_friction_model = stick and a '
                             'vehicle.leaf_spring_friction')
        #: the stick elements' sliders (None without stick friction)
        self.sliders = Sliders(self.model.stick_stiffness_npm, self.model._ff) \
            if self.model.sticks else None
        #: The road the tires follow (enveloped when ``tire_envelope_m`` > 0).
        self.road = road.enveloped(tire_envelope_m)
        self.tire_envelope_m = float(tire_envelope_m)
        self.speed_mps = speed_mps
        #: (time_s, speed_mps, distance_m at the knots) of a varying speed, or None
        self.speed_profile = None if speed_profile is None else speed_knots(*speed_profile)
        self.rate_hz = rate_hz
        fastest = self.model.max_pole_magnitude()
        if substeps is None:
            substeps = default_substeps(rate_hz)
            substeps = max(substeps, int(math.ceil(fastest / (STABLE_LAMBDA_H * rate_hz))))
        self.substeps, self.step_s = checked_substeps(substeps, fastest, rate_hz)
        x0 = self.road.start_m if start_m is None else float(start_m)
        if not (math.isfinite(x0) and self.road.start_m <= x0 < self.road.end_m):
            raise ValueError(f'start_m = {start_m!r} must lie in [{self.road.start_m:g}, '
                             f'{self.road.end_m:g}) m (the road the tire follows)')
        self.start_m = x0
        if lateral_acceleration is None:
            self._ay_func = None
            self._ay_const = 0.0
        elif callable(lateral_acceleration):
            self._ay_func = lateral_acceleration
            self._ay_const = 0.0
        else:
            value = float(lateral_acceleration)
            if not math.isfinite(value):
                raise ValueError(f'lateral_acceleration = {value!r} must be finite')
            self._ay_func = None
            self._ay_const = value
        self._half_rate = 2.0 * substeps * rate_hz     # stage-time index per second
        self._last_sample = self._find_last_sample()
        self._accelerations = self.model.make_accelerations()
        self._outputs = self.model.make_outputs()
        self._slopes = self.road.segment_slopes()
        self._g1, self._g2 = (c / m for c, m in zip(vehicle.tire_damping_nspm,
                                                     vehicle.unsprung_mass_kg))
        self.reset()

    # ----------------------------------------------------------------------------------------

    def reset(self) -> None:
        """Back to the equilibrium at t = 0 (the next :meth:`step` returns sample 0)."""
        self._k = -1                  # index of the last sample returned
        self._chunk_first = None      # first sample index of the prepared block
        self._prepare(0)
        u1, u2, ay = self._inputs[0][0], self._inputs[1][0], self._inputs[4][0]
        d1, d2 = (a[0] for a in self._sample_rate)
        if self.sliders is None:
            self._state = tuple(float(v) for v in self.model.equilibrium(
                (u1, u2), (d1, d2), ay))
        else:
            held = tuple(self.friction_start * f for f in self.model._ff)
            self._state = tuple(float(v) for v in self.model.equilibrium(
                (u1, u2), (d1, d2), ay, slider_force_n=held))
            self.sliders.start(self._extensions(self._state), [-f for f in held])
            self.model.slider_base[:] = self.sliders.base
        self.stop_reason = ''

    def _sample(self, row: tuple) -> PlantSample:
        return PlantSample._from_row(row)

    def _road_changed(self) -> None:
        self._slopes = self.road.segment_slopes()

    def _prepare(self, first: int) -> None:
        """Road, road rate and a_y at the stage times of samples first .. first + block."""
        per = 2 * self.substeps
        last = min(first + _CHUNK_SAMPLES, self._last_sample)
        j = np.arange(per * first, per * last + 1)
        x = self._distance(j)
        road_x = self.road.distance_m
        if self.crossfall_m[0]:
            u = [(np.interp(x, road_x, self.road.elevation_m[:, i]) + self.crossfall_m[i]
                  ).tolist() for i in (0, 1)]
        else:
            u = [np.interp(x, road_x, self.road.elevation_m[:, i]).tolist() for i in (0, 1)]
        # Road rate at the samples (outputs): v * slope of the segment holding x (point rate).
        xs = x[::per]
        seg = np.clip(np.searchsorted(road_x, xs, side='right') - 1, 0, len(road_x) - 2)
        speed = self.speed_mps if self.speed_profile is None else \
            self.speed_at(j[::per] / self._half_rate)
        self._sample_rate = [(speed * self._slopes[seg, i]).tolist() for i in (0, 1)]
        # Road rate inside the integration: over each RK4 substep, the mean rate
        # r = (u(t + h) - u(t)) / h, the exact rate wherever the substep lies on one segment of
        # the interpolated road. du/dt jumps at the knots; with r (and the wheel-velocity
        # correction of _rk4_sample) the substep's integral of the tire-damping force is exact
        # and RK4 keeps its accuracy (checked against solve_ivp in test_plant.py; with the
        # point rate the error was O(h), about 1e-4 relative at 4 substeps).
        du = [((np.asarray(ui[2::2]) - np.asarray(ui[:-2:2])) / self.step_s).tolist()
              for ui in u]
        t = (j / self._half_rate).tolist()
        if self._ay_func is None:
            ay = [self._ay_const] * len(t)
        else:
            ay = [float(self._ay_func(tj)) for tj in t]
            bad = [i for i, a in enumerate(ay) if not math.isfinite(a)]
            if bad:
                raise ValueError(f'lateral_acceleration({t[bad[0]]:g} s) = {ay[bad[0]]!r} is '
                                 f'not finite')
        self._chunk_first = first
        self._chunk_last = last
        self._times = t
        self._dist = x.tolist()
        self._inputs = (u[0], u[1], du[0], du[1], ay)

    def _row(self, k: int) -> tuple[float, ...]:
        """The output record of sample k from the current state."""
        i = 2 * self.substeps * (k - self._chunk_first)
        u1, u2, ay = self._inputs[0][i], self._inputs[1][i], self._inputs[4][i]
        d1, d2 = (a[k - self._chunk_first] for a in self._sample_rate)
        zs, ph, z1, z2, vs, vp, v1, v2 = self._state
        q1, q2, dq1, dq2, fb1, fb2, f1, f2, n1, n2, a_s, a_p, a_1, a_2 = self._outputs(
            zs, ph, z1, z2, vs, vp, v1, v2, u1, u2, d1, d2, ay)
        return (self._times[i], self._dist[i], q1, q2, dq1, dq2, ph, vp, zs, vs, z1, z2, v1, v2,
                u1, u2, d1, d2, fb1, fb2, f1, f2, n1, n2, ay, a_s, a_p, a_1, a_2)

    def _advance(self, base: int) -> None:
        if self.sliders is None:
            self._state = _rk4_sample(self._accelerations, self._state, self._inputs, base,
                                      self.substeps, self.step_s, self._g1, self._g2)
        else:       # one RK4 step at a time, the sliders advanced after each
            for n in range(self.substeps):
                self._state = _rk4_sample(self._accelerations, self._state, self._inputs,
                                          base + 2 * n, 1, self.step_s, self._g1, self._g2)
                self.sliders.advance(self._extensions(self._state))
                self.model.slider_base[:] = self.sliders.base

    def _extensions(self, state) -> tuple[float, float]:
        """q_1, q_2 (m) of a state (MODEL.md's kinematics)."""
        zs, ph, z1, z2 = state[:4]
        sp = self.model._s * math.sin(ph)
        return zs + sp - z1, zs - sp - z2


def _rk4_sample(acc, state, inputs, base, substeps, h, g1, g2):
    """Advance ``state`` by ``substeps`` classical RK4 steps of ``h`` seconds.

    ``inputs`` = (u_1, u_2, du_1, du_2, a_y): u and a_y are lists at stage-time indices
    (substep i uses base + 2i at its start, base + 2i + 1 in the middle for stages 2 and 3,
    base + 2i + 2 at its end); du lists hold one mean rate per substep (index (base + 2i)/2).
    ``g_i = ct_i / m_i`` (1/s).

    Notes
    -----
    With tire damping, du/dt jumps at every knot of the interpolated road, which would cost
    RK4 its order. The wheels are therefore integrated in the variable
    ``P_i = dz_ui - g_i u_i`` (momentum minus the tire damper's share, per unit mass), whose
    rate ``ddz_ui - g_i du_i`` holds no du in contact: the system is continuous in time. In
    terms of dz_ui this is classical RK4 with the stage-2 and stage-3 wheel velocities
    corrected by ``g_i ((u_i(t + h/2) - u_i(t)) - r_i h/2)`` (zero unless a knot lies in the
    first half of the substep; the stage-4 correction is zero by the choice of r_i).
    """
    zs, ph, z1, z2, vs, vp, v1, v2 = state
    u1, u2, d1, d2, ay = inputs
    h2 = 0.5 * h
    h6 = h / 6.0
    j = base
    for _ in range(substeps):
        r1 = d1[j >> 1]
        r2 = d2[j >> 1]
        m = j + 1
        e1 = g1 * ((u1[m] - u1[j]) - r1 * h2)
        e2 = g2 * ((u2[m] - u2[j]) - r2 * h2)
        # Stage 1 at t.
        as1, ap1, a11, a21 = acc(zs, ph, z1, z2, vs, vp, v1, v2, u1[j], u2[j], r1, r2, ay[j])
        # Stage 2 at t + h/2.
        zs2 = zs + h2 * vs
        ph2 = ph + h2 * vp
        z12 = z1 + h2 * v1
        z22 = z2 + h2 * v2
        vs2 = vs + h2 * as1
        vp2 = vp + h2 * ap1
        v12 = v1 + h2 * a11 + e1
        v22 = v2 + h2 * a21 + e2
        as2, ap2, a12, a22 = acc(zs2, ph2, z12, z22, vs2, vp2, v12, v22, u1[m], u2[m], r1, r2,
                                 ay[m])
        # Stage 3 at t + h/2.
        zs3 = zs + h2 * vs2
        ph3 = ph + h2 * vp2
        z13 = z1 + h2 * v12
        z23 = z2 + h2 * v22
        vs3 = vs + h2 * as2
        vp3 = vp + h2 * ap2
        v13 = v1 + h2 * a12 + e1
        v23 = v2 + h2 * a22 + e2
        as3, ap3, a13, a23 = acc(zs3, ph3, z13, z23, vs3, vp3, v13, v23, u1[m], u2[m], r1, r2,
                                 ay[m])
        # Stage 4 at t + h.
        j += 2
        zs4 = zs + h * vs3
        ph4 = ph + h * vp3
        z14 = z1 + h * v13
        z24 = z2 + h * v23
        vs4 = vs + h * as3
        vp4 = vp + h * ap3
        v14 = v1 + h * a13
        v24 = v2 + h * a23
        as4, ap4, a14, a24 = acc(zs4, ph4, z14, z24, vs4, vp4, v14, v24, u1[j], u2[j], r1, r2,
                                 ay[j])
        zs += h6 * (vs + 2.0 * (vs2 + vs3) + vs4)
        ph += h6 * (vp + 2.0 * (vp2 + vp3) + vp4)
        z1 += h6 * (v1 + 2.0 * (v12 + v13) + v14)
        z2 += h6 * (v2 + 2.0 * (v22 + v23) + v24)
        vs += h6 * (as1 + 2.0 * (as2 + as3) + as4)
        vp += h6 * (ap1 + 2.0 * (ap2 + ap3) + ap4)
        v1 += h6 * (a11 + 2.0 * (a12 + a13) + a14)
        v2 += h6 * (a21 + 2.0 * (a22 + a23) + a24)
    return zs, ph, z1, z2, vs, vp, v1, v2


def simulate(vehicle: VehicleParameters, road: RoadProfile, *, speed_mps: float,
             rate_hz: float, duration_s: float,
             lateral_acceleration: float | Callable[[float], float] | None = None,
             substeps: int | None = None, start_m: float | None = None,
             tire_envelope_m: float = 0.0, speed_profile: tuple | None = None,
             springs: SpringOptions | None = None, friction_start: float = 0.0,
             crossfall_rad: float = 0.0) -> Trajectory:
    """Drive ``duration_s`` seconds (or to the end of the road) and return every sample.

    Parameters are those of :class:`Plant`, plus ``duration_s`` (s, >= 0). The trajectory
    holds ``floor(duration_s * rate_hz) + 1`` samples (sample 0 at t = 0), the same numbers
    as stepping a :class:`Plant`; if the road ends first it is truncated there,
    ``completed`` is False and ``stop_reason`` says where.
    """
    duration_s = float(duration_s)
    if not (math.isfinite(duration_s) and duration_s >= 0.0):
        raise ValueError(f'duration_s = {duration_s!r} must be >= 0 s')
    plant = Plant(vehicle, road, speed_mps=speed_mps, rate_hz=rate_hz, substeps=substeps,
                  lateral_acceleration=lateral_acceleration, start_m=start_m,
                  tire_envelope_m=tire_envelope_m, speed_profile=speed_profile,
                  springs=springs, friction_start=friction_start, crossfall_rad=crossfall_rad)
    wanted = int(math.floor(duration_s * plant.rate_hz + 1e-9)) + 1
    rows = []
    for _ in range(wanted):
        row = plant._next_row()
        if row is None:
            break
        rows.append(row)
    completed = len(rows) == wanted
    reason = (f'duration {duration_s:g} s simulated' if completed else
              f'truncated at {len(rows)} of {wanted} samples: {plant.stop_reason}')
    return Trajectory._from_rows(rows, rate_hz=plant.rate_hz, speed_mps=plant.speed_mps,
                                 substeps=plant.substeps, completed=completed,
                                 stop_reason=reason)
