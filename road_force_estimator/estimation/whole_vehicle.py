"""The whole vehicle's outputs per sample and per drive (``vehicle.model: articulated``,
INTERFACES.md "The whole vehicle"): every wheel's load, every wheel's static load, each
unit's load transfer ratio (tractor, trailer, combination; instantaneous and quasi-static)
and each unit's lateral acceleration, from the readings of ``/suspension/deflections`` as
they come (the model's channel order, from the vehicle's ``deflection_reference``).

:class:`WholeVehicleEstimator` is the one per-sample path (the observer node's);
:func:`estimate_whole_vehicle` runs it over a drive online (the same numbers, sample by
sample) or runs the smoother offline and the same load-transfer recursion over its loads.
The model observer is :mod:`.articulated`'s; the LTR the truth's
(:class:`~.core.unit_loads.UnitLoadTransfer`: right minus left over their sum, each unit's
wheels, the quasi-static one low-passed by two first-order lags at
:data:`~.core.unit_loads.QUASI_STATIC_CUTOFF_HZ`), stepped by each sample's own step.
Signs: loads >= 0 pressing the road (N), LTR > 0 when the right wheels carry more.

Weigh in motion: with ``vehicle.deflection_reference: zero_load`` every instrumented wheel's
static load comes from its readings (:class:`WheelStaticTracker`, the front axle's law of
:mod:`.static_load` per deflection channel: ``F_c = F_0 + m_j g / 2 - k mean(q_meas)``), the
payload unknown; the core gets each reading less a lagged offset
(:data:`OFFSET_TIME_CONSTANT_S`), and each sample's load is its static estimate plus the
dynamic tire force. The model's gains stay the file's (the
payload moves no design here, unlike the front axle's ``MASS_REDESIGN_FRACTION``); an axle
without sensors keeps the file's static load. ``innovations_gated`` counts, per channel, the
samples the observer's innovation gate (``observer.innovation_gate``) replaced.

The road online: every wheel's road per finalized sample (the causal one at zero latency, the
fixed-lag one with ``observer.latency``: :class:`.models.articulated_rows.WheelRoads`) and
the fused profile streamed (:class:`.fused_stream.FusedStream`: each point once the last axle
has passed it, the rule of :func:`.articulated.fuse_roads` made causal).
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Sequence

import numpy as np

from road_force_estimator.core.articulated_parameters import ArticulatedParameters
from road_force_estimator.core.parameters import GRAVITY_MPS2, ObserverParameters
from road_force_estimator.core.unit_loads import UnitLoadTransfer
from road_force_estimator.estimation.articulated import (
    ArticulatedEstimate, ArticulatedOnline, estimate_articulated)
from road_force_estimator.estimation.fused_stream import FusedPoints, FusedStream
from road_force_estimator.estimation.models.articulated import ArticulatedObserverModel
from road_force_estimator.estimation.models.articulated_rows import CONV, DIST, columns
from road_force_estimator.estimation.static_load import TIME_CONSTANT_S

__all__ = ['UNITS', 'OFFSET_TIME_CONSTANT_S', 'WholeVehicleSample', 'WholeVehicleArrays',
           'WholeVehicleEstimator', 'WheelStaticTracker', 'estimate_whole_vehicle']

#: The lag (s) between each deflection's running mean and the offset the core's reading is
#: taken less: shorter than the front axle's 10 s (:mod:`.static_load`), because a truck that
#: sets off on an uneven road starts with its axles mm off their mean (the road's long waves
#: under the tri-axle group, up to 8 mm on class C), which a 10 s lag leaves in the core for
#: tens of seconds. Class C at 20 m/s, 10 um, 10 ms, zero-load readings, worst axle's
#: dynamic-load error 5-20 s / 20-40 s: 23.5 / 5.4 % with 10 s, 7.9 / 3.3 with 3 s,
#: 4.5 / 3.3 with 1 s, 4.2 / 3.3 with 0.3 s; class A: 24.5 / 7.4 with 10 s, 7.1 / 6.6 with
#: 1 s (the payload 4 t off the file's: the same to 0.4 point).
OFFSET_TIME_CONSTANT_S = 1.0

#: The units whose load transfer is estimated, in the order of the LTR fields.
UNITS = ('tractor', 'trailer', 'combination')


@dataclass(frozen=True)
class WholeVehicleSample:
    """One sample's estimate: ``load_n`` and ``static_n`` per wheel (N, the order of
    :attr:`WholeVehicleEstimator.wheel_names`), ``ltr`` and ``ltr_quasi_static`` per unit of
    :data:`UNITS`, ``lateral_mps2`` of the tractor and the trailer (m/s^2);
    ``innovations_gated`` per channel (:attr:`WholeVehicleEstimator.channel_names`) the
    samples gated so far; ``road_m`` every wheel's road (m, the wheels' order; online the
    causal or fixed-lag one), ``fused`` the fused profile's points the last axle passed with
    this sample, each ``(stamp_ns, distance_m, left_m, right_m)`` (online)."""

    stamp_ns: int
    distance_m: float
    converged: bool
    load_n: tuple
    static_n: tuple
    ltr: tuple
    ltr_quasi_static: tuple
    lateral_mps2: tuple
    innovations_gated: tuple = ()
    #: the front axle's own (LTR, quasi-static LTR) from its two wheels (``/load_transfer``)
    front_ltr: tuple = ()
    road_m: tuple = ()
    fused: tuple = ()


@dataclass(frozen=True)
class WholeVehicleArrays:
    """A drive's estimate, the fields of :class:`WholeVehicleSample` as arrays: per sample
    (m,), per wheel or unit (k, m); ``road_m`` every wheel's road (m; offline the smoother's,
    online the per-sample one); ``innovations_gated`` the drive's gated samples per channel
    (``channel_names``' order); ``fused`` online the streamed fused profile (every point the
    last axle passed), None offline (:func:`.articulated.fuse_roads` there)."""

    stamps_ns: np.ndarray
    distance_m: np.ndarray
    converged: np.ndarray
    wheel_names: tuple
    axle_names: tuple
    axle_bodies: tuple
    load_n: np.ndarray
    static_n: np.ndarray
    ltr: np.ndarray
    ltr_quasi_static: np.ndarray
    lateral_mps2: np.ndarray
    road_m: np.ndarray | None = None
    innovations_gated: tuple = ()
    channel_names: tuple = ()
    #: (2, m): the front axle's own LTR and quasi-static LTR from its two wheels
    front_ltr: np.ndarray | None = None
    fused: FusedPoints | None = None

    @property
    def axle_load_n(self) -> np.ndarray:
        """The static axle loads (N; (axles, m)): both wheels' static loads."""
        return self.static_n.reshape(len(self.axle_names), 2, -1).sum(axis=1)

    @property
    def gross_weight_n(self) -> np.ndarray:
        """The gross vehicle weight (N; (m,)): every wheel's static load."""
        return self.static_n.sum(axis=0)


class _Transfer:
    """Each unit's LTR from finalized rows, stepped by their stamps, and the front axle's own
    (the same recursion given the front axle alone: its wheels as both units, each needing
    one): ``[LTR, quasi-static] per unit + front`` (8 numbers)."""

    def __init__(self, vehicle: ArticulatedParameters, static_n) -> None:
        bodies = [a.body for a in vehicle.axles]
        static = np.reshape(static_n, (-1, 2))
        self.ltr = UnitLoadTransfer(bodies, static, 1e-3)
        self.front = UnitLoadTransfer(('tractor', 'trailer'), static[[0, 0]], 1e-3)
        self.last: int | None = None

    def update(self, stamp_ns: int, loads: Sequence[float]) -> list:
        dt = 0.0 if self.last is None else (stamp_ns - self.last) * 1e-9
        self.last = stamp_ns
        left, right = loads[0], loads[1]
        return self.ltr.update(loads, dt) + self.front.update((left, right, left, right),
                                                              dt)[:2]


class WheelStaticTracker:
    """Every instrumented wheel's static load from zero-load readings (module notes), one
    sample at a time: per deflection channel the running mean of :mod:`.static_load` (plain
    until ``time_constant_s`` of samples, then forgetting with it) and the core's offset
    lagging it by ``offset_time_constant_s`` (:data:`OFFSET_TIME_CONSTANT_S`).

    Parameters
    ----------
    model : ArticulatedObserverModel
        The file's vehicle: axle masses, stiffnesses, ``deflection_zero_load``; its statics
        are the loads until the first sample (and stay those of axles without sensors).
    """

    def __init__(self, model: ArticulatedObserverModel,
                 time_constant_s: float = TIME_CONSTANT_S,
                 offset_time_constant_s: float = OFFSET_TIME_CONSTANT_S) -> None:
        if not (time_constant_s > 0.0 and offset_time_constant_s > 0.0):
            raise ValueError(f'time constants {time_constant_s!r}, '
                             f'{offset_time_constant_s!r} s: must be > 0')
        self.tau = float(time_constant_s)
        self.tau_offset = float(offset_time_constant_s)
        v = model.vehicle
        self._q = [k for k, ch in enumerate(model.channels) if ch[0] == 'q']
        self._wheel = [2 * model.channels[k][1] + model.channels[k][2] for k in self._q]
        self._k = [v.axles[model.channels[k][1]].suspension_stiffness_npm[
            model.channels[k][2]] for k in self._q]
        self._b = [v.axles[model.channels[k][1]].deflection_zero_load_n[model.channels[k][2]]
                   + 0.5 * v.axles[model.channels[k][1]].mass_kg * GRAVITY_MPS2
                   for k in self._q]
        self._n = 0
        self._mean = [0.0] * len(self._q)
        self._offset = [0.0] * len(self._q)
        #: every wheel's static load (N) after the last sample
        self.static_n = [float(f) for f in model.static_wheel_load_n]

    def update(self, y: list, dt: float) -> list:
        """One sample's readings (the model's channels, m and rad; ``y`` changed in place and
        returned: each deflection less the core's offset) after a step ``dt`` (s; ignored for
        the first)."""
        n = self._n = self._n + 1
        a = 1.0 / n
        c = 1.0
        if n > 1:
            b = dt / self.tau
            if b > a:
                a = b if b < 1.0 else 1.0
            c = dt / self.tau_offset
            if c > 1.0:
                c = 1.0
        mean, offset, static = self._mean, self._offset, self.static_n
        for i, k in enumerate(self._q):
            m = mean[i] = mean[i] + a * (y[k] - mean[i])
            o = offset[i] = m if n == 1 else offset[i] + c * (m - offset[i])
            y[k] -= o
            static[self._wheel[i]] = self._b[i] - self._k[i] * m
        return y


class WholeVehicleEstimator:
    """Every output of the whole vehicle one sample at a time: :meth:`step` returns the samples
    finalized by that input (an ``observer.latency``'s samples late), :meth:`finish` the
    rest. ``static_n``: every wheel's static load (N), the file's statics, or under
    ``zero_load`` the tracker's after the last input (module notes)."""

    def __init__(self, vehicle: ArticulatedParameters,
                 observer: ObserverParameters | None = None) -> None:
        obs = ObserverParameters() if observer is None else observer
        self.vehicle = vehicle
        self.online = ArticulatedOnline(vehicle, obs.latency_s, obs)
        self.model = self.online.model
        self.wheel_names = self.online.wheel_names
        self.axle_names = vehicle.axle_names
        self.axle_bodies = tuple(a.body for a in vehicle.axles)
        self.channel_names = self.model.channel_names
        self.static_n = tuple(float(f) for f in self.model.static_wheel_load_n)
        nw = len(self.wheel_names)
        cols = columns(nw)
        self._load, self._ay = cols['load'], cols['ay']
        self._transfer = _Transfer(vehicle, self.static_n)
        self._dynamic = cols['dynamic']
        self._road = cols['road']
        #: the fused profile streamed (every axle of the vehicle, front first)
        self.fused = FusedStream([a.position_m for a in vehicle.axles])
        self.tracker = WheelStaticTracker(self.model) if vehicle.zero_load else None
        self._pending: dict[int, tuple] = {}      # each held sample's static loads
        self._last: int | None = None

    def step(self, stamp_ns: int, readings: Sequence[float], speed_mps: float
             ) -> list[WholeVehicleSample]:
        """One input: ``readings`` the model's channels (:attr:`channel_names`; m, rad, from
        the vehicle's deflection reference), ``speed_mps`` (m/s).

        Raises
        ------
        ValueError
            A reading or the speed not finite.
        """
        stamp = int(stamp_ns)
        y = [float(r) for r in readings]      # from the equilibrium unless zero_load
        if self.tracker is not None:
            if not math.isfinite(sum(y)):
                raise ValueError(f'sample at {stamp} ns: not finite')
            dt = 0.0 if self._last is None else (stamp - self._last) * 1e-9
            self.tracker.update(y, dt)
            self.static_n = tuple(self.tracker.static_n)
            self._pending[stamp] = self.static_n
        out = self._samples(self.online.step(stamp, y, float(speed_mps)))
        self._last = stamp
        return out

    def finish(self) -> list[WholeVehicleSample]:
        """The samples a latency still held."""
        return self._samples(self.online.finish())

    def _samples(self, ready: list) -> list[WholeVehicleSample]:
        out = []
        gated = tuple(self.online.core.gated)
        for stamp, row in ready:
            if self.tracker is None:
                static, loads = self.static_n, row[self._load]
            else:
                static = self._pending.pop(int(stamp))
                loads = [s + d for s, d in zip(static, row[self._dynamic])]
            t = self._transfer.update(int(stamp), loads)
            road = row[self._road]
            x = float(row[DIST])
            out.append(WholeVehicleSample(int(stamp), x, bool(row[CONV] > 0.5),
                                          tuple(loads), static, tuple(t[0:6:2]),
                                          tuple(t[1:6:2]), tuple(row[self._ay]), gated,
                                          tuple(t[6:]), tuple(road),
                                          tuple(self.fused.push(stamp, x, road, loads,
                                                                static))))
        return out


def _arrays(est: WholeVehicleEstimator, samples: list, road=None, gated=None
            ) -> WholeVehicleArrays:
    m = len(samples)
    fused = None
    if gated is None:             # online: the samples' roads and the streamed points
        gated = samples[-1].innovations_gated if samples else ()
        road = np.array([s.road_m for s in samples], float).reshape(
            m, len(est.wheel_names)).T.copy()
        fused = FusedPoints.from_points([p for s in samples for p in s.fused])

    def field(name: str) -> np.ndarray:
        return np.array([getattr(s, name) for s in samples], float).reshape(m, -1).T.copy()

    return WholeVehicleArrays(
        np.array([s.stamp_ns for s in samples], np.int64),
        np.array([s.distance_m for s in samples], float),
        np.array([s.converged for s in samples], bool), est.wheel_names, est.axle_names,
        est.axle_bodies, field('load_n'), field('static_n'), field('ltr'),
        field('ltr_quasi_static'), field('lateral_mps2'), road,
        tuple(int(g) for g in gated), tuple(est.channel_names), field('front_ltr'), fused)


def estimate_whole_vehicle(vehicle: ArticulatedParameters, stamps_ns, readings, speed_mps, *,
                           observer: ObserverParameters | None = None,
                           offline: bool = False) -> WholeVehicleArrays:
    """Every output over a drive: online :class:`WholeVehicleEstimator` sample by sample (its
    numbers exactly), offline the smoother (:func:`.articulated.estimate_articulated`) and the
    same load transfer over its loads.

    Parameters
    ----------
    stamps_ns : (m,) int, increasing
    readings : (m, channels) as :meth:`WholeVehicleEstimator.step` takes them
    speed_mps : (m,) or float (m/s)
    """
    est = WholeVehicleEstimator(vehicle, observer)
    stamps = np.asarray(stamps_ns, np.int64)
    v = np.broadcast_to(np.asarray(speed_mps, float), stamps.shape)
    if not offline:
        samples = []
        for s, y, vi in zip(stamps.tolist(), np.asarray(readings, float), v.tolist()):
            samples += est.step(s, y, vi)
        samples += est.finish()
        return _arrays(est, samples)
    y = np.array(readings, float)
    statics = None
    if est.tracker is not None:       # the online tracker's static loads and offsets
        statics = np.empty((stamps.size, len(est.wheel_names)))
        steps = np.zeros(stamps.size)
        steps[1:] = np.diff(stamps) * 1e-9
        update, tracked = est.tracker.update, est.tracker.static_n
        for k, dt in enumerate(steps.tolist()):
            y[k] = update(y[k].tolist(), dt)
            statics[k] = tracked
    smoothed: ArticulatedEstimate = estimate_articulated(
        vehicle, stamps, y, v, offline=True, observer=observer,
        from_equilibrium=statics is not None)
    samples = []
    for k, stamp in enumerate(stamps.tolist()):
        if statics is None:
            static, loads = est.static_n, smoothed.load_n[:, k].tolist()
        else:
            static = tuple(statics[k].tolist())
            loads = (statics[k] + smoothed.dynamic_n[:, k]).tolist()
        t = est._transfer.update(stamp, loads)
        samples.append(WholeVehicleSample(
            stamp, float(smoothed.distance_m[k]), bool(smoothed.converged[k]), tuple(loads),
            static, tuple(t[0:6:2]), tuple(t[1:6:2]), tuple(smoothed.lateral_mps2[:, k]),
            smoothed.innovations_gated, tuple(t[6:])))
    return _arrays(est, samples, smoothed.road_m, smoothed.innovations_gated)
