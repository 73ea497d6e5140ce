"""The whole vehicle in a drive's report (an articulated drive, MODEL.md "The whole vehicle"):
its truth, and with articulated parameters its estimate (:func:`append_estimate`).

From the drive's ``/ground_truth/wheel_loads`` and ``/ground_truth/load_transfer/*``: per
wheel the static load the drive was simulated with, the mean, lowest and highest load, the
dynamic load's RMS, the DLC (std / mean) and the samples at zero load (lift-off); per axle
and for the gross vehicle weight the sums of the static loads; per unit the largest |LTR| and
|quasi-static LTR|. ``report.md`` gains the section "The whole vehicle (ground truth)",
``report.json`` the key ``whole_vehicle``, the folder ``axles.csv`` (one row per wheel).

The estimate (:func:`summarize_estimate`, over the converged samples): per axle the static
load and the gross vehicle weight (the mean of the static loads' sums), per wheel the mean and
peak load and the DLC, per unit the largest |LTR| and |quasi-static LTR|; with the truth per
wheel the RMS of the load error in % of the true dynamic load's RMS (about the drive's static
load) and the trailer's quasi-static LTR error (RMS and largest), at the stamps both have;
the model fit per axle (:mod:`~.estimation.axle_fit`: which axle or sensor does not
fit).
``report.md`` gains "The whole vehicle (estimate)", ``report.json`` the key
``whole_vehicle_estimate``, ``segments.csv`` the columns :func:`segment_columns` names
(INTERFACES.md "The whole vehicle").
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from road_force_estimator.core.parameters import GRAVITY_MPS2
from road_force_estimator.report.folder import csv_cell, json_safe

__all__ = ['summarize_truth', 'truth_markdown', 'append_to_report', 'AXLE_COLUMNS',
           'summarize_estimate', 'estimate_markdown', 'segment_columns', 'segment_table',
           'column_decimals',
           'append_estimate']

#: Columns of axles.csv.
AXLE_COLUMNS = ('wheel', 'axle', 'body', 'static_load_n', 'mean_load_n', 'min_load_n',
                'max_load_n', 'dynamic_rms_n', 'dlc', 'lift_off_samples')
_UNITS = ('tractor', 'trailer', 'combination')


def summarize_truth(truth) -> dict[str, Any]:
    """The numbers of the section from an :class:`~.bagio.articulated_drive.ArticulatedTruth`
    (any object with its attributes)."""
    loads = np.asarray(truth.wheel_load_n, float)
    static = np.asarray(truth.static_load_n, float)
    names = list(truth.wheel_names)
    axles = list(truth.axle_names)
    bodies = list(truth.axle_bodies) if truth.axle_bodies else [''] * len(axles)
    wheels = []
    for i, name in enumerate(names):
        col = loads[:, i]
        mean = float(np.mean(col)) if col.size else float('nan')
        std = float(np.std(col)) if col.size else float('nan')
        dyn = col - (static[i] if np.isfinite(static[i]) else mean)
        wheels.append({'wheel': name, 'axle': axles[i // 2], 'body': bodies[i // 2],
                       'static_load_n': float(static[i]), 'mean_load_n': mean,
                       'min_load_n': float(np.min(col)) if col.size else float('nan'),
                       'max_load_n': float(np.max(col)) if col.size else float('nan'),
                       'dynamic_rms_n': float(np.sqrt(np.mean(dyn ** 2))) if col.size
                       else float('nan'),
                       'dlc': std / mean if mean > 0.0 else float('nan'),
                       'lift_off_samples': int(np.count_nonzero(col <= 0.0))})
    axle_static = [float(static[2 * j] + static[2 * j + 1]) for j in range(len(axles))]
    ltr = np.asarray(truth.unit_ltr, float)
    units = {}
    for u, unit in enumerate(_UNITS):
        x, y = ltr[:, 2 * u], ltr[:, 2 * u + 1]
        units[unit] = {'max_abs_ltr': _nanmax_abs(x), 'max_abs_ltr_quasi_static':
                       _nanmax_abs(y)}
    return {'samples': int(loads.shape[0]), 'wheels': wheels,
            'axle_static_load_t': [a / GRAVITY_MPS2 / 1000.0 for a in axle_static],
            'axles': axles, 'axle_bodies': bodies,
            'gross_weight_t': float(np.nansum(static)) / GRAVITY_MPS2 / 1000.0
            if np.isfinite(static).all() else float('nan'),
            'units': units, 'rejected': truth.rejected}


def _nanmax_abs(a: np.ndarray) -> float:
    a = a[np.isfinite(a)]
    return float(np.max(np.abs(a))) if a.size else float('nan')


def truth_markdown(s: dict[str, Any], estimated: bool = False) -> list[str]:
    """The report section (markdown lines); ``estimated``: the whole vehicle's estimate is in
    the report too."""
    what = ("the whole vehicle's estimate is in the section before" if estimated else
            "the estimate above is the front axle's (a front-axle tool reads an articulated "
            "drive's front axle); the other axles have no estimate")
    lines = ['', '## The whole vehicle (ground truth)', '',
             f'The drive\'s truth for every axle ({s["samples"]} samples): {what}. Also in '
             '`axles.csv`.', '',
             '| axle | body | static load (t) |', '|---|---|---|']
    for axle, body, t in zip(s['axles'], s['axle_bodies'], s['axle_static_load_t']):
        lines.append(f'| {axle} | {body or "?"} | {t:.2f} |')
    lines += [f'| gross vehicle weight | | {s["gross_weight_t"]:.2f} |', '',
              '| wheel | static (kN) | mean (kN) | min (kN) | max (kN) | dynamic RMS (kN) | '
              'DLC | lift-off samples |', '|---|---|---|---|---|---|---|---|']
    for w in s['wheels']:
        lines.append(f'| {w["wheel"]} | {w["static_load_n"] / 1e3:.2f} | '
                     f'{w["mean_load_n"] / 1e3:.2f} | {w["min_load_n"] / 1e3:.2f} | '
                     f'{w["max_load_n"] / 1e3:.2f} | {w["dynamic_rms_n"] / 1e3:.2f} | '
                     f'{w["dlc"]:.3f} | {w["lift_off_samples"]} |')
    lines += ['', '| unit | max abs LTR | max abs quasi-static LTR |', '|---|---|---|']
    for unit, u in s['units'].items():
        lines.append(f'| {unit} | {u["max_abs_ltr"]:.3f} | {u["max_abs_ltr_quasi_static"]:.3f} |')
    return lines


def append_to_report(folder: str | Path, truth, summary: dict[str, Any] | None = None,
                     estimated: bool = False) -> dict[str, Any]:
    """Add the section to the report folder (``report.md``, ``report.json``, ``axles.csv``);
    the section's numbers (also put in ``summary['whole_vehicle']`` when given)."""
    folder = Path(folder)
    s = summarize_truth(truth)
    with open(folder / 'axles.csv', 'w') as out:
        out.write(','.join(AXLE_COLUMNS) + '\n')
        for w in s['wheels']:
            out.write(','.join(csv_cell(w[c]) for c in AXLE_COLUMNS) + '\n')
    _append_section(folder, 'whole_vehicle', s, truth_markdown(s, estimated), summary)
    return s


def _append_section(folder: Path, key: str, s: dict[str, Any], lines: list[str],
                    summary: dict[str, Any] | None) -> None:
    """A section's ``lines`` at the end of ``report.md`` and its numbers ``s`` under ``key``
    in ``report.json`` (the files that exist) and in ``summary`` (when given)."""
    md = folder / 'report.md'
    if md.exists():
        md.write_text(md.read_text().rstrip('\n') + '\n' + '\n'.join(lines) + '\n')
    js = folder / 'report.json'
    if js.exists():
        data = json.loads(js.read_text())
        data[key] = json_safe(s)
        js.write_text(json.dumps(data, indent=2) + '\n')
    if summary is not None:
        summary[key] = s


def segment_columns(axle_names) -> tuple[str, ...]:
    """The whole vehicle's columns of ``segments.csv`` (INTERFACES.md), after the front
    axle's: per axle ``peak_load_<axle>_left_n`` / ``_right_n``, ``dlc_<axle>_left`` /
    ``_right``, ``static_load_<axle>_n``, then ``gross_weight_n`` and
    ``max_abs_ltr_trailer_quasi_static``."""
    cols: list[str] = []
    for a in axle_names:
        cols += [f'peak_load_{a}_left_n', f'peak_load_{a}_right_n', f'dlc_{a}_left',
                 f'dlc_{a}_right', f'static_load_{a}_n']
    return tuple(cols) + ('gross_weight_n', 'max_abs_ltr_trailer_quasi_static')


def column_decimals(name: str) -> int:
    """Decimals of a whole-vehicle column in ``segments.csv``: 1 N of load, 1e-4 of DLC and
    LTR."""
    return 4 if name.startswith(('dlc_', 'max_abs_ltr')) else 0


def _source(wv):
    """``wv`` as a source of rows (``n``, ``meta``, ``rows(lo, hi)``): itself, or its arrays'
    (:class:`~.estimation.whole_vehicle.ArraysRows`)."""
    from road_force_estimator.estimation.whole_vehicle import ArraysRows

    return wv if hasattr(wv, 'rows') else ArraysRows(wv)


#: The samples the report's sums take at a time (the same bits however many: they add in
#: sample order).
SUM_ROWS = 1 << 16


def segment_table(wv, start_m, end_m, rows: int | None = None) -> dict[str, np.ndarray]:
    """The columns of :func:`segment_columns` for the segments ``[start_m, end_m)`` (the last
    one's end inclusive) from the converged samples of ``wv`` (a
    :class:`~.estimation.whole_vehicle.WholeVehicleArrays`, or a source of its rows read
    ``rows`` samples at a time, :data:`SUM_ROWS` by default) by their distance (the front
    axle's, m): peak load and DLC
    (std / mean) per wheel, mean static axle load and gross weight, largest |quasi-static
    LTR| of the trailer; NaN in a segment without a sample. Every sample counts, converged
    or not, as in the front axle's columns. The sums add in sample order (``np.bincount``
    continued from piece to piece: the same bits in one piece or many)."""
    source = _source(wv)
    rows = max(int(rows or SUM_ROWS), 1)
    start = np.asarray(start_m, float)
    end = np.asarray(end_m, float)
    k = start.size
    names = source.meta.axle_names
    if k == 0:
        return {c: np.zeros(0) for c in segment_columns(names)}
    wheels = 2 * len(names)
    counts = np.zeros(k, np.int64)
    total = np.zeros((wheels, k))
    square = np.zeros((wheels, k))
    static = np.zeros((len(names), k))
    gross = np.zeros(k)
    peak = np.full((wheels, k), np.nan)
    peak_qs = np.full(k, np.nan)
    bins = np.arange(k)

    def add(acc: np.ndarray, seg: np.ndarray, values: np.ndarray) -> None:
        acc[:] = np.bincount(np.concatenate([bins, seg]), np.concatenate([acc, values]),
                             minlength=k)

    for lo in range(0, source.n, rows):
        part = source.rows(lo, min(lo + rows, source.n))
        x = np.asarray(part.distance_m, float)
        use = np.isfinite(x)
        x = x[use]
        seg = np.searchsorted(start, x, side='right') - 1
        inside = (seg >= 0) & np.where(seg == k - 1, x <= end[-1],
                                       x < end[np.clip(seg, 0, k - 1)])
        seg = seg[inside]
        if not seg.size:
            continue
        at = np.flatnonzero(use)[inside]     # one wheel's row at a time (no (wheels, m) copy)
        loads = np.asarray(part.load_n, float)
        st = np.asarray(part.static_n, float)
        counts += np.bincount(seg, minlength=k)
        for i in range(wheels):
            f = loads[i, at]
            np.fmax.at(peak[i], seg, f)
            add(total[i], seg, f)
            add(square[i], seg, f * f)
        for j in range(len(names)):
            add(static[j], seg, st[2 * j, at] + st[2 * j + 1, at])
        add(gross, seg, _wheel_sum(st, at))
        np.fmax.at(peak_qs, seg, np.abs(np.asarray(part.ltr_quasi_static, float)[1, at]))
    table: dict[str, np.ndarray] = {}

    def mean(sums: np.ndarray) -> np.ndarray:
        with np.errstate(invalid='ignore', divide='ignore'):
            return np.where(counts > 0, sums / counts, np.nan)

    for j, a in enumerate(names):
        for side, word in enumerate(('left', 'right')):
            i = 2 * j + side
            m = mean(total[i])
            with np.errstate(invalid='ignore', divide='ignore'):
                std = np.sqrt(np.maximum(mean(square[i]) - m * m, 0.0))
                table[f'dlc_{a}_{word}'] = np.where(counts > 1, std / m, np.nan)
            table[f'peak_load_{a}_{word}_n'] = peak[i]
        table[f'static_load_{a}_n'] = mean(static[j])
    table['gross_weight_n'] = mean(gross)
    table['max_abs_ltr_trailer_quasi_static'] = peak_qs
    return {c: table[c] for c in segment_columns(names)}


def _wheel_sum(static: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """``static[:, rows].sum(axis=0)`` (the same bits: the same additions in the same order)
    a block of samples at a time (no (wheels, m) copy)."""
    out = np.empty(rows.size)
    for r0 in range(0, rows.size, 1 << 16):
        out[r0:r0 + (1 << 16)] = static[:, rows[r0:r0 + (1 << 16)]].sum(axis=0)
    return out


def _append_segments_csv(path: Path, wv) -> dict[str, np.ndarray]:
    """Add the whole vehicle's columns to ``segments.csv`` (its segments' bounds)."""
    import csv

    with path.open(newline='') as f:
        rows = list(csv.reader(f))
    header, body = rows[0], rows[1:]
    start = [float(r[header.index('start_m')]) for r in body]
    end = [float(r[header.index('end_m')]) for r in body]
    table = segment_table(wv, start, end)
    names = list(table)
    with path.open('w', newline='') as f:
        w = csv.writer(f, lineterminator='\n')
        w.writerow(header + names)
        for i, r in enumerate(body):
            w.writerow(r + [csv_cell(table[c][i], column_decimals(c)) for c in names])
    return table


def _ordered_sum(total: float, values: np.ndarray) -> float:
    """``total`` plus ``values`` added one by one in order (``np.cumsum``: the same bits
    however the values are cut into pieces)."""
    if not values.size:
        return total
    return float(np.cumsum(np.concatenate([[total], values]))[-1])


def summarize_estimate(wv, truth=None, rows: int | None = None) -> dict[str, Any]:
    """The numbers of the estimate's section from ``wv`` (a
    :class:`~.estimation.whole_vehicle.WholeVehicleArrays`, or a source of its rows read
    ``rows`` samples at a time, :data:`SUM_ROWS` by default) and, when given, the drive's
    :class:`~.bagio.articulated_drive.ArticulatedTruth` (its accuracy at the shared stamps).
    Means and spreads from sums in sample order (:func:`_ordered_sum`; the spread
    ``sqrt(mean(f^2) - mean(f)^2)``): the same bits in one piece or many."""
    from road_force_estimator.estimation.whole_vehicle import UNITS
    from road_force_estimator.interfaces import wheel_joints

    source = _source(wv)
    rows = max(int(rows or SUM_ROWS), 1)
    meta = source.meta
    names = wheel_joints(meta.axle_names)
    axles = list(meta.axle_names)
    nw = len(names)
    n_use = 0
    total = [0.0] * nw
    square = [0.0] * nw
    static = [0.0] * nw
    axle_total = [0.0] * len(axles)
    peak = [-np.inf] * nw
    ltr_max = {u: [np.nan, np.nan] for u in UNITS}
    codes_seen: dict[int, int] = {}
    has_codes = False
    gaps = 0
    check = (truth is not None and len(truth.stamps_ns)
             and tuple(truth.wheel_names) == names)
    acc = _AccuracySums(truth, nw) if check else None
    for lo in range(0, source.n, rows):
        part = source.rows(lo, min(lo + rows, source.n))
        use = np.asarray(part.converged, bool)
        n_use += int(np.count_nonzero(use))
        loads = np.asarray(part.load_n, float)     # one wheel's row at a time
        st = np.asarray(part.static_n, float)
        for i in range(nw):
            f = loads[i, use]
            total[i] = _ordered_sum(total[i], f)
            square[i] = _ordered_sum(square[i], f * f)
            static[i] = _ordered_sum(static[i], st[i, use])
            if f.size:                        # a NaN load stays NaN (as np.max's)
                peak[i] = float(np.maximum(peak[i], np.max(f)))
        for j in range(len(axles)):
            axle_total[j] = _ordered_sum(axle_total[j], st[2 * j, use] + st[2 * j + 1, use])
        for k, u in enumerate(UNITS):
            for c, field in enumerate((part.ltr, part.ltr_quasi_static)):
                ltr_max[u][c] = float(np.fmax(ltr_max[u][c], _nanmax_abs(
                    np.asarray(field, float)[k, use])))
        codes = getattr(part, 'imu_codes', None)
        if codes is not None:
            has_codes = True
            for c in np.unique(codes).tolist():
                codes_seen[c] = codes_seen.get(c, 0) + int(np.count_nonzero(codes == c))
        if getattr(part, 'gaps', None) is not None and part.gaps.size:
            gaps = int(part.gaps[-1])
        if acc is not None:
            acc.add(part, use)
    nan = float('nan')
    axle_static = [t / n_use if n_use else nan for t in axle_total]
    wheels = []
    for i, name in enumerate(names):
        mean = total[i] / n_use if n_use else nan
        spread = math.sqrt(max(square[i] / n_use - mean * mean, 0.0)) if n_use else nan
        wheels.append({'wheel': name, 'axle': axles[i // 2],
                       'static_load_n': static[i] / n_use if n_use else nan,
                       'mean_load_n': mean,
                       'max_load_n': peak[i] if n_use else nan,
                       'dlc': spread / mean if n_use and mean > 0.0 else nan})
    units = {u: {'max_abs_ltr': ltr_max[u][0], 'max_abs_ltr_quasi_static': ltr_max[u][1]}
             for u in UNITS}
    out: dict[str, Any] = {
        'samples': int(source.n), 'converged': n_use,
        'axles': axles, 'axle_bodies': list(meta.axle_bodies),
        'axle_static_load_n': axle_static,
        'gross_weight_n': float(np.sum(axle_static)), 'wheels': wheels, 'units': units,
        'gaps': gaps}
    if has_codes or getattr(meta, 'imu_codes', None) is not None:
        # the tractor IMU's pairing (:mod:`~.estimation.imu_hold`)
        from road_force_estimator.estimation.imu_hold import IMU_MAX_AGE_S, STATES
        out['tractor_imu'] = {'max_age_s': IMU_MAX_AGE_S, **{
            w: codes_seen.get(c, 0) for c, w in enumerate(STATES)}}
    fit = getattr(meta, 'axle_fit', None)
    if fit is not None and fit.measured:
        from road_force_estimator.estimation.axle_fit import ONLINE_THRESHOLD, THRESHOLD
        fits = [f for _, f in getattr(meta, 'axle_fits', ())]    # online: every verdict
        out['model_fit'] = {'verdict': 'mismatch' if fit.culprits else 'ok',
                            'culprits': list(fit.culprits),
                            'threshold': (fit.threshold if math.isfinite(fit.threshold)
                                          else ONLINE_THRESHOLD if fits else THRESHOLD),
                            'length_m': float(fit.length_m),
                            'misfit': dict(zip(fit.axle_names,
                                               (float(m) for m in fit.axle_misfit))),
                            'online_verdicts': len(fits),
                            'online_mismatches': sum(bool(f.culprits) for f in fits)}
    friction = getattr(meta, 'friction_velocity', None)     # offline, tanh friction stated
    if friction is not None:
        out['friction_velocity'] = friction.as_dict()
    if acc is not None:
        out['accuracy'] = acc.result(names)
    return out


class _AccuracySums:
    """Per wheel the RMS load error (% of the true dynamic load's RMS: about the truth's
    static load, else its mean) and the trailer's quasi-static LTR error, over the converged
    samples whose stamps the truth has, from sums in sample order piece by piece."""

    def __init__(self, truth, wheels: int) -> None:
        self.truth = truth
        self.static = np.asarray(truth.static_load_n, float)
        self.samples = 0
        self.err = [0.0] * wheels
        self.dyn = [0.0] * wheels            # about the static load, where it is finite
        self.true_total = [0.0] * wheels
        self.true_square = [0.0] * wheels
        self.d2 = 0.0
        self.d_n = 0
        self.d_max = float('nan')

    def add(self, wv, use: np.ndarray) -> None:
        truth = self.truth
        stamps = np.asarray(wv.stamps_ns, np.int64)
        at = np.clip(np.searchsorted(truth.stamps_ns, stamps), 0, len(truth.stamps_ns) - 1)
        hit = use & (np.asarray(truth.stamps_ns)[at] == stamps)
        est = np.asarray(wv.load_n, float)[:, hit]
        true = np.asarray(truth.wheel_load_n, float)[at[hit]].T
        self.samples += int(np.count_nonzero(hit))
        for i in range(est.shape[0]):
            self.err[i] = _ordered_sum(self.err[i], (est[i] - true[i]) ** 2)
            self.true_total[i] = _ordered_sum(self.true_total[i], true[i])
            self.true_square[i] = _ordered_sum(self.true_square[i], true[i] ** 2)
            if np.isfinite(self.static[i]):
                self.dyn[i] = _ordered_sum(self.dyn[i], (true[i] - self.static[i]) ** 2)
        ltr_true = np.asarray(truth.unit_ltr, float)[at[hit], 3]
        ltr_est = np.asarray(wv.ltr_quasi_static, float)[1, hit]
        d = (ltr_est - ltr_true)[np.isfinite(ltr_true)]
        self.d2 = _ordered_sum(self.d2, d ** 2)
        self.d_n += d.size
        self.d_max = float(np.fmax(self.d_max, _nanmax_abs(d)))

    def result(self, names: tuple) -> dict[str, Any]:
        nan = float('nan')
        n = self.samples
        pct = []
        for i in range(len(names)):
            if not n:
                pct.append(nan)
                continue
            if np.isfinite(self.static[i]):
                dyn = math.sqrt(self.dyn[i] / n)
            else:
                mean = self.true_total[i] / n
                dyn = math.sqrt(max(self.true_square[i] / n - mean * mean, 0.0))
            err = math.sqrt(self.err[i] / n)
            pct.append(100.0 * err / dyn if dyn > 0.0 else nan)
        return {'samples': n, 'load_rms_pct_dynamic': dict(zip(names, pct)),
                'ltr_trailer_quasi_static_rms_error': math.sqrt(self.d2 / self.d_n)
                if self.d_n else nan,
                'ltr_trailer_quasi_static_max_error': self.d_max}


def _fused_iri(fused, rows: int | None = None) -> dict[str, Any]:
    """The fused profile's extent and IRI (m/km, left and right; NaN when too short):
    :func:`~.core.iri.iri` of its arrays, or of a spilled one (``n`` points, ``read(lo,
    hi)``: :class:`~.pipeline.whole_vehicle.SpilledFused`) ``rows`` points at a time
    (:data:`SUM_ROWS` by default; :func:`~.core.iri_chunks.profile_iri`: the same bits)."""
    from road_force_estimator.core import iri as iri_mod
    from road_force_estimator.core.iri_chunks import profile_iri

    if hasattr(fused, 'read'):
        n = int(fused.n)
        ends = [fused.read(i, i + 1).distance_m for i in ((0, n - 1) if n else ())]
    else:
        x = np.asarray(fused.distance_m, float)
        n = int(x.size)
        ends = [x[:1], x[-1:]] if n else []
    out: dict[str, Any] = {'axles': int(fused.axles), 'points': n,
                           'length_m': float(ends[1][0] - ends[0][0]) if n else 0.0,
                           'iri_m_per_km': [float('nan')] * 2}
    try:
        if hasattr(fused, 'read'):
            def read(lo, hi):
                f = fused.read(lo, hi)
                return f.distance_m, np.column_stack([f.left_m, f.right_m])

            values = profile_iri(n, read, rows or SUM_ROWS)
        else:
            values = iri_mod.iri(x, np.column_stack([fused.left_m, fused.right_m]))
        out['iri_m_per_km'] = [float(v) for v in values]
    except ValueError:                   # shorter than the quarter car's start
        pass
    return out


def estimate_markdown(s: dict[str, Any]) -> list[str]:
    """The estimate's report section (markdown lines)."""
    lines = ['', '## The whole vehicle (estimate)', '',
             f'Every wheel estimated from `/suspension/deflections` ({s["samples"]} samples, '
             f'{s["converged"]} converged and summarized here; '
             f'{s.get("gaps", 0)} gaps in the stamps, each restarting the estimate); the front '
             "axle's loads and load transfer above are its front wheels. Per segment in "
             '`segments.csv`.', '',
             '| axle | body | static load (kN) |', '|---|---|---|']
    for axle, body, f in zip(s['axles'], s['axle_bodies'], s['axle_static_load_n']):
        lines.append(f'| {axle} | {body} | {f / 1e3:.2f} |')
    lines += [f'| gross vehicle weight | | {s["gross_weight_n"] / 1e3:.2f} |', '']
    acc = s.get('accuracy')
    head = '| wheel | static (kN) | mean (kN) | peak (kN) | DLC |'
    rule = '|---|---|---|---|---|'
    if acc:
        head += ' load error (% of true dynamic RMS) |'
        rule += '---|'
    lines += [head, rule]
    for w in s['wheels']:
        row = (f'| {w["wheel"]} | {w["static_load_n"] / 1e3:.2f} | {w["mean_load_n"] / 1e3:.2f} '
               f'| {w["max_load_n"] / 1e3:.2f} | {w["dlc"]:.3f} |')
        if acc:
            row += f' {acc["load_rms_pct_dynamic"][w["wheel"]]:.1f} |'
        lines.append(row)
    lines += ['', '| unit | max abs LTR | max abs quasi-static LTR |', '|---|---|---|']
    for unit, u in s['units'].items():
        lines.append(f'| {unit} | {u["max_abs_ltr"]:.3f} | {u["max_abs_ltr_quasi_static"]:.3f} |')
    imu = s.get('tractor_imu')
    if imu:
        lines += ['', f"The tractor IMU's a_y (`/imu/tractor`, the latest at or before each "
                  f"sample): {imu['fresh']} samples fresh, {imu['stale']} stale (older than "
                  f"{imu['max_age_s']:g} s: the last a_y held) and {imu['missing']} missing "
                  '(none yet: fed 0).']
    fp = s.get('fused_profile')
    if fp:
        left, right = fp['iri_m_per_km']
        lines += ['', f'The road fused over the {fp["axles"]} axles (`/road_profile/fused/*`, '
                  f'{fp["length_m"]:.0f} m every axle has passed): IRI {left:.2f} m/km left, '
                  f'{right:.2f} m/km right. ' + (
                      "Streamed online, each point once the last axle had passed it; the road, "
                      "its figures and the segments' IRI above are the whole vehicle's front "
                      "wheels' own road per sample (the node's `/road_profile/*`)."
                      if fp.get('streamed') else
                      "The road, its figures and the segments' IRI above are the fused "
                      "profile's, the last metres (where the trailer's axles have not passed) "
                      "the whole vehicle's front wheels' road.")]
    if s.get('friction_velocity'):
        from road_force_estimator.report.summary import friction_velocity_line
        lines += ['', friction_velocity_line(s['friction_velocity'])
                  + ' One v_f for every spring.']
    fit = s.get('model_fit')
    if fit:
        from road_force_estimator.estimation.axle_fit import ADVICE
        cells = ', '.join(f'{a} {100 * m:.1f} %' for a, m in fit['misfit'].items())
        verdict = (f'**{", ".join(fit["culprits"])}** {ADVICE}' if fit['culprits']
                   else 'every axle fits')
        online = (f'online, the last of {fit["online_verdicts"]} verdicts '
                  f'({fit["online_mismatches"]} named an axle or sensor), '
                  if fit.get('online_verdicts') else '')
        lines += ['', f"Model fit per axle ({online}each axle's road against the other axles' "
                  f'over {fit["length_m"]:.0f} m; misfit bound, threshold '
                  f'{100 * fit["threshold"]:g} %: {cells}): {verdict}.']
    if acc:
        lines += ['', f'Against the drive\'s truth ({acc["samples"]} samples): the trailer\'s '
                  'quasi-static LTR error RMS '
                  f'{acc["ltr_trailer_quasi_static_rms_error"]:.4f}, largest '
                  f'{acc["ltr_trailer_quasi_static_max_error"]:.4f}.']
    return lines


def append_estimate(folder: str | Path, wv, truth=None,
                    summary: dict[str, Any] | None = None, fused=None) -> dict[str, Any]:
    """Add the whole vehicle's estimate to the report folder (``report.md``,
    ``report.json``'s ``whole_vehicle_estimate``, ``segments.csv``'s columns) and, with
    ``truth``, the truth's section; the estimate's numbers (also in
    ``summary['whole_vehicle_estimate']`` when given; ``wv`` the arrays or a source of
    their rows, :func:`summarize_estimate`'s). ``fused``: the fused profile
    (``distance_m``, ``left_m``, ``right_m``, ``axles``; m): its IRI in the section (offline
    the report's road, profile figures and segment IRI are already the fused profile's,
    online the front wheels' own road: :func:`~.pipeline.whole_vehicle.fused_road`)."""
    folder = Path(folder)
    s = summarize_estimate(wv, truth)
    if fused is not None:
        s['fused_profile'] = _fused_iri(fused)
        meta = wv.meta if hasattr(wv, 'rows') else wv
        s['fused_profile']['streamed'] = getattr(meta, 'fused', None) is not None
    if (folder / 'segments.csv').exists():
        _append_segments_csv(folder / 'segments.csv', wv)
    _append_section(folder, 'whole_vehicle_estimate', s, estimate_markdown(s), summary)
    if truth is not None and len(truth.stamps_ns):
        append_to_report(folder, truth, summary, estimated=True)
    return s
