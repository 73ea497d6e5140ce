"""The estimator: from (q_1, q_2, phi) samples to wheel loads, road profile and LTR.

One sample in, one estimate out (:meth:`Estimator.update`), and a batch path
(:func:`estimate_batch`) that runs the very same step function and so gives identical numbers.
The method is ``observer.discretization`` (the cores: :mod:`.methods`):

- ``'model'`` (the default): the Kalman unknown-input observer of :mod:`.observer.online` on the
  paper's roll-plane model (the road and an unknown roll moment as states), its noise and
  road roughness estimated online; an optional sliding-mode injection on the output error
  (``observer.sliding_mode_gain``, off by default). Its accuracy per road, noise level and
  latency: ``python -m bench.accuracy.run_benchmark --docs docs/benchmark.md``.
- ``'euler'`` (the paper's scheme), ``'taylor'``, ``'implicit'``, ``'filtering'`` (Levant and
  Livne's filtering differentiators): the differentiator chain of :mod:`.chain`, with that
  scheme (how each converges with the rate: ``python -m bench.studies.chain_rate``).

Both end in MODEL.md's reconstruction (:mod:`.reconstruction`; the body heave of
:mod:`.body_heave`, the LTR of :mod:`.reconstruction`).

Latency (``observer.latency`` = T > 0): :meth:`Estimator.update` returns, per accepted input,
the estimate of the sample N = round(T / dt) samples back, stamped with that sample's stamp
(None for the first N inputs); :meth:`Estimator.flush` returns the rest at the end of the data,
so that every accepted input gets exactly one estimate, in order. The model method corrects
them with its exact fixed-lag smoother; the chain only delays. :func:`estimate_batch` returns
row k = the estimate of sample k whatever the latency (the flushed ones included).

Every output refers to the stamp of the newest accepted sample (with the explicit schemes
``euler``/``taylor`` the differentiator outputs are one-step predictions that do not use that
sample's value yet; see :mod:`.differentiator`).

Robustness (counted in :class:`EstimatorStatus`; nothing non-finite ever leaves):

- the first sample initialises (differentiators at ``(f, 0, 0)``, body heave at rest at 0);
- the rules of :mod:`.acceptance` reject non-finite, malformed and impossible samples and
  duplicate or backwards stamps; the last estimate is held (:attr:`Estimator.last`);
- steps use the real dt; a step longer than ``max(gap_threshold_s, 10 typical periods)`` is
  a gap (``gap_threshold_s`` defaults to :data:`GAP_THRESHOLD_S` = 0.1 s, i.e. 100 samples
  at 1 kHz; streams slower than ~20 Hz need a larger one): the estimate restarts at that
  sample (``resets``, ``gaps``) and reconverges; a non-finite intermediate (never seen,
  guarded anyway) also restarts it (``resets``, ``numerical_resets``), and so does a step
  the model's design cannot handle (no stable filter at that dt: ``resets``, ``gaps``);
- with the deflections read from a mechanical zero (``vehicle.deflection_reference:
  zero_load``) each accepted reading first goes through :mod:`.static_load`: the static
  wheel loads and the sprung mass are estimated from the slow part of the readings, the
  core gets the extensions from the estimated equilibrium, the estimated F_c,i for its
  loads and, when the mass moves by more than 2 %, a vehicle of the new mass (its gains
  designed again);
- ``converged`` turns true once the time since the last (re)start reaches
  ``settling_time_s`` (chain: :func:`.chain.settling_time_s`); it is about the loads and LTR:
  the profile's body-heave high-pass needs a few ``lambda_c / v`` more.
"""
from __future__ import annotations

import itertools
from typing import Callable

import numpy as np

from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
from road_force_estimator.estimation.acceptance import (
    GAP_THRESHOLD_S, SampleGate, batch_inputs, check_gap_threshold, output_stamps)
from road_force_estimator.estimation.methods import CORES
from road_force_estimator.estimation.models.front_axle import FrontAxleModel
from road_force_estimator.estimation.sensor_health import FaultDetector, FaultSettings
from road_force_estimator.estimation.speed_check import SpeedCheck
from road_force_estimator.estimation.static_load import StaticLoadTracker
from road_force_estimator.estimation.outputs import (
    N_COLUMNS, Column, Estimate, EstimateArrays, EstimatorStatus, estimate_from_row,
    field_columns, hold_rejected)

__all__ = ['Estimator', 'BatchRun', 'estimate_batch', 'PROGRESS_BLOCK']

#: Samples between two calls of the ``progress`` callback of :func:`estimate_batch`.
PROGRESS_BLOCK = 10_000


class Estimator:
    """Per-sample estimator of wheel loads, road profile and LTR (MODEL.md steps 1-9).

    Parameters
    ----------
    vehicle : VehicleParameters
        The axle's parameters (masses, stiffnesses, track, static loads).
    observer : ObserverParameters
        The method (``discretization``: ``'model'`` or a chain scheme), the latency, the
        profile cutoff wavelength; for the chain L per channel (``lipschitz_deflection`` for
        both deflections, ``lipschitz_roll``); for the model the sliding-mode gain and the
        noise / roughness settings (0 = estimated online, see :mod:`.models.front_axle`).
    gap_threshold_s : float
        Shortest step that is a gap (s), default :data:`GAP_THRESHOLD_S`.

    Notes
    -----
    :meth:`update` returns a new immutable :class:`Estimate`, or None for a rejected sample
    or while nothing is due yet (latency). :attr:`core` is the method's core (:mod:`.methods`).
    """

    def __init__(self, vehicle: VehicleParameters | None = None,
                 observer: ObserverParameters | None = None, *,
                 gap_threshold_s: float = GAP_THRESHOLD_S) -> None:
        vehicle = VehicleParameters() if vehicle is None else vehicle
        observer = ObserverParameters() if observer is None else observer
        self.gap_threshold_s = check_gap_threshold(gap_threshold_s)
        self.vehicle = vehicle
        self.observer = observer
        if observer.discretization not in CORES:
            raise ValueError(f'discretization = {observer.discretization!r}: must be one of '
                             f'{", ".join(CORES)}')
        #: the vehicle model the core estimates (:mod:`.models`)
        self.model = FrontAxleModel(vehicle)
        self.core = CORES[observer.discretization](self.model, observer)
        self._ready = self.core.ready
        #: the static-load estimate (:mod:`.static_load`) under zero_load, else None
        self.static_load = StaticLoadTracker(vehicle) if vehicle.zero_load else None
        #: stuck and drifting sensors (:mod:`.sensor_health`)
        self.faults = FaultDetector(FaultSettings.of(observer, vehicle,
                                                     self.model.channel_names))
        self.reset()

    # -- state ----------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget everything (counters included); the next sample initialises."""
        self._status = EstimatorStatus()
        self._gate = SampleGate(self.gap_threshold_s, self._status)
        self.last: Estimate | None = None
        self._accepted = 0
        self._x = 0.0
        self._v = 0.0
        self._dt = 0.0
        self._t_run = 0.0
        self._flushed = False
        self._speed = SpeedCheck()
        self._raw = (0.0, 0.0)
        self.faults.reset()
        if self.static_load is not None:
            self.static_load.reset()
            self.core.set_vehicle(self.vehicle)
        self.core.reset()

    @property
    def status(self) -> EstimatorStatus:
        """Counters and flags, brought up to date when read."""
        st = self._status
        gate = self._gate
        core = self.core
        st.accepted = self._accepted
        st.time_since_start_s = self._t_run
        st.settling_time_s = self.settling_time_s
        st.converged = core.last_converged
        st.last_stamp_ns = gate.stamp if gate.started else None
        st.last_dt_s = self._dt
        st.typical_dt_s = gate.dt_typ
        st.speed_contradicted = self._speed.contradicted
        row = core.last_row
        if row is not None:
            st.last_residual_nm = row[Column.RESIDUAL]
            st.lift_off = (row[Column.LIFT_OFF1], row[Column.LIFT_OFF2])
        core.fill_status(st)
        fc = self.faults.counts()
        st.sensor_faults = fc.flags
        st.stuck_episodes, st.stuck_samples = fc.stuck_episodes, fc.stuck_samples
        st.drift_episodes, st.drift_samples = fc.drift_episodes, fc.drift_samples
        st.fault_first_ns = fc.first_ns
        tracker = self.static_load
        st.static_load_n = self.vehicle.static_load_n if tracker is None else tracker.static_n
        st.sprung_mass_kg = (self.vehicle.sprung_mass_kg if tracker is None
                             else tracker.sprung_mass_kg)
        return st

    @property
    def settling_time_s(self) -> float:
        """Current settling time (s) (chain: :func:`.chain.settling_time_s`; model:
        :meth:`.ModelCore.settling_time_s`)."""
        return self.core.settling_time_s(self._gate.dt_typ)

    def update(self, stamp_ns: int, q_m, roll_rad: float, speed_mps: float) -> Estimate | None:
        """Take one sample; return the estimate due now, or None.

        With no latency the estimate is that of this sample (at ``stamp_ns``); with
        ``observer.latency`` > 0 that of the sample N steps back, with its stamp (None while
        fewer than N samples have come). None also for a rejected sample (counted in
        :attr:`status`).

        Parameters
        ----------
        stamp_ns : int
            Measurement stamp (ns), strictly increasing.
        q_m : sequence of 2 floats
            Suspension extensions ``[q_1 (left), q_2 (right)]`` (m).
        roll_rad : float
            Roll angle (rad), > 0 when the left side goes up.
        speed_mps : float
            Vehicle speed (m/s).
        """
        pair = self._gate.check_pair(q_m)
        if pair is None or not self._process(stamp_ns, pair[0], pair[1], roll_rad, speed_mps):
            return None
        if not self._ready:
            return None
        stamp, row = self._ready.popleft()
        if row[Column.FN1] <= 0.0 or row[Column.FN2] <= 0.0:
            self._status.negative_load_samples += 1
        est = estimate_from_row(stamp, row)
        self.last = est
        return est

    def flush(self) -> list[Estimate]:
        """The estimates still held back (``observer.latency`` > 0), at the end of the data.

        Each is the best estimate of its sample from the data received (the model's
        fixed-lag correction over the samples that did arrive). After a flush of the model
        the next sample starts a new run (counted in ``resets``), as after a gap. With no
        latency: an empty list.
        """
        self._finish()
        out = [estimate_from_row(stamp, row) for stamp, row in self._ready]
        self._status.negative_load_samples += sum(
            est.wheel_load_n[0] <= 0.0 or est.wheel_load_n[1] <= 0.0 for est in out)
        self._ready.clear()
        if out:
            self.last = out[-1]
        return out

    def _finish(self) -> None:
        """Finalize every held-back estimate into the ready queue."""
        if self.core.finish():
            self._flushed = True

    # -- the step shared by both paths -----------------------------------------------------
    def _process(self, stamp_ns, q1, q2, phi, v) -> bool:
        """Validate one sample and advance; False if it was rejected.

        Estimates that became final (with a latency: of earlier samples) are appended to
        the core's ``ready`` as ``(stamp_ns, row)``.
        """
        sample = self._gate.check(stamp_ns, q1, q2, phi, v)
        if sample is None:
            return False
        stamp, q1, q2, phi, v, dt, restart, dt_typ = sample
        self._raw = (q1, q2)
        if self.static_load is not None:
            q1, q2 = self._static_step(q1, q2, 0.0 if restart else dt)
        if restart or self._flushed:
            vm = self._speed.restart(q1, q2, v)
        else:
            vm = self._speed.step(dt, q1, q2, v)   # the model's speed (v unless contradicted)
        if restart:
            return self._advance(stamp, q1, q2, phi, v, vm, dt, True, 0.0)
        if self._flushed:
            self._flushed = False
            self._status.resets += 1
            return self._advance(stamp, q1, q2, phi, v, vm, dt, True, 0.0)
        try:
            if self._advance(stamp, q1, q2, phi, v, vm, dt, False, dt_typ):
                return True
            self._status.numerical_resets += 1
        except ValueError:    # a step the model design cannot handle: a gap
            self._status.gaps += 1
        self._status.resets += 1
        return self._advance(stamp, q1, q2, phi, v, vm, dt, True, 0.0)

    def _static_step(self, q1: float, q2: float, dt: float) -> tuple[float, float]:
        """zero_load: the static-load estimate of one accepted reading (m, m) after dt (s; 0 at
        a restart) handed to the core; the extensions from the estimated equilibrium."""
        tracker = self.static_load
        q1, q2 = tracker.update(q1, q2, dt)
        if tracker.redesign is not None:
            self.core.set_vehicle(tracker.redesign)
        self.core.set_static_loads(*tracker.static_n)
        return q1, q2

    def _advance(self, stamp: int, q1: float, q2: float, phi: float, v: float, vm: float,
                 dt: float, restart: bool, dt_typ: float) -> bool:
        """One step of the core (or a (re)start); False (state untouched) if non-finite.
        ``v`` the recorded speed (the distance), ``vm`` the model's (:mod:`.speed_check`);
        ``dt_typ``: the typical step (s) once this sample is used."""
        gate = self._gate
        x = self._x + 0.5 * (self._v + v) * dt if gate.started else 0.0
        t_run = 0.0 if restart else self._t_run + dt
        exclude = getattr(self.core, 'set_excluded', None)
        if exclude is not None:    # a stuck sensor is not fed (the model's core)
            stuck = self.faults.stuck
            exclude(tuple(j for j in self.model.droppable_channels if stuck[j]))
        if not self.core.step(stamp, (q1, q2, phi), vm, dt, restart, x, t_run, dt_typ):
            return False
        gate.commit(stamp, dt_typ)
        rates = getattr(self.core, 'body_rates', None)
        self.faults.step(stamp, (*self._raw, phi), None if rates is None else rates())
        self._x = x
        self._v = v
        self._dt = dt
        self._t_run = t_run
        self._accepted += 1
        return True


class BatchRun:
    """:func:`estimate_batch` block after block: one :class:`Estimator` fed whole arrays.

    :meth:`feed` takes the next block of samples and returns the estimates that became due
    (with a latency some come with later blocks), :meth:`finish` the rest; the numbers are
    those of the per-sample path (the same step function, in order), whatever the blocks.
    Memory: the block's rows only (``(k, N_COLUMNS)`` floats), never the whole drive's.
    ``rows`` False: the filter and its innovations only, no row made
    (:attr:`.ModelCore.rows`, the model's core only; :meth:`feed` and :meth:`finish` return
    none), for a fit that reads the innovations (:mod:`.friction_fit`).
    """

    def __init__(self, vehicle: VehicleParameters | None = None,
                 observer: ObserverParameters | None = None, *,
                 gap_threshold_s: float = GAP_THRESHOLD_S, rows: bool = True) -> None:
        self.estimator = Estimator(vehicle, observer, gap_threshold_s=gap_threshold_s)
        if not rows:
            if not hasattr(self.estimator.core, 'rows'):
                raise ValueError(f'rows=False: the {self.estimator.observer.discretization!r} '
                                 'core always makes its rows (the model core only)')
            self.estimator.core.rows = False
        self.rows = bool(rows)
        #: accepted samples so far and rows returned so far
        self.accepted = 0
        self.returned = 0

    def feed(self, stamps_ns, q_m, roll_rad, speed_mps
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One block of samples (as :func:`estimate_batch`'s arrays).

        Returns
        -------
        valid : ndarray of bool, shape (k,)
            Accepted samples of the block.
        contradicted : ndarray of bool, shape (k,)
            Samples whose speed the deflections contradicted (:mod:`.speed_check`).
        rows : ndarray, shape (j, N_COLUMNS)
            The estimates that became due, in order: row i is that of accepted sample
            ``returned + i`` of the whole run (counted before this call).
        """
        stamps, q, phi, speed = batch_inputs(stamps_ns, q_m, roll_rad, speed_mps)
        est = self.estimator
        process = est._process
        ready = est._ready
        check = est._speed
        rows: list = []
        take = rows.append
        valid: list = []
        flag = valid.append
        contradicted: list = []
        mark = contradicted.append
        for t, (a, b), p, v in zip(stamps.tolist(), q.tolist(), phi.tolist(), speed.tolist()):
            before = check.contradicted
            flag(process(t, a, b, p, v))
            mark(check.contradicted != before)
            while ready:
                take(ready.popleft()[1])
        valid_arr = np.array(valid, dtype=bool)
        self.accepted += int(valid_arr.sum())
        return valid_arr, np.array(contradicted, dtype=bool), self._table(rows)

    def finish(self) -> np.ndarray:
        """The estimates still held back at the end (latency), as rows (``(j, N_COLUMNS)``)."""
        est = self.estimator
        est._finish()
        rows = [row for _, row in est._ready]
        est._ready.clear()
        out = self._table(rows)
        if self.rows and self.returned != self.accepted:   # never: one per accepted sample
            raise RuntimeError(f'{self.returned} estimates for {self.accepted} accepted samples')
        return out

    def _table(self, rows: list) -> np.ndarray:
        self.returned += len(rows)
        return np.fromiter(itertools.chain.from_iterable(rows), dtype=float,
                           count=len(rows) * N_COLUMNS).reshape(len(rows), N_COLUMNS)


def _fault_flags(faults: FaultDetector, accepted: np.ndarray, n: int) -> np.ndarray:
    """The detector's flags per sample of a batch (``accepted``: the sample of each accepted
    one, in order); a rejected sample holds the flags before it."""
    out = np.zeros((n, faults.n), dtype=np.int8)
    for k, ch, code in faults.events:
        out[accepted[k]:, ch] = code
    return out


def estimate_batch(stamps_ns, q_m, roll_rad, speed_mps, vehicle: VehicleParameters | None = None,
                   observer: ObserverParameters | None = None, *,
                   gap_threshold_s: float = GAP_THRESHOLD_S,
                   progress: Callable[[int], object] | None = None) -> EstimateArrays:
    """Run the estimator over whole arrays; identical numbers to :meth:`Estimator.update`.

    Parameters
    ----------
    stamps_ns : array_like of int, shape (n,)
        Stamps (ns); disorder, duplicates and gaps are handled as in the per-sample path.
    q_m : array_like, shape (n, 2)
        Suspension extensions [left, right] (m).
    roll_rad : array_like, shape (n,)
        Roll angle (rad).
    speed_mps : array_like, shape (n,) or scalar
        Speed (m/s).
    vehicle, observer : parameters (defaults when None).
    progress : callable, optional
        Called with the number of samples done after every :data:`PROGRESS_BLOCK` of them
        (e.g. a progress bar's ``update``).

    Returns
    -------
    EstimateArrays
        Row k is the estimate *for* sample k, whatever the latency: the per-sample path's
        outputs of :meth:`Estimator.update` followed by :meth:`Estimator.flush`, in order, are
        the rows where ``valid``. Every field per sample, the ``valid`` mask and the final
        status counters. Runs block by block (:class:`BatchRun`): the rows go into the
        fields as they come (about the fields' own size in memory, not a row list's).
    """
    stamps, q, phi, speed = batch_inputs(stamps_ns, q_m, roll_rad, speed_mps)
    n = stamps.shape[0]
    run = BatchRun(vehicle, observer, gap_threshold_s=gap_threshold_s)
    fields, columns = field_columns(n)
    valid = np.zeros(n, dtype=bool)
    contradicted = np.zeros(n, dtype=bool)
    accepted = np.empty(n, dtype=np.int64)         # sample index of each accepted sample

    def place(rows: np.ndarray) -> None:
        at = accepted[run.returned - rows.shape[0]:run.returned]
        for j, col in enumerate(columns):
            col[at] = rows[:, j]

    for start in range(0, n, PROGRESS_BLOCK):
        stop = min(n, start + PROGRESS_BLOCK)
        ok, contra, rows = run.feed(stamps[start:stop], q[start:stop], phi[start:stop],
                                    speed[start:stop])
        valid[start:stop] = ok
        contradicted[start:stop] = contra
        new = np.flatnonzero(ok) + start
        accepted[run.accepted - new.size:run.accepted] = new
        place(rows)
        if progress is not None:
            progress(stop - start)
    place(run.finish())
    if run.accepted and run.accepted < n:
        # rejected rows hold the previous row (zeros before the first accepted sample)
        held, src = hold_rejected(valid)
        for arr in fields.values():
            arr[held] = arr[src]
    out = EstimateArrays(stamp_ns=output_stamps(stamps), valid=valid, status=run.estimator.status,
                         speed_contradicted=contradicted, **fields)
    out.fault_flags = _fault_flags(run.estimator.faults, accepted[:run.accepted], n)
    out.status.negative_load_samples = out.negative_load_samples()
    return out
