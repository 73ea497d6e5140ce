"""The offline estimate of a recording (``estimate_bag --mode offline``): the best non-causal
estimate for the observer's method (:func:`estimate_recording`).

The model observer (``observer.discretization: model``, the default) goes through its forward
filter and RTS smoother over each run (:func:`smooth`: the recording's rejections and gaps
(:func:`.acceptance.accept_arrays`), the static loads under ``zero_load``, the distance and
the speed check (:func:`prepare`), then the runs through :class:`.smoothing.smoother.Smoother`
with the front axle's model (:func:`smoothed_rows`)); a differentiator scheme through the
zero-phase chain (:func:`.chain.zero_phase.estimate_offline`). With the distance fused from
GNSS (:func:`fused_speed`) the speed is scaled first.
"""
from __future__ import annotations

from types import SimpleNamespace
from typing import Iterator

import numpy as np

from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
from road_force_estimator.estimation.acceptance import (
    GAP_THRESHOLD_S, accept_arrays, batch_inputs, output_stamps)
from road_force_estimator.estimation.chain.zero_phase import estimate_offline
from road_force_estimator.estimation.friction_fit import (
    FrictionVelocity, fit_end, fits, likeliest_velocity)
from road_force_estimator.estimation.models.front_axle import FrontAxleModel
from road_force_estimator.estimation.outputs import (
    Column, EstimateArrays, EstimatorStatus, field_columns, hold_rejected)
from road_force_estimator.estimation.reconstruction import Reconstruction, distance_m
from road_force_estimator.estimation.smoothing.smoother import Smoother
from road_force_estimator.estimation.speed_check import check_arrays
from road_force_estimator.estimation.static_load import track_recording

__all__ = ['estimate_recording', 'fused_speed', 'attach_distance_source', 'smooth', 'prepare',
           'smoothed_rows', 'fill_status', 'last_row', 'LAST_ROW_FIELDS', 'rows_of',
           'left_out_rows', 'readings', 'spill_readings']




def estimate_recording(stamps_ns, q_m, roll_rad, speed_mps,
                       vehicle: VehicleParameters | None = None,
                       observer: ObserverParameters | None = None, *,
                       gap_threshold_s: float = GAP_THRESHOLD_S, fixes=None):
    """The offline mode of ``estimate_bag``: the best non-causal estimate for ``observer``.

    With ``observer.discretization == 'model'`` (the default) the model observer's own
    forward filter and Rauch-Tung-Striebel smoother (:func:`.smoother.smooth`): the
    same model and noise estimates as the online observer, over the whole recording. With a
    differentiator scheme (``euler``, ``taylor``, ``implicit``), the zero-phase chain of
    :func:`estimate_offline`. Row k is the estimate for sample k in both.

    The distance is the one :func:`.odometer.distance_speed` picks for
    ``observer.distance_source`` and ``fixes`` (``stamps_ns``, ``latitude_deg``,
    ``longitude_deg``, or None): with ``gnss``, or ``auto`` (the default) when the fixes give
    the odometer scale to 0.2 %, the speed times the scale fitted from the fixes
    (:func:`.odometer.fit_odometer`, :func:`.odometer.scale_at`), else the speed's. The
    result's ``distance_source`` says which and why; its ``odometer`` attribute is the fit
    when one was made (or None when ``gnss`` was asked and the fixes make none).
    """
    observer = ObserverParameters() if observer is None else observer
    speed_mps, source = fused_speed(stamps_ns, speed_mps, fixes, observer.distance_source)
    if observer.discretization == 'model':
        est = smooth(stamps_ns, q_m, roll_rad, speed_mps, vehicle, observer,
                     gap_threshold_s=gap_threshold_s)
    else:
        est = estimate_offline(stamps_ns, q_m, roll_rad, speed_mps, vehicle, observer,
                               gap_threshold_s=gap_threshold_s)
    attach_distance_source(est, source)
    return est


def fused_speed(stamps_ns, speed_mps, fixes, distance_source: str = 'gnss'):
    """``(the speed the distance integrates, the odometer.DistanceSource)``: the speed times
    the odometer scale of the fixes, or the speed as given (its ``reason`` says why)."""
    from road_force_estimator.estimation import odometer

    return odometer.distance_speed(distance_source, stamps_ns, speed_mps, fixes)


def attach_distance_source(est, source) -> None:
    """``est.distance_source`` (always) and ``est.odometer`` (the fit, when one was made or
    ``gnss`` was asked), as the report and the bag's counts read them."""
    est.distance_source = source
    if source.fit is not None or source.requested == 'gnss':
        est.odometer = source.fit
        est.fused = True


def smooth(stamps_ns, q_m, roll_rad, speed_mps, vehicle: VehicleParameters | None = None,
           observer: ObserverParameters | None = None, *,
           gap_threshold_s: float = GAP_THRESHOLD_S,
           window: tuple[int, int] | None = None) -> EstimateArrays:
    """Offline estimate: the model observer's forward filter and its RTS smoother.

    The same model, gains and outputs as the online observer (:class:`.ModelCore`, linear
    injection; the sliding-mode term, a correction of the causal estimate, has no place in a
    smoother), over the whole recording: for each run (the estimator's rejections and gap
    rule split the data, :func:`.accept_arrays`), the noise and roughness are estimated from
    the whole run (unless set in ``observer``), the steady-state Kalman filter runs forward
    and the Rauch-Tung-Striebel smoother (Rauch, Tung, Striebel 1965) backward; the body
    heave is the zero-phase band-limited double integral of the smoothed body acceleration.
    A stuck sensor's stretch is smoothed without it (:func:`left_out_rows`).

    Parameters
    ----------
    stamps_ns, q_m, roll_rad, speed_mps : as :func:`.estimate_batch`.
    vehicle, observer : parameters (defaults when None); ``observer.latency`` is ignored.
    gap_threshold_s : float
        As :class:`.Estimator`.
    window : (int, int), optional
        ``(window, overlap)``, samples, for even runs longer than both (:func:`window_samples`).

    Returns
    -------
    EstimateArrays
        Row k = the smoothed estimate of sample k; rejected rows hold the previous row (valid
        False); ``converged`` is False within the settling time of each run's start; the
        status counts what the estimator would count (and carries the noise and roughness
        used).
    """
    prep = prepare(stamps_ns, q_m, roll_rad, speed_mps, vehicle, observer,
                   gap_threshold_s=gap_threshold_s)
    smoother = Smoother(FrontAxleModel(prep.vehicle), prep.observer, window)
    fields, columns = field_columns(prep.n)
    for idx, part in smoothed_rows(prep, smoother, columns):
        if idx is not None:                     # (None: written in place)
            for col, values in zip(columns, part):
                col[idx] = values
    acc, valid = prep.acc, prep.valid
    if acc.size and acc.size < valid.size:          # rejected rows hold the previous row
        held, src = hold_rejected(valid)
        for arr in fields.values():
            arr[held] = arr[src]
    status = EstimatorStatus(**prep.counts)
    fill_status(status, acc.size, prep.contradicted, prep.last_stamp_ns,
                last_row(fields, acc[-1]) if acc.size else None, smoother)
    flags = np.zeros(prep.n, bool)
    flags[acc] = prep.contradicted
    out = EstimateArrays(stamp_ns=prep.stamps_out, valid=valid, status=status,
                         speed_contradicted=flags, **fields)
    faults = FaultRows(prep)
    out.fault_flags = faults.flags(0, prep.n, valid, np.column_stack(
        [out.body_heave_rate[acc], out.droll[acc]]))
    faults.fill_status(status)
    status.negative_load_samples = out.negative_load_samples()
    out.friction_velocity = prep.friction_velocity
    return out


class FaultRows:
    """The stuck and drifting sensors (:mod:`.sensor_health`) of an offline estimate, over
    its input rows in order (the whole recording at once, or piece by piece: the same steps,
    the same flags): each accepted sample's readings and the body's rates of its smoothed
    estimate."""

    def __init__(self, prep: SimpleNamespace) -> None:
        from road_force_estimator.estimation.models.front_axle import CHANNEL_NAMES
        from road_force_estimator.estimation.sensor_health import FaultDetector, FaultSettings

        self.prep = prep
        self.detector = FaultDetector(FaultSettings.of(prep.observer, prep.vehicle,
                                                       CHANNEL_NAMES))
        self.last = np.zeros(self.detector.n, dtype=np.int8)   # the flags a row holds

    def flags(self, a: int, b: int, ok: np.ndarray, rates: np.ndarray) -> np.ndarray:
        """The flags (``(b - a, channels)`` int8) of input rows ``a:b``, whose accepted
        ones (``ok``) have the smoothed body rates ``rates`` ((k, 2): heave, roll); a
        rejected row holds the flags before it."""
        det, prep = self.detector, self.prep
        idx = np.flatnonzero(ok) + a
        stamps = rows_of(prep.stamps_out, a, b)[ok].tolist()
        values = readings(prep, idx).tolist()
        k0, seen = det.samples, len(det.events)
        for stamp, v, r in zip(stamps, values, np.asarray(rates, dtype=float).tolist()):
            det.step(stamp, v, r)
        codes = np.empty((idx.size, det.n), dtype=np.int8)
        codes[:] = self.last
        for k, ch, code in det.events[seen:]:
            codes[k - k0:, ch] = code
        out = np.empty((b - a, det.n), dtype=np.int8)
        src = np.where(ok, np.cumsum(ok) - 1, -1)
        np.maximum.accumulate(src, out=src)
        out[src < 0] = self.last
        out[src >= 0] = codes[src[src >= 0]]
        if idx.size:
            self.last = codes[-1].copy()
        return out

    def fill_status(self, status: EstimatorStatus) -> None:
        """The flags and counts into ``status`` (:class:`.EstimatorStatus`)."""
        fc = self.detector.counts()
        status.sensor_faults = fc.flags
        status.stuck_episodes, status.stuck_samples = fc.stuck_episodes, fc.stuck_samples
        status.drift_episodes, status.drift_samples = fc.drift_episodes, fc.drift_samples
        status.fault_first_ns = fc.first_ns


def prepare(stamps_ns, q_m, roll_rad, speed_mps, vehicle: VehicleParameters | None = None,
            observer: ObserverParameters | None = None, *,
            gap_threshold_s: float = GAP_THRESHOLD_S) -> SimpleNamespace:
    """What :func:`smooth` takes of a whole recording before its runs: the estimator's
    rejections and gap rule (:func:`.accept_arrays`), the static loads under ``zero_load``
    (:func:`.track_recording`: the offset off the readings, the vehicle of the last estimate),
    the distance (continued across gaps) and the model's speed (the recorded one unless the
    deflections contradict it, :func:`.check_arrays`). Attributes: ``n``, ``stamps_out``,
    ``valid``, ``counts``, ``acc`` (the accepted rows), ``last_stamp_ns``, ``q``, ``phi``, ``y``
    (the (n, 3) array of both when ``q`` and ``phi`` are its views, else None),
    ``static`` (N, (acc.size, 2), or None), ``vehicle``, ``observer``, ``t`` (s from the first
    accepted stamp, per accepted sample), ``dist`` (m), ``v_model`` (m/s), ``contradicted``,
    ``starts`` (each run's first index into ``acc``, then ``acc.size``), ``friction_velocity``
    (the tanh friction's ``v_f`` taken and the file's, :class:`.friction_fit.FrictionVelocity`,
    or None: no tanh friction stated)."""
    vehicle = VehicleParameters() if vehicle is None else vehicle
    observer = ObserverParameters() if observer is None else observer
    stamps, q, phi, speed = batch_inputs(stamps_ns, q_m, roll_rad, speed_mps)
    valid, restart, stamp_int, cnt = accept_arrays(stamps, q, phi, speed, gap_threshold_s)
    acc = np.flatnonzero(valid)
    # zero_load: the static loads (the online estimator's numbers), the offset off the readings
    q, static, vehicle = track_recording(vehicle, q, acc, stamp_int, restart)
    # seconds from the first accepted stamp: epoch stamps (~1.7e9 s) in float seconds lose
    # ~0.2 us, enough to make an even sample step look uneven
    t_all = (stamp_int[acc] - (stamp_int[acc[0]] if acc.size else 0)) * 1e-9
    v_all = speed[acc]
    steps = np.zeros(acc.size)
    steps[1:] = np.diff(stamp_int[acc]) * 1e-9
    contradicted, v_model = check_arrays(steps, q[acc], v_all, restart[acc])
    del steps
    file_vf = vehicle.leaf_spring_friction_velocity_mps
    vehicle = fit_friction_velocity(vehicle, observer, stamp_int[acc], q[acc], phi[acc],
                                    v_model, restart[acc])
    friction = FrictionVelocity.of(
        file_vf, vehicle.leaf_spring_friction_velocity_mps, observer,
        vehicle.leaf_spring_friction_model, vehicle.leaf_spring_friction_n, vehicle.zero_load)
    return SimpleNamespace(
        n=stamps.shape[0], stamps_out=output_stamps(stamps), valid=valid, counts=cnt, acc=acc,
        last_stamp_ns=int(stamp_int[acc[-1]]) if acc.size else None, q=q, phi=phi,
        y=_joined(q, phi), static=static, vehicle=vehicle, observer=observer, t=t_all,
        dist=distance_m(np.diff(t_all), v_all), v_model=v_model, contradicted=contradicted,
        starts=np.flatnonzero(restart[acc]).tolist() + [acc.size], friction_velocity=friction)


def fit_friction_velocity(vehicle: VehicleParameters, observer: ObserverParameters, stamps_ns,
                          q, phi, speed, restart, table: list | None = None
                          ) -> VehicleParameters:
    """``vehicle`` with the tanh friction's ``v_f`` (``vehicle.leaf_spring_friction_velocity``)
    that makes the drive likeliest (:mod:`.friction_fit`'s rule), with
    ``observer.friction_velocity_fit`` (else, and without tanh friction, or under
    ``zero_load``, ``vehicle`` as it is).

    The front axle's online observer (no latency, :class:`.estimator.BatchRun`) over the first
    run's first :data:`.friction_fit.FIT_S` seconds of the accepted samples (``stamps_ns``,
    ``q``, ``phi``, ``speed``, ``restart``: per accepted sample), making no rows (``rows``
    False: the filter and its innovations only, as the whole vehicle's fit). Not under
    ``zero_load`` (the whole vehicle fits there): the readings here are the tracker's, less
    its offset, which a ``zero_load`` vehicle's :class:`.BatchRun` would track again, and the
    tracker's offset lag (:data:`.static_load.TIME_CONSTANT_S`, 10 s) is half the fit's seconds.
    ``table``: the likelihood per ``v_f`` (:func:`.friction_fit.likeliest_velocity`), when
    fitted.
    """
    from dataclasses import replace

    from road_force_estimator.estimation.estimator import BatchRun

    if (not fits(observer, vehicle.leaf_spring_friction_model, vehicle.leaf_spring_friction_n)
            or vehicle.zero_load or len(stamps_ns) == 0):
        return vehicle
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    later = np.flatnonzero(np.asarray(restart, bool)[1:]) + 1      # the first run only
    end = fit_end(stamps, int(later[0]) if later.size else stamps.size)
    obs = replace(observer, latency_s=0.0)

    def nll_terms(v_f: float) -> list:
        run = BatchRun(replace(vehicle, leaf_spring_friction_velocity_mps=v_f), obs, rows=False)
        terms = run.estimator.core.nll_terms = []
        run.feed(stamps[:end], q[:end], phi[:end], speed[:end])
        return terms

    return replace(vehicle, leaf_spring_friction_velocity_mps=likeliest_velocity(
        vehicle.leaf_spring_friction_velocity_mps, nll_terms, table))


def readings(prep: SimpleNamespace, rows, *, rows_in_file: bool = False):
    """The readings ``[q_1, q_2, phi]`` ((k, 3), m and rad) of a recording's input rows
    ``rows`` (:func:`prepare`; ascending indices or a slice): from ``prep.y`` (the (n, 3)
    array, or a :class:`~.core.spill.SpillColumn` of it, :func:`spill_readings`: the rows'
    range read and indexed), else ``prep.q`` and ``prep.phi``. ``rows_in_file`` (a slice of
    a file's rows): a :class:`~.core.spill.SpillRows` of them, read when they are needed."""
    y = prep.y
    if y is None:
        return np.column_stack([prep.q[rows], prep.phi[rows]])
    if isinstance(y, np.ndarray):
        return y[rows]
    from road_force_estimator.core.spill import SpillRows

    if isinstance(rows, slice):
        return (SpillRows(y, rows.start, rows.stop) if rows_in_file
                else y.read(rows.start, rows.stop))
    if rows.size == 0:
        return np.empty((0,) + y.shape)
    lo = int(rows[0])
    return y.read(lo, int(rows[-1]) + 1)[rows - lo]


def spill_readings(prep: SimpleNamespace, folder) -> None:
    """``prep``'s readings (:func:`prepare`) moved into a :class:`~.core.spill.SpillColumn`
    (n, 3) in ``folder`` (``prep.y``; ``prep.q`` and ``prep.phi`` None): :func:`readings`
    reads them back, the same numbers (the offline stream in pieces)."""
    from road_force_estimator.core.spill import SpillColumn

    out = SpillColumn(float, 3, folder)
    try:
        for a in range(0, prep.n, _REPEAT_CHUNK):
            out.append(readings(prep, slice(a, a + _REPEAT_CHUNK)))
    except BaseException:
        out.close()
        raise
    prep.y, prep.q, prep.phi = out, None, None


def rows_of(column, a: int, b: int) -> np.ndarray:
    """Rows ``a:b`` of an array or of a :class:`.core.spill.SpillColumn`."""
    return column[a:b] if isinstance(column, np.ndarray) else column.read(a, b)


def _joined(q: np.ndarray, phi: np.ndarray) -> np.ndarray | None:
    """The (n, 3) array ``[q_1, q_2, phi]`` whose views ``q`` and ``phi`` are (the offline
    stream's inputs: the measurements are not copied again), else None."""
    base = q.base
    if (base is None or phi.base is not base or base.ndim != 2 or base.shape[1] != 3
            or base.dtype != np.float64 or not base.flags.c_contiguous
            or q.shape[0] > base.shape[0]):
        return None
    start = base.__array_interface__['data'][0]
    if (q.__array_interface__['data'][0] != start or q.strides != base.strides
            or phi.__array_interface__['data'][0] != start + 16):
        return None
    return base[:q.shape[0]]


def smoothed_rows(prep: SimpleNamespace, smoother: Smoother, columns: list | None = None
                  ) -> Iterator[tuple[np.ndarray | slice | None, list]]:
    """The smoothed rows of a recording (:func:`prepare`) in order, ``(rows, columns)``:
    ``rows`` the input rows (indices or a slice) and ``columns`` (slots :class:`.Column`) their
    estimates, the distance and the static loads (:meth:`.Reconstruction.restatic`) in.
    With ``columns`` (the recording's, each (n,)) a run without a rejected sample inside is
    written into them directly, and comes as ``(None, columns of its rows)``."""
    acc, starts, t_all = prep.acc, prep.starts, prep.t
    restat = Reconstruction(smoother.vehicle, prep.observer.rollover_cutoff_frequency_hz)
    left = left_out_rows(prep)
    for r0, r1 in zip(starts[:-1], starts[1:]):
        idx = acc[r0:r1]
        whole = idx[-1] - idx[0] + 1 == idx.size               # no rejected sample inside
        src = slice(idx[0], idx[-1] + 1) if whole else idx      # views when whole
        direct = [col[src] for col in columns] if whole and columns is not None else None
        t = t_all[r0:r1]
        y = readings(prep, src, rows_in_file=whole)
        for a, b, part in smoother.pieces(t, y, prep.v_model[r0:r1], direct,
                                          None if left is None else left[r0:r1]):
            part[Column.DISTANCE][:] = rows_of(prep.dist, r0 + a, r0 + b)
            if prep.static is not None:
                restat.restatic(part, prep.static[r0 + a:r0 + b], t[a:b],
                                None if a == 0 else float(t[a - 1]))
            if part is direct:
                yield None, part
            elif whole:
                yield slice(idx[a], idx[b - 1] + 1), part
            else:
                yield idx[a:b], part
            del part                  # (let go before the next window is computed)


#: Accepted samples :func:`left_out_rows` looks at a time for a repeated reading.
_REPEAT_CHUNK = 1 << 20


def left_out_rows(prep: SimpleNamespace) -> np.ndarray | None:
    """The readings of a recording's accepted samples (:func:`prepare`) that the smoother
    leaves out: bool ``(accepted, 3)`` (``q_1``, ``q_2``, roll), or None when none.

    A stuck sensor's stretch (:func:`.sensor_health.left_out`: flagged, and its held
    readings before the flag), from the stuck rule of the detector that flags the estimate
    (:class:`FaultRows`: the same samples, stamps and readings; the stuck flags do not
    depend on the body's rates, so they are known before the smoother). A stuck flag needs a
    reading repeated to within ``observer.fault_stuck_tolerance``: a recording without one
    (noisy readings) is not stepped through the detector twice.
    """
    from road_force_estimator.estimation.models.front_axle import CHANNEL_NAMES
    from road_force_estimator.estimation.sensor_health import (
        FaultDetector, FaultSettings, flag_codes, left_out)

    acc = prep.acc
    tol = prep.observer.fault_stuck_tolerance
    repeated = False
    for a in range(0, max(acc.size - 1, 0), _REPEAT_CHUNK):
        idx = acc[a:a + _REPEAT_CHUNK + 1]
        vals = readings(prep, idx)
        if np.any(np.abs(np.diff(vals, axis=0)) <= tol):
            repeated = True
            break
    if not repeated:
        return None
    det = FaultDetector(FaultSettings.of(prep.observer, prep.vehicle, CHANNEL_NAMES))
    stamps = np.empty(acc.size, np.int64)
    k = 0
    for a in range(0, prep.n, _REPEAT_CHUNK):
        b = min(prep.n, a + _REPEAT_CHUNK)
        ok = prep.valid[a:b]
        part = rows_of(prep.stamps_out, a, b)[ok]
        stamps[k:k + part.size] = part
        k += part.size
    step = det.step
    for a in range(0, acc.size, _REPEAT_CHUNK):
        b = min(acc.size, a + _REPEAT_CHUNK)
        for stamp, v in zip(stamps[a:b].tolist(), readings(prep, acc[a:b]).tolist()):
            step(stamp, v)
    return left_out(flag_codes(det.events, acc.size, det.n), det.stuck_since, stamps)


def last_row(fields: dict, row: int) -> dict:
    """What the status takes of the last accepted row ``row`` of the fields (or a piece's)."""
    return {name: fields[name][row] for name in LAST_ROW_FIELDS}


#: The fields of the last accepted row that the status reports (:func:`fill_status`).
LAST_ROW_FIELDS = ('residual_nm', 'lift_off', 'converged', 'static_load_n')


def fill_status(status: EstimatorStatus, accepted: int, contradicted: np.ndarray,
                last_stamp_ns: int | None, last: dict | None, smoother: Smoother) -> None:
    """The status of :func:`smooth` (``status`` made from the estimator's counts): the
    accepted and contradicted counts, the last accepted sample's stamp and flags (``last``,
    :func:`last_row`; None without one), the smoother's levels and vehicle."""
    status.accepted = int(accepted)
    status.speed_contradicted = int(np.count_nonzero(contradicted))
    vehicle = smoother.vehicle
    status.sprung_mass_kg = vehicle.sprung_mass_kg
    status.static_load_n = vehicle.static_load_n
    if last is not None:
        status.last_stamp_ns = int(last_stamp_ns)
        status.last_residual_nm = float(last['residual_nm'])
        status.lift_off = tuple(bool(b) for b in last['lift_off'])
        status.converged = bool(last['converged'])
        status.static_load_n = tuple(float(f) for f in last['static_load_n'])
    smoother.fill_status(status)
