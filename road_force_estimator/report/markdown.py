"""``report.md``: the Markdown summary of a drive's report (from :func:`~.summary.summarize`)."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from road_force_estimator.core.segments import SEGMENT_COLUMNS

__all__ = ['write_markdown']


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
    """``report.md`` from :func:`~.summary.summarize`'s results."""
    s = summary
    how = ('causal, what the observer node publishes' if s['mode'] == 'online'
           else 'non-causal, the whole recording')
    lines = [f'# Estimate report: {s["input"] or "drive"}', '',
             f'Mode **{s["mode"]}** ({how}); '
             f'{s["samples"]["estimated"]} samples estimated over {_fmt(s["duration_s"])} s and '
             f'{_fmt(s["distance_m"], 1)} m.', '', '## Summary', '',
             '| item | value |', '|---|---|']
    lines += _summary_rows(s)
    lines += _messages_section(s)
    lines += _accuracy_section(s)
    lines += ['', f'## Segments ({_fmt(s["segment_length_m"], 0)} m)', '',
              'Also in `segments.csv`. DLC = std/mean of the wheel load; lift-offs = events.', '']
    lines += _segment_markdown(segments)
    if figures:
        lines += ['', '## Figures', '']
        for name in figures:
            lines += [f'![{name[:-4]}]({name})', '']
    Path(path).write_text('\n'.join(lines).rstrip() + '\n')


def _finding_rows(s: dict[str, Any]) -> list[tuple[str, Any]]:
    """Rows of what went wrong with the input or the estimate, when it did."""
    rows: list[tuple[str, Any]] = []
    sc = s.get('speed_contradicted')
    if sc:
        spans = ', '.join(f'{a:.3f}-{b:.3f}' for a, b in sc['spans_s'])
        rows.append(('WARNING: speed reads standing while the deflections show motion '
                     '(samples; spans, s)', f'{sc["samples"]}; {spans}'))
    if s.get('negative_load_samples'):
        rows.append(('load estimates below zero, published as 0 N (samples)',
                     s['negative_load_samples']))
    return rows


def _summary_rows(s: dict[str, Any]) -> list[str]:
    """The rows of the summary table."""
    smp = s['samples']
    rows = [('deflection samples in the input (accepted by the reader)', smp['input']),
            ('samples estimated', smp['estimated']),
            ('samples rejected (all topics and the estimator)', s['rejected_total']),
            ('restarts (gaps)', f'{s["resets"]} ({s["gaps"]})'),
            ('settling time of the estimator (s)', _fmt(s['settling_time_s'], 3)),
            ('first converged sample (s)', _fmt(s['first_converged_s'], 3)),
            ('converged samples', smp['converged']),
            ('samples with a wheel lifted off', s['lift_off_samples']),
            *_finding_rows(s),
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
    return [f'| {a} | {b} |' for a, b in rows]


def _messages_section(s: dict[str, Any]) -> list[str]:
    """Messages per topic, rejections by topic and reason, breaks in the bag."""
    lines = ['', '### Messages and rejections', '', '| topic | messages |', '|---|---|']
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
    return lines


def _accuracy_section(s: dict[str, Any]) -> list[str]:
    """The accuracy table (or why there is none) and what was judged."""
    acc = s.get('accuracy')
    lines = ['', '## Accuracy', '']
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
    return lines
