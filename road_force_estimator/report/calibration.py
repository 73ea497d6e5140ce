"""The calibration report: Markdown, JSON and figures of a
:class:`road_force_estimator.calibration.calibrate.CalibrationResult`.

``calibration.md`` and ``calibration.json`` hold each parameter with its nominal and fitted
value and 95 % interval, the alignment found, the force scale, what was held and why, the fit
residual against the sensor noise, and the timings; ``deflections.png`` shows the measured
against the fitted deflections and roll (and the residual) over a few seconds,
``spectra.png`` their power spectral densities (Welch). matplotlib (Agg) is imported only
when figures are drawn.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
from scipy import signal

# The APIs the report uses (one place, for the lead to re-point).
from road_force_estimator.core.parameters import SPECS
from road_force_estimator.calibration.model import OPTIONAL

__all__ = ['write_report', 'report_dict', 'markdown']

_CHANNEL_NAMES = ('left deflection (m)', 'right deflection (m)', 'roll (rad)')


def report_dict(result, *, drive: str = '', profile: str = '', output: str = '') -> dict:
    """Everything of the report as plain values."""
    a = result.alignment
    return {
        'drive': drive, 'profile': profile, 'parameter_file': output,
        'alignment': {**a.as_dict(), 'fine_offset_m': result.fine_alignment[0],
                      'fine_scale': result.fine_alignment[1]},
        'scale_known': result.scale_known, 'scale_note': result.scale_note,
        'parameters': [e.as_dict() for e in result.parameters],
        'not_identifiable': list(result.not_identifiable),
        'correlated': [list(c) for c in result.correlated],
        'residual_rms': result.residual_rms.tolist(),
        'noise_high_frequency': result.noise_high_frequency.tolist(),
        'channels': list(_CHANNEL_NAMES),
        'used_samples': result.used_samples, 'used_duration_s': result.used_duration_s,
        'used_distance_m': result.used_distance_m, 'sample_period_s': result.dt_s,
        'rejected_samples': result.rejected_samples, 'function_evaluations': result.nfev,
        'timings_s': result.timings_s,
        'extending': _extending(),
        'covariance': 'sandwich with the auto- and cross-covariance of the residuals '
                      '(Bartlett window by the rule of Politis 2003)',
        'covariance_window_s': result.covariance_window_s,
    }


def _extending() -> str:
    """What the fit could free and does not (the optional parameters the core lacks)."""
    missing = [name for name, _, _ in OPTIONAL if name not in SPECS]
    text = ('; '.join(missing) + ': not in the parameter table, not fitted (freed as soon as '
            'the core has them). ') if missing else ''
    return text + 'The sensor offsets are reported, not written: no parameter carries them yet'



def _number(x: float, digits: int = 6) -> str:
    if x is None or not math.isfinite(x):
        return 'n/a'
    return f'{x:.{digits}g}'


def _parameter_rows(d: dict) -> list[str]:
    rows = ['| parameter | unit | nominal | fitted | 95 % interval | change | status |',
            '|---|---|---|---|---|---|---|']
    for p in d['parameters']:
        if p['kind'] in ('offset', 'alignment'):
            change = ''
        elif p['nominal']:
            change = f'{100.0 * (p["value"] / p["nominal"] - 1.0):+.2f} %'
        else:
            change = ''
        g = 9 if p['kind'] == 'alignment' else 6
        rows.append(f'| `{p["name"]}` | {p["unit"]} | {_number(p["nominal"], g)} | '
                    f'{_number(p["value"], g)} | [{_number(p["ci95_low"], g)}, '
                    f'{_number(p["ci95_high"], g)}] | {change} | {p["status"]} |')
    return rows


def markdown(d: dict) -> str:
    """The Markdown text of a :func:`report_dict`."""
    a = d['alignment']
    lines = ['# Calibration report', '',
             f'Drive `{d["drive"]}` over the survey `{d["profile"]}`; parameter file '
             f'`{d["parameter_file"]}`.', '',
             '## Alignment', '',
             f'Survey distance = {a["offset_m"] + a["fine_offset_m"]:.3f} m + '
             f'{a["scale"] + a["fine_scale"]:.6f} x drive distance (odometer error '
             f'{100.0 * (a["scale"] + a["fine_scale"] - 1.0):+.3f} %). Cross-correlation: '
             f'{a["correlation"]:.3f} over {a["overlap_m"]:.0f} m (searched offsets '
             f'{a["offset_range_m"][0]:g}..{a["offset_range_m"][1]:g} m, scales '
             f'{a["scale_range"][0]:g}..{a["scale_range"][1]:g}, {a["scales_tried"]} tried); '
             f'the fit refined it by {a["fine_offset_m"]:+.4f} m and {a["fine_scale"]:+.2e}.',
             '', '## Force scale', '', d['scale_note'][:1].upper() + d['scale_note'][1:] + '.',
             '',
             '## Parameters', '', *_parameter_rows(d), '']
    if d['not_identifiable']:
        lines += ['Held at their nominal values because this drive cannot tell them apart '
                  '(rank-deficient Jacobian or a 95 % interval wider than +-50 %): '
                  + ', '.join(f'`{n}`' for n in d['not_identifiable']) + '.', '']
    if d['correlated']:
        lines += ['Strongly correlated estimates (|r| > 0.95): ' + '; '.join(
            f'`{x}` / `{y}` ({r:+.3f})' for x, y, r in d['correlated']) + '.', '']
    lines += [d['extending'] + '.', '', '## Fit residual against the sensor noise', '',
              '| channel | residual RMS | noise (second differences) | ratio |',
              '|---|---|---|---|']
    for name, r, n in zip(d['channels'], d['residual_rms'], d['noise_high_frequency']):
        ratio = r / n if n and math.isfinite(n) and n > 0 else math.nan
        lines.append(f'| {name} | {_number(r)} | {_number(n)} | {_number(ratio)} |')
    t = d['timings_s']
    lines += ['', f'{d["used_samples"]} samples fitted ({d["used_duration_s"]:.1f} s, '
              f'{d["used_distance_m"]:.0f} m; {d["rejected_samples"]} missing on the sample '
              f'grid); {d["function_evaluations"]} evaluations; alignment '
              f'{t.get("alignment", 0):.1f} s, fit {t.get("fit", 0):.1f} s.', '',
              'The residual RMS is the noise level the fit leaves (the by-product noise '
              'estimate); the second-difference estimate is an upper bound of the white noise '
              'where the signal is smooth. A ratio near 1 means the model explains the drive '
              'down to the noise.', '']
    return '\n'.join(lines)


def _figures(result, folder: Path) -> list[Path]:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    out = []
    t, y, f = result.t_s, result.measured, result.fitted
    window = t <= t[0] + min(5.0, t[-1] - t[0])
    fig, axes = plt.subplots(3, 1, figsize=(10, 8), sharex=True)
    for c, ax in enumerate(axes):
        ax.plot(t[window], y[window, c], lw=0.8, label='measured')
        ax.plot(t[window], f[window, c], lw=0.8, ls='--', label='fitted')
        ax.plot(t[window], y[window, c] - f[window, c], lw=0.6, label='residual')
        ax.set_ylabel(_CHANNEL_NAMES[c])
        ax.set_title(_CHANNEL_NAMES[c].split(' (')[0], fontsize=10)
    axes[0].legend(loc='upper right')
    axes[-1].set_xlabel('time (s)')
    fig.suptitle(FIGURE_TITLES['deflections.png'], fontsize=11)
    fig.tight_layout()
    out.append(folder / 'deflections.png')
    fig.savefig(out[-1], dpi=100)
    plt.close(fig)
    fs = 1.0 / result.dt_s
    fig, axes = plt.subplots(3, 1, figsize=(10, 8), sharex=True)
    nper = int(min(y.shape[0], 4096))
    for c, ax in enumerate(axes):
        for data, label in ((y[:, c], 'measured'), (f[:, c], 'fitted'),
                            (y[:, c] - f[:, c], 'residual')):
            fr, p = signal.welch(data - np.mean(data), fs=fs, nperseg=nper)
            ax.loglog(fr[1:], p[1:], lw=0.8, label=label)
        name, unit = _CHANNEL_NAMES[c][:-1].split(' (')
        ax.set_ylabel(f'PSD ({unit}²/Hz)')
        ax.set_title(f'{name}: power spectral density (Welch)', fontsize=10)
    axes[0].legend(loc='lower left')
    axes[-1].set_xlabel('frequency (Hz)')
    fig.suptitle(FIGURE_TITLES['spectra.png'], fontsize=11)
    fig.tight_layout()
    out.append(folder / 'spectra.png')
    fig.savefig(out[-1], dpi=100)
    plt.close(fig)
    return out


#: The figures' titles, also their captions in calibration.md.
FIGURE_TITLES = {
    'deflections.png': 'Measured and fitted signals and the residual (first 5 s of the drive)',
    'spectra.png': 'Power spectral densities of the measured, fitted and residual signals',
}


def figure_links() -> list[str]:
    """The figures' section of calibration.md (the files are written beside it)."""
    lines = ['## Figures', '']
    for name, title in FIGURE_TITLES.items():
        lines += [f'![{title}]({name})', '', f'{title}: [{name}]({name}).', '']
    return lines


def write_report(result, folder: str | Path, *, drive: str = '', profile: str = '',
                 output: str = '', figures: bool = True) -> list[Path]:
    """Write ``calibration.md``, ``calibration.json`` and (``figures``) the PNGs into
    ``folder`` (created); returns the paths written."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    d = report_dict(result, drive=drive, profile=profile, output=output)
    md = folder / 'calibration.md'
    md.write_text(markdown(d) + ('\n'.join(['', *figure_links()]) if figures else ''))
    js = folder / 'calibration.json'
    js.write_text(json.dumps(d, indent=2, allow_nan=True))
    paths = [md, js]
    if figures:
        paths += _figures(result, folder)
    return paths
