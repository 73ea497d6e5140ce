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
samples the observer's innovation gate (``observer.innovation_gate``) replaced. Offline,
and online at every latency, ``axle_fit`` says which axle or sensor does not fit
(:mod:`.axle_fit`: each axle's road against the other axles' at the same distance).

Gaps (:mod:`.articulated`'s rule, the front axle's): a step longer than ``max(0.1 s, 10
typical steps)`` restarts the observer (online and offline, each run smoothed on its own);
the static-load tracker keeps its mean and offset over it (a step of 0: the load has not
changed, as :mod:`.static_load`'s), the load transfer's filters step over it; ``gaps``
counts them (per sample: the gaps so far).

The road online: every wheel's road per finalized sample (at zero latency from the bodies,
:class:`.models.articulated_rows.BodyRoads`; the fixed-lag one with ``observer.latency`` from
the wheels, :class:`.models.articulated_rows.WheelRoads`) and
the fused profile streamed (:class:`.fused_stream.FusedStream`: each point once the last axle
has passed it, the rule of :func:`.articulated.fuse_roads` made causal).

Sensor health (:mod:`.sensor_health`, :meth:`.FaultSettings.of_whole_vehicle`): every
channel flagged ``stuck`` when it alone stays still, each deflection of a unit with three
instrumented axles or more flagged ``drift`` against its neighbours (:class:`.UnitDrift`),
from the readings as they come (before the static-load tracker) and the speed: the same flags
online, at a latency and offline. Online (every latency) a stuck channel, deflection or
roll, is left out of the filter while flagged (:meth:`.ModelCore.set_excluded`: below);
a drifting deflection stays fed; offline the smoother leaves each stuck stretch out, the
held readings before the flag too (:func:`.sensor_health.left_out`, :meth:`.Smoother.pieces`
``left_out``). ``sensor_flags`` per sample
(:data:`.sensor_health.CODES`), ``faults`` the drive's counts.

The tanh friction's ``v_f`` offline (``observer.friction_velocity_fit``, the front axle's rule,
:mod:`.friction_fit`): :meth:`WholeVehicleOfflineStream.finish` fits one ``v_f`` for every
spring (:func:`fit_friction_velocity`) on the first run's readings before its smoother, so a
drive in one block and in pieces take the same; not under ``zero_load``.

The tractor IMU without a fresh a_y (``imu``; a sample whose pairing, :mod:`.imu_hold`, is
stale or missing: ``imu_fresh`` False, ``imu_codes`` not 0) is left out the same way, online
and offline, for that sample: its row (:func:`imu_left_out`), and with pendulum roll sensors
the roll rows too (they read ``phi + a_y / g`` and a_y is not known; the rolls without the
IMU would be the tilt / lateral-acceleration ambiguity, whose gain design fails). The held
a_y fed instead cost 2.4-3.3 x the fresh IMU's load error on the tractor through a curve
(``python -m bench.studies.imu_dropout``).
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, fields, replace
import math
from typing import Callable, Iterable, Iterator, Sequence

import numpy as np

from road_force_estimator.core.articulated_parameters import ArticulatedParameters
from road_force_estimator.core.parameters import GRAVITY_MPS2, ObserverParameters
from road_force_estimator.core.unit_loads import UnitLoadTransfer, unit_masks
from road_force_estimator.estimation.acceptance import GAP_THRESHOLD_S, StepGaps
from road_force_estimator.estimation.articulated import (
    ArticulatedOnline, run_starts)
from road_force_estimator.estimation.axle_fit import (
    ONLINE_MIN_LATENCY_S, AxleFit, OnlineAxleFit, assess_axles)
from road_force_estimator.estimation.friction_fit import (
    FrictionVelocity, fit_end, fits, likeliest_velocity)
from road_force_estimator.estimation.fused_stream import FusedPoints, FusedStream
from road_force_estimator.estimation.rollover_warning import LtrPredictor, predicted_ltr
from road_force_estimator.estimation.models.articulated import ArticulatedObserverModel
from road_force_estimator.estimation.models.articulated_rows import CONV, DIST, columns
from road_force_estimator.estimation.sensor_health import (
    CODES, FaultCounts, FaultDetector, FaultSettings, left_out)
from road_force_estimator.estimation.static_load import TIME_CONSTANT_S

__all__ = ['UNITS', 'OFFSET_TIME_CONSTANT_S', 'PIECE_ROWS',
           'STREAM_WINDOW_SAMPLES', 'STREAM_OVERLAP_S', 'WholeVehicleSample',
           'WholeVehicleArrays', 'WholeVehicleEstimator', 'WheelStaticTracker',
           'WholeVehicleOfflineStream', 'estimate_whole_vehicle', 'concatenate_arrays',
           'fit_axles', 'CHUNK_ROWS', 'WholeVehicleOnlineStream', 'estimate_online_blocks',
           'imu_left_out', 'ROW_FIELDS', 'take_rows', 'join_rows', 'ArraysRows',
           'fit_friction_velocity']

#: The lag (s) between each deflection's running mean and the offset the core's reading is
#: taken less: shorter than the front axle's 10 s (:mod:`.static_load`), because a truck that
#: sets off on an uneven road starts with its axles mm off their mean (the road's long waves
#: under the tri-axle group, up to 8 mm on class C), which a 10 s lag leaves in the core for
#: tens of seconds. Class C at 20 m/s, 10 um, 10 ms, zero-load readings, worst axle's
#: dynamic-load error 5-20 s / 20-40 s: 23.5 / 5.4 % with 10 s, 7.9 / 3.3 with 3 s,
#: 4.5 / 3.3 with 1 s, 4.2 / 3.3 with 0.3 s; class A: 24.5 / 7.4 with 10 s, 7.1 / 6.6 with
#: 1 s (the payload 4 t off the file's: the same to 0.4 point).
OFFSET_TIME_CONSTANT_S = 1.0

# A stuck channel is left out of the filter at every latency: each step takes its prediction
# for its reading (no fixed-lag output is given the held reading) and
# ``observer.fault_stuck_time`` is 0.05 s. On class C and A at 20 m/s
# (``python -m bench.studies.articulated_sensor_faults``'s drives), a channel stuck for 2 s cost
# the worst axle 17.8-25.4 % (deflections) and 3.2-9.4 % (rolls) at 10 ms against 3.2 / 6.4 %
# clean; fed, 43-79 % and 238-285 %. Offline the smoother leaves the stretch out
# (``python -m bench.studies.articulated_sensor_faults --only latency --faults stuck
# --modes offline``).

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
    #: the gaps in the input so far, this sample's included (each restarted the estimate)
    gaps: int = 0
    #: every wheel's road (m; online, the finalized sample's), wheels in ``wheel_names``
    road_m: tuple = ()
    #: the fused profile's points this sample completed (:class:`.fused_stream.FusedStream`)
    fused: tuple = ()
    #: the model fit per axle this sample completed online (:class:`.axle_fit.OnlineAxleFit`)
    axle_fit: AxleFit | None = None
    #: each unit's predicted LTR (:class:`.rollover_warning.LtrPredictor`: the quasi-static
    #: LTR a lead ahead, for a rollover warning), the order of :data:`UNITS`
    ltr_predicted: tuple = ()
    #: each channel's sensor flag at this sample (:data:`.sensor_health.CODES`: 0 ok, 1
    #: stuck, 2 drift; ``channel_names``' order)
    sensor_flags: tuple = ()


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
    #: (m,) int: the gaps so far at each sample (each restarted the estimate)
    gaps: np.ndarray | None = None

    @property
    def gap_count(self) -> int:
        """The drive's gaps."""
        return int(self.gaps[-1]) if self.gaps is not None and self.gaps.size else 0

    #: the model fit per axle (:class:`.axle_fit.AxleFit`: which axle or sensor does not
    #: fit) over the instrumented axles: offline the drive's, online the last verdict (at
    #: every latency); None with fewer than 3 of them, or online before the first verdict
    axle_fit: AxleFit | None = None
    #: online, the fused profile's points streamed (:class:`.fused_stream.FusedPoints`)
    fused: FusedPoints | None = None
    #: online, each verdict of the model fit per axle as ``(stamp_ns, AxleFit)`` at the
    #: sample that completed it (:class:`.axle_fit.OnlineAxleFit`; ``axle_fit`` the last)
    axle_fits: tuple = ()
    #: (channels, m) int8: each sample's sensor flags (:data:`.sensor_health.CODES`: 0 ok,
    #: 1 stuck, 2 drift), or None
    fault_flags: np.ndarray | None = None
    #: the drive's sensor flags and counts by channel (:class:`.sensor_health.FaultCounts`)
    faults: FaultCounts | None = None
    #: (m,) int8: each sample's tractor IMU pairing (:mod:`.imu_hold`: 0 fresh, 1 stale, 2
    #: missing) where the caller paired it, or None
    imu_codes: np.ndarray | None = None
    #: the input messages its reader dropped, topic -> reason -> count (the caller's; e.g.
    #: :class:`road_force_estimator.bagio.checks.Rejects`' counts), or None
    rejected: dict | None = None
    #: the input messages its reader read, topic -> count (the caller's), or None
    messages: dict | None = None
    #: offline, the tanh friction's ``v_f`` taken and the file's
    #: (:class:`.friction_fit.FrictionVelocity`, :attr:`WholeVehicleOfflineStream.
    #: friction_velocity`); None: online, or no tanh friction stated
    friction_velocity: FrictionVelocity | None = None

    @property
    def axle_load_n(self) -> np.ndarray:
        """The static axle loads (N; (axles, m)): both wheels' static loads."""
        return self.static_n.reshape(len(self.axle_names), 2, -1).sum(axis=1)

    @property
    def ltr_predicted(self) -> np.ndarray:
        """Each unit's predicted LTR ((units, m); :func:`.rollover_warning.predicted_ltr` of
        the quasi-static LTR: online the samples' ``ltr_predicted`` exactly)."""
        return predicted_ltr(self.stamps_ns, self.ltr_quasi_static)

    @property
    def gross_weight_n(self) -> np.ndarray:
        """The gross vehicle weight (N; (m,)): every wheel's static load."""
        return self.static_n.sum(axis=0)


class _Transfer:
    """Each unit's LTR from finalized rows, stepped by their stamps, and the front axle's own
    (the same recursion given the front axle alone, one unit of its two wheels): ``[LTR,
    quasi-static] per unit + front`` (8 numbers). One recursion of four units, the front
    axle's first: the tractor's sums go on from it and the combination's from the tractor's
    (:class:`.UnitLoadTransfer`: the same additions, the same bits as each unit summed
    alone)."""

    def __init__(self, vehicle: ArticulatedParameters, static_n) -> None:
        bodies = [a.body for a in vehicle.axles]
        static = np.reshape(static_n, (-1, 2))
        self.ltr = UnitLoadTransfer(bodies, static, 1e-3,
                                    units=[[0], *unit_masks(bodies)])
        self.last: int | None = None

    def update(self, stamp_ns: int, loads: Sequence[float]) -> list:
        dt = 0.0 if self.last is None else (stamp_ns - self.last) * 1e-9
        self.last = stamp_ns
        out = self.ltr.update(loads, dt)
        return out[2:] + out[:2]


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


def imu_left_out(model: ArticulatedObserverModel) -> tuple[int, ...]:
    """The channels (indices of ``model``'s) left out of a sample without a fresh a_y (module
    notes): the IMU's, and the roll sensors' where they are pendulums read with the IMU
    (``model.pendulum``); () without the IMU."""
    if not model.imu:
        return ()
    rolls = tuple(model.roll_channels) if model.pendulum else ()
    return tuple(sorted(rolls + (len(model.channels) - 1,)))


class WholeVehicleEstimator:
    """Every output of the whole vehicle one sample at a time: :meth:`step` returns the samples
    finalized by that input (an ``observer.latency``'s samples late), :meth:`finish` the
    rest. ``static_n``: every wheel's static load (N), the file's statics, or under
    ``zero_load`` the tracker's after the last input (module notes). ``imu``: the readings'
    last channel is the tractor IMU's a_y (m/s^2, ``/imu/tractor``'s
    ``linear_acceleration.y``; :data:`.models.articulated.IMU_CHANNEL`)."""

    def __init__(self, vehicle: ArticulatedParameters,
                 observer: ObserverParameters | None = None, *,
                 gap_threshold_s: float = GAP_THRESHOLD_S, imu: bool = False) -> None:
        obs = ObserverParameters() if observer is None else observer
        self.vehicle = vehicle
        self.online = ArticulatedOnline(vehicle, obs.latency_s, obs,
                                        gap_threshold_s=gap_threshold_s, imu=imu)
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
        self._predictor = LtrPredictor()
        self._dynamic = cols['dynamic']
        self._road = cols['road']
        #: the fused profile streamed (every axle of the vehicle, front first)
        self.fused = FusedStream([a.position_m for a in vehicle.axles])
        self.tracker = WheelStaticTracker(self.model) if vehicle.zero_load else None
        #: the model fit per instrumented axle online (3 such axles; below
        #: ``ONLINE_MIN_LATENCY_S`` on the causal road, :mod:`.axle_fit`'s ``causal``)
        inst = [j for j, a in enumerate(vehicle.axles) if a.instrumented]
        self._fit_rows = [2 * j + side for j in inst for side in (0, 1)]
        self.axle_fit_online = (
            OnlineAxleFit([vehicle.axles[j].position_m for j in inst],
                          [vehicle.axles[j].name for j in inst],
                          causal=obs.latency_s < ONLINE_MIN_LATENCY_S)
            if len(inst) >= 3 else None)
        self._pending: dict[int, tuple] = {}      # each held sample's static loads
        self._gaps: deque = deque()                # each held sample's gaps so far
        self._last: int | None = None
        #: stuck and drifting sensors (:mod:`.sensor_health`; module notes)
        self.faults = FaultDetector(FaultSettings.of_whole_vehicle(obs, self.model))
        self._codes: deque = deque()               # each held sample's sensor flags
        self._flags = (0,) * len(self.channel_names)
        self._events = 0
        #: left out of a sample without a fresh a_y (module notes)
        self.imu_out = frozenset(imu_left_out(self.model))

    def step(self, stamp_ns: int, readings: Sequence[float], speed_mps: float,
             imu_fresh: bool = True) -> list[WholeVehicleSample]:
        """One input: ``readings`` the model's channels (:attr:`channel_names`; m, rad, from
        the vehicle's deflection reference), ``speed_mps`` (m/s); ``imu_fresh`` False: the
        IMU's a_y (the last reading) is not fresh, the sample's :attr:`imu_out` channels are
        left out (module notes).

        Raises
        ------
        ValueError
            A reading or the speed not finite.
        """
        stamp = int(stamp_ns)
        y = list(map(float, readings))      # from the equilibrium unless zero_load
        raw = y if self.tracker is None else list(y)
        faults = self.faults
        stuck = faults.stuck
        if True in stuck or not imu_fresh or self.online.core.schedule.excluded:
            out = {k for k, s in enumerate(stuck) if s}       # left out (module notes)
            if not imu_fresh:
                out |= self.imu_out
            self.online.core.set_excluded(tuple(sorted(out)))
        if self.tracker is not None:
            if not math.isfinite(sum(y)):
                raise ValueError(f'sample at {stamp} ns: not finite')
            dt = 0.0 if self.online.starts_run(stamp) else (stamp - self._last) * 1e-9
            self.tracker.update(y, dt)
            self.static_n = tuple(self.tracker.static_n)
            self._pending[stamp] = self.static_n
        ready = self.online.step(stamp, y, float(speed_mps))
        self._gaps.append(self.online.gaps)
        faults.step(stamp, raw, (float(speed_mps),))
        if len(faults.events) != self._events:
            self._events = len(faults.events)
            self._flags = tuple(CODES[f] for f in faults.flags)
        self._codes.append(self._flags)
        out = self._samples(ready)
        self._last = stamp
        return out

    def finish(self) -> list[WholeVehicleSample]:
        """The samples a latency still held."""
        return self._samples(self.online.finish())

    def _samples(self, ready: list) -> list[WholeVehicleSample]:
        out = []
        if not ready:
            return out
        gated = tuple(self.online.core.gated)
        transfer, push, predict = self._transfer.update, self.fused.push, self._predictor.update
        for stamp, row in ready:
            stamp = int(stamp)
            if self.tracker is None:
                static, loads = self.static_n, row[self._load]
            else:
                static = self._pending.pop(stamp)
                loads = tuple([s + d for s, d in zip(static, row[self._dynamic])])
            t = transfer(stamp, loads)
            quasi_static = (t[1], t[3], t[5])
            road = row[self._road]
            x = float(row[DIST])
            fit = None
            if self.axle_fit_online is not None:
                rows = self._fit_rows
                fit = self.axle_fit_online.push(stamp, x, np.asarray(road)[rows],
                                                np.asarray(loads)[rows],
                                                np.asarray(static)[rows])
            out.append(_sample(stamp, x, bool(row[CONV] > 0.5), loads, static,
                               (t[0], t[2], t[4]), quasi_static, row[self._ay], gated,
                               (t[6], t[7]), self._gaps.popleft(), road,
                               tuple(push(stamp, x, road, loads, static)), fit,
                               predict(stamp, quasi_static), self._codes.popleft()))
        return out


_SAMPLE_FIELDS = tuple(f.name for f in fields(WholeVehicleSample))
_new = object.__new__


def _sample(*values) -> WholeVehicleSample:
    """A :class:`WholeVehicleSample` of every field's value in their order, made without the
    frozen dataclass's ``__init__`` (one ``object.__setattr__`` per field: 3.9 against 1.2 us
    a sample): the same object, its fields in its ``__dict__``."""
    if len(values) != len(_SAMPLE_FIELDS):
        raise TypeError(f'{len(values)} values for the {len(_SAMPLE_FIELDS)} fields')
    sample = _new(WholeVehicleSample)
    sample.__dict__.update(zip(_SAMPLE_FIELDS, values))
    return sample


def _arrays(est: WholeVehicleEstimator, samples: list, road=None, gated=None,
            gaps: np.ndarray | None = None) -> WholeVehicleArrays:
    m = len(samples)
    fused = None
    fits: tuple = ()
    if gated is None:             # online: the samples' roads and the streamed points
        gated = samples[-1].innovations_gated if samples else ()
        road = np.array([s.road_m for s in samples], float).reshape(
            m, len(est.wheel_names)).T.copy()
        fused = FusedPoints.from_points([p for s in samples for p in s.fused])
        fits = tuple((s.stamp_ns, s.axle_fit) for s in samples if s.axle_fit is not None)

    def field(name: str) -> np.ndarray:
        return np.array([getattr(s, name) for s in samples], float).reshape(m, -1).T.copy()

    return WholeVehicleArrays(
        np.array([s.stamp_ns for s in samples], np.int64),
        np.array([s.distance_m for s in samples], float),
        np.array([s.converged for s in samples], bool), est.wheel_names, est.axle_names,
        est.axle_bodies, field('load_n'), field('static_n'), field('ltr'),
        field('ltr_quasi_static'), field('lateral_mps2'), road,
        tuple(int(g) for g in gated), tuple(est.channel_names), field('front_ltr'),
        np.array([s.gaps for s in samples], np.int64) if gaps is None else gaps,
        fused=fused, axle_fits=fits, axle_fit=fits[-1][1] if fits else None,
        fault_flags=np.array([s.sensor_flags for s in samples], np.int8).reshape(
            m, len(est.channel_names)).T.copy(), faults=est.faults.counts())


def estimate_whole_vehicle(vehicle: ArticulatedParameters, stamps_ns, readings, speed_mps, *,
                           observer: ObserverParameters | None = None,
                           offline: bool = False,
                           gap_threshold_s: float = GAP_THRESHOLD_S,
                           windows: bool = False,
                           imu: bool = False,
                           chunk_rows: int | None = None,
                           imu_codes=None) -> WholeVehicleArrays:
    """Every output over a drive: online :class:`WholeVehicleEstimator` sample by sample (its
    numbers exactly), offline the smoother (:func:`.articulated.estimate_articulated`) and the
    same load transfer over its loads.

    Parameters
    ----------
    stamps_ns : (m,) int, increasing
    readings : (m, channels) as :meth:`WholeVehicleEstimator.step` takes them
    speed_mps : (m,) or float (m/s)
    gap_threshold_s : the shortest step that is a gap (s; module notes)
    windows : offline, smooth a run longer than :data:`STREAM_WINDOW_SAMPLES` and its
        overlap in windows (:class:`WholeVehicleOfflineStream` ``eager``: the load pass's
        rows held a window at a time; each field within ~3e-4 of its RMS of the one-block
        estimate); False: the smoother's own rule (the one-block numbers)
    imu : the readings' last column is the tractor IMU's a_y (m/s^2)
    chunk_rows : online, the samples turned into arrays at a time (no per-sample object
        held longer; :data:`CHUNK_ROWS`; the same numbers whatever it is)
    imu_codes : (m,) each sample's IMU pairing (:mod:`.imu_hold` codes; not 0: the a_y is
        not fresh, :func:`imu_left_out`'s channels are left out of that sample); None:
        every a_y fresh

    Raises
    ------
    ValueError
        No sample (a drive's estimate has at least one).
    """
    stamps = np.asarray(stamps_ns, np.int64)
    if stamps.size == 0:
        raise ValueError('estimate_whole_vehicle: no samples (stamps_ns is empty)')
    v = np.broadcast_to(np.asarray(speed_mps, float), stamps.shape)
    if not offline:
        y, c = np.asarray(readings, float), max(int(chunk_rows or CHUNK_ROWS), 1)
        return estimate_online_blocks(        # fed a chunk at a time: no list held
            vehicle, ((stamps[a:a + c], y[a:a + c], v[a:a + c],
                       None if imu_codes is None else imu_codes[a:a + c])
                      for a in range(0, stamps.size, c)),
            observer=observer, gap_threshold_s=gap_threshold_s, imu=imu,
            capacity=stamps.size, chunk_rows=c)
    stream = WholeVehicleOfflineStream(vehicle, observer, gap_threshold_s=gap_threshold_s,
                                       eager=bool(windows), imu=imu)
    stream.feed(stamps, readings, v, imu_codes)
    out = concatenate_arrays(list(stream.finish()))
    return replace(out, axle_fit=fit_axles(vehicle, out),
                   friction_velocity=stream.friction_velocity)


def estimate_online_blocks(vehicle: ArticulatedParameters, blocks: Iterable[tuple], *,
                           observer: ObserverParameters | None = None,
                           gap_threshold_s: float = GAP_THRESHOLD_S, imu: bool = False,
                           capacity: int = 0,
                           chunk_rows: int | None = None,
                           sink: Callable[[WholeVehicleArrays], None] | None = None
                           ) -> WholeVehicleArrays:
    """:func:`estimate_whole_vehicle` online over a drive's ``blocks`` (each ``(stamps_ns,
    readings, speed_mps[, imu_codes])`` as :meth:`WholeVehicleOnlineStream.feed` takes
    them, consumed as they come): the same arrays, the blocks' inputs never held together;
    ``capacity``: the samples the arrays are reserved for at once (a bag's metadata; grown
    past it). ``sink``: each piece handed to it instead (none gathered); the arrays returned
    then hold no sample, only what is the drive's (the fused points, the model-fit verdicts,
    the gated innovations and the sensor counts; the pieces' own are those so far)."""
    online = WholeVehicleOnlineStream(vehicle, observer, gap_threshold_s=gap_threshold_s,
                                      imu=imu, chunk_rows=chunk_rows)
    gathered = _OnlineArrays(online.estimator, 0 if sink is not None else capacity,
                             keep=sink is None)
    for block in blocks:
        for piece in online.feed(*block):
            gathered.add(piece)
            if sink is not None:
                sink(piece)
    for piece in online.finish():
        gathered.add(piece)
        if sink is not None:
            sink(piece)
    return gathered.arrays()


#: The samples :func:`estimate_whole_vehicle` converts to arrays at a time online (no
#: per-sample object held longer).
CHUNK_ROWS = 1 << 14

#: The per-sample fields of :class:`WholeVehicleArrays` (the sample the last axis).
_PER_SAMPLE = ('stamps_ns', 'distance_m', 'converged', 'load_n', 'static_n', 'ltr',
               'ltr_quasi_static', 'lateral_mps2', 'road_m', 'front_ltr', 'gaps',
               'fault_flags')


class _Gathered:
    """Per-sample fields of :class:`WholeVehicleArrays` pieces written into arrays reserved
    for ``capacity`` samples (doubling past it; trimmed at the end): the pieces' own bits,
    without a list of pieces and their concatenation held at once."""

    def __init__(self, capacity: int) -> None:
        self.capacity = max(int(capacity), 1)
        self.cols: dict | None = None
        self.n = 0

    def add(self, piece: WholeVehicleArrays) -> None:
        m = len(piece.stamps_ns)
        if self.cols is None:
            self.cols = {f: None if getattr(piece, f) is None else
                         np.empty(getattr(piece, f).shape[:-1] + (max(self.capacity, m),),
                                  getattr(piece, f).dtype) for f in _PER_SAMPLE}
        n = self.n
        for f, col in self.cols.items():
            if col is None:
                continue
            if n + m > col.shape[-1]:
                grown = np.empty(col.shape[:-1] + (max(2 * col.shape[-1], n + m),), col.dtype)
                grown[..., :n] = col[..., :n]
                self.cols[f] = col = grown
            col[..., n:n + m] = getattr(piece, f)
        self.n = n + m

    def fields(self) -> dict:
        """Each per-sample field over the pieces added (C-contiguous; None: the pieces'
        None)."""
        cols, self.cols = self.cols or {}, None
        return {f: None if c is None else
                (c if c.shape[-1] == self.n else np.ascontiguousarray(c[..., :self.n]))
                for f, c in cols.items()}


class _OnlineArrays:
    """The online pieces (:class:`WholeVehicleOnlineStream`'s) as one
    :class:`WholeVehicleArrays`, written into arrays reserved for ``capacity`` samples
    (:class:`_Gathered`): the same arrays as converting every sample at once."""

    def __init__(self, est: WholeVehicleEstimator, capacity: int, keep: bool = True):
        self.est = est
        self.out = _Gathered(capacity)
        self.keep = keep
        self.fused: list = []
        self.fits: list = []
        self.gated: tuple = ()

    def add(self, a: WholeVehicleArrays) -> None:
        self.gated = a.innovations_gated
        self.fits += a.axle_fits
        if a.fused.stamps_ns.size:
            self.fused.append(a.fused)
        if self.keep:
            self.out.add(a)

    def arrays(self) -> WholeVehicleArrays:
        """Every sample's fields (after :meth:`WholeVehicleEstimator.finish`'s were added);
        not kept: none, with the drive's fused points, verdicts and counts."""
        if not self.out.n:
            if not self.keep:
                fits = tuple(self.fits)
                est, w = self.est, len(self.est.wheel_names)

                def empty(rows: int | None, dtype=float) -> np.ndarray:
                    return np.zeros((0,) if rows is None else (rows, 0), dtype)

                none = WholeVehicleArrays(
                    empty(None, np.int64), empty(None), empty(None, bool), est.wheel_names,
                    est.axle_names, est.axle_bodies, empty(w), empty(w), empty(len(UNITS)),
                    empty(len(UNITS)), empty(None), empty(w), (), tuple(est.channel_names),
                    empty(2), empty(None, np.int64),
                    fault_flags=empty(len(est.channel_names), np.int8),
                    faults=est.faults.counts())
                return replace(none, fused=FusedPoints(*(
                    np.concatenate([getattr(p, f) for p in self.fused]) for f in
                    ('stamps_ns', 'distance_m', 'left_m', 'right_m')))
                    if self.fused else FusedPoints.from_points([]),
                    innovations_gated=tuple(int(g) for g in self.gated), axle_fits=fits,
                    axle_fit=fits[-1][1] if fits else None)
            return _arrays(self.est, [])
        fused = (FusedPoints(*(np.concatenate([getattr(p, f) for p in self.fused]) for f in
                               ('stamps_ns', 'distance_m', 'left_m', 'right_m')))
                 if self.fused else FusedPoints.from_points([]))
        fits = tuple(self.fits)
        est = self.est
        return WholeVehicleArrays(
            wheel_names=est.wheel_names, axle_names=est.axle_names,
            axle_bodies=est.axle_bodies, innovations_gated=tuple(int(g) for g in self.gated),
            channel_names=tuple(est.channel_names), fused=fused, axle_fits=fits,
            axle_fit=fits[-1][1] if fits else None, faults=est.faults.counts(),
            **self.out.fields())


class WholeVehicleOnlineStream:
    """:class:`WholeVehicleEstimator` carried from block to block of a drive (the node's
    numbers: the same bits however the drive is cut): :meth:`feed` steps a block's samples
    and returns the pieces completed (:class:`WholeVehicleArrays` of ``chunk_rows`` samples,
    :data:`CHUNK_ROWS` by default; each piece's ``fused`` the points its samples completed,
    ``axle_fits`` its verdicts, ``innovations_gated`` and ``faults`` the counts so far),
    :meth:`finish` the rest (what a latency held). What it keeps between blocks does not grow
    with the drive: the estimator's state and at most one piece's samples."""

    def __init__(self, vehicle: ArticulatedParameters,
                 observer: ObserverParameters | None = None, *,
                 gap_threshold_s: float = GAP_THRESHOLD_S, imu: bool = False,
                 chunk_rows: int | None = None) -> None:
        self.estimator = WholeVehicleEstimator(vehicle, observer,
                                               gap_threshold_s=gap_threshold_s, imu=imu)
        self.chunk_rows = max(int(chunk_rows or CHUNK_ROWS), 1)
        #: the samples fed so far
        self.fed = 0
        self._pending: list = []

    def feed(self, stamps_ns, readings, speed_mps, imu_codes=None
             ) -> list[WholeVehicleArrays]:
        """One block: ``stamps_ns`` (m,) increasing across blocks, ``readings`` (m, channels)
        as :meth:`WholeVehicleEstimator.step` takes them, ``speed_mps`` (m,) or a float
        (m/s), ``imu_codes`` (m,) the IMU's pairing (:func:`estimate_whole_vehicle`'s; None:
        every a_y fresh); the pieces completed.

        Raises
        ------
        ValueError
            A reading or the speed not finite (:meth:`WholeVehicleEstimator.step`).
        """
        stamps = np.asarray(stamps_ns, np.int64)
        v = np.broadcast_to(np.asarray(speed_mps, float), stamps.shape)
        out = []
        step, chunk, pending = self.estimator.step, self.chunk_rows, self._pending
        fresh = (np.ones(stamps.size, bool) if imu_codes is None else
                 np.asarray(imu_codes).reshape(-1) == 0).tolist()
        for s, y, vi, f in zip(stamps.tolist(), np.asarray(readings, float), v.tolist(), fresh):
            pending += step(s, y, vi, f)
            if len(pending) >= chunk:
                out.append(self._piece())
                pending = self._pending
        self.fed += stamps.size
        return out

    def finish(self) -> list[WholeVehicleArrays]:
        """The last piece (the samples a latency held with those not yet handed out)."""
        self._pending += self.estimator.finish()
        return [self._piece()] if self._pending else []

    def _piece(self) -> WholeVehicleArrays:
        piece = _arrays(self.estimator, self._pending)
        self._pending = []
        return piece


#: The per-sample fields :func:`take_rows` and :func:`join_rows` cut and join (with the
#: tractor IMU's pairing codes).
ROW_FIELDS = _PER_SAMPLE + ('imu_codes',)


def take_rows(wv: WholeVehicleArrays, lo: int, hi: int) -> WholeVehicleArrays:
    """The samples ``lo:hi`` of ``wv`` (views), what is the drive's (names, counts, fused
    points, verdicts, rejections) as it is."""
    return replace(wv, **{f: getattr(wv, f)[..., lo:hi] for f in ROW_FIELDS
                          if getattr(wv, f) is not None})


def join_rows(a: WholeVehicleArrays, b: WholeVehicleArrays) -> WholeVehicleArrays:
    """The samples of ``a`` then ``b`` (consecutive rows of one drive), the drive's fields
    ``a``'s."""
    return replace(a, **{f: np.concatenate([getattr(a, f), getattr(b, f)], axis=-1)
                         for f in ROW_FIELDS if getattr(a, f) is not None})


class ArraysRows:
    """A drive's :class:`WholeVehicleArrays` as a source of rows (``n`` samples, ``meta``
    the drive's fields, :meth:`rows` the samples ``lo:hi``), as the sinks of a drive in
    blocks read a spilled estimate (:class:`road_force_estimator.pipeline.whole_vehicle.
    SpilledEstimate`)."""

    def __init__(self, wv: WholeVehicleArrays) -> None:
        self.meta = wv
        self.n = int(len(wv.stamps_ns))

    def rows(self, lo: int, hi: int) -> WholeVehicleArrays:
        return take_rows(self.meta, lo, hi)


def concatenate_arrays(pieces: Sequence[WholeVehicleArrays]) -> WholeVehicleArrays:
    """Pieces of one drive's estimate (:meth:`WholeVehicleOfflineStream.finish`'s, in order)
    as one: the per-sample fields joined, the counts the last piece's."""
    if not pieces:
        raise ValueError('no piece: nothing estimated')
    last = pieces[-1]

    def join(name: str):
        parts = [getattr(p, name) for p in pieces]
        if any(a is None for a in parts):
            return None
        return np.concatenate(parts, axis=-1)

    return WholeVehicleArrays(
        join('stamps_ns'), join('distance_m'), join('converged'), last.wheel_names,
        last.axle_names, last.axle_bodies, join('load_n'), join('static_n'), join('ltr'),
        join('ltr_quasi_static'), join('lateral_mps2'), join('road_m'),
        last.innovations_gated, last.channel_names, join('front_ltr'), join('gaps'),
        fault_flags=join('fault_flags'), faults=last.faults)


#: Most samples of a piece :meth:`WholeVehicleOfflineStream.finish` hands out.
PIECE_ROWS = 1 << 16
#: The stream's smoother windows (samples; :class:`.smoothing.smoother.Smoother`'s
#: ``window``): the load pass's rows are held a window and its overlaps at a time (~60
#: columns, ~75 MB at 1 kHz), not the run's.
STREAM_WINDOW_SAMPLES = 1 << 17
#: The overlap of the stream's windows on each side (s). The smoother's own rule (16 time
#: constants of the filter's slowest mode) would be 445 s here: the articulated model's
#: slowest mode is 27.8 s (the road levels under the axles, neutral, :mod:`.articulated`),
#: but what it moves in the loads is small: on 40 s of class C at 20 m/s, 1 kHz, windows of
#: 10 s took each field within 3.1e-4 of its RMS of the one-block estimate with 2 s of
#: overlap, 2.2e-4 with 5 s, 1.3e-4 with 10 s (the loads' error against the truth the same
#: to 1e-6 of a point: 2.79 %).
STREAM_OVERLAP_S = 10.0


class _Columns:
    """Growable per-sample columns (doubling, trimmed by :meth:`arrays`): one array per
    ``(dtype, row shape)``."""

    def __init__(self, specs: Sequence[tuple], capacity: int) -> None:
        self.n = 0
        self.cols = [np.empty((max(int(capacity), 1),) + tuple(shape), dtype)
                     for dtype, shape in specs]

    def append(self, *blocks) -> None:
        k = np.shape(blocks[0])[0]
        if self.n + k > self.cols[0].shape[0]:
            size = max(2 * self.cols[0].shape[0], self.n + k)
            self.cols = [np.concatenate([c[:self.n], np.empty((size - self.n,) + c.shape[1:],
                                                              c.dtype)]) for c in self.cols]
        for c, b in zip(self.cols, blocks):
            c[self.n:self.n + k] = b
        self.n += k

    def arrays(self) -> list:
        cols, self.cols = self.cols, []
        return [c[:self.n] for c in cols]


class WholeVehicleOfflineStream:
    """:func:`estimate_whole_vehicle` offline over blocks of samples, its estimate handed out
    in pieces (:class:`WholeVehicleArrays` of at most :data:`PIECE_ROWS` samples, in order):
    a long drive's per-sample outputs are never held whole.

    :meth:`feed` gathers a block (the smoother needs the whole run first: its noise and
    roughness statistics, the road's profile pass), running the static-load tracker as it
    comes (zero-load readings: the readings kept less its offsets, its static loads kept or,
    with ``spill``, in a temporary file there, as is then a windowed run's road between its
    profile pass and its windows, :attr:`.Smoother.spill`); :meth:`finish` smooths run after run
    (:class:`.smoothing.smoother.Smoother`: with ``eager`` a run longer than one window and
    its overlap goes in windows of :data:`STREAM_WINDOW_SAMPLES` and
    :data:`STREAM_OVERLAP_S`; ``window`` = ``(window, overlap)`` samples instead; without
    ``eager`` and ``window`` the smoother's own rule, :func:`estimate_whole_vehicle`'s),
    the braking response chunk by chunk, the load transfer carried from piece to piece. What
    is held whole: the stamps, readings, speeds and ``a_x`` of the drive (the smoother's
    inputs, 8 (3 + channels) bytes a sample), the road's profile pass columns and the static
    loads unless spilled; with ``spill`` the readings and the sensor flags are in files too,
    the smoother reading the readings a piece at a time (:class:`~.core.spill.SpillRows`: its
    statistics, windows and profile pass; the same bits). Without windows the pieces are
    :func:`estimate_whole_vehicle`'s numbers bit for bit; with them within ~3e-4 of each
    field's RMS (:data:`STREAM_OVERLAP_S`; the road the same bits: its profile pass is over
    the whole run).
    """

    def __init__(self, vehicle: ArticulatedParameters,
                 observer: ObserverParameters | None = None, *,
                 gap_threshold_s: float = GAP_THRESHOLD_S,
                 window: tuple[int, int] | None = None, eager: bool = True,
                 capacity: int = 0, spill=None, piece_rows: int = PIECE_ROWS,
                 imu: bool = False) -> None:
        self.est = WholeVehicleEstimator(vehicle, observer, gap_threshold_s=gap_threshold_s,
                                         imu=imu)
        self.observer = ObserverParameters() if observer is None else observer
        self.gap_threshold_s = gap_threshold_s
        self.window, self.eager, self.spill = window, eager, spill
        self.piece_rows = max(int(piece_rows), 1)
        ny, nw = len(self.est.channel_names), len(self.est.wheel_names)
        tracker = self.est.tracker
        self._statics = None
        #: with ``spill`` the readings in a file (the smoother reads them a piece at a time)
        self._y = None
        # each sample's sensor flags (with ``spill`` in a file, read a piece at a time)
        self._codes = _Columns([(np.int8, (ny,))], capacity)
        if spill:
            from road_force_estimator.core.spill import SpillColumn
            self._y = SpillColumn(float, ny, spill)
            self._codes = SpillColumn(np.int8, ny, spill)
            self._in = _Columns([(np.int64, ()), (float, ())], capacity)
            if tracker is not None:
                self._statics = SpillColumn(float, nw, spill)
        else:
            self._in = _Columns([(np.int64, ()), (float, (ny,)), (float, ())], capacity)
            if tracker is not None:
                self._statics = _Columns([(float, (nw,))], capacity)
        self._clock = StepGaps(gap_threshold_s)
        self._last: int | None = None
        self._last_row = None
        self._stale = _Columns([(bool, ())], capacity)       # each sample's a_y not fresh
        self._flags_before = list(self.est.faults.flags)
        #: gated samples per channel so far (complete once :meth:`finish` is exhausted)
        self.innovations_gated: tuple = ()
        #: the tanh friction's v_f (m/s) the smoother takes: the file's, once :meth:`finish`
        #: has begun the fitted one (:func:`fit_friction_velocity`)
        self.friction_velocity_mps = vehicle.leaf_spring_friction_velocity_mps
        #: the same as the report states it, with the file's (:class:`.friction_fit.
        #: FrictionVelocity`; None: no tanh friction stated), once :meth:`finish` has begun
        self.friction_velocity: FrictionVelocity | None = None

    @property
    def fed(self) -> int:
        """Samples fed so far."""
        return self._in.n

    def feed(self, stamps_ns, readings, speed_mps, imu_codes=None) -> list:
        """One block: stamps (k,) ns increasing (over the blocks too), readings (k, channels)
        as :meth:`WholeVehicleEstimator.step` takes them, speed (k,) or float (m/s), the
        IMU's pairing codes (k,) (:func:`estimate_whole_vehicle`'s; None: every a_y fresh);
        no piece (see the class notes)."""
        stamps = np.asarray(stamps_ns, np.int64).reshape(-1)
        k = stamps.size
        self._stale.append(np.zeros(k, bool) if imu_codes is None else
                           np.asarray(imu_codes).reshape(-1) != 0)
        y = np.array(readings, float, copy=True).reshape(k, -1)
        v = np.broadcast_to(np.asarray(speed_mps, float), (k,))
        if k:
            self._codes.append(self._fault_codes(stamps, y, v))
        tracker = self.est.tracker
        if tracker is not None and k:
            statics = np.empty((k, len(self.est.wheel_names)))
            update, tracked, clock = tracker.update, tracker.static_n, self._clock
            last = self._last
            for i, s in enumerate(stamps.tolist()):
                dt = 0.0 if last is None else (s - last) * 1e-9
                if last is not None and clock.take(dt):
                    dt = 0.0              # a gap: the mean and the offset kept
                y[i] = update(y[i].tolist(), dt)
                statics[i] = tracked
                last = s
            self._statics.append(statics)
        if k:
            self._last = int(stamps[-1])
        if self._y is None:
            self._in.append(stamps, y, v)
        else:
            self._y.append(y)
            self._in.append(stamps, v)
        return []

    def _fault_codes(self, stamps: np.ndarray, y: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The sensor flags ((k, channels) int8) of a block's readings (before the tracker)
        and speeds: the online estimator's detector, sample by sample."""
        det = self.est.faults
        k0, seen = det.samples, len(det.events)
        step = det.step
        for s, row, vi in zip(stamps.tolist(), y.tolist(), v.tolist()):
            step(s, row, (vi,))
        codes = np.empty((stamps.size, det.n), np.int8)
        codes[:] = [CODES[f] for f in self._flags_before]
        for i, ch, code in det.events[seen:]:
            codes[i - k0:, ch] = code
        self._flags_before = list(det.flags)
        return codes

    def finish(self) -> Iterator[WholeVehicleArrays]:
        """The estimate, piece after piece (see the class notes)."""
        from road_force_estimator.estimation.smoothing.smoother import Smoother
        from road_force_estimator.estimation.models.articulated_rows import columns as cols_of

        if self._y is None:
            stamps, y, v = self._in.arrays()
        else:                                    # the readings read a piece at a time
            from road_force_estimator.core.spill import SpillRows

            (stamps, v), y = self._in.arrays(), SpillRows(self._y)
        codes = (self._codes.arrays()[0] if self._y is None else SpillRows(self._codes))
        statics = self._statics
        if isinstance(statics, _Columns):
            statics = statics.arrays()[0]
        est = self.est
        window = self.window
        if window is None and self.eager and stamps.size > 1:
            dt = float(np.median(np.diff(stamps))) * 1e-9
            window = (STREAM_WINDOW_SAMPLES, int(math.ceil(STREAM_OVERLAP_S / dt)))
        cols = cols_of(len(est.wheel_names))
        nw = len(est.wheel_names)
        starts = run_starts(stamps, self.gap_threshold_s)
        bounds = list(zip(starts.tolist(), starts[1:].tolist() + [stamps.size]))
        # a stuck channel's stretch not fed to the smoother (module notes)
        since = est.faults.stuck_since          # (no stuck flag: no codes read whole)
        left = (left_out(codes[0:len(codes)] if since else codes, since, stamps)
                if len(codes) else None)
        stale = self._stale.arrays()[0]
        if est.imu_out and stale.any():        # no fresh a_y: its rows left out too
            if left is None:
                left = np.zeros((len(codes), len(est.channel_names)), bool)
            left[np.ix_(stale, sorted(est.imu_out))] = True
        # the friction's v_f fitted (module notes), on the readings the smoother takes
        end = fit_end(stamps, bounds[0][1]) if bounds else 0   # (20 s: read, not the run)
        vehicle = fit_friction_velocity(est.vehicle, self.observer, stamps[:end], y[:end],
                                        v[:end], None if left is None else left[:end],
                                        imu=est.model.imu)
        self.friction_velocity_mps = vehicle.leaf_spring_friction_velocity_mps
        self.friction_velocity = FrictionVelocity.of(
            est.vehicle.leaf_spring_friction_velocity_mps, self.friction_velocity_mps,
            self.observer, est.vehicle.leaf_spring_friction_model,
            est.vehicle.spring_friction_n,
            est.vehicle.zero_load)
        model = (est.model if vehicle is est.vehicle else est.model.with_vehicle(vehicle))
        braking = est.online.braking if model is est.model else model.braking_response()
        smoother = Smoother(model, self.observer, window, eager=self.eager)
        smoother.spill = self.spill or None      # a windowed run's road in a file
        dist = 0.0
        prev: int | None = None
        for run, (a0, b0) in enumerate(bounds):
            t = (stamps[a0:b0] - stamps[a0]) * 1e-9
            tdts = np.diff(t)
            ax = braking.offline_ax(t, v[a0:b0])
            for a, b, off, _ in braking.responses(tdts, ax, self.piece_rows):
                if self._y is None:
                    y[a0 + a:a0 + b] -= off                   # the known a_x's share
                else:
                    self._y.write(a0 + a, self._y.read(a0 + a, a0 + b) - off)
            response = braking.responses(tdts, ax, self.piece_rows)
            held = None                                      # (a, dynamic) not used yet
            run_y = y[a0:b0] if self._y is None else y.sub(a0, b0)
            for a, b, pc in smoother.pieces(t, run_y, v[a0:b0],
                                            left_out=None if left is None else left[a0:b0]):
                rows = np.column_stack(pc)
                dyn = np.empty((nw, b - a))
                k = a
                while k < b:
                    if held is None:
                        ra, rb, _, d = next(response)
                        held = (ra, d)
                    ra, d = held
                    hi = min(b, ra + d.shape[1])
                    dyn[:, k - a:hi - a] = d[:, k - ra:hi - ra]
                    if hi == ra + d.shape[1]:
                        held = None
                    k = hi
                rows[:, cols['load']] += dyn.T
                rows[:, cols['dynamic']] += dyn.T
                for c0 in range(0, b - a, self.piece_rows):
                    c1 = min(b - a, c0 + self.piece_rows)
                    g0, g1 = a0 + a + c0, a0 + a + c1
                    st = stamps[g0:g1]
                    steps = np.diff(st) * 1e-9
                    first = (0.0 if prev is None else (int(st[0]) - prev) * 1e-9)
                    inc = np.abs(v[g0 + 1:g1]) * steps
                    d_run = np.cumsum(np.concatenate([[dist + abs(v[g0]) * first], inc]))
                    dist = float(d_run[-1])
                    prev = int(st[-1])
                    static = (None if statics is None else
                              np.asarray(statics[g0:g1] if isinstance(statics, np.ndarray)
                                         else statics.read(g0, g1)))
                    yield self._piece(st, rows[c0:c1], d_run, static, run, g0 == a0,
                                      smoother, codes[g0:g1])
                del rows, dyn, pc         # (let go before the next window is computed)
        self.innovations_gated = tuple(int(g) for g in smoother.gated.tolist())
        self.close()

    def close(self) -> None:
        """Close the files of ``spill`` (the readings, sensor flags, static loads): after
        :meth:`finish`, or on a failure before it ends."""
        for f in (self._y, self._codes, self._statics):
            if f is not None and not isinstance(f, _Columns):
                f.close()

    def _piece(self, stamps: np.ndarray, rows: np.ndarray, dist: np.ndarray, static,
               gaps: int, starts_run: bool, smoother, codes: np.ndarray | None = None
               ) -> WholeVehicleArrays:
        """One piece from the smoother's rows (the braking response added), the distance
        (m), the static loads ((k, wheels) or None: the file's) and the gaps before it."""
        est = self.est
        nw = len(est.wheel_names)
        cols = columns(nw)
        k = stamps.size
        road = rows[:, cols['road']].T.copy() if rows.shape[1] >= cols['size'] else None
        if static is None:
            static = np.broadcast_to(np.asarray(est.static_n, float), (k, nw))
            loads = rows[:, cols['load']]
        else:
            loads = static + rows[:, cols['dynamic']]
        ltr = np.empty((8, k))
        update = est._transfer.update
        for i, (s, f) in enumerate(zip(stamps.tolist(), loads.tolist())):
            ltr[:, i] = update(s, f)
        g = np.full(k, gaps, np.int64)
        return WholeVehicleArrays(
            stamps.copy(), dist.copy(), rows[:, CONV] > 0.5, est.wheel_names, est.axle_names,
            est.axle_bodies, np.ascontiguousarray(loads.T), np.array(static, float).T.copy(),
            ltr[0:6:2].copy(), ltr[1:6:2].copy(), rows[:, cols['ay']].T.copy(), road,
            tuple(int(x) for x in smoother.gated.tolist()), tuple(est.channel_names),
            ltr[6:].copy(), g, fault_flags=None if codes is None else codes.T.copy(),
            faults=est.faults.counts())


def fit_friction_velocity(vehicle: ArticulatedParameters, observer: ObserverParameters,
                          stamps_ns, readings, speed_mps, left=None, *, imu: bool = False,
                          table: list | None = None) -> ArticulatedParameters:
    """``vehicle`` with the tanh friction's ``v_f`` (``vehicle.leaf_spring_friction_velocity``,
    one for every spring) that makes the drive likeliest (:mod:`.friction_fit`'s rule), with
    ``observer.friction_velocity_fit`` and some spring's tanh friction stated, not under
    ``zero_load``; else, or with the file's ``v_f`` the likeliest, ``vehicle`` itself.

    The whole vehicle's online observer (:class:`.articulated.ArticulatedOnline`, no latency)
    over the first :data:`.friction_fit.FIT_S` s of ``stamps_ns`` (ns; the first run's:
    the caller gives no other), ``readings`` ((m, channels) from the equilibrium, as the
    smoother takes them), ``speed_mps`` ((m,), m/s); ``left`` ((m, channels) bool or None):
    the channels the smoother leaves out of each sample, left out here too. ``table``: the
    likelihood per ``v_f`` (:func:`.friction_fit.likeliest_velocity`), when fitted.

    Not under ``zero_load`` (as the front axle's): on the tracker's readings (less its
    offsets) the fit took one grid step more than the truth's v_f on 20 s of class C (the
    truth's 0.01 m/s: 0.014; 0.005: 0.01; ``python -m bench.studies.friction_lag
    --whole-vehicle``, its last table; from the equilibrium its offline table's 0.01 and
    0.007): a file stating the right v_f would be moved off it.
    """
    if (vehicle.zero_load or not fits(
            observer, vehicle.leaf_spring_friction_model,
            vehicle.spring_friction_n)):
        return vehicle
    stamps = np.asarray(stamps_ns, np.int64)
    end = fit_end(stamps, stamps.size)
    if end == 0:
        return vehicle
    y = np.asarray(readings, float)[:end].tolist()
    v = np.broadcast_to(np.asarray(speed_mps, float), stamps.shape)[:end].tolist()
    out = [()] * end if left is None else [tuple(np.flatnonzero(r).tolist())
                                           for r in np.asarray(left, bool)[:end]]
    obs = replace(observer, latency_s=0.0)

    def nll_terms(v_f: float) -> list:
        online = ArticulatedOnline(replace(vehicle, leaf_spring_friction_velocity_mps=v_f),
                                   0.0, obs, imu=imu, rows=False)
        core, step = online.core, online.step
        terms = core.nll_terms = []
        for s, yi, vi, o in zip(stamps[:end].tolist(), y, v, out):
            core.set_excluded(o)
            step(s, yi, vi)
        return terms

    v_f = likeliest_velocity(vehicle.leaf_spring_friction_velocity_mps, nll_terms, table)
    if v_f == vehicle.leaf_spring_friction_velocity_mps:
        return vehicle
    return replace(vehicle, leaf_spring_friction_velocity_mps=v_f)


def fit_axles(vehicle: ArticulatedParameters, wv: WholeVehicleArrays) -> AxleFit | None:
    """The model fit per instrumented axle of an offline estimate
    (:func:`.axle_fit.assess_axles` on its roads, loads and static loads); None without a
    road (online) or with fewer than 3 instrumented axles (no median of the others)."""
    axles = [j for j, a in enumerate(vehicle.axles) if a.instrumented]
    if wv.road_m is None or len(axles) < 3 or len(wv.stamps_ns) < 2:
        return None
    rows = [2 * j + s for j in axles for s in (0, 1)]
    return assess_axles(wv.stamps_ns, wv.distance_m, wv.road_m[rows], wv.load_n[rows],
                        wv.static_n[rows], [vehicle.axles[j].position_m for j in axles],
                        [vehicle.axles[j].name for j in axles])
