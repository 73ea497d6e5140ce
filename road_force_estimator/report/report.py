"""The report of an estimated drive: figures, the per-segment table and a Markdown summary.

What :func:`write_report` puts in a report folder (``estimate_bag`` writes ``DIR/report/``):

``report.md``
    Summary (samples processed, rejected by topic and reason, breaks in the bag, restarts,
    convergence), accuracy against the ground truth when the bag has it (wheel-load error RMS
    as a % of the true dynamic-load RMS and of the static load, band-passed profile error %,
    LTR error), the IRI of the whole drive, the per-segment table and the figures.
``segments.csv``
    One row per segment (default 100 m): :data:`road_force_estimator.core.segments.SEGMENT_COLUMNS`
    (IRI left/right of the estimated and, when known, the true profile; DLC; peak loads;
    max |LTR|; lift-off events; coordinates when the drive has ``/fix``).
``report.json``
    The summary's numbers, for programs.
``states.png``, ``body.png``, ``wheels.png``, ``profile.png``, ``loads.png``, ``overview.png``
    Like the seed paper's figures 5-10: the differentiator states and rates (q, dq, ddq, phi,
    dphi, ddphi) with the measurements, the body acceleration and heave, the wheel heaves, the
    band-passed profile against the truth (or a reference LPA profile), the loads and LTR
    against the truth, and an overview of the whole drive with the per-segment IRI.

Accuracy is judged as in MODEL.md "Metrics" and the benchmark: on the samples the estimator
calls converged (and where the truth exists), loads and LTR directly, the profile through the
same zero-phase 0.5-30 m band-pass on estimate and truth (:mod:`.metrics`), from 30 m after the
first judged sample to 30 m before the end (the band-pass's edge transients).

matplotlib (Agg backend) is imported here only, and only when figures are drawn.
"""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from road_force_estimator.core import iri as iri_mod
from road_force_estimator.core import metrics
from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
from road_force_estimator.core.segments import SEGMENT_COLUMNS, segment_table

__all__ = [
    'FIGURES', 'DEFAULT_SEGMENT_LENGTH_M', 'DEFAULT_WINDOW_S', 'Aligned', 'align',
    'accuracy', 'drive_segments', 'summarize', 'write_segments_csv', 'write_markdown',
    'write_figures', 'write_report',
]

#: Figure files of a report, in the order of the Markdown.
FIGURES = ('states.png', 'body.png', 'wheels.png', 'profile.png', 'loads.png', 'overview.png')
#: Default segment length (m).
DEFAULT_SEGMENT_LENGTH_M = 100.0
#: Time window of the detail figures (s) and distance window of the profile figure (m).
DEFAULT_WINDOW_S = 2.0
DEFAULT_PROFILE_WINDOW_M = 100.0
#: Window of the moving RMS that decides the measured convergence time (s).
CONVERGENCE_WINDOW_S = 0.1
#: A reference profile is aligned with the drive within +- this distance (m).
REFERENCE_SEARCH_M = 10.0
#: Most points drawn per curve in the whole-drive figure.
MAX_OVERVIEW_POINTS = 20000

_SIDES = ('left', 'right')


# ----------------------------------------------------------------------------------------------
# aligning estimate, truth and reference

class Aligned:
    """Estimate, truth and reference on the estimate's accepted samples.

    Attributes
    ----------
    rows : ndarray of int
        Indices of the accepted (``valid``) estimates, in order.
    t_s : ndarray
        Time since the first accepted sample (s), at ``rows``.
    x_m : ndarray
        Travelled distance (m), at ``rows``.
    true_load_n, true_road_m : ndarray (m, 2) or None
        Ground truth at the same stamps (None without truth; NaN rows where it is missing).
    reference_m : ndarray (m, 2) or None
        A reference profile (e.g. an LPA bag) at the same distances, when no truth.
    converged : ndarray of bool
        The estimator's ``converged`` at ``rows``.
    """

    def __init__(self, est, drive=None, reference=None,
                 reference_offset_m: float | None = None) -> None:
        valid = np.asarray(est.valid, dtype=bool)
        self.rows = np.flatnonzero(valid)
        stamps = np.asarray(est.stamp_ns, dtype=np.int64)[self.rows]
        self.stamps_ns = stamps
        self.t_s = (stamps - stamps[0]) * 1e-9 if stamps.size else np.zeros(0)
        self.x_m = np.asarray(est.distance_m, dtype=float)[self.rows]
        self.reported_converged = np.asarray(est.converged, dtype=bool)[self.rows]
        #: Rows judged: the estimator's ``converged``; if it never reported convergence, the
        #: rows from its settling time on (:attr:`judged_from` says which).
        self.converged = self.reported_converged
        self.judged_from = 'converged'
        if self.rows.size and not self.converged.any():
            settle = float(getattr(getattr(est, 'status', None), 'settling_time_s', 0.0) or 0.0)
            self.converged = self.t_s >= settle
            self.judged_from = 'settling time'
        self.true_load_n = self.true_road_m = None
        truth = getattr(drive, 'truth', None)
        if truth is not None and self.rows.size:
            at = truth.at(stamps)
            if np.isfinite(at.wheel_load_n).any():
                self.true_load_n = np.asarray(at.wheel_load_n, dtype=float)
            if np.isfinite(at.road_m).any():
                self.true_road_m = np.asarray(at.road_m, dtype=float)
        self.reference_m = None
        self.reference_name = ''
        self.reference_offset_m = None
        if reference is not None and self.true_road_m is None and self.rows.size:
            xr = np.asarray(reference.distance_m, dtype=float)
            if reference_offset_m is None:
                reference_offset_m = _best_offset(self, est, reference)
            self.reference_offset_m = float(reference_offset_m)
            pos = xr[0] + self.reference_offset_m + self.x_m
            inside = (pos >= xr[0]) & (pos <= xr[-1])
            ref = np.full((self.rows.size, 2), np.nan)
            for i in (0, 1):
                ref[inside, i] = np.interp(pos[inside], xr, reference.elevation_m[:, i])
            self.reference_m = ref
            self.reference_name = getattr(reference, 'name', '') or 'reference profile'

    def pick(self, est, name: str) -> np.ndarray:
        """Field ``name`` of the estimates at :attr:`rows`."""
        return np.asarray(getattr(est, name))[self.rows]

    @property
    def profile_truth(self) -> np.ndarray | None:
        """The profile to judge against: the truth, else the reference, else None."""
        return self.true_road_m if self.true_road_m is not None else self.reference_m

    def increasing(self) -> np.ndarray:
        """Mask of rows whose distance exceeds every earlier one (a standstill repeats x)."""
        x = self.x_m
        if x.size == 0:
            return np.zeros(0, bool)
        before = np.concatenate([[-np.inf], np.maximum.accumulate(x)[:-1]])
        return x > before


def align(est, drive=None, reference=None, reference_offset_m: float | None = None) -> Aligned:
    """:class:`Aligned` for the estimates ``est`` (and the drive's truth, or a reference)."""
    return Aligned(est, drive, reference, reference_offset_m)


def _best_offset(al: Aligned, est, reference, search_m: float = REFERENCE_SEARCH_M) -> float:
    """Distance along the reference at the drive's start (m, from the reference's start):
    the offset in ``[-search_m, search_m]`` that maximises the correlation of the band-passed
    profiles (both tracks, converged samples); 0 when they cannot be band-passed."""
    up = al.increasing() & al.converged
    if np.count_nonzero(up) < 100:
        return 0.0
    x = al.x_m[up]
    bp_est = _bandpass(x, al.pick(est, 'road_m')[up])
    xr = np.asarray(reference.distance_m, dtype=float)
    bp_ref = _bandpass(xr, np.asarray(reference.elevation_m, dtype=float))
    if bp_est is None or bp_ref is None:
        return 0.0

    def score(offset: float) -> float:
        pos = xr[0] + offset + x
        inside = (pos >= xr[0]) & (pos <= xr[-1])
        if np.count_nonzero(inside) < 0.5 * x.size:
            return -np.inf
        total = 0.0
        for i in (0, 1):
            a = bp_est[inside, i]
            b = np.interp(pos[inside], xr, bp_ref[:, i])
            den = math.sqrt(float(np.dot(a, a)) * float(np.dot(b, b)))
            total += float(np.dot(a, b)) / den if den > 0.0 else 0.0
        return total

    best = 0.0
    for step, span in ((0.05, search_m), (0.0025, 0.05)):
        grid = best + np.arange(-span, span + 0.5 * step, step)
        scores = [score(o) for o in grid]
        best = float(grid[int(np.argmax(scores))])
    return best


def _bandpass(x: np.ndarray, z: np.ndarray) -> np.ndarray | None:
    """Band-passed profile (0.5-30 m), or None when the drive is too short or too coarse."""
    try:
        return metrics.profile_bandpass(x, z)
    except ValueError:
        return None


def _pooled(rms: np.ndarray, ref: np.ndarray) -> float:
    with np.errstate(divide='ignore', invalid='ignore'):
        return float(100.0 * math.sqrt(np.mean(np.square(rms))) /
                     math.sqrt(np.mean(np.square(ref))))


def _floats(a) -> list[float]:
    return [float(v) for v in np.ravel(a)]


# ----------------------------------------------------------------------------------------------
# numbers

def accuracy(est, al: Aligned, vehicle: VehicleParameters) -> dict[str, Any] | None:
    """Errors against the truth (None without truth or without a converged sample).

    Returns
    -------
    dict
        ``samples_judged``; loads: ``load_rms_n``, ``load_peak_n``, ``load_rms_pct_dynamic``,
        ``load_rms_pct_static`` (per wheel) and ``load_rms_pct_dynamic_both`` (pooled);
        ``convergence_s`` (measured: the 100 ms moving RMS of the load error stays below
        max(2 x its judged RMS, 1 % of the static load) from then on); LTR: ``ltr_rms_error``,
        ``ltr_peak_error``, ``max_abs_ltr``, ``max_abs_ltr_true``; profile (when a truth or
        reference profile exists and the drive is long enough): ``profile_samples_judged``,
        ``profile_rms_m``, ``profile_rms_pct_band`` (per wheel), ``profile_rms_pct_band_both``,
        ``profile_against``.
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
                max_abs_ltr=lt['max_abs'], max_abs_ltr_true=lt['max_abs_truth'],
                convergence_s=_convergence(al, load, static, float(np.sqrt(np.mean(
                    np.square(st.rms))))))
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


def _convergence(al: Aligned, load: np.ndarray, static: np.ndarray, judged_rms: float) -> float:
    """Measured convergence time (s) of the load error (see :func:`accuracy`)."""
    ok = np.isfinite(al.true_load_n).all(axis=1)
    if not ok.any() or not al.converged.any():
        return math.inf
    last = int(np.flatnonzero(al.converged)[-1])
    sel = np.flatnonzero(ok[:last + 1])
    if sel.size < 2:
        return math.inf
    err2 = np.mean(np.square(load[sel] - al.true_load_n[sel]), axis=1)
    dt = float(np.median(np.diff(al.t_s[sel])))
    w = max(1, int(round(CONVERGENCE_WINDOW_S / dt))) if dt > 0 else 1
    c = np.concatenate([[0.0], np.cumsum(err2)])
    lo = np.maximum(np.arange(sel.size) - w + 1, 0)
    mrms = np.sqrt((c[1:] - c[lo]) / (np.arange(sel.size) - lo + 1))
    tol = max(2.0 * judged_rms, 0.01 * float(np.mean(static)))
    return metrics.convergence_time(al.t_s[sel], mrms, tol)


def _iri_hook(distance_m, elevation_m, edges_m) -> np.ndarray:
    """:func:`road_force_estimator.core.iri.iri_segments`, NaN where the profile is too short."""
    try:
        return iri_mod.iri_segments(distance_m, elevation_m, edges_m)
    except ValueError:
        return np.full(len(edges_m) - 1, np.nan)


def drive_segments(est, al: Aligned, drive=None, *,
                   segment_length_m: float = DEFAULT_SEGMENT_LENGTH_M) -> dict[str, np.ndarray]:
    """Per-segment table (:func:`road_force_estimator.core.segments.segment_table`) of a drive.

    IRI of the estimated profile and of the truth (or the reference) profile; coordinates from
    the drive's fixes. Empty columns when the drive covers less than one sample of distance.
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
        return segment_table(
            al.x_m[up], np.asarray(est.wheel_load_n)[rows], np.asarray(est.ltr)[rows],
            np.asarray(est.lift_off)[rows], profile_m=np.asarray(est.road_m)[rows],
            true_profile_m=true_profile, iri_segments=_iri_hook,
            stamps_ns=np.asarray(est.stamp_ns)[rows],
            fix_stamps_ns=None if fixes is None else fixes.stamps_ns,
            fix_latitude_deg=None if fixes is None else fixes.latitude_deg,
            fix_longitude_deg=None if fixes is None else fixes.longitude_deg,
            segment_length_m=segment_length_m)
    except ValueError:
        return empty


def _whole_iri(x: np.ndarray, z: np.ndarray | None) -> list[float] | None:
    if z is None or not np.isfinite(z).all():
        return None
    try:
        return _floats(iri_mod.iri(x, z))
    except ValueError:
        return None


def _whole_from_segments(x: np.ndarray, z: np.ndarray | None, segments: dict,
                         prefix: str) -> list[float] | None:
    """Whole-drive IRI of a profile (left, right) from its per-segment IRI (columns
    ``{prefix}_left/right_m_per_km``; one quarter-car run instead of two): the mean over the
    segments weighted by their slope intervals (:func:`~.iri.interval_counts`); computed
    afresh (:func:`_whole_iri`) when the segments do not give it."""
    start, end = segments.get('start_m'), segments.get('end_m')
    if z is None or start is None or len(start) == 0 or not np.isfinite(z).all():
        return _whole_iri(x, z)
    try:
        counts = iri_mod.interval_counts(x, np.concatenate([start, end[-1:]]))
    except ValueError:
        return _whole_iri(x, z)
    values = np.column_stack([segments[f'{prefix}_left_m_per_km'],
                              segments[f'{prefix}_right_m_per_km']])
    used = counts > 0
    if counts.sum() == 0 or not np.isfinite(values[used]).all():
        return _whole_iri(x, z)
    return _floats(values[used].T @ counts[used] / counts.sum())


def summarize(est, drive=None, vehicle: VehicleParameters | None = None,
              observer: ObserverParameters | None = None, *, mode: str = 'online',
              input_name: str = '', reference=None, reference_offset_m: float | None = None,
              segment_length_m: float = DEFAULT_SEGMENT_LENGTH_M,
              extra: dict[str, Any] | None = None) -> tuple[dict[str, Any], dict, Aligned]:
    """The report's numbers: ``(summary, segments, aligned)``.

    Parameters
    ----------
    est : EstimateArrays (or the offline mode's)
    drive : road_force_estimator.bagio.Drive, optional
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
        default: the offset within +-:data:`REFERENCE_SEARCH_M` that best correlates the
        band-passed profiles.
    segment_length_m : float
        Segment length (m).
    extra : dict, optional
        More counts to show (e.g. samples whose speed was taken from the first twist).
    """
    vehicle = VehicleParameters() if vehicle is None else vehicle
    observer = ObserverParameters() if observer is None else observer
    al = align(est, drive, reference, reference_offset_m)
    st = est.status
    rejected: dict[str, dict[str, int]] = {}
    for topic, reasons in sorted((getattr(drive, 'rejected', None) or {}).items()):
        rejected[topic] = {r: int(c) for r, c in sorted(reasons.items()) if c}
    core = {'nonfinite': st.rejected_nonfinite, 'out_of_range': st.rejected_range,
            'duplicate_or_backwards_stamp': st.rejected_time}
    core = {k: int(v) for k, v in core.items() if v}
    if core:
        rejected['estimator'] = core
    conv_rows = np.flatnonzero(al.reported_converged)
    summary: dict[str, Any] = {
        'input': input_name,
        'mode': mode,
        'messages': dict(sorted((getattr(drive, 'messages', None) or {}).items())),
        'samples': {
            'input': int(len(est.stamp_ns)),
            'estimated': int(st.accepted),
            'converged': int(conv_rows.size),
        },
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
        'lift_off_samples': int(np.count_nonzero(np.asarray(est.lift_off)[al.rows].any(axis=1))),
        'max_abs_ltr': float(np.max(np.abs(al.pick(est, 'ltr')))) if al.rows.size else 0.0,
        'fixes': int(len(drive.fixes.stamps_ns)) if getattr(drive, 'fixes', None) else 0,
        'has_ground_truth': al.true_load_n is not None,
        'reference_profile': al.reference_name or None,
        'reference_offset_m': al.reference_offset_m,
        'segment_length_m': float(segment_length_m),
        'parameters': {**vehicle.to_parameters(), **observer.to_parameters()},
    }
    if extra:
        summary['notes'] = dict(extra)
    for key in ('noise_std', 'cutoff_hz'):
        if hasattr(est, key):
            summary.setdefault('offline', {})[key] = _floats(getattr(est, key))
    summary['accuracy'] = accuracy(est, al, vehicle)
    up = al.increasing()
    segments = drive_segments(est, al, drive, segment_length_m=segment_length_m)
    iri_est = iri_true = None
    if np.count_nonzero(up) >= 2:
        x = al.x_m[up]
        iri_est = _whole_from_segments(x, al.pick(est, 'road_m')[up], segments, 'iri')
        truth = al.profile_truth
        if truth is not None:
            iri_true = _whole_from_segments(x, truth[up], segments, 'true_iri')
    summary['iri_m_per_km'] = {'estimated': iri_est, 'true': iri_true}
    summary['segments'] = int(len(segments['start_m']))
    return summary, segments, al


# ----------------------------------------------------------------------------------------------
# files

def _cell(value) -> str:
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value)).lower()
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    v = float(value)
    return 'nan' if math.isnan(v) else repr(v)


def write_segments_csv(path: str | Path, segments: dict[str, np.ndarray]) -> None:
    """``segments.csv``: a header of :data:`SEGMENT_COLUMNS`, one row per segment (exact
    numbers, ``nan`` where unknown)."""
    with Path(path).open('w', newline='') as f:
        w = csv.writer(f, lineterminator='\n')
        w.writerow(SEGMENT_COLUMNS)
        n = len(segments['start_m'])
        for i in range(n):
            w.writerow([_cell(segments[c][i]) for c in SEGMENT_COLUMNS])


def _fmt(v, digits: int = 2) -> str:
    if v is None:
        return 'n/a'
    if isinstance(v, (list, tuple)):
        return ' / '.join(_fmt(x, digits) for x in v)
    if isinstance(v, (bool, np.bool_)):
        return 'yes' if v else 'no'
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    v = float(v)
    if math.isnan(v):
        return 'n/a'
    if math.isinf(v):
        return 'never' if v > 0 else '-inf'
    return f'{v:.{digits}f}'


def _segment_markdown(segments: dict[str, np.ndarray]) -> list[str]:
    n = len(segments['start_m'])
    if n == 0:
        return ['No segment: the drive covers no distance.']
    have_true = np.isfinite(segments['true_iri_left_m_per_km']).any()
    have_fix = np.isfinite(segments['start_lat']).any()
    head = ['from (m)', 'to (m)', 'IRI L (m/km)', 'IRI R (m/km)']
    if have_true:
        head += ['true IRI L', 'true IRI R']
    head += ['DLC L', 'DLC R', 'peak L (kN)', 'peak R (kN)', 'max abs LTR', 'lift-offs']
    if have_fix:
        head += ['start lat, lon', 'end lat, lon']
    lines = ['| ' + ' | '.join(head) + ' |', '|' + '---|' * len(head)]
    for i in range(n):
        s = {k: segments[k][i] for k in SEGMENT_COLUMNS}
        row = [_fmt(s['start_m'], 1), _fmt(s['end_m'], 1), _fmt(s['iri_left_m_per_km']),
               _fmt(s['iri_right_m_per_km'])]
        if have_true:
            row += [_fmt(s['true_iri_left_m_per_km']), _fmt(s['true_iri_right_m_per_km'])]
        row += [_fmt(s['dlc_left'], 3), _fmt(s['dlc_right'], 3),
                _fmt(s['peak_load_left_n'] / 1e3, 1), _fmt(s['peak_load_right_n'] / 1e3, 1),
                _fmt(s['max_abs_ltr'], 3), str(int(s['lift_offs']))]
        if have_fix:
            row += [f'{_fmt(s["start_lat"], 6)}, {_fmt(s["start_lon"], 6)}',
                    f'{_fmt(s["end_lat"], 6)}, {_fmt(s["end_lon"], 6)}']
        lines.append('| ' + ' | '.join(row) + ' |')
    return lines


def write_markdown(path: str | Path, summary: dict[str, Any], segments: dict[str, np.ndarray],
                   figures: list[str]) -> None:
    """``report.md`` from :func:`summarize`'s results."""
    s = summary
    lines = [f'# Estimate report: {s["input"] or "drive"}', '',
             f'Mode **{s["mode"]}** ({"causal, what the observer node publishes" if s["mode"] == "online" else "non-causal, the whole recording"}); '  # noqa: E501
             f'{s["samples"]["estimated"]} samples estimated over {_fmt(s["duration_s"])} s and '
             f'{_fmt(s["distance_m"], 1)} m.', '', '## Summary', '',
             '| item | value |', '|---|---|']
    smp = s['samples']
    rows = [('deflection samples in the input (accepted by the reader)', smp['input']),
            ('samples estimated', smp['estimated']),
            ('samples rejected (all topics and the estimator)', s['rejected_total']),
            ('restarts (gaps)', f'{s["resets"]} ({s["gaps"]})'),
            ('settling time of the estimator (s)', _fmt(s['settling_time_s'], 3)),
            ('first converged sample (s)', _fmt(s['first_converged_s'], 3)),
            ('converged samples', smp['converged']),
            ('samples with a wheel lifted off', s['lift_off_samples']),
            ('max abs LTR', _fmt(s['max_abs_ltr'], 3)),
            ('GNSS fixes', s['fixes']),
            ('IRI of the estimated profile, left / right (m/km)',
             _fmt(s['iri_m_per_km']['estimated'])),
            ('IRI of the true (or reference) profile, left / right (m/km)',
             _fmt(s['iri_m_per_km']['true']))]
    if s.get('reference_profile'):
        rows += [('reference profile (no ground truth)', s['reference_profile']),
                 ('drive start along the reference (m)', _fmt(s['reference_offset_m'], 3))]
    if 'offline' in s:
        rows += [('offline: noise estimated q1 / q2 (um), phi (mrad)',
                  f'{_fmt([1e6 * v for v in s["offline"]["noise_std"][:2]])}, '
                  f'{_fmt(1e3 * s["offline"]["noise_std"][2], 3)}'),
                 ('offline: low-pass cut-offs q1 / q2 / phi (Hz)',
                  _fmt(s['offline']['cutoff_hz'], 1))]
    for key, value in (s.get('notes') or {}).items():
        rows.append((key, value))
    lines += [f'| {a} | {b} |' for a, b in rows]
    lines += ['', '### Messages and rejections', '', '| topic | messages |', '|---|---|']
    lines += [f'| `{t}` | {c} |' for t, c in s['messages'].items()]
    lines += ['']
    if s['rejected']:
        lines += ['| where | reason | count |', '|---|---|---|']
        for topic, reasons in s['rejected'].items():
            for reason, count in reasons.items():
                lines.append(f'| `{topic}` | {reason} | {count} |')
    else:
        lines.append('Nothing was rejected.')
    if s['issues']:
        lines += ['', 'Breaks found while reading (everything before each break was used):', '']
        lines += [f'- {issue}' for issue in s['issues']]
    acc = s.get('accuracy')
    lines += ['', '## Accuracy', '']
    if not acc:
        lines.append('No ground truth in the bag: accuracy not judged.')
    else:
        lines += ['| figure | left | right | both |', '|---|---|---|---|']
        if 'load_rms_n' in acc:
            lines += [
                f'| wheel-load error RMS (N) | {_fmt(acc["load_rms_n"][0], 0)} | '
                f'{_fmt(acc["load_rms_n"][1], 0)} | |',
                f'| wheel-load error RMS, % of the true dynamic-load RMS | '
                f'{_fmt(acc["load_rms_pct_dynamic"][0])} | {_fmt(acc["load_rms_pct_dynamic"][1])}'
                f' | {_fmt(acc["load_rms_pct_dynamic_both"])} |',
                f'| wheel-load error RMS, % of the static load | '
                f'{_fmt(acc["load_rms_pct_static"][0])} | {_fmt(acc["load_rms_pct_static"][1])}'
                ' | |',
                f'| wheel-load error peak (N) | {_fmt(acc["load_peak_n"][0], 0)} | '
                f'{_fmt(acc["load_peak_n"][1], 0)} | |',
                f'| LTR error RMS / peak | | | {_fmt(acc["ltr_rms_error"], 4)} / '
                f'{_fmt(acc["ltr_peak_error"], 4)} |',
                f'| max abs LTR estimated / true | | | {_fmt(acc["max_abs_ltr"], 3)} / '
                f'{_fmt(acc["max_abs_ltr_true"], 3)} |',
                f'| measured convergence time (s) | | | {_fmt(acc["convergence_s"], 3)} |']
        if 'profile_rms_m' in acc:
            lines += [
                f'| profile error RMS in the 0.5-30 m band (mm) | '
                f'{_fmt(1e3 * acc["profile_rms_m"][0], 3)} | '
                f'{_fmt(1e3 * acc["profile_rms_m"][1], 3)} | |',
                f'| profile error RMS, % of the band-passed '
                f'{"truth" if acc["profile_against"] == "ground truth" else "reference"} | '
                f'{_fmt(acc["profile_rms_pct_band"][0])} | '
                f'{_fmt(acc["profile_rms_pct_band"][1])} | '
                f'{_fmt(acc["profile_rms_pct_band_both"])} |']
        if s.get('judged_from') == 'settling time':
            lines += ['', 'The estimator never reported convergence: samples are judged from '
                      f'its settling time ({_fmt(s["settling_time_s"], 3)} s) on.']
        lines += ['', f'Judged on {acc.get("samples_judged", 0)} converged samples (loads, LTR)'
                  + (f' and {acc["profile_samples_judged"]} profile samples against the '
                     f'{acc["profile_against"]}, 30 m in from each end' if
                     'profile_samples_judged' in acc else '') + '.']
    lines += ['', f'## Segments ({_fmt(s["segment_length_m"], 0)} m)', '',
              'Also in `segments.csv`. DLC = std/mean of the wheel load; lift-offs = events.', '']
    lines += _segment_markdown(segments)
    if figures:
        lines += ['', '## Figures', '']
        for name in figures:
            lines += [f'![{name[:-4]}]({name})', '']
    Path(path).write_text('\n'.join(lines).rstrip() + '\n')


def _json_safe(obj):
    if isinstance(obj, dict):
        return {str(k): _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json_safe(v) for v in obj]
    if isinstance(obj, (np.bool_, bool)):
        return bool(obj)
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        return v if math.isfinite(v) else None
    return obj


# ----------------------------------------------------------------------------------------------
# figures

def _window(al: Aligned, length_s: float) -> np.ndarray:
    """Row mask of a detail window: ``length_s`` from a third of the converged stretch."""
    t = al.t_s
    if t.size == 0:
        return np.zeros(0, bool)
    conv = np.flatnonzero(al.converged)
    lo, hi = (t[conv[0]], t[conv[-1]]) if conv.size else (t[0], t[-1])
    start = lo + max(0.0, (hi - lo - length_s)) / 3.0
    mask = (t >= start) & (t <= start + length_s)
    return mask if np.count_nonzero(mask) >= 2 else np.ones(t.size, bool)


def _legend(ax, **kwargs) -> None:
    """A legend, when the axes have labelled artists."""
    if ax.get_legend_handles_labels()[0]:
        ax.legend(**kwargs)


def _decimate(n: int) -> slice:
    return slice(None, None, max(1, int(math.ceil(n / MAX_OVERVIEW_POINTS))))


def write_figures(folder: str | Path, est, al: Aligned, drive=None, *,
                  segments: dict[str, np.ndarray] | None = None, title: str = '',
                  window_s: float = DEFAULT_WINDOW_S,
                  profile_window_m: float = DEFAULT_PROFILE_WINDOW_M) -> list[str]:
    """Draw the figures of :data:`FIGURES` into ``folder``; the file names written."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    folder = Path(folder)
    if al.rows.size < 2:
        return []
    written = []
    w = _window(al, window_s)
    t = al.t_s[w]
    colors = ('tab:blue', 'tab:red')
    meas_q = meas_phi = None
    if drive is not None and hasattr(drive, 'q_m') and len(drive.q_m) == len(est.stamp_ns):
        meas_q = np.asarray(drive.q_m)[al.rows][w]
        meas_phi = np.asarray(drive.roll_rad)[al.rows][w]

    def finish(fig, name: str, heading: str) -> None:
        fig.suptitle(f'{heading}{" - " + title if title else ""}', fontsize=11)
        fig.tight_layout()
        fig.savefig(folder / name, dpi=110)
        plt.close(fig)
        written.append(name)

    # Figure 5 of the paper: the differentiator states and rates.
    fig, ax = plt.subplots(3, 2, figsize=(11, 8), sharex=True)
    rows = (('q_m', 'dq', 'ddq'), ('roll_rad', 'droll', 'ddroll'))
    labels = (('q (mm)', 'dq (mm/s)', 'ddq (m/s$^2$)'),
              ('phi (mrad)', 'dphi (mrad/s)', 'ddphi (rad/s$^2$)'))
    scales = ((1e3, 1e3, 1.0), (1e3, 1e3, 1.0))
    for col in (0, 1):
        for r in range(3):
            a = ax[r, col]
            y = al.pick(est, rows[col][r])[w] * scales[col][r]
            if col == 0:
                for side in (0, 1):
                    if r == 0 and meas_q is not None:
                        a.plot(t, 1e3 * meas_q[:, side], color=colors[side], lw=0.5, alpha=0.35,
                               label=f'measured {_SIDES[side]}')
                    a.plot(t, y[:, side], color=colors[side], lw=1.0,
                           label=f'estimated {_SIDES[side]}')
            else:
                if r == 0 and meas_phi is not None:
                    a.plot(t, 1e3 * meas_phi, color='0.5', lw=0.5, alpha=0.5, label='measured')
                a.plot(t, y, color='k', lw=1.0, label='estimated')
            a.set_ylabel(labels[col][r])
            a.grid(True, alpha=0.3)
            if r == 0:
                _legend(a, fontsize=7, loc='upper right')
        ax[2, col].set_xlabel('time (s)')
    ax[0, 0].set_title('suspension deflections', fontsize=10)
    ax[0, 1].set_title('roll angle', fontsize=10)
    finish(fig, 'states.png', 'States and rates')

    # Figures 6 and 7: body acceleration and body heave.
    fig, ax = plt.subplots(2, 1, figsize=(11, 6), sharex=True)
    ax[0].plot(t, al.pick(est, 'body_accel_mps2')[w], color='k', lw=1.0)
    ax[0].set_ylabel('dd z_s (m/s$^2$)')
    ax[0].set_title('body heave acceleration', fontsize=10)
    ax[1].plot(t, 1e3 * al.pick(est, 'body_heave_m')[w], color='k', lw=1.0)
    ax[1].set_ylabel('z_s (mm)')
    ax[1].set_title('body heave (band-limited)', fontsize=10)
    ax[1].set_xlabel('time (s)')
    for a in ax:
        a.grid(True, alpha=0.3)
    finish(fig, 'body.png', 'Body acceleration and heave')

    # Figure 8: wheel heaves.
    fig, ax = plt.subplots(2, 1, figsize=(11, 6), sharex=True)
    zu = 1e3 * al.pick(est, 'wheel_heave_m')[w]
    acc_u = al.pick(est, 'wheel_accel_mps2')[w]
    for side in (0, 1):
        ax[0].plot(t, zu[:, side], color=colors[side], lw=1.0, label=_SIDES[side])
        ax[1].plot(t, acc_u[:, side], color=colors[side], lw=0.8, label=_SIDES[side])
    ax[0].set_ylabel('z_u (mm)')
    ax[0].set_title('wheel heaves (band-limited)', fontsize=10)
    ax[1].set_ylabel('dd z_u (m/s$^2$)')
    ax[1].set_title('wheel accelerations', fontsize=10)
    ax[1].set_xlabel('time (s)')
    for a in ax:
        a.grid(True, alpha=0.3)
        _legend(a, fontsize=7, loc='upper right')
    finish(fig, 'wheels.png', 'Wheel heaves')

    # Figure 9: the band-passed profile against the truth or the reference.
    up = al.increasing()
    x = al.x_m[up]
    road = al.pick(est, 'road_m')[up]
    truth = al.profile_truth
    truth_up = truth[up] if truth is not None else None
    if truth_up is not None and not np.isfinite(truth_up).all():
        ok = np.isfinite(truth_up).all(axis=1)
        truth_up = (np.column_stack([np.interp(x, x[ok], truth_up[ok, i]) for i in (0, 1)])
                    if ok.sum() >= 2 else None)
    bp_est = _bandpass(x, road)
    bp_true = _bandpass(x, truth_up) if truth_up is not None else None
    against = 'truth' if al.true_road_m is not None else (al.reference_name or 'reference')
    fig, ax = plt.subplots(2, 1, figsize=(11, 6), sharex=True)
    conv_x = x[al.converged[up]] if al.converged[up].any() else x
    x0 = conv_x[0] + max(0.0, conv_x[-1] - conv_x[0] - profile_window_m) / 3.0
    pw = (x >= x0) & (x <= x0 + profile_window_m)
    for side in (0, 1):
        a = ax[side]
        if bp_est is not None:
            if bp_true is not None:
                a.plot(x[pw], 1e3 * bp_true[pw, side], color='0.4', lw=1.6, label=against)
            a.plot(x[pw], 1e3 * bp_est[pw, side], color=colors[side], lw=1.0,
                   label='estimated')
            a.set_ylabel('elevation, 0.5-30 m band (mm)', fontsize=8)
        else:
            a.plot(x[pw], 1e3 * road[pw, side], color=colors[side], lw=1.0, label='estimated')
            a.set_ylabel('elevation (mm)')
        a.set_title(f'{_SIDES[side]} wheel path', fontsize=10)
        a.grid(True, alpha=0.3)
        _legend(a, fontsize=7, loc='upper right')
    ax[1].set_xlabel('distance (m)')
    finish(fig, 'profile.png', 'Road profile')

    # Figure 10: wheel loads and LTR against the truth.
    fig, ax = plt.subplots(3, 1, figsize=(11, 8), sharex=True)
    load = al.pick(est, 'wheel_load_n')[w] / 1e3
    true = al.true_load_n[w] / 1e3 if al.true_load_n is not None else None
    for side in (0, 1):
        a = ax[side]
        if true is not None:
            a.plot(t, true[:, side], color='0.4', lw=1.6, label='truth')
        a.plot(t, load[:, side], color=colors[side], lw=1.0, label='estimated')
        a.set_ylabel(f'F_n {_SIDES[side]} (kN)')
        _legend(a, fontsize=7, loc='upper right')
    ltr = al.pick(est, 'ltr')[w]
    if true is not None:
        ax[2].plot(t, (true[:, 1] - true[:, 0]) / (true[:, 0] + true[:, 1]), color='0.4',
                   lw=1.6, label='truth')
    ax[2].plot(t, ltr, color='k', lw=1.0, label='estimated')
    ax[2].set_ylabel('LTR')
    _legend(ax[2], fontsize=7, loc='upper right')
    ax[2].set_xlabel('time (s)')
    for a in ax:
        a.grid(True, alpha=0.3)
    finish(fig, 'loads.png', 'Vertical wheel loads and load transfer ratio')

    # Overview: the whole drive.
    fig, ax = plt.subplots(3, 1, figsize=(11, 9))
    d = _decimate(al.rows.size)
    tt = al.t_s[d]
    if al.true_load_n is not None:
        tl = al.true_load_n[d]
        ax[0].plot(tt, (tl[:, 1] - tl[:, 0]) / (tl[:, 0] + tl[:, 1]), color='0.4', lw=0.6,
                   label='truth')
    ax[0].plot(tt, al.pick(est, 'ltr')[d], color='k', lw=0.4, label='estimated')
    ax[0].set_ylabel('LTR')
    ax[0].set_xlabel('time (s)')
    ax[0].set_title('load transfer ratio over the drive (|LTR| = 1: a wheel lifts off)',
                    fontsize=10)
    _legend(ax[0], fontsize=7, loc='upper right')
    dx = _decimate(x.size)
    if bp_est is not None:
        if bp_true is not None:
            ax[1].plot(x[dx], 1e3 * bp_true[dx, 0], color='0.4', lw=0.6, label=f'{against} left')
        ax[1].plot(x[dx], 1e3 * bp_est[dx, 0], color=colors[0], lw=0.5, label='estimated left')
        ax[1].set_ylabel('left, 0.5-30 m band (mm)', fontsize=8)
    ax[1].set_xlabel('distance (m)')
    ax[1].set_title('road profile over the drive', fontsize=10)
    _legend(ax[1], fontsize=7, loc='upper right')
    if segments is not None and len(segments['start_m']):
        mid = 0.5 * (segments['start_m'] + segments['end_m'])
        width = 0.2 * float(np.min(segments['end_m'] - segments['start_m']))
        offsets = ((-1.5, 'iri_left_m_per_km', colors[0], 'estimated left'),
                   (-0.5, 'iri_right_m_per_km', colors[1], 'estimated right'),
                   (0.5, 'true_iri_left_m_per_km', '0.3', f'{against} left'),
                   (1.5, 'true_iri_right_m_per_km', '0.6', f'{against} right'))
        for off, key, color, label in offsets:
            if np.isfinite(segments[key]).any():
                ax[2].bar(mid + off * width, segments[key], width=width, color=color,
                          label=label)
        top = np.nanmax([np.nanmax(segments[k]) if np.isfinite(segments[k]).any() else 0.0
                         for _, k, _, _ in offsets])
        ax[2].set_ylim(0.0, 1.4 * top if top > 0.0 else 1.0)
        ax[2].set_ylabel('IRI (m/km)')
        ax[2].set_xlabel('segment centre (m)')
        ax[2].set_title('IRI per segment', fontsize=10)
        _legend(ax[2], fontsize=7, loc='upper right', ncol=2)
    for a in ax:
        a.grid(True, alpha=0.3)
    finish(fig, 'overview.png', 'The whole drive')
    return written


def write_report(folder: str | Path, est, drive=None, vehicle: VehicleParameters | None = None,
                 observer: ObserverParameters | None = None, *, mode: str = 'online',
                 input_name: str = '', reference=None, reference_offset_m: float | None = None,
                 segment_length_m: float = DEFAULT_SEGMENT_LENGTH_M, figures: bool = True,
                 extra: dict[str, Any] | None = None) -> dict[str, Any]:
    """Write the report folder (see the module notes); returns the summary.

    Parameters are those of :func:`summarize`, plus ``folder`` (created if needed) and
    ``figures`` (False: numbers and tables only).
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    summary, segments, al = summarize(
        est, drive, vehicle, observer, mode=mode, input_name=input_name, reference=reference,
        reference_offset_m=reference_offset_m, segment_length_m=segment_length_m, extra=extra)
    names: list[str] = []
    if figures:
        names = write_figures(folder, est, al, drive, segments=segments,
                              title=f'{input_name} ({mode})' if input_name else mode)
    summary['figures'] = names
    write_segments_csv(folder / 'segments.csv', segments)
    write_markdown(folder / 'report.md', summary, segments, names)
    (folder / 'report.json').write_text(json.dumps(_json_safe(summary), indent=2) + '\n')
    return summary
