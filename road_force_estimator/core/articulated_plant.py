"""The articulated plant: the tractor and semi-trailer of :mod:`.articulated_model` driven over
a road, one output sample at a time, and its ground truth.

Every axle runs in the front axle's two wheel paths, delayed by its distance: at the front
axle's distance X(t) the road under axle j is the (enveloped) profile at ``X - xi_j``, plus
``+-w_j tan(crossfall)`` (``simulator.road_crossfall``: the road plane tilted). The drive
starts with the last axle on the road's start (``X_0 = start + xi_N``) and ends when the front
axle reaches its end (never extrapolated). The speed is constant or a profile with stops
(:mod:`.speed_profile`); the longitudinal acceleration a_x = dv/dt, taken over each RK4 step as
its mean (the exact change of speed), drives the braking pitch; the lateral acceleration is
a :class:`.lateral_profile.LateralProfile` (or a constant).

Integration: classical RK4 with ``substeps`` steps per output sample (default: 1 at 1 kHz,
checked against ``scipy.integrate.solve_ivp`` in test_articulated_plant.py), the road
linearly interpolated in distance at every stage time, the tire-damping rate the mean over the
step. The stick friction's sliders advance once per step (:class:`.friction.Sliders`). The
drive starts at the equilibrium on the road under the tires
(:meth:`.ArticulatedModel.equilibrium`).

:class:`ArticulatedPlant` gives one sample per :meth:`ArticulatedPlant.step` (the node);
:func:`simulate_articulated` all of them as arrays (:class:`ArticulatedTrajectory`), the same
numbers: both run :meth:`ArticulatedPlant._next_row`.
"""
from __future__ import annotations

import array
from dataclasses import dataclass
import math

import numpy as np

from road_force_estimator.core.articulated_model import ArticulatedModel
from road_force_estimator.core.articulated_parameters import ArticulatedParameters
from road_force_estimator.core.friction import Sliders
from road_force_estimator.core.lateral_profile import LateralProfile
from road_force_estimator.core.road import RoadProfile
from road_force_estimator.core.sampled_plant import (
    STABLE_LAMBDA_H, SampledPlant, checked_rates, checked_substeps)
from road_force_estimator.core.speed_profile import speed_knots

__all__ = ['ArticulatedPlant', 'ArticulatedSample', 'ArticulatedTrajectory', 'RowLayout',
           'simulate_articulated', 'articulated_substeps', 'MAX_ARTICULATED_STEP_S']

#: Longest RK4 step (s) the automatic choice allows: 1 ms (one step per sample at 1 kHz).
#: The fastest pole of the defaults is about 150 1/s (|lambda| h = 0.15); the error against
#: solve_ivp on a class C road with a stop and a curve stays below 1e-4 of the dynamic load
#: RMS (test_articulated_plant.py).
MAX_ARTICULATED_STEP_S = 1e-3
_CHUNK_SAMPLES = 256


def articulated_substeps(rate_hz: float, fastest_pole: float) -> int:
    """RK4 steps per sample: a step of at most :data:`MAX_ARTICULATED_STEP_S` and within
    RK4's stability on the fastest pole (1/s)."""
    n = max(1, int(math.ceil(1.0 / (rate_hz * MAX_ARTICULATED_STEP_S) - 1e-9)))
    return max(n, int(math.ceil(fastest_pole / (STABLE_LAMBDA_H * rate_hz))))


class RowLayout:
    """Columns of one output record (a flat tuple) by name: slices for :attr:`index`.

    ``t_s, distance_m, speed_mps, longitudinal_accel_mps2, lateral_accel_mps2`` (one each);
    ``state`` (2 n); per tire [axle j left, right, ...] (2 N each): ``q_m``, ``dq_mps``,
    ``spring_force_n`` (on the body), ``tire_force_dynamic_n``, ``wheel_load_n``; ``accel``
    (n coordinate accelerations); ``road_m`` (2 N, under each tire).
    """

    def __init__(self, n_dof: int, n_axles: int) -> None:
        widths = [('t_s', 1), ('distance_m', 1), ('speed_mps', 1),
                  ('longitudinal_accel_mps2', 1), ('lateral_accel_mps2', 1),
                  ('state', 2 * n_dof), ('q_m', 2 * n_axles), ('dq_mps', 2 * n_axles),
                  ('spring_force_n', 2 * n_axles), ('tire_force_dynamic_n', 2 * n_axles),
                  ('wheel_load_n', 2 * n_axles), ('accel', n_dof), ('road_m', 2 * n_axles)]
        self.index: dict[str, slice] = {}
        col = 0
        for name, width in widths:
            self.index[name] = slice(col, col + width)
            col += width
        self.width = col
        self.n_dof, self.n_axles = n_dof, n_axles


class ArticulatedSample:
    """One output record with named views (floats; per-tire lists [axle j left, right, ...])."""

    __slots__ = ('row', 'layout')

    def __init__(self, row: tuple, layout: RowLayout) -> None:
        self.row, self.layout = row, layout

    def __getattr__(self, name: str):
        index = object.__getattribute__(self, 'layout').index
        if name not in index:
            raise AttributeError(name)
        part = object.__getattribute__(self, 'row')[index[name]]
        return part[0] if len(part) == 1 and name not in ('state', 'accel') else part


@dataclass(frozen=True)
class ArticulatedTrajectory:
    """Every sample of a drive: ``data`` (n, width) with the columns of ``layout``; the named
    views as arrays (:meth:`column`), ``rate_hz``, ``substeps``, ``completed``,
    ``stop_reason`` and the ``model`` (statics, names)."""

    data: np.ndarray
    layout: RowLayout
    model: ArticulatedModel
    rate_hz: float
    substeps: int
    completed: bool
    stop_reason: str

    def __len__(self) -> int:
        return int(self.data.shape[0])

    def column(self, name: str) -> np.ndarray:
        """A named view: (n,) for scalars, (n, width) otherwise."""
        sl = self.layout.index[name]
        part = self.data[:, sl]
        return part[:, 0] if part.shape[1] == 1 and name not in ('state', 'accel') else part

    def __getattr__(self, name: str):
        if name in ('data', 'layout', 'model') or name.startswith('__'):
            raise AttributeError(name)
        if name in self.layout.index:
            return self.column(name)
        raise AttributeError(name)


class ArticulatedPlant(SampledPlant):
    """The articulated plant, one output sample at a time (the interface of
    :class:`.plant.Plant`: :meth:`step`, :meth:`extend_road`, :attr:`road`, ...).

    Parameters
    ----------
    vehicle : ArticulatedParameters
    road : RoadProfile
        Both wheel paths; enveloped by ``tire_envelope_m`` (m, 0 = point contact).
    speed_mps, rate_hz : float
        Constant (or nominal) speed (m/s, > 0) and output rate (Hz).
    speed_profile : (time_s, speed_mps), optional
        A varying speed with stops (:mod:`.speed_profile`).
    lateral_acceleration : None, float, LateralProfile or callable
        a_y (m/s^2, > 0 left); a callable takes an array of times.
    start_m : float, optional
        The front axle's distance at the start (default: the road's start + the vehicle's
        length: every axle on the road).
    substeps : int, optional
        RK4 steps per sample (default :func:`articulated_substeps`).
    crossfall_rad : float
        The road plane's cross slope (rad, > 0 left wheel path higher).
    friction_start : float
        Stick friction: the force each slider holds at the start per unit F_f (> 0 upward on
        the body).
    model : ArticulatedModel, optional
        The model (default: the vehicle's, with its per-axle springs).
    """

    def __init__(self, vehicle: ArticulatedParameters, road: RoadProfile, *, speed_mps: float,
                 rate_hz: float, speed_profile=None, lateral_acceleration=None,
                 start_m: float | None = None, substeps: int | None = None,
                 tire_envelope_m: float = 0.0, crossfall_rad: float = 0.0,
                 friction_start: float = 0.0, model: ArticulatedModel | None = None) -> None:
        speed_mps, rate_hz = checked_rates(road, speed_mps, rate_hz)
        self.vehicle = vehicle
        self.model = model if model is not None else ArticulatedModel.from_vehicle_springs(
            vehicle)
        if friction_start and not self.model.sticks:
            raise ValueError(f'simulator.leaf_spring_friction_start = {friction_start:g}: '
                             'needs vehicle.leaf_spring_friction_model = stick and a '
                             'leaf_spring_friction')
        m = self.model
        self.layout = RowLayout(m.n_dof, m.n_axles)
        self.tire_envelope_m = float(tire_envelope_m)
        self.road = road.enveloped(self.tire_envelope_m)
        self.speed_mps, self.rate_hz = speed_mps, rate_hz
        self.speed_profile = None if speed_profile is None else speed_knots(*speed_profile)
        fastest = m.max_pole_magnitude()
        if substeps is None:
            substeps = articulated_substeps(rate_hz, fastest)
        self.substeps, self.step_s = checked_substeps(substeps, fastest, rate_hz)
        self.offsets = np.array([a.position_m for a in vehicle.axles])
        self.lengths_m = m.length_m
        x0 = self.road.start_m + self.lengths_m if start_m is None else float(start_m)
        if not (math.isfinite(x0) and self.road.start_m + self.lengths_m <= x0 + 1e-12
                and x0 < self.road.end_m):
            raise ValueError(f'start_m = {x0!r}: the front axle must start in '
                             f'[{self.road.start_m + self.lengths_m:g}, {self.road.end_m:g}) m '
                             f'(every axle, {self.lengths_m:g} m behind it, on the road)')
        self.start_m = x0
        self.crossfall = np.array([w * math.tan(crossfall_rad) * s for a in vehicle.axles
                                   for w in (a.wheel_half_track_m,) for s in (1.0, -1.0)])
        self._lateral = _lateral(lateral_acceleration)
        self.friction_start = float(friction_start)
        self._acc, self._out = m.functions()
        self._rk4 = _make_rk4(m.n_dof)
        self._q_rows = _extension_function(m)
        self._half_rate = 2.0 * self.substeps * rate_hz
        self._last_sample = self._find_last_sample()
        self.reset()

    # ----------------------------------------------------------------------------------------

    def reset(self) -> None:
        """Back to the equilibrium at t = 0 (the next :meth:`step` returns sample 0)."""
        self._k = -1
        self._prepare(0)
        m = self.model
        forces = [-self.friction_start * f for f in m.friction_n.reshape(-1)]
        x, fb = m.equilibrium(self._u[0], self._ay[0], self._ax[0], forces,
                              road_rate_mps=self._start_rates())
        self._state = tuple(float(v) for v in x)
        self.sliders = Sliders(m.stick_stiffness_npm(), m.friction_n.reshape(-1).tolist())
        self.sliders.base = list(fb)
        self.stop_reason = ''

    def _sample(self, row: tuple) -> ArticulatedSample:
        return ArticulatedSample(row, self.layout)

    def lateral_at(self, t_s):
        """a_y (m/s^2) at time(s) t_s."""
        return self._lateral(np.asarray(t_s, float))

    # ----------------------------------------------------------------------------------------

    def _start_rates(self) -> np.ndarray:
        """The road rate under each tire at the start (m/s): the speed times the slope of the
        segment under it (right-continuous), whatever part of the road is known yet (a live
        road's plant starts as a batch one)."""
        road_x = self.road.distance_m
        pos = self.start_m - self.offsets
        seg = np.clip(np.searchsorted(road_x, pos, side='right') - 1, 0, len(road_x) - 2)
        slopes = self.road.segment_slopes()[seg]                # (axles, 2)
        return (float(self.speed_at(0.0)) * slopes).reshape(-1)

    def _prepare(self, first: int) -> None:
        """Road, rates, a_y and a_x at the stage times of samples first .. first + block."""
        per = 2 * self.substeps
        last = min(first + _CHUNK_SAMPLES, self._last_sample)
        j = np.arange(per * first, per * last + 1)
        x = self._distance(j)
        t = j / self._half_rate
        road_x, elev = self.road.distance_m, self.road.elevation_m
        pos = x[:, None] - self.offsets[None, :]            # (stages, axles)
        u = np.empty((j.size, 2 * self.model.n_axles))
        u[:, 0::2] = np.interp(pos, road_x, elev[:, 0])
        u[:, 1::2] = np.interp(pos, road_x, elev[:, 1])
        if np.any(self.crossfall):
            u += self.crossfall
        self._u = u.tolist()
        self._du = ((u[2::2] - u[:-2:2]) / self.step_s).tolist() if j.size > 1 else \
            [[0.0] * u.shape[1]]
        speed = self.speed_at(t)
        self._speed = np.broadcast_to(speed, t.shape).tolist()
        ax = (np.asarray(speed)[2::2] - np.asarray(speed)[:-2:2]) / self.step_s \
            if j.size > 1 and self.speed_profile is not None else np.zeros(max(j.size // 2, 1))
        self._ax = np.asarray(ax, float).tolist()
        ay = np.broadcast_to(np.asarray(self._lateral(t), float), t.shape)
        if not np.all(np.isfinite(ay)):
            raise ValueError('lateral acceleration: not finite')
        self._ay = ay.tolist()
        self._times = t.tolist()
        self._dist = x.tolist()
        self._chunk_first, self._chunk_last = first, last

    def _row(self, k: int) -> tuple:
        i = 2 * self.substeps * (k - self._chunk_first)
        s = max(i // 2 - 1, 0)                           # the last step into the sample
        ax = self._ax[min(s, len(self._ax) - 1)]
        du = self._du[min(s, len(self._du) - 1)]
        out = self._out(self._state, self._u[i], du, self._ay[i], ax, self.sliders.base)
        m2 = 2 * self.model.n_axles
        head = (self._times[i], self._dist[i], self._speed[i], ax, self._ay[i])
        return head + self._state + out[:5 * m2] + out[5 * m2:] + tuple(self._u[i])

    def _advance(self, base: int) -> None:
        state, acc, h = self._state, self._acc, self.step_s
        u, du, ay, ax = self._u, self._du, self._ay, self._ax
        sliders = self.sliders
        sticks = self.model.sticks
        for n in range(self.substeps):
            j = base + 2 * n
            fb = sliders.base
            state = self._rk4(acc, state, u[j], u[j + 1], u[j + 2], du[j >> 1], ay[j],
                              ay[j + 1], ay[j + 2], ax[j >> 1], h, fb)
            if sticks:
                sliders.advance(self._q_rows(state))
        self._state = state


def _lateral(value):
    """a_y as a function of an array of times."""
    if value is None:
        return lambda t: np.zeros(np.shape(t))
    if isinstance(value, LateralProfile):
        return value.at
    if callable(value):
        return lambda t: np.asarray([float(value(x)) for x in np.ravel(t)]).reshape(np.shape(t))
    a = float(value)
    if not math.isfinite(a):
        raise ValueError(f'lateral_acceleration = {a!r} must be finite')
    return lambda t: np.full(np.shape(t), a)


def _make_rk4(n: int):
    """One classical RK4 step of the n-coordinate system, written out (source compiled once
    per size): ``rk4(acc, x, u0, um, u1, du, y0, ym, y1, ax, h, fb)`` with the road and a_y at
    the step's start, middle and end."""
    p = [f'p{i}' for i in range(n)]
    v = [f'v{i}' for i in range(n)]
    lines = ['def rk4(acc, x, u0, um, u1, du, y0, ym, y1, ax, h, fb):',
             '    h2 = 0.5 * h', '    h6 = h / 6.0',
             f'    ({", ".join(p + v)},) = x',
             f'    ({", ".join(f"a{i}" for i in range(n))},) = acc(x, u0, du, y0, ax, fb)']
    prev_v, prev_a = v, [f'a{i}' for i in range(n)]
    for stage, (scale, road, lat) in enumerate((('h2', 'um', 'ym'), ('h2', 'um', 'ym'),
                                               ('h', 'u1', 'y1')), start=2):
        sp = [f'{pi} + {scale} * {prev_v[i]}' for i, pi in enumerate(p)]
        sv = [f'v{i} + {scale} * {prev_a[i]}' for i in range(n)]
        names_v = [f's{stage}v{i}' for i in range(n)]
        names_a = [f's{stage}a{i}' for i in range(n)]
        lines.append(f'    ({", ".join(names_v)},) = ({", ".join(sv)},)')
        lines.append(f'    ({", ".join(names_a)},) = acc(({", ".join(sp)}, {", ".join(names_v)}'
                     f'), {road}, du, {lat}, ax, fb)')
        prev_v, prev_a = names_v, names_a
    newp = [f'p{i} + h6 * (v{i} + 2.0 * (s2v{i} + s3v{i}) + s4v{i})' for i in range(n)]
    newv = [f'v{i} + h6 * (a{i} + 2.0 * (s2a{i} + s3a{i}) + s4a{i})' for i in range(n)]
    lines.append(f'    return ({", ".join(newp + newv)},)')
    namespace: dict = {}
    exec(compile('\n'.join(lines) + '\n', f'<rk4, {n} coordinates>', 'exec'), namespace)
    return namespace['rk4']


def _extension_function(model: ArticulatedModel):
    """``q(state) -> [q_j,i]`` (m): the suspension extensions (the stick sliders' input)."""
    _, out = model.functions()
    m2 = 2 * model.n_axles
    zero = [0.0] * m2

    def extensions(state):
        return out(state, zero, zero, 0.0, 0.0, zero)[:m2]

    return extensions


def simulate_articulated(vehicle: ArticulatedParameters, road: RoadProfile, *, speed_mps: float,
                         rate_hz: float, duration_s: float, progress=None,
                         **options) -> ArticulatedTrajectory:
    """Drive ``duration_s`` seconds (or to the end of the road): every sample.

    ``options`` are those of :class:`ArticulatedPlant`; ``progress(n)`` is called every 5000
    samples. The numbers are those of stepping an :class:`ArticulatedPlant`.
    """
    duration_s = float(duration_s)
    if not (math.isfinite(duration_s) and duration_s >= 0.0):
        raise ValueError(f'duration_s = {duration_s!r} must be >= 0 s')
    plant = ArticulatedPlant(vehicle, road, speed_mps=speed_mps, rate_hz=rate_hz, **options)
    wanted = int(math.floor(duration_s * plant.rate_hz + 1e-9)) + 1
    flat = array.array('d')           # the rows end to end (a list of tuples costs more)
    nxt = plant._next_row
    done = 0
    for k in range(wanted):
        row = nxt()
        if row is None:
            break
        flat.extend(row)
        done += 1
        if progress is not None and k % 5000 == 4999:
            progress(5000)
    completed = done == wanted
    reason = (f'duration {duration_s:g} s simulated' if completed else
              f'truncated at {done} of {wanted} samples: {plant.stop_reason}')
    data = np.frombuffer(flat, dtype=np.float64).reshape(-1, plant.layout.width).copy()
    return ArticulatedTrajectory(data, plant.layout, plant.model, plant.rate_hz,
                                 plant.substeps, completed, reason)
