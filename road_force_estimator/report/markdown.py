"""``report.md``: the Markdown summary of a drive's report (from :func:`~.summary.summarize`)."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from road_force_estimator.core.segments import SEGMENT_COLUMNS
from road_force_estimator.core.units import Units, units

__all__ = ['write_markdown', 'FIGURE_NOTES']


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


def _segment_markdown(segments: dict[str, np.ndarray], u: Units,
                      against: str = 'true') -> list[str]:
    """The segment table; ``against``: the word for the comparison columns ('true' for a
    ground truth, 'reference' for a reference profile)."""
    n = len(segments['start_m'])
    if n == 0:
        return ['No segment: the drive covers no distance.']
    have_true = np.isfinite(segments['true_iri_left_m_per_km']).any()
    have_fix = np.isfinite(segments['start_lat']).any()
    lu, iu = u.length_unit, u.iri_unit
    head = [f'from ({lu})', f'to ({lu})', f'IRI L ({iu})', f'IRI R ({iu})']
    if have_true:
        head += [f'{against} IRI L ({iu})', f'{against} IRI R ({iu})']
    head += ['DLC L', 'DLC R', 'peak L (kN)', 'peak R (kN)', 'max abs LTR',
             'static L (kN)', 'static R (kN)', 'max abs LTR quasi-static', 'lift-offs']
    if have_fix:
        head += ['start lat, lon', 'end lat, lon']
    lines = ['| ' + ' | '.join(head) + ' |', '|' + '---|' * len(head)]
    for i in range(n):
        s = {k: segments[k][i] for k in SEGMENT_COLUMNS}
        row = [u.length_text(s['start_m'], 1), u.length_text(s['end_m'], 1)]
        if not np.isfinite(s['peak_load_left_n']):
            row += ['no data (gap)'] + [''] * (len(head) - 3)
            lines.append('| ' + ' | '.join(row) + ' |')
            continue
        row += [u.iri_text(s['iri_left_m_per_km']), u.iri_text(s['iri_right_m_per_km'])]
        if have_true:
            row += [u.iri_text(s['true_iri_left_m_per_km']),
                    u.iri_text(s['true_iri_right_m_per_km'])]
        row += [_fmt(s['dlc_left'], 3), _fmt(s['dlc_right'], 3),
                _fmt(s['peak_load_left_n'] / 1e3, 1), _fmt(s['peak_load_right_n'] / 1e3, 1),
                _fmt(s['max_abs_ltr'], 3), _fmt(s['static_load_left_n'] / 1e3, 2),
                _fmt(s['static_load_right_n'] / 1e3, 2), _fmt(s['max_abs_ltr_quasi_static'], 3),
                str(int(s['lift_offs']))]
        if have_fix:
            row += [f'{_fmt(s["start_lat"], 6)}, {_fmt(s["start_lon"], 6)}',
                    f'{_fmt(s["end_lat"], 6)}, {_fmt(s["end_lon"], 6)}']
        lines.append('| ' + ' | '.join(row) + ' |')
    return lines


def write_markdown(path: str | Path, summary: dict[str, Any], segments: dict[str, np.ndarray],
                   figures: list[str]) -> None:
    """``report.md`` from :func:`~.summary.summarize`'s results (in its ``units``)."""
    s = summary
    u = units(s.get('units', 'si'))
    how = ('causal, what the observer node publishes' if s['mode'] == 'online'
           else 'non-causal, the whole recording')
    lines = [f'# Estimate report: {s["input"] or "drive"}', '',
             f'Mode **{s["mode"]}** ({how}); '
             f'{s["samples"]["estimated"]} samples estimated over {_fmt(s["duration_s"])} s and '
             f'{u.length_text(s["distance_m"], 1)} {u.length_unit}.', '']
    lines += _run_section(s, u)
    lines += ['## Summary', '', '| item | value |', '|---|---|']
    lines += _summary_rows(s, u)
    lines += _summary_notes(s, u)
    lines += _messages_section(s)
    lines += _sensors_section(s)
    lines += _accuracy_section(s)
    lines += ['', f'## Segments ({u.segment_text(s["segment_length_m"])})', '',
              'Also in `segments.csv` (SI units, named in its columns). DLC = std/mean of the '
              'wheel load; lift-offs = events. "no data": no sample in the segment (a gap in '
              'the recording); such segments have no IRI and are left out of the whole-drive '
              'IRI, never counted as smooth road.' + _tail_text(segments, s, u), '']
    lines += _segment_markdown(segments, u, 'reference' if _against_reference(s) else 'true')
    if figures:
        lines += ['', '## Figures', '']
        for name in figures:
            lines += [f'![{name[:-4]}]({name})', '', FIGURE_NOTES.get(name, ''), '']
    Path(path).write_text('\n'.join(lines).rstrip() + '\n')


def _against_reference(s: dict[str, Any]) -> bool:
    """The comparison is with a reference profile (an LPA survey), not a ground truth."""
    return bool(s.get('reference_profile')) or (s.get('iri_m_per_km') or {}).get(
        'reference') == 'reference profile'


def _tail_text(segments: dict[str, np.ndarray], s: dict[str, Any], u: Units) -> str:
    """The sentence naming a last segment that is not of the nominal length."""
    if len(segments['start_m']) == 0:
        return ''
    nominal = float(s['segment_length_m'])
    last = float(segments['end_m'][-1] - segments['start_m'][-1])
    if abs(last - nominal) <= 0.01 * nominal:     # the last sample's spacing, not a tail
        return ''
    how = ('a remainder shorter than half a segment joins it' if last > nominal
           else 'the drive ends inside it')
    return (f' The last segment ({u.length_text(segments["start_m"][-1], 1)} to '
            f'{u.length_text(segments["end_m"][-1], 1)} {u.length_unit}) is '
            f'{u.length_text(last, 1)} {u.length_unit} long, not '
            f'{u.length_text(nominal, 1)}: {how}.')


#: What each figure shows (under it in report.md).
FIGURE_NOTES = {
    'states.png': 'The differentiator states over a 2 s window (detail figures: 2 s from a '
                  'third of the converged stretch, so that single oscillations can be seen); '
                  'measured deflections and roll light, estimates solid.',
    'body.png': 'Body heave acceleration and heave over the same 2 s window.',
    'wheels.png': 'Wheel heaves and accelerations over the same 2 s window, both wheels.',
    'profile.png': 'Band-passed (0.5-30 m) profile over a 100 m window, truth dashed, the '
                   'error (estimate - truth) in its own panel.',
    'loads.png': 'Wheel loads (plotted as max(0, F): a tire cannot pull) and LTR over the 2 s '
                 'window, truth dashed, the load error in its own panel.',
    'overview.png': 'The whole drive: per pixel column the min-max envelope of LTR and of '
                    'the band-passed profile of both wheels, and the IRI per segment with '
                    "FHWA's condition bands (good < 95, fair 95-170, poor > 170 in/mi).",
}


def _run_section(s: dict[str, Any], u: Units) -> list[str]:
    """What was run: the command, the parameters, the version, the road, the speed."""
    run = s.get('run') or {}
    if not run:
        return []
    sp = run.get('speed_mps')
    speed = (f'{sp["mean"]:.2f} m/s mean ({sp["min"]:.2f} to {sp["max"]:.2f} m/s, '
             f'{3.6 * sp["mean"]:.1f} km/h, {sp["mean"] / 0.44704:.1f} mph)' if sp else 'n/a')
    latency = run.get('latency_s', 0.0)
    mode = (f'{s["mode"]}, latency {1e3 * latency:g} ms' if s['mode'] == 'online'
            else f'{s["mode"]} (non-causal: no latency)')
    static = run.get('static_load_n') or []
    over = ', '.join(f'`{o}`' for o in run.get('overrides') or ()) or 'none'
    rows = [('command line', f'`{run["command"]}`' if run.get('command') else 'n/a (API call)'),
            ('package version', f'road_force_estimator {run.get("package_version", "?")}'),
            ('mode', mode),
            ('parameter file', f'`{run["params_file"]}`' if run.get('params_file')
             else 'none (package defaults)'),
            ('overrides (-p)', over),
            ('road source (from the bag)', run.get('road_source') or 'not recorded'),
            ('speed', speed),
            ('static wheel loads left / right (N)', ' / '.join(f'{v:.0f}' for v in static))]
    lines = ['## What was run', '', '| item | value |', '|---|---|']
    lines += [f'| {a} | {b} |' for a, b in rows]
    lines += ['', '<details><summary>Parameter values used</summary>', '',
              '| parameter | value |', '|---|---|']
    lines += [f'| `{k}` | {_param_text(v)} |' for k, v in sorted(s['parameters'].items())]
    lines += ['', '</details>', '']
    return lines


def _param_text(v) -> str:
    if isinstance(v, (list, tuple)):
        return '[' + ', '.join(_param_text(x) for x in v) + ']'
    return f'{v:.6g}' if isinstance(v, float) else str(v)


def _finding_rows(s: dict[str, Any]) -> list[tuple[str, Any]]:
    """Rows of what went wrong with the input, when it did (the negative loads have their
    own row)."""
    rows: list[tuple[str, Any]] = []
    sc = s.get('speed_contradicted')
    if sc:
        spans = ', '.join(f'{a:.3f}-{b:.3f}' for a, b in sc['spans_s'])
        rows.append(('WARNING: speed reads standing while the deflections show motion '
                     '(samples; spans, s)', f'{sc["samples"]}; {spans}'))
    return rows


def _static_label(s: dict[str, Any]) -> str:
    """What the static loads are: estimated (zero_load) or configured."""
    reference = (s.get('parameters') or {}).get('vehicle.deflection_reference', 'equilibrium')
    if reference == 'zero_load':
        return ('static wheel loads at the end, left / right (N; estimated: '
                'vehicle.deflection_reference = zero_load)')
    return ('static wheel loads, left / right (N; configured: vehicle.static_load, or from '
            'the masses where it is 0)')


def _summary_rows(s: dict[str, Any], u: Units) -> list[str]:
    """The rows of the summary table."""
    smp = s['samples']
    conv = s.get('convergence') or {}
    iri = s['iri_m_per_km']
    ref = {'enveloped': 'reference: the true profile enveloped by the tire',
           'truth': 'true profile', 'reference profile': 'reference profile'}.get(
        iri.get('reference'), 'true (or reference) profile')
    rows = [('deflection samples in the input (accepted by the reader)', smp['input']),
            ('samples estimated', smp['estimated']),
            ('samples rejected (all topics and the estimator)', s['rejected_total']),
            ('estimator restarts (of which after a gap in the stamps)',
             f'{s["resets"]} ({s["gaps"]})'),
            ('convergence time t_0 (s)', _fmt(conv.get('time_s'), 3)),
            ('converged samples', smp['converged']),
            ('samples with a wheel lifted off', s['lift_off_samples']),
            ('samples where a load estimate went below zero (plotted as 0)',
             s.get('negative_load_samples', 0)),
            *_finding_rows(s),
            ('max abs LTR', _fmt(s['max_abs_ltr'], 3)),
            (_static_label(s),
             ' / '.join(f'{v:.0f}' for v in s.get('static_load_final_n') or ()) or 'n/a'),
            ('GNSS fixes', s['fixes']),
            (f'IRI of the whole drive, estimated profile, left / right ({u.iri_unit})',
             ' / '.join(u.iri_text(v) for v in iri['estimated']) if iri['estimated'] else 'n/a'),
            (f'IRI of the whole drive, {ref}, left / right ({u.iri_unit})',
             ' / '.join(u.iri_text(v) for v in iri['true']) if iri['true'] else 'n/a')]
    if iri.get('raw'):
        rows.append((f'IRI of the whole drive, raw road (before the tire envelope), left / '
                     f'right ({u.iri_unit})', ' / '.join(u.iri_text(v) for v in iri['raw'])))
    if s.get('segments_without_data'):
        rows.append(('segments without data (gap; no IRI)', s['segments_without_data']))
    if s.get('reference_profile'):
        rows += [('reference profile (no ground truth)', s['reference_profile']),
                 ('drive start along the reference (m)', _fmt(s['reference_offset_m'], 3))]
    if 'offline' in s:
        rows += [('offline: noise estimated q1 / q2 (um), phi (mrad)',
                  f'{_fmt([1e6 * v for v in s["offline"]["noise_std"][:2]])}, '
                  f'{_fmt(1e3 * s["offline"]["noise_std"][2], 3)}'),
                 ('offline: low-pass cut-offs q1 / q2 / phi (Hz)',
                  _fmt(s['offline']['cutoff_hz'], 1))]
    rows += _distance_rows(s.get('distance'))
    rows += _odometer_rows(s.get('odometer', False))
    for key, value in (s.get('notes') or {}).items():
        rows.append((key, value))
    return [f'| {a} | {b} |' for a, b in rows]


def _distance_rows(source) -> list[tuple[str, Any]]:
    """Which distance the estimate ran on and why (observer.distance_source)."""
    if not source:
        return []
    what = ('GNSS-corrected (the speed times the odometer scale from /fix)'
            if source['used'] == 'gnss' else "the speed's (the integral of /vehicle/twist)")
    return [(f'distance (observer.distance_source = {source["requested"]})',
             f'{what}: {source["reason"]}')]


def _odometer_rows(odo) -> list[tuple[str, Any]]:
    """The odometer fusion's rows (none when it was off)."""
    if odo is False:
        return []
    if not odo:
        return [('odometer scale from GNSS', 'n/a (too few fixes: distance from the speed)')]
    applied = 'applied to the distance' if odo['applied'] else \
        f'NOT applied ({odo["problem"]}): distance from the speed'
    return [('odometer scale from GNSS (true m per odometer m, +- 1 std)',
             f'{odo["scale"]:.5f} +- {odo["scale_std"]:.5f}, {applied}'),
            ('speed reads high by (%, +- 1 std)',
             f'{odo["speed_error_pct"]:.3f} +- {odo["speed_error_std_pct"]:.3f}'),
            ('fixes used / rejected as outliers / position restarts; fix noise (m)',
             f'{odo["fixes"] - odo["fixes_rejected"]} / {odo["fixes_rejected"]} / '
             f'{odo["resets"]}; {odo["fix_noise_m"]:.2f}')]


def _summary_notes(s: dict[str, Any], u: Units) -> list[str]:
    """What the summary's figures mean: convergence, restarts, the reference profile."""
    conv = s.get('convergence') or {}
    if conv.get('source') == 'measured':
        what = (f'the first time after which the {1e3 * conv["window_s"]:g} ms moving RMS of '
                f'the wheel-load error (both wheels) stays below its tolerance '
                f'({conv["tolerance_n"]:.0f} N: twice the judged RMS error, at least 1 % of '
                f'the static load) for {conv["hold_s"]:g} s (MODEL.md "Metrics")')
    else:
        what = ("no truth to measure it against: the estimator's own figure, the time of "
                f'its first converged sample ({_fmt(conv.get("time_s"), 3)} s after the start '
                'or a restart)')
        settling = conv.get('settling_time_s')
        if settling is not None and math.isfinite(settling) and settling > 0.0 and abs(
                settling - (conv.get('time_s') or 0.0)) > 5e-4:
            what += (f"; the differentiators' own settling time is {_fmt(settling, 3)} s "
                     '(the chain declares convergence only after it)')
    notes = ['', f'- Convergence time t_0: {what}.',
             '- Restarts: the estimator starts again from rest after a gap in the stamps '
             '(longer than its gap threshold) or a reset; 0 (0) = it ran through once.']
    if s.get('friction_velocity'):              # offline, a file stating tanh friction
        from road_force_estimator.report.summary import friction_velocity_line
        notes.append('- ' + friction_velocity_line(s['friction_velocity']))
    ref = (s['iri_m_per_km'] or {}).get('reference')
    if ref == 'enveloped':
        notes.append('- True IRI: of the ground-truth profile, which is the road enveloped by '
                     'the simulated tire (a moving average over the tire envelope length): what '
                     "the tire follows and what accuracy is judged against, on the truth's own "
                     'samples (the same in the online and offline reports); the raw road is '
                     'shown beside it when the bag names it.')
    return notes + ['']


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


def _sensors_section(s: dict[str, Any]) -> list[str]:
    """Per sensor: the innovations the gate kept from the filter (spikes), the stuck and
    drift flags raised (estimation.sensor_health), when first, and the flag at the end."""
    sensors = s.get('sensors') or {}
    if not sensors:
        return []
    lines = ['', '### Sensors', '',
             'Innovations gated: samples kept from the filter, beyond `observer.innovation_gate` '
             'standard deviations (spikes). Stuck / drift: flags raised '
             '(`observer.fault_*`), with the time of the first (s from the first sample). A '
             'stuck sensor is left out of the estimate while flagged (offline its whole held '
             'stretch, from before the flag); a drifting one stays fed.', '',
             '| sensor | innovations gated | stuck flags (samples) | first stuck (s) | '
             'drift flags (samples) | first drift (s) | at the end |',
             '|---|---:|---:|---:|---:|---:|---|']
    for name, v in sensors.items():
        lines.append(f'| `{name}` | {v["innovations_gated"]} | {v["stuck_flags"]} '
                     f'({v["stuck_samples"]}) | {_fmt(v["first_stuck_s"])} | '
                     f'{v["drift_flags"]} ({v["drift_samples"]}) | {_fmt(v["first_drift_s"])} | '
                     f'{v["flag"]} |')
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
                f'{_fmt(acc["max_abs_ltr_true"], 3)} |']
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
        if 'profile_xcorr' in acc:
            lines.append(
                f'| profile cross correlation, IRI-filtered (ProVAL; 1 = identical), lowest '
                f'segment in "both" | {_fmt(acc["profile_xcorr"][0], 3)} | '
                f'{_fmt(acc["profile_xcorr"][1], 3)} | '
                f'{_fmt(acc["profile_xcorr_segment_min"], 3)} |')
        if acc.get('profile_against') not in (None, 'ground truth'):
            lines += ['', 'The estimate is the road as the tire follows it: enveloped over the '
                      "tire's contact (a moving average over its length, about 0.25 m), which "
                      'smooths the short waves a profiler records. A reference that is not '
                      'enveloped (a raw LPA or profiler survey) differs from it by that '
                      'envelope, so the profile error against it includes the envelope (on a '
                      'simulated drive, the error against the enveloped ground truth is the '
                      "estimator's own)."]
        if s.get('judged_from') == 'settling time':
            lines += ['', 'The estimator never reported convergence: samples are judged from '
                      f'its settling time ({_fmt(s["settling_time_s"], 3)} s) on.']
        lines += ['', _judged_text(acc)]
    return lines


def _judged_text(acc: dict[str, Any]) -> str:
    """Which samples the accuracy was judged on (loads and LTR need a load truth)."""
    parts = []
    if 'samples_judged' in acc:
        parts.append(f'{acc["samples_judged"]} converged samples (loads, LTR)')
    if 'profile_samples_judged' in acc:
        parts.append(f'{acc["profile_samples_judged"]} profile samples against the '
                     f'{acc["profile_against"]}, 30 m in from each end')
    if 'profile_xcorr' in acc:
        where = ('the distance truly travelled' if acc['profile_xcorr_distance'] == 'true'
                 else "the estimate's distance")
        parts.append('the cross correlation from 30 m after the first converged sample, the '
                     f'truth at {where}, the estimate at its own (best offsets '
                     + ' / '.join(f'{_fmt(v, 2)}' for v in acc['profile_xcorr_lag_m'])
                     + ' m)')
    text = 'Judged on ' + ' and '.join(parts) + '.'
    if 'samples_judged' not in acc:
        text += (' Loads and LTR are not judged: the bag has no ground truth of the loads '
                 '(a reference profile judges the profile only).')
    return text
