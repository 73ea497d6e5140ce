"""The figures of a drive's report, like the seed paper's figures 5-10 (matplotlib, Agg).

:data:`FIGURES`, drawn by :func:`write_figures`: the differentiator states and rates (q, dq,
ddq, phi, dphi, ddphi) with the measurements, the body acceleration and heave, the wheel
heaves, the band-passed profile against the truth (or a reference LPA profile), the loads and
LTR against the truth, and an overview of the whole drive with the per-segment IRI. The detail
figures show a window of ``window_s`` (2 s: short enough to see single oscillations; the
profile one ``profile_window_m``) from a third of the converged stretch.

Readable at a glance: left blue, right orange, estimates solid, truth dashed black, the error
(estimate - truth) in its own panel; loads are drawn as max(0, F) (a tire cannot pull); the
whole-drive figure draws per pixel column the min-max envelope (no smear of 45 000 points),
both wheels; IRI bars over FHWA's condition bands (good < 95, fair 95-170, poor > 170 in/mi),
in the report's units.

matplotlib (its ``Figure`` and the Agg canvas, never pyplot: no global state, no backend
chosen) is imported here only, and only when figures are drawn.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from road_force_estimator.report.alignment import Aligned, bandpass

__all__ = ['FIGURES', 'DEFAULT_WINDOW_S', 'DEFAULT_PROFILE_WINDOW_M', 'MAX_OVERVIEW_POINTS',
           'ENVELOPE_COLUMNS', 'FigureDrive', 'envelope', 'window_start', 'write_figures']

#: Figure files of a report, in the order of the Markdown.
FIGURES = ('states.png', 'body.png', 'wheels.png', 'profile.png', 'loads.png', 'overview.png')
#: Time window of the detail figures (s) and distance window of the profile figure (m).
DEFAULT_WINDOW_S = 2.0
DEFAULT_PROFILE_WINDOW_M = 100.0
#: Most points drawn per curve in the whole-drive figure (kept for callers; the figure now
#: draws :data:`ENVELOPE_COLUMNS` min-max columns).
MAX_OVERVIEW_POINTS = 20000

#: zlib level of the PNG files (1: a third of the default 6's encoding time, files ~20 %
#: larger).
PNG_COMPRESS_LEVEL = 1

#: Pixel columns of the whole-drive figure's envelope.
ENVELOPE_COLUMNS = 1200

_SIDES = ('left', 'right')
_COLORS = ('tab:blue', 'tab:orange')
_TRUTH = {'color': 'k', 'ls': '--', 'lw': 1.1}
_ERROR = ('tab:purple', 'tab:brown')
_BANDS = (('good', '#c8e6c9'), ('fair', '#fff3c4'), ('poor', '#ffcdd2'))


@dataclass(frozen=True)
class FigureDrive:
    """What the figures read of a drive (:class:`.bagio.Drive` has these fields): the
    measured deflections ``q_m`` ((n, 2), m) and roll ``roll_rad`` ((n,), rad) of the
    estimate's samples, the ground truth (:class:`.bagio.GroundTruth` or None)."""

    q_m: np.ndarray
    roll_rad: np.ndarray
    truth: Any = None
    fixes: Any = None


def window_start(lo_s: float, hi_s: float, length_s: float) -> float:
    """Where a detail window of ``length_s`` starts (s) in the converged stretch
    ``[lo_s, hi_s]`` (s; the whole drive when nothing converged): a third of the way into
    what is left of it (the one rule of one block's figures and of many blocks')."""
    return lo_s + max(0.0, (hi_s - lo_s - length_s)) / 3.0


def _window(al: Aligned, length_s: float) -> np.ndarray:
    """Row mask of a detail window: ``length_s`` from a third of the converged stretch
    (:func:`window_start`); every row when fewer than two fall in it."""
    t = al.t_s
    if t.size == 0:
        return np.zeros(0, bool)
    conv = np.flatnonzero(al.converged)
    lo, hi = (t[conv[0]], t[conv[-1]]) if conv.size else (t[0], t[-1])
    start = window_start(lo, hi, length_s)
    mask = (t >= start) & (t <= start + length_s)
    return mask if np.count_nonzero(mask) >= 2 else np.ones(t.size, bool)


def _legend(ax, **kwargs) -> None:
    """A legend, when the axes have labelled artists."""
    if ax.get_legend_handles_labels()[0]:
        ax.legend(**kwargs)


@dataclass
class _Canvas:
    """What every figure needs: the output folder and title, the estimates, the
    alignment, the detail window ``w`` and its times ``t`` (s); the file names written."""

    folder: Path
    title: str
    est: Any
    al: Aligned
    w: np.ndarray
    t: np.ndarray
    units: str = 'si'
    static_load_n: tuple[float, float] | None = None
    written: list[str] = field(default_factory=list)

    def pick(self, name: str) -> np.ndarray:
        """Field ``name`` of the estimates in the detail window."""
        return self.al.pick(self.est, name)[self.w]

    def subplots(self, rows: int, cols: int, figsize: tuple[float, float], **kwargs):
        """A figure of ``rows`` x ``cols`` axes (``figsize`` in inches) and its axes."""
        from matplotlib.figure import Figure

        fig = Figure(figsize=figsize)
        return fig, fig.subplots(rows, cols, **kwargs)

    def finish(self, fig, name: str, heading: str) -> None:
        """Title, lay out (:func:`_layout`), save ``name`` (110 dpi, PNG at
        :data:`PNG_COMPRESS_LEVEL`)."""
        w, h = fig.get_size_inches()
        fig.suptitle(f'{heading}{" - " + self.title if self.title else ""}', fontsize=11,
                     y=1.0 - 0.12 / h, va='top')
        _layout(fig)
        fig.savefig(self.folder / name, dpi=110, pil_kwargs={'compress_level': PNG_COMPRESS_LEVEL})
        self.written.append(name)


def _layout(fig) -> None:
    """Fixed margins for the report's figures (11 in wide; tick labels of up to ~7
    characters, one axis label and a panel title per axes; between rows the x tick labels and
    label only where the rows do not share their x axis): about what ``tight_layout`` finds,
    without its extra pass over every text (a third of the figures' time)."""
    w, h = fig.get_size_inches()
    axes = fig.axes
    rows, cols = axes[0].get_subplotspec().get_gridspec().get_geometry()
    shared = len(axes) > 1 and axes[0].get_shared_x_axes().joined(axes[0], axes[-1])
    gap = 0.4 if shared else 0.85           # between rows (in): a title, + ticks and label
    top, bottom, left, right, wgap = 0.75, 0.55, 0.85, 0.3, 0.9
    height = (h - top - bottom - (rows - 1) * gap) / rows
    width = (w - left - right - (cols - 1) * wgap) / cols
    fig.subplots_adjust(left=left / w, right=1.0 - right / w, bottom=bottom / h,
                        top=1.0 - top / h, hspace=gap / height, wspace=wgap / width)


@dataclass
class _Profiles:
    """The estimated profile and its truth (or reference) on the rows of increasing distance
    ``up``: distances ``x`` (m), the estimate ``road`` (m), both band-passed (None when they
    cannot be) and the name of what the estimate is compared with."""

    up: np.ndarray
    x: np.ndarray
    road: np.ndarray
    bp_est: np.ndarray | None
    bp_true: np.ndarray | None
    against: str


def _profiles(est, al: Aligned) -> _Profiles:
    """The profiles of figure 9 and the overview (truth gaps interpolated over distance)."""
    up = al.increasing()
    x = al.x_m[up]
    road = al.pick(est, 'road_m')[up]
    truth = al.profile_truth
    truth_up = truth[up] if truth is not None else None
    if truth_up is not None and not np.isfinite(truth_up).all():
        ok = np.isfinite(truth_up).all(axis=1)
        truth_up = (np.column_stack([np.interp(x, x[ok], truth_up[ok, i]) for i in (0, 1)])
                    if ok.sum() >= 2 else None)
    bp_est = bandpass(x, road)
    bp_true = bandpass(x, truth_up) if truth_up is not None else None
    against = 'truth' if al.true_road_m is not None else (al.reference_name or 'reference')
    return _Profiles(up, x, road, bp_est, bp_true, against)


def write_figures(folder: str | Path, est, al: Aligned, drive=None, *,
                  segments: dict[str, np.ndarray] | None = None, title: str = '',
                  window_s: float = DEFAULT_WINDOW_S,
                  profile_window_m: float = DEFAULT_PROFILE_WINDOW_M,
                  units: str = 'si',
                  static_load_n: tuple[float, float] | None = None) -> list[str]:
    """Draw the figures of :data:`FIGURES` into ``folder``; the file names written
    (``units``: those of the IRI bars; ``static_load_n``: the static wheel loads (N), drawn
    as a line on the loads)."""
    folder = Path(folder)
    if al.rows.size < 2:
        return []
    w = _window(al, window_s)
    c = _Canvas(folder, title, est, al, w, al.t_s[w], units, static_load_n)
    _states_figure(c, drive)
    _body_figure(c)
    _wheels_figure(c)
    profiles = _profiles(est, al)
    _profile_figure(c, profiles, profile_window_m)
    _loads_figure(c)
    _overview_figure(c, profiles, segments)
    return c.written


def _states_figure(c: _Canvas, drive) -> None:
    """Figure 5 of the paper: the differentiator states and rates."""
    est, al, t = c.est, c.al, c.t
    meas_q = meas_phi = None
    if drive is not None and hasattr(drive, 'q_m') and len(drive.q_m) == len(est.stamp_ns):
        meas_q = np.asarray(drive.q_m)[al.rows][c.w]
        meas_phi = np.asarray(drive.roll_rad)[al.rows][c.w]
    fig, ax = c.subplots(3, 2, (11, 8), sharex=True)
    rows = (('q_m', 'dq', 'ddq'), ('roll_rad', 'droll', 'ddroll'))
    labels = (('q (mm)', 'dq (mm/s)', 'ddq (m/s²)'),
              ('phi (mrad)', 'dphi (mrad/s)', 'ddphi (rad/s²)'))
    scales = ((1e3, 1e3, 1.0), (1e3, 1e3, 1.0))
    for col in (0, 1):
        for r in range(3):
            a = ax[r, col]
            y = c.pick(rows[col][r]) * scales[col][r]
            if col == 0:
                for side in (0, 1):
                    if r == 0 and meas_q is not None:
                        a.plot(t, 1e3 * meas_q[:, side], color=_COLORS[side], lw=0.5,
                               alpha=0.35, label=f'measured {_SIDES[side]}')
                    a.plot(t, y[:, side], color=_COLORS[side], lw=1.0,
                           label=f'estimated {_SIDES[side]}')
            else:
                if r == 0 and meas_phi is not None:
                    a.plot(t, 1e3 * meas_phi, color='0.5', lw=0.5, alpha=0.5, label='measured')
                a.plot(t, y, color='tab:green', lw=1.0, label='estimated')
            a.set_ylabel(labels[col][r])
            a.grid(True, alpha=0.3)
            if r == 0:
                _legend(a, fontsize=7, loc='upper right')
        ax[2, col].set_xlabel('time (s)')
    ax[0, 0].set_title('suspension deflections', fontsize=10)
    ax[0, 1].set_title('roll angle', fontsize=10)
    c.finish(fig, 'states.png', 'States and rates')


def _body_figure(c: _Canvas) -> None:
    """Figures 6 and 7: body acceleration and body heave."""
    t = c.t
    fig, ax = c.subplots(2, 1, (11, 6), sharex=True)
    ax[0].plot(t, c.pick('body_accel_mps2'), color='tab:green', lw=1.0)
    ax[0].set_ylabel('dd z_s (m/s²)')
    ax[0].set_title('body heave acceleration', fontsize=10)
    ax[1].plot(t, 1e3 * c.pick('body_heave_m'), color='tab:green', lw=1.0)
    ax[1].set_ylabel('z_s (mm)')
    ax[1].set_title('body heave (band-limited)', fontsize=10)
    ax[1].set_xlabel('time (s)')
    for a in ax:
        a.grid(True, alpha=0.3)
    c.finish(fig, 'body.png', 'Body acceleration and heave')


def _wheels_figure(c: _Canvas) -> None:
    """Figure 8: wheel heaves."""
    t = c.t
    fig, ax = c.subplots(2, 1, (11, 6), sharex=True)
    zu = 1e3 * c.pick('wheel_heave_m')
    acc_u = c.pick('wheel_accel_mps2')
    for side in (0, 1):
        ax[0].plot(t, zu[:, side], color=_COLORS[side], lw=1.0, label=_SIDES[side])
        ax[1].plot(t, acc_u[:, side], color=_COLORS[side], lw=0.8, label=_SIDES[side])
    ax[0].set_ylabel('z_u (mm)')
    ax[0].set_title('wheel heaves (band-limited)', fontsize=10)
    ax[1].set_ylabel('dd z_u (m/s²)')
    ax[1].set_title('wheel accelerations', fontsize=10)
    ax[1].set_xlabel('time (s)')
    for a in ax:
        a.grid(True, alpha=0.3)
        _legend(a, fontsize=7, loc='upper right')
    c.finish(fig, 'wheels.png', 'Wheel heaves')


def _profile_figure(c: _Canvas, p: _Profiles, profile_window_m: float) -> None:
    """Figure 9: the band-passed profile against the truth or the reference, and the error."""
    x, road, up = p.x, p.road, p.up
    fig, ax = c.subplots(3, 1, (11, 8), sharex=True)
    conv_x = x[c.al.converged[up]] if c.al.converged[up].any() else x
    x0 = conv_x[0] + max(0.0, conv_x[-1] - conv_x[0] - profile_window_m) / 3.0
    pw = (x >= x0) & (x <= x0 + profile_window_m)
    for side in (0, 1):
        a = ax[side]
        if p.bp_est is not None:
            a.plot(x[pw], 1e3 * p.bp_est[pw, side], color=_COLORS[side], lw=1.2,
                   label='estimated')
            if p.bp_true is not None:
                a.plot(x[pw], 1e3 * p.bp_true[pw, side], label=p.against, **_TRUTH)
                ax[2].plot(x[pw], 1e3 * (p.bp_est[pw, side] - p.bp_true[pw, side]),
                           color=_COLORS[side], lw=0.9, label=_SIDES[side])
            a.set_ylabel('0.5-30 m band (mm)', fontsize=8)
        else:
            a.plot(x[pw], 1e3 * road[pw, side], color=_COLORS[side], lw=1.0, label='estimated')
            a.set_ylabel('elevation (mm)')
        a.set_title(f'{_SIDES[side]} wheel path', fontsize=10)
    ax[2].axhline(0.0, color='k', lw=0.5)
    ax[2].set_ylabel('error (mm)')
    ax[2].set_title(f'error: estimated - {p.against}' if p.bp_true is not None
                    else 'error: no truth or reference', fontsize=10)
    ax[2].set_xlabel('distance (m)')
    for a in ax:
        a.grid(True, alpha=0.3)
        _legend(a, fontsize=7, loc='upper right')
    c.finish(fig, 'profile.png', 'Road profile (100 m window)')


def _loads_figure(c: _Canvas) -> None:
    """Figure 10: wheel loads (max(0, F)) and LTR against the truth, the load error."""
    t, al = c.t, c.al
    fig, ax = c.subplots(4, 1, (11, 10), sharex=True)
    raw = c.pick('wheel_load_n')
    load = np.maximum(raw, 0.0) / 1e3
    true = al.true_load_n[c.w] / 1e3 if al.true_load_n is not None else None
    for side in (0, 1):
        a = ax[side]
        a.plot(t, load[:, side], color=_COLORS[side], lw=1.2, label='estimated, max(0, F)')
        if true is not None:
            a.plot(t, true[:, side], label='truth', **_TRUTH)
        if c.static_load_n is not None:
            a.axhline(c.static_load_n[side] / 1e3, color='0.45', lw=0.9, ls=':',
                      label=f'static load {c.static_load_n[side] / 1e3:.1f} kN')
        if true is not None:
            ax[2].plot(t, 1e3 * (raw[:, side] / 1e3 - true[:, side]), color=_COLORS[side],
                       lw=0.9, label=_SIDES[side])
        below = int(np.count_nonzero(raw[:, side] < 0.0))
        a.set_ylabel(f'F_n {_SIDES[side]} (kN)')
        a.set_title(f'{_SIDES[side]} wheel load' + (f' ({below} samples of this window below '
                                                     'zero, drawn at 0)' if below else ''),
                    fontsize=10)
    ax[2].axhline(0.0, color='k', lw=0.5)
    ax[2].set_ylabel('error (N)')
    ax[2].set_title('load error: estimated - truth' if true is not None
                    else 'load error: no truth in the bag', fontsize=10)
    ltr = c.pick('ltr')
    ax[3].plot(t, ltr, color='tab:green', lw=1.2, label='estimated')
    if true is not None:
        ax[3].plot(t, (true[:, 1] - true[:, 0]) / (true[:, 0] + true[:, 1]), label='truth',
                   **_TRUTH)
    ax[3].set_ylabel('LTR')
    ax[3].set_title('load transfer ratio (F_right - F_left) / (F_left + F_right)', fontsize=10)
    ax[3].set_xlabel('time (s)')
    for a in ax:
        a.grid(True, alpha=0.3)
        _legend(a, fontsize=7, loc='upper right')
    c.finish(fig, 'loads.png', 'Vertical wheel loads and load transfer ratio (2 s window)')


def envelope(x: np.ndarray, y: np.ndarray, columns: int = ENVELOPE_COLUMNS
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per pixel column (``columns`` equal bins of ``x``): the bin centre, min and max of
    ``y`` (NaN where a bin is empty); the points themselves when there are fewer."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    if x.size <= 2 * columns or x[-1] <= x[0]:
        return x, y, y
    edges = np.linspace(x[0], x[-1], columns + 1)
    lo = np.full(columns, np.inf)
    hi = np.full(columns, -np.inf)
    if np.all(x[1:] >= x[:-1]):
        # sorted (time, or distance along the drive): each bin is one stretch of samples,
        # reduced in one pass (ufunc.at, per sample, costs ~10x more)
        starts = np.searchsorted(x, edges[1:-1], side='left')    # bin j: x >= edges[j]
        bounds = np.concatenate([[0], starts, [x.size]])
        full = np.flatnonzero(bounds[1:] > bounds[:-1])
        lo[full] = np.minimum.reduceat(y, bounds[full])
        hi[full] = np.maximum.reduceat(y, bounds[full])
    else:
        b = np.clip(np.searchsorted(edges, x, side='right') - 1, 0, columns - 1)
        np.minimum.at(lo, b, y)
        np.maximum.at(hi, b, y)
    empty = ~np.isfinite(lo)
    lo[empty] = hi[empty] = np.nan
    return 0.5 * (edges[:-1] + edges[1:]), lo, hi


def _band(ax, x, y, color: str, label: str, *, truth: bool = False) -> None:
    """The envelope of ``y`` over ``x``: a coloured band for an estimate, a grey band with a
    dashed outline behind it for a truth."""
    xc, lo, hi = envelope(x, y)
    if truth:
        ax.fill_between(xc, lo, hi, color='0.75', lw=0, zorder=1)
        ax.plot(xc, hi, lw=0.4, ls='--', color='k', zorder=1, label=label)
        ax.plot(xc, lo, lw=0.4, ls='--', color='k', zorder=1)
    else:
        ax.fill_between(xc, lo, hi, color=color, alpha=0.6, lw=0, label=label, zorder=2)


def _overview_figure(c: _Canvas, p: _Profiles, segments: dict[str, np.ndarray] | None) -> None:
    """The whole drive: LTR over time, the band-passed profiles, the IRI per segment."""
    al = c.al
    fig, ax = c.subplots(4, 1, (11, 11))
    _band(ax[0], al.t_s, al.pick(c.est, 'ltr'), 'tab:green', 'estimated')
    if al.true_load_n is not None:
        tl = al.true_load_n
        _band(ax[0], al.t_s, (tl[:, 1] - tl[:, 0]) / (tl[:, 0] + tl[:, 1]), 'k', 'truth',
              truth=True)
    ax[0].set_ylabel('LTR')
    ax[0].set_xlabel('time (s)')
    ax[0].set_title('load transfer ratio over the drive, min-max per pixel column '
                    '(|LTR| = 1: a wheel lifts off)', fontsize=10)
    from road_force_estimator.core.units import units as unit_system

    u = unit_system(c.units)
    xs = p.x * u.length_per_m
    for side in (0, 1):
        a = ax[1 + side]
        if p.bp_est is not None:
            _band(a, xs, 1e3 * p.bp_est[:, side], _COLORS[side], f'estimated {_SIDES[side]}')
            if p.bp_true is not None:
                _band(a, xs, 1e3 * p.bp_true[:, side], 'k', f'{p.against} {_SIDES[side]}',
                      truth=True)
            a.set_ylabel('0.5-30 m band (mm)', fontsize=8)
        a.set_xlabel(f'distance ({u.length_unit})')
        a.set_title(f'road profile over the drive, {_SIDES[side]} wheel path (min-max per '
                    'pixel column)', fontsize=10)
    for a in ax[:3]:
        _legend(a, fontsize=7, loc='upper right')
    if segments is not None and len(segments['start_m']):
        _iri_bars(ax[3], segments, p.against, c.units)
    for a in ax:
        a.grid(True, alpha=0.3)
    c.finish(fig, 'overview.png', 'The whole drive')


#: The IRI bars reach at most this fraction of their axes' height (the legend above).
LEGEND_CLEAR = 0.7


def _iri_bars(ax, segments: dict[str, np.ndarray], against: str, units: str = 'si') -> None:
    """IRI per segment in ``units``: estimated and true (or reference), left and right, over
    FHWA's condition bands."""
    from road_force_estimator.core.units import condition_bands, units as unit_system

    u = unit_system(units)
    k = u.iri_per_m_per_km
    mid = u.length(1.0) * 0.5 * (segments['start_m'] + segments['end_m'])
    width = 0.2 * u.length(1.0) * float(np.min(segments['end_m'] - segments['start_m']))
    offsets = ((-1.5, 'iri_left_m_per_km', _COLORS[0], 'estimated left', None),
               (-0.5, 'iri_right_m_per_km', _COLORS[1], 'estimated right', None),
               (0.5, 'true_iri_left_m_per_km', 'white', f'{against} left', _COLORS[0]),
               (1.5, 'true_iri_right_m_per_km', 'white', f'{against} right', _COLORS[1]))
    for off, key, color, label, edge in offsets:
        if np.isfinite(segments[key]).any():
            ax.bar(mid + off * width, k * segments[key], width=width, color=color, label=label,
                   edgecolor=edge or color, hatch='//' if edge else None, zorder=3)
    top = np.nanmax([np.nanmax(segments[key]) if np.isfinite(segments[key]).any() else 0.0
                     for _, key, _, _, _ in offsets]) * k
    good, poor = condition_bands(u)
    # the bars in the lower 70 % of the axes: the legend's one row above them covers none
    ymax = max(top / LEGEND_CLEAR if top > 0.0 else 1.0, 1.1 * good)
    for (name, colour), lo, hi in zip(_BANDS, (0.0, good, poor), (good, poor, max(ymax, poor))):
        ax.axhspan(lo, hi, color=colour, zorder=0)
        if lo < ymax:
            ax.text(0.005, min(0.5 * (lo + min(hi, ymax)), ymax), name, fontsize=8,
                    transform=ax.get_yaxis_transform(), va='center', color='0.3')
    ax.set_ylim(0.0, ymax)
    ax.set_ylabel(f'IRI ({u.iri_unit})')
    ax.set_xlabel(f'segment centre ({u.length_unit})')
    ax.set_title(f'IRI per segment; FHWA condition: good < {good:.3g}, fair, poor > '
                 f'{poor:.3g} {u.iri_unit}', fontsize=10)
    _legend(ax, fontsize=7, loc='upper center', ncol=4, borderaxespad=0.3)
