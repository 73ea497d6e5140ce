"""The whole vehicle's truth in a drive's report (an articulated drive, MODEL.md "The whole
vehicle"), where the estimator gives the front axle only (the articulated observer is the
next step).

From the drive's ``/ground_truth/wheel_loads`` and ``/ground_truth/load_transfer/*``: per
wheel the static load the drive was simulated with, the mean, lowest and highest load, the
dynamic load's RMS, the DLC (std / mean) and the samples at zero load (lift-off); per axle
and for the gross vehicle weight the sums of the static loads; per unit the largest |LTR| and
|quasi-static LTR|. ``report.md`` gains the section "The whole vehicle (ground truth)",
``report.json`` the key ``whole_vehicle``, the folder ``axles.csv`` (one row per wheel).
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from road_force_estimator.core.parameters import GRAVITY_MPS2
from road_force_estimator.report.folder import csv_cell, json_safe

__all__ = ['summarize_truth', 'truth_markdown', 'append_to_report', 'AXLE_COLUMNS']

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


def truth_markdown(s: dict[str, Any]) -> list[str]:
    """The report section (markdown lines)."""
    lines = ['', '## The whole vehicle (ground truth)', '',
             f'The drive\'s truth for every axle ({s["samples"]} samples): the estimate above '
             "is the front axle's (a front-axle tool reads an articulated drive's front axle); "
             'the other axles have no estimate yet. Also in `axles.csv`.', '',
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


def append_to_report(folder: str | Path, truth, summary: dict[str, Any] | None = None
                     ) -> dict[str, Any]:
    """Add the section to the report folder (``report.md``, ``report.json``, ``axles.csv``);
    the section's numbers (also put in ``summary['whole_vehicle']`` when given)."""
    folder = Path(folder)
    s = summarize_truth(truth)
    with open(folder / 'axles.csv', 'w') as out:
        out.write(','.join(AXLE_COLUMNS) + '\n')
        for w in s['wheels']:
            out.write(','.join(csv_cell(w[c]) for c in AXLE_COLUMNS) + '\n')
    md = folder / 'report.md'
    if md.exists():
        md.write_text(md.read_text().rstrip('\n') + '\n' + '\n'.join(truth_markdown(s)) + '\n')
    js = folder / 'report.json'
    if js.exists():
        data = json.loads(js.read_text())
        data['whole_vehicle'] = json_safe(s)
        js.write_text(json.dumps(data, indent=2) + '\n')
    if summary is not None:
        summary['whole_vehicle'] = s
    return s
