"""The numbers of a drive's report: accuracy against the truth, the per-segment table, the
whole-drive IRI and the summary dict (what ``report.json`` holds).

Accuracy is judged as in MODEL.md "Metrics" and the benchmark: on the samples the estimator
calls converged (and where the truth exists), loads and LTR directly, the profile through the
same zero-phase 0.5-30 m band-pass on estimate and truth
(:mod:`road_force_estimator.core.metrics`), from 30 m after the first judged sample to 30 m
before the end (the band-pass's edge transients).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from road_force_estimator.core import iri as iri_mod
from road_force_estimator.core import metrics
from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
from road_force_estimator.core.segments import SEGMENT_COLUMNS, segment_table
from road_force_estimator.report import drive_info
from road_force_estimator.report.alignment import Aligned, align
from road_force_estimator.report.correlation import correlation_figures

__all__ = ['DEFAULT_SEGMENT_LENGTH_M', 'CONVERGENCE_WINDOW_S', 'CONVERGENCE_HOLD_S',
           'accuracy', 'drive_segments', 'summarize', 'convergence', 'friction_summary',
           'friction_velocity_line', 'friction_velocity_note']

#: Default segment length (m).
DEFAULT_SEGMENT_LENGTH_M = 100.0
#: Window of the moving RMS of the load error whose convergence is measured (s).
CONVERGENCE_WINDOW_S = 0.1
#: The convergence time is the first time after which that error stays inside its tolerance
#: for this long (s; MODEL.md "Metrics").
CONVERGENCE_HOLD_S = 1.0


def _pooled(rms: np.ndarray, ref: np.ndarray) -> float:
    with np.errstate(divide='ignore', invalid='ignore'):
        return float(100.0 * math.sqrt(np.mean(np.square(rms))) /
                     math.sqrt(np.mean(np.square(ref))))


def _floats(a) -> list[float]:
    return [float(v) for v in np.ravel(a)]


def accuracy(est, al: Aligned, vehicle: VehicleParameters) -> dict[str, Any] | None:
    """Errors against the truth (None without truth or without a converged sample).

    Returns
    -------
    dict
        ``samples_judged``; loads: ``load_rms_n``, ``load_peak_n``, ``load_rms_pct_dynamic``,
        ``load_rms_pct_static`` (per wheel) and ``load_rms_pct_dynamic_both`` (pooled);
        ``convergence_s`` and ``convergence_tolerance_n`` (:func:`convergence`); LTR:
        ``ltr_rms_error``, ``ltr_peak_error``, ``max_abs_ltr``, ``max_abs_ltr_true``; profile
        (when a truth or reference profile exists and the drive is long enough):
        ``profile_samples_judged``, ``profile_rms_m``, ``profile_rms_pct_band`` (per wheel),
        ``profile_rms_pct_band_both``, ``profile_against``; the IRI-filtered cross
        correlation is added by :func:`summarize` (:mod:`.correlation`).
    """
    out: dict[str, Any] = {}
    static = np.asarray(vehicle.static_load_n, dtype=float)
    if al.true_load_n is not None:
        load = al.pick(est, 'wheel_load_n')
        mask = al.converged & np.isfinite(al.true_load_n).all(axis=1)
        if np.count_nonzero(mask) >= 2:
            st = metrics.load_errors(load, np.nan_to_num(al.true_load_n), static, mask=mask)
            true = al.true_load_n
            ltr_true = (true[:, 1] - true[:, 0]) / (true[:, 0] + true[:, 1])
            lt = metrics.ltr_stats(al.pick(est, 'ltr'), np.nan_to_num(ltr_true), mask=mask)
            out.update(
                samples_judged=int(np.count_nonzero(mask)),
                load_rms_n=_floats(st.rms), load_peak_n=_floats(st.peak),
                load_rms_pct_dynamic=_floats(st.rms_pct),
                load_rms_pct_static=_floats(st.rms_pct_static),
                load_rms_pct_dynamic_both=_pooled(st.rms, st.reference_rms),
                true_dynamic_rms_n=_floats(st.reference_rms),
                ltr_rms_error=lt['rms_error'], ltr_peak_error=lt['peak_error'],
                max_abs_ltr=lt['max_abs'], max_abs_ltr_true=lt['max_abs_truth'])
            out['convergence_s'], out['convergence_tolerance_n'] = _convergence(
                al, load, static, float(np.sqrt(np.mean(np.square(st.rms)))))
    truth = al.profile_truth
    if truth is not None:
        road = al.pick(est, 'road_m')
        up = al.increasing() & np.isfinite(truth).all(axis=1)
        x = al.x_m[up]
        judged = al.converged[up]
        if np.any(judged):
            first = x[np.argmax(judged)]
            edge = metrics.BAND_LONG_M
            pmask = judged & (x >= first + edge) & (x <= x[-1] - edge)
            if np.count_nonzero(pmask) > 10:
                try:
                    pe = metrics.profile_errors(x, road[up], truth[up], mask=pmask)
                except ValueError:
                    pe = None
                if pe is not None:
                    out.update(profile_samples_judged=int(np.count_nonzero(pmask)),
                               profile_rms_m=_floats(pe.rms),
                               profile_rms_pct_band=_floats(pe.rms_pct),
                               profile_rms_pct_band_both=_pooled(pe.rms, pe.reference_rms),
                               profile_against=('ground truth' if al.true_road_m is not None
                                                else al.reference_name))
    return out or None


def convergence(t_s: np.ndarray, error_n: np.ndarray, tolerance_n: float, *,
                window_s: float = CONVERGENCE_WINDOW_S,
                hold_s: float = CONVERGENCE_HOLD_S) -> float:
    """The convergence time t_0 (s) of a load error (MODEL.md "Metrics"): the first time after
    which the ``window_s`` moving RMS of ``error_n`` ((n,) or (n, 2) per wheel, pooled) stays
    below ``tolerance_n`` for ``hold_s``; ``inf`` if it never does."""
    t = np.asarray(t_s, dtype=float)
    err = np.asarray(error_n, dtype=float)
    err2 = np.mean(np.square(err.reshape(t.size, -1)), axis=1)
    if t.size < 2:
        return math.inf
    dt = float(np.median(np.diff(t)))
    w = max(1, int(round(window_s / dt))) if dt > 0 else 1
    c = np.concatenate([[0.0], np.cumsum(err2)])
    lo = np.maximum(np.arange(t.size) - w + 1, 0)
    mrms = np.sqrt((c[1:] - c[lo]) / (np.arange(t.size) - lo + 1))
    return metrics.convergence_time(t, mrms, tolerance_n, window_s=hold_s)


def _convergence(al: Aligned, load: np.ndarray, static: np.ndarray,
                 judged_rms: float) -> tuple[float, float]:
    """Measured convergence time (s) of the load error and its tolerance (N): the tolerance
    is max(2 x the judged RMS, 1 % of the static load) (see :func:`convergence`)."""
    tol = max(2.0 * judged_rms, 0.01 * float(np.mean(static)))
    ok = np.isfinite(al.true_load_n).all(axis=1)
    if not ok.any() or not al.converged.any():
        return math.inf, tol
    last = int(np.flatnonzero(al.converged)[-1])
    sel = np.flatnonzero(ok[:last + 1])
    if sel.size < 2:
        return math.inf, tol
    return convergence(al.t_s[sel], load[sel] - al.true_load_n[sel], tol), tol


def _iri_hook(distance_m, elevation_m, edges_m) -> np.ndarray:
    """:func:`road_force_estimator.core.iri.iri_segments`, NaN where the profile is too short."""
    try:
        return iri_mod.iri_segments(distance_m, elevation_m, edges_m)
    except ValueError:
        return np.full(len(edges_m) - 1, np.nan)


def drive_segments(est, al: Aligned, drive=None, *,
                   segment_length_m: float = DEFAULT_SEGMENT_LENGTH_M) -> dict[str, np.ndarray]:
    """Per-segment table (:func:`road_force_estimator.core.segments.segment_table`) of a drive.

    IRI of the estimated profile and of the truth (on the truth's own samples:
    :func:`~.drive_info.true_segment_iri`) or the reference profile; coordinates from the
    drive's fixes. Empty columns when the drive covers less than one sample of distance.
    """
    up = al.increasing()
    empty = {name: np.zeros(0) for name in SEGMENT_COLUMNS}
    if np.count_nonzero(up) < 2:
        return empty
    rows = al.rows[up]
    truth = al.profile_truth
    true_profile = None
    if truth is not None:
        t = truth[up]
        if np.isfinite(t).all():
            true_profile = t
        elif np.isfinite(t).any(axis=1).sum() >= 2:
            ok = np.isfinite(t).all(axis=1)
            x = al.x_m[up]
            true_profile = np.column_stack([np.interp(x, x[ok], t[ok, i]) for i in (0, 1)])
    fixes = getattr(drive, 'fixes', None)
    try:
        table = segment_table(
            al.x_m[up], np.asarray(est.wheel_load_n)[rows], np.asarray(est.ltr)[rows],
            np.asarray(est.lift_off)[rows], profile_m=np.asarray(est.road_m)[rows],
            true_profile_m=true_profile, iri_segments=_iri_hook,
            stamps_ns=np.asarray(est.stamp_ns)[rows],
            fix_stamps_ns=None if fixes is None else fixes.stamps_ns,
            fix_latitude_deg=None if fixes is None else fixes.latitude_deg,
            fix_longitude_deg=None if fixes is None else fixes.longitude_deg,
            segment_length_m=segment_length_m,
            ltr_quasi_static=_quasi_static(est, rows),
            static_load_n=_optional(est, 'static_load_n', rows))
    except ValueError:
        return empty
    if drive is not None and len(table['start_m']):
        edges = np.concatenate([table['start_m'], table['end_m'][-1:]])
        own = drive_info.true_segment_iri(drive, al, edges)
        if own is not None:
            table['true_iri_left_m_per_km'] = own[:, 0]
            table['true_iri_right_m_per_km'] = own[:, 1]
    return table


def whole_iri(x: np.ndarray, z: np.ndarray | None) -> list[float] | None:
    if z is None or not np.isfinite(z).all():
        return None
    try:
        return _floats(iri_mod.iri(x, z))
    except ValueError:
        return None


def whole_from_segments(x: np.ndarray, z: np.ndarray | None, segments: dict,
                         prefix: str) -> list[float] | None:
    """Whole-drive IRI of a profile (left, right) from its per-segment IRI (columns
    ``{prefix}_left/right_m_per_km``; one quarter-car run instead of two): the mean over the
    segments weighted by their slope intervals (:func:`~.iri.interval_counts`); computed
    afresh (:func:`whole_iri`) when the segments do not give it."""
    start, end = segments.get('start_m'), segments.get('end_m')
    if z is None or start is None or len(start) == 0 or not np.isfinite(z).all():
        return whole_iri(x, z)
    try:
        counts = iri_mod.interval_counts(x, np.concatenate([start, end[-1:]]))
    except ValueError:
        return whole_iri(x, z)
    values = np.column_stack([segments[f'{prefix}_left_m_per_km'],
                              segments[f'{prefix}_right_m_per_km']])
    used = (counts > 0) & np.isfinite(values).all(axis=1)
    if not used.any():
        return whole_iri(x, z) if np.isfinite(values).all() else None
    # Segments without data (a gap) are left out, never averaged as zero.
    return _floats(values[used].T @ counts[used] / counts[used].sum())


def summarize(est, drive=None, vehicle: VehicleParameters | None = None,
              observer: ObserverParameters | None = None, *, mode: str = 'online',
              input_name: str = '', reference=None, reference_offset_m: float | None = None,
              segment_length_m: float = DEFAULT_SEGMENT_LENGTH_M,
              extra: dict[str, Any] | None = None, units: str = 'si',
              run_info: dict[str, Any] | None = None,
              raw_road=None) -> tuple[dict[str, Any], dict, Aligned]:
    """The report's numbers: ``(summary, segments, aligned)``.

    Parameters
    ----------
    est : EstimateArrays (or the offline mode's)
    drive : bagio.Drive, optional
        What was read: messages, rejections, breaks, truth, fixes.
    vehicle, observer : parameters used.
    mode : 'online' or 'offline'.
    input_name : str
        Shown in the report.
    reference : RoadProfile, optional
        A reference profile (e.g. the LPA survey of the road driven), used when the drive has
        no ground truth.
    reference_offset_m : float, optional
        Distance along the reference where the drive starts (m from the reference's start);
        default: the offset within +-:data:`~.alignment.REFERENCE_SEARCH_M` that best
        correlates the band-passed profiles.
    segment_length_m : float
        Segment length (m).
    extra : dict, optional
        More counts to show (e.g. samples whose speed was taken from the first twist).
    units : 'si' or 'us'
        Units of the report's text (``report.json`` and ``segments.csv`` stay SI).
    run_info : dict, optional
        ``command``, ``params_file``, ``overrides``: shown in the report
        (:func:`~.drive_info.run_description`).
    raw_road : RoadProfile, optional
        The road before the tire envelope (default: read from the bag's simulator parameters
        when the source is no bag: :func:`~.drive_info.raw_road`).
    """
    vehicle = VehicleParameters() if vehicle is None else vehicle
    observer = ObserverParameters() if observer is None else observer
    al = align(est, drive, reference, reference_offset_m)
    st = est.status
    rejected = rejections(drive, st)
    conv_rows = np.flatnonzero(al.reported_converged)
    summary: dict[str, Any] = {
        'input': input_name,
        'mode': mode,
        'messages': dict(sorted((getattr(drive, 'messages', None) or {}).items())),
        'samples': {'input': int(len(est.stamp_ns)), 'estimated': int(st.accepted),
                    'converged': int(conv_rows.size)},
        'judged_from': al.judged_from,
        'rejected': rejected,
        'rejected_total': int(sum(sum(r.values()) for r in rejected.values())),
        'issues': list(getattr(drive, 'issues', ()) or ()),
        'resets': int(st.resets),
        'gaps': int(st.gaps),
        'duration_s': float(al.t_s[-1]) if al.t_s.size else 0.0,
        'distance_m': float(al.x_m[-1] - al.x_m[0]) if al.x_m.size else 0.0,
        'settling_time_s': float(st.settling_time_s),
        'first_converged_s': float(al.t_s[conv_rows[0]]) if conv_rows.size else math.inf,
        **_load_counts(est, al),
        'fixes': int(len(drive.fixes.stamps_ns)) if getattr(drive, 'fixes', None) else 0,
        'has_ground_truth': al.true_load_n is not None,
        'reference_profile': al.reference_name or None,
        'reference_offset_m': al.reference_offset_m,
        'segment_length_m': float(segment_length_m),
        'units': units,
        'run': drive_info.run_description(drive, est, vehicle, observer, mode, run_info),
        'parameters': {**vehicle.to_parameters(), **observer.to_parameters()},
    }
    summary.update(notes(est, extra))
    stamps = np.asarray(est.stamp_ns, dtype=np.int64)
    summary['sensors'] = sensor_summary(st, int(stamps[0]) if stamps.size else 0)
    summary.update(_odometer_summary(est))
    summary.update(friction_summary(est))
    summary.update(_speed_findings(est))
    summary['accuracy'] = accuracy(est, al, vehicle)
    segments = drive_segments(est, al, drive, segment_length_m=segment_length_m)
    _add_correlation(summary['accuracy'], est, al, drive, segments, segment_length_m)
    summary.update(segment_counts(segments))
    summary['iri_m_per_km'] = _drive_iri(est, al, segments, drive, raw_road)
    summary['convergence'] = convergence_summary(summary)
    return summary, segments, al


def _odometer_summary(est) -> dict[str, Any]:
    """``{'distance': which distance and why}`` (:class:`.odometer.DistanceSource`, when the
    estimate says) and ``{'odometer': the GNSS fit}`` when one was made."""
    out: dict[str, Any] = {}
    if est.distance_source is not None:
        out['distance'] = est.distance_source.as_dict()
    if est.fused:
        out['odometer'] = est.odometer.as_dict() if est.odometer is not None else None
    return out


def friction_summary(est) -> dict[str, Any]:
    """``{'friction_velocity': the tanh friction's v_f taken and the file's}``
    (:meth:`.friction_fit.FrictionVelocity.as_dict`) of an offline estimate (its arrays or
    its :class:`.OfflineStream`) whose file states a tanh friction, else {}."""
    fv = getattr(est, 'friction_velocity', None)
    return {} if fv is None else {'friction_velocity': fv.as_dict()}


def friction_velocity_line(fv: dict[str, Any]) -> str:
    """The report's line of ``report.json``'s ``friction_velocity`` (:func:`friction_summary`):
    the v_f taken, and whether it was fitted from the drive or is the file's."""
    from road_force_estimator.estimation.friction_fit import FIT_GRID, FIT_LEAD_NATS

    head = f"Leaf-spring friction v_f: {fv['taken_mps']:g} m/s"
    if not fv['fitted']:
        return f"{head}, the file's (not fitted: {fv['reason']})."
    if fv['taken_mps'] == fv['file_mps']:
        return (f"{head}, the file's: fitted from the drive, no v_f of "
                f'{FIT_GRID[0]:g}-{FIT_GRID[-1]:g} x it was likelier by '
                f'{FIT_LEAD_NATS:g} nats.')
    return (f"{head} fitted from the drive (the file's {fv['file_mps']:g}; put it in the "
            'file for the online node: `vehicle.leaf_spring_friction_velocity`).')


def friction_velocity_note(fv: dict[str, Any]) -> str | None:
    """estimate_bag's line on stderr where the fit changed ``v_f`` (``fv``: ``report.json``'s
    ``friction_velocity``), else None."""
    if fv['taken_mps'] == fv['file_mps']:
        return None
    return (f"leaf-spring friction v_f {fv['taken_mps']:g} m/s fitted from the drive (the "
            f"file's {fv['file_mps']:g} m/s); the online node takes it from "
            'vehicle.leaf_spring_friction_velocity')


def _add_correlation(acc: dict[str, Any] | None, est, al: Aligned, drive, segments: dict,
                     segment_length_m: float) -> None:
    """The IRI-filtered cross correlation (:mod:`.correlation`) into the accuracy figures, on
    the report's segments."""
    if acc is None:
        return
    edges = (np.concatenate([segments['start_m'], segments['end_m'][-1:]])
             if len(segments['start_m']) else None)
    acc.update(correlation_figures(est, al, drive, edges, segment_length_m=segment_length_m))


def sensor_summary(st, t0: int) -> dict[str, dict[str, Any]]:
    """Per sensor (channel name) of an :class:`.EstimatorStatus`: ``innovations_gated``
    (spikes kept from the filter), ``stuck_flags`` / ``stuck_samples``, ``drift_flags`` /
    ``drift_samples`` (:mod:`~road_force_estimator.estimation.sensor_health`),
    ``first_stuck_s`` / ``first_drift_s`` (s from ``t0``, the first sample's stamp (ns);
    None: never) and ``flag`` (at the end)."""
    names = list(getattr(st, 'sensor_faults', None) or getattr(st, 'innovations_gated', None)
                 or {})
    out: dict[str, dict[str, Any]] = {}
    for name in names:
        first = (getattr(st, 'fault_first_ns', None) or {}).get(name, {})
        out[name] = {
            'innovations_gated': int((st.innovations_gated or {}).get(name, 0)),
            'stuck_flags': int((st.stuck_episodes or {}).get(name, 0)),
            'stuck_samples': int((st.stuck_samples or {}).get(name, 0)),
            'first_stuck_s': (first['stuck'] - t0) * 1e-9 if 'stuck' in first else None,
            'drift_flags': int((st.drift_episodes or {}).get(name, 0)),
            'drift_samples': int((st.drift_samples or {}).get(name, 0)),
            'first_drift_s': (first['drift'] - t0) * 1e-9 if 'drift' in first else None,
            'flag': (st.sensor_faults or {}).get(name, 'ok')}
    return out


def notes(est, extra: dict[str, Any] | None) -> dict[str, Any]:
    """``notes`` (the caller's extra counts) and ``offline`` (the noise and cut-offs the
    offline mode estimated), when there are any."""
    out: dict[str, Any] = {'notes': dict(extra)} if extra else {}
    for key in ('noise_std', 'cutoff_hz'):
        if hasattr(est, key):
            out.setdefault('offline', {})[key] = _floats(getattr(est, key))
    return out


def segment_counts(segments: dict[str, np.ndarray]) -> dict[str, int]:
    """Segments; those without data (no sample: a gap) and those without IRI."""
    return {'segments': int(len(segments['start_m'])),
            'segments_without_data': int(np.count_nonzero(
                ~np.isfinite(segments['peak_load_left_n']))),
            'segments_without_iri': int(np.count_nonzero(
                ~np.isfinite(segments['iri_left_m_per_km'])))}


def _load_counts(est, al: Aligned) -> dict[str, Any]:
    """Samples with a wheel lifted off, with a load estimate below zero; the largest |LTR|."""
    return {
        'lift_off_samples': int(np.count_nonzero(np.asarray(est.lift_off)[al.rows].any(axis=1))),
        'negative_load_samples': _negative_loads(est, al),
        'max_abs_ltr': float(np.max(np.abs(al.pick(est, 'ltr')))) if al.rows.size else 0.0,
        'static_load_final_n': _final_static(est, al)}


def _final_static(est, al: Aligned) -> list[float] | None:
    """The static wheel loads in use at the last estimate (N, [left, right]): configured, or
    estimated under zero_load (None for estimates without them)."""
    values = getattr(est, 'static_load_n', None)
    if values is None or not al.rows.size:
        return None
    return _floats(np.asarray(values)[al.rows[-1]])


def _negative_loads(est, al: Aligned) -> int:
    """Accepted samples where a wheel's load estimate went below zero (the estimator publishes
    0 N there: :attr:`EstimateArrays.load_clipped`; estimates without it: ``wheel_load_n <
    0``)."""
    below = getattr(est, 'load_clipped', None)
    if below is None:
        below = np.asarray(est.wheel_load_n, dtype=float) < 0.0
    below = np.asarray(below, dtype=bool).reshape(len(est.stamp_ns), -1)
    return int(np.count_nonzero(below[al.rows].any(axis=1))) if al.rows.size else 0


def convergence_summary(s: dict[str, Any]) -> dict[str, Any]:
    """The one convergence figure of the report: measured against the truth when there is
    one (:func:`convergence`), else the estimator's own (its first converged sample)."""
    acc = s.get('accuracy') or {}
    if 'convergence_s' in acc:
        return {'time_s': acc['convergence_s'], 'source': 'measured',
                'tolerance_n': acc['convergence_tolerance_n'],
                'window_s': CONVERGENCE_WINDOW_S, 'hold_s': CONVERGENCE_HOLD_S}
    return {'time_s': s['first_converged_s'], 'source': 'estimator',
            'settling_time_s': s['settling_time_s']}


def _speed_findings(est) -> dict[str, Any]:
    """``speed_contradicted``: samples and the spans (s from the first stamp) where the
    deflections contradicted a standing speed, only when there are some."""
    out: dict[str, Any] = {}
    flags = getattr(est, 'speed_contradicted', None)
    if flags is not None and np.any(flags):
        t = (np.asarray(est.stamp_ns, dtype=np.int64) - int(est.stamp_ns[0])) * 1e-9
        f = np.concatenate([[False], np.asarray(flags, bool), [False]]).astype(np.int8)
        starts = np.flatnonzero(np.diff(f) == 1)
        ends = np.flatnonzero(np.diff(f) == -1) - 1
        out['speed_contradicted'] = {
            'samples': int(np.count_nonzero(flags)),
            'spans_s': [[round(float(t[a]), 3), round(float(t[b]), 3)]
                        for a, b in zip(starts.tolist(), ends.tolist())]}
    return out


def rejections(drive, st) -> dict[str, dict[str, int]]:
    """Rejected samples by topic and reason: the reader's (``drive.rejected``), then the
    estimator's (``'estimator'``), zero counts left out."""
    rejected: dict[str, dict[str, int]] = {}
    for topic, reasons in sorted((getattr(drive, 'rejected', None) or {}).items()):
        rejected[topic] = {r: int(c) for r, c in sorted(reasons.items()) if c}
    core = {'nonfinite': st.rejected_nonfinite, 'out_of_range': st.rejected_range,
            'speed_out_of_range': getattr(st, 'rejected_speed', 0),
            'frozen_values': getattr(st, 'rejected_stale', 0),
            'duplicate_or_backwards_stamp': st.rejected_time}
    core = {k: int(v) for k, v in core.items() if v}
    if core:
        rejected['estimator'] = core
    return rejected


def _drive_iri(est, al: Aligned, segments: dict, drive=None, raw_road=None
               ) -> dict[str, Any]:
    """Whole-drive IRI (m/km, left and right): ``estimated``; ``true``, the reference
    profile's (the truth on its own samples: the road enveloped by the tire,
    :func:`~.drive_info.true_profile_iri`; else the reference profile given); ``raw``, the road
    before the envelope; ``reference`` says which; None where unknown."""
    up = al.increasing()
    iri_est = iri_true = raw = None
    reference = None
    if np.count_nonzero(up) >= 2:
        x = al.x_m[up]
        iri_est = whole_from_segments(x, al.pick(est, 'road_m')[up], segments, 'iri')
        own = drive_info.true_profile_iri(drive, al, raw_road) if drive is not None else None
        if own is not None:
            iri_true, raw = own['enveloped'], own['raw']
            reference = 'enveloped'
        elif al.profile_truth is not None:
            iri_true = whole_from_segments(x, al.profile_truth[up], segments, 'true_iri')
            reference = 'truth' if al.true_road_m is not None else 'reference profile'
    return {'estimated': iri_est, 'true': iri_true, 'raw': raw, 'reference': reference}


def _quasi_static(est, rows) -> np.ndarray | None:
    """The estimate's quasi-static LTR at ``rows`` (None for estimates without one)."""
    return _optional(est, 'ltr_quasi_static', rows)


def _optional(est, name: str, rows) -> np.ndarray | None:
    """The estimate's field ``name`` at ``rows`` (None for estimates without it)."""
    values = getattr(est, name, None)
    return None if values is None else np.asarray(values)[rows]
