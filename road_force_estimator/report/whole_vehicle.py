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
offline the model fit per axle (:mod:`~.estimation.axle_fit`: which axle or sensor does not
fit).
``report.md`` gains "The whole vehicle (estimate)", ``report.json`` the key
``whole_vehicle_estimate``, ``segments.csv`` the columns :func:`segment_columns` names
(INTERFACES.md "The whole vehicle").
"""
from __future__ import annotations

import json
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


def segment_table(wv, start_m, end_m) -> dict[str, np.ndarray]:
    """The columns of :func:`segment_columns` for the segments ``[start_m, end_m)`` (the last
    one's end inclusive) from the converged samples of ``wv`` (a
    :class:`~.estimation.whole_vehicle.WholeVehicleArrays`) by their distance (the front
    axle's, m): peak load and DLC (std / mean) per wheel, mean static axle load and gross
    weight, largest |quasi-static LTR| of the trailer; NaN in a segment without a sample.
    Every sample counts, converged or not, as in the front axle's columns."""
    start = np.asarray(start_m, float)
    end = np.asarray(end_m, float)
    k = start.size
    use = np.isfinite(np.asarray(wv.distance_m, float))
    x = np.asarray(wv.distance_m, float)[use]
    if k == 0:
        return {c: np.zeros(0) for c in segment_columns(wv.axle_names)}
    seg = np.searchsorted(start, x, side='right') - 1
    inside = (seg >= 0) & np.where(seg == k - 1, x <= end[-1],
                                   x < end[np.clip(seg, 0, k - 1)])
    seg = seg[inside]
    rows = np.flatnonzero(use)[inside]        # one wheel's row at a time (no (wheels, m) copy)
    loads = np.asarray(wv.load_n, float)
    static = np.asarray(wv.static_n, float)
    qs = np.asarray(wv.ltr_quasi_static, float)[1, rows]
    counts = np.bincount(seg, minlength=k)
    table: dict[str, np.ndarray] = {}

    def mean(values: np.ndarray) -> np.ndarray:
        with np.errstate(invalid='ignore', divide='ignore'):
            return np.where(counts > 0, np.bincount(seg, values, minlength=k) / counts, np.nan)

    for j, a in enumerate(wv.axle_names):
        for side, word in enumerate(('left', 'right')):
            f = loads[2 * j + side, rows]
            peak = np.full(k, np.nan)
            np.fmax.at(peak, seg, f)
            m = mean(f)
            with np.errstate(invalid='ignore', divide='ignore'):
                std = np.sqrt(np.maximum(mean(f * f) - m * m, 0.0))
                table[f'dlc_{a}_{word}'] = np.where(counts > 1, std / m, np.nan)
            table[f'peak_load_{a}_{word}_n'] = peak
        table[f'static_load_{a}_n'] = mean(static[2 * j, rows] + static[2 * j + 1, rows])
    table['gross_weight_n'] = mean(_wheel_sum(static, rows))
    peak_qs = np.full(k, np.nan)
    np.fmax.at(peak_qs, seg, np.abs(qs))
    table['max_abs_ltr_trailer_quasi_static'] = peak_qs
    return {c: table[c] for c in segment_columns(wv.axle_names)}


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


def summarize_estimate(wv, truth=None) -> dict[str, Any]:
    """The numbers of the estimate's section from ``wv`` (a
    :class:`~.estimation.whole_vehicle.WholeVehicleArrays`) and, when given, the drive's
    :class:`~.bagio.articulated_drive.ArticulatedTruth` (its accuracy at the shared stamps)."""
    from road_force_estimator.estimation.whole_vehicle import UNITS
    from road_force_estimator.interfaces import wheel_joints

    names = wheel_joints(wv.axle_names)
    use = np.asarray(wv.converged, bool)
    loads = np.asarray(wv.load_n, float)       # one wheel's row at a time (no copy of all)
    static = np.asarray(wv.static_n, float)
    axles = list(wv.axle_names)
    axle_static = [float(np.mean(static[2 * j, use] + static[2 * j + 1, use])) if use.any()
                   else float('nan') for j in range(len(axles))]
    wheels = []
    for i, name in enumerate(names):
        f = loads[i, use]
        mean = float(np.mean(f)) if f.size else float('nan')
        wheels.append({'wheel': name, 'axle': axles[i // 2],
                       'static_load_n': float(np.mean(static[i, use])) if f.size
                       else float('nan'),
                       'mean_load_n': mean,
                       'max_load_n': float(np.max(f)) if f.size else float('nan'),
                       'dlc': float(np.std(f)) / mean if f.size and mean > 0.0
                       else float('nan')})
    units = {u: {'max_abs_ltr': _nanmax_abs(np.asarray(wv.ltr, float)[k, use]),
                 'max_abs_ltr_quasi_static': _nanmax_abs(
                     np.asarray(wv.ltr_quasi_static, float)[k, use])}
             for k, u in enumerate(UNITS)}
    out: dict[str, Any] = {
        'samples': int(len(wv.stamps_ns)), 'converged': int(np.count_nonzero(use)),
        'axles': axles, 'axle_bodies': list(wv.axle_bodies),
        'axle_static_load_n': axle_static,
        'gross_weight_n': float(np.sum(axle_static)), 'wheels': wheels, 'units': units,
        'gaps': int(wv.gap_count) if hasattr(wv, 'gap_count') else 0}
    codes = getattr(wv, 'imu_codes', None)
    if codes is not None:       # the tractor IMU's pairing (:mod:`~.estimation.imu_hold`)
        from road_force_estimator.estimation.imu_hold import IMU_MAX_AGE_S, STATES
        out['tractor_imu'] = {'max_age_s': IMU_MAX_AGE_S, **{
            w: int(np.count_nonzero(np.asarray(codes) == c)) for c, w in enumerate(STATES)}}
    fit = getattr(wv, 'axle_fit', None)
    if fit is not None and fit.measured:
        from road_force_estimator.estimation.axle_fit import ONLINE_THRESHOLD, THRESHOLD
        fits = [f for _, f in getattr(wv, 'axle_fits', ())]    # online: every verdict
        out['model_fit'] = {'verdict': 'mismatch' if fit.culprits else 'ok',
                            'culprits': list(fit.culprits),
                            'threshold': ONLINE_THRESHOLD if fits else THRESHOLD,
                            'length_m': float(fit.length_m),
                            'misfit': dict(zip(fit.axle_names,
                                               (float(m) for m in fit.axle_misfit))),
                            'online_verdicts': len(fits),
                            'online_mismatches': sum(bool(f.culprits) for f in fits)}
    if truth is not None and len(truth.stamps_ns) and tuple(truth.wheel_names) == names:
        out['accuracy'] = _accuracy(wv, truth, use, names)
    return out


def _accuracy(wv, truth, use: np.ndarray, names: tuple) -> dict[str, Any]:
    """Per wheel the RMS load error (% of the true dynamic load's RMS) and the trailer's
    quasi-static LTR error, over the converged samples whose stamps the truth has."""
    stamps = np.asarray(wv.stamps_ns, np.int64)
    at = np.clip(np.searchsorted(truth.stamps_ns, stamps), 0, len(truth.stamps_ns) - 1)
    hit = use & (np.asarray(truth.stamps_ns)[at] == stamps)
    est = np.asarray(wv.load_n, float)[:, hit]
    true = np.asarray(truth.wheel_load_n, float)[at[hit]].T
    static = np.asarray(truth.static_load_n, float)
    pct = []
    for i in range(est.shape[0]):
        ref = static[i] if np.isfinite(static[i]) else np.mean(true[i])
        dyn = float(np.sqrt(np.mean((true[i] - ref) ** 2))) if true.shape[1] else float('nan')
        err = float(np.sqrt(np.mean((est[i] - true[i]) ** 2))) if true.shape[1] \
            else float('nan')
        pct.append(100.0 * err / dyn if dyn > 0.0 else float('nan'))
    ltr_true = np.asarray(truth.unit_ltr, float)[at[hit], 3]
    ltr_est = np.asarray(wv.ltr_quasi_static, float)[1, hit]
    d = (ltr_est - ltr_true)[np.isfinite(ltr_true)]
    return {'samples': int(np.count_nonzero(hit)),
            'load_rms_pct_dynamic': dict(zip(names, pct)),
            'ltr_trailer_quasi_static_rms_error': float(np.sqrt(np.mean(d ** 2))) if d.size
            else float('nan'),
            'ltr_trailer_quasi_static_max_error': _nanmax_abs(d)}


def _fused_iri(fused) -> dict[str, Any]:
    """The fused profile's extent and IRI (m/km, left and right; NaN when too short)."""
    from road_force_estimator.core import iri as iri_mod

    x = np.asarray(fused.distance_m, float)
    out: dict[str, Any] = {'axles': int(fused.axles), 'points': int(x.size),
                           'length_m': float(x[-1] - x[0]) if x.size else 0.0,
                           'iri_m_per_km': [float('nan')] * 2}
    try:
        out['iri_m_per_km'] = [float(v) for v in iri_mod.iri(
            x, np.column_stack([fused.left_m, fused.right_m]))]
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
    ``summary['whole_vehicle_estimate']`` when given). ``fused``: the fused profile
    (``distance_m``, ``left_m``, ``right_m``, ``axles``; m): its IRI in the section (offline
    the report's road, profile figures and segment IRI are already the fused profile's,
    online the front wheels' own road: :func:`~.pipeline.whole_vehicle.fused_road`)."""
    folder = Path(folder)
    s = summarize_estimate(wv, truth)
    if fused is not None:
        s['fused_profile'] = _fused_iri(fused)
        s['fused_profile']['streamed'] = getattr(wv, 'fused', None) is not None
    if (folder / 'segments.csv').exists():
        _append_segments_csv(folder / 'segments.csv', wv)
    _append_section(folder, 'whole_vehicle_estimate', s, estimate_markdown(s), summary)
    if truth is not None and len(truth.stamps_ns):
        append_to_report(folder, truth, summary, estimated=True)
    return s
