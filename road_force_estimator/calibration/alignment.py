"""Alignment of a drive's odometer distance with a survey's distance (MODEL.md "Calibration").

The survey distance under the tires is ``offset + scale * x`` with ``x`` the drive's distance
(the integral of its speed, m): an unknown start offset and an odometer scale error. Both are
found by a normalised cross-correlation of the observer's estimated profile (the road the
estimator reconstructs from the drive with the nominal parameters) with the survey's, both
band-passed (:func:`road_force_estimator.core.metrics.profile_bandpass`, default 0.5-10 m) on a
common grid: for each scale of a grid fine enough that the drive's far end moves by at most
half a grid step between scales, every offset at once by FFT. The normalisation is Pearson's
over the overlap of each candidate (the drive may run off either end of the survey). A best
correlation below ``min_correlation`` means the drive is not on that road: refused.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np
from scipy import signal

# The core API the alignment uses (one place, for the lead to re-point).
from road_force_estimator.core.metrics import profile_bandpass
from road_force_estimator.core.road import RoadProfile

__all__ = ['Alignment', 'AlignmentError', 'align', 'DEFAULT_BAND_M', 'MIN_CORRELATION']

#: Wavelength band of the correlation (m).
DEFAULT_BAND_M = (0.5, 10.0)
#: Below this best normalised correlation the drive is refused (not on that road).
MIN_CORRELATION = 0.5
#: Grid spacing of the correlation (m).
GRID_M = 0.1
#: The first pass over the scales takes every COARSE_STEPS-th; the second the fine steps
#: around the best.
COARSE_STEPS = 8
#: Estimated profile dropped at the start of the drive (observer convergence), m.
SKIP_M = 10.0


class AlignmentError(ValueError):
    """The drive cannot be placed on the survey (no overlap, too weak a correlation)."""


@dataclass(frozen=True)
class Alignment:
    """Where the drive lies on the survey: ``survey_m = offset_m + scale * drive_m``.

    ``correlation`` is the best normalised correlation (Pearson, band-passed profiles),
    ``overlap_m`` the survey length it was computed over, ``offset_range_m`` and
    ``scale_range`` what was searched, ``scales_tried`` how many scales.
    """

    offset_m: float
    scale: float
    correlation: float
    overlap_m: float
    offset_range_m: tuple[float, float]
    scale_range: tuple[float, float]
    scales_tried: int

    def survey_m(self, drive_m):
        """Survey distance (m) of drive distance(s) ``drive_m`` (m)."""
        return self.offset_m + self.scale * np.asarray(drive_m, dtype=float)

    def as_dict(self) -> dict:
        """Plain values for reports."""
        return {'offset_m': self.offset_m, 'scale': self.scale,
                'odometer_error_percent': (self.scale - 1.0) * 100.0,
                'correlation': self.correlation, 'overlap_m': self.overlap_m,
                'offset_range_m': list(self.offset_range_m),
                'scale_range': list(self.scale_range), 'scales_tried': self.scales_tried}


def _bandpassed(x: np.ndarray, z: np.ndarray, band: tuple[float, float]) -> np.ndarray:
    return profile_bandpass(x, z, short_m=band[0], long_m=band[1])


def _drive_signal(drive_m: np.ndarray, profile_m: np.ndarray, band) -> tuple[float, np.ndarray]:
    """The estimated profile on a 0.1 m grid of drive distance, band-passed: (x_0, (k, 2))."""
    keep = np.concatenate(([True], np.diff(drive_m) > 0.0))
    x, z = drive_m[keep], profile_m[keep]
    first = x[0] + min(SKIP_M, 0.1 * (x[-1] - x[0]))
    grid = np.arange(first, x[-1], GRID_M)
    if grid.size < 16:
        raise AlignmentError(f'the drive covers {x[-1] - x[0]:.1f} m: too short to align')
    zg = np.column_stack([np.interp(grid, x, z[:, i]) for i in range(2)])
    return float(grid[0]), _bandpassed(grid, zg, band)


def _survey_signal(survey: RoadProfile, band, lo: float, hi: float):
    """The survey band-passed on the grid [lo, hi] (zeros and mask 0 outside it)."""
    xs = np.arange(survey.start_m, survey.end_m, GRID_M)
    zs = _bandpassed(xs, survey.elevation_at(xs), band)
    grid = lo + GRID_M * np.arange(int(math.ceil((hi - lo) / GRID_M)) + 1)
    inside = (grid >= xs[0]) & (grid <= xs[-1])
    g = np.zeros((grid.size, 2))
    g[inside] = np.column_stack([np.interp(grid[inside], xs, zs[:, i]) for i in range(2)])
    return grid, g, inside.astype(float)


def _correlations(g, mask_g, e):
    """Normalised correlation and overlap count for every lag ('valid' lags of g)."""
    mask_e = np.ones(e.shape[0])
    num = sum(signal.correlate(g[:, i], e[:, i], mode='valid', method='fft') for i in range(2))
    ge2 = sum(signal.correlate(g[:, i] ** 2, mask_e, mode='valid', method='fft')
              for i in range(2))
    ee2 = sum(signal.correlate(mask_g, e[:, i] ** 2, mode='valid', method='fft')
              for i in range(2))
    count = signal.correlate(mask_g, mask_e, mode='valid', method='fft')
    with np.errstate(invalid='ignore', divide='ignore'):
        rho = num / np.sqrt(np.maximum(ge2, 0.0) * np.maximum(ee2, 0.0))
    return np.nan_to_num(rho, nan=-1.0), count


def _refine(rho: np.ndarray, k: int) -> float:
    """Sub-grid lag of a peak by a parabola through three points."""
    if 0 < k < rho.size - 1:
        a, b, c = rho[k - 1], rho[k], rho[k + 1]
        den = a - 2.0 * b + c
        if den < 0.0:
            return k + 0.5 * (a - c) / den
    return float(k)


class _Scan:
    """The best normalised correlation over scales (each scale: every offset by FFT)."""

    def __init__(self, g, mask_g, grid, e_drive, x0, lo, hi, min_overlap_m) -> None:
        self.g, self.mask_g, self.grid, self.e_drive = g, mask_g, grid, e_drive
        self.x0, self.lo, self.hi, self.min_overlap_m = x0, lo, hi, min_overlap_m
        self.t_drive = x0 + GRID_M * np.arange(e_drive.shape[0])

    def at(self, s: float) -> tuple[float, float, float, float]:
        """(correlation, scale, offset m, overlap m) of the best offset at scale ``s``."""
        x0, grid = self.x0, self.grid
        # The drive's estimate at survey spacing: sample j at drive distance x0 + j dx / s.
        xj = x0 + GRID_M / s * np.arange(int(self.e_drive.shape[0] * s))
        e = np.column_stack([np.interp(xj, self.t_drive, self.e_drive[:, c]) for c in range(2)])
        # Lag k puts e[0] at grid[k] = offset + s x0.
        rho, count = _correlations(self.g, self.mask_g, e)
        offsets = grid[0] + np.arange(rho.size) * GRID_M - s * x0
        ok = (count * GRID_M >= self.min_overlap_m) & (offsets >= self.lo) & (offsets <= self.hi)
        if not np.any(ok):
            return (-2.0, float(s), 0.0, 0.0)
        k = int(np.argmax(np.where(ok, rho, -2.0)))
        offset = grid[0] + _refine(rho, k) * GRID_M - s * x0
        return (float(rho[k]), float(s), float(offset), float(count[k] * GRID_M))

    def best(self, scales, progress, start: float, share: float):
        out = (-2.0, 1.0, 0.0, 0.0)
        for i, s in enumerate(scales):
            out = max(out, self.at(s))
            if progress is not None:
                progress(start + share * (i + 1) / len(scales))
        return out


def align(drive_m, profile_m, survey: RoadProfile, *, start_m: float = 0.0,
          search_m: float = 50.0, scale_error: float = 0.03, band=DEFAULT_BAND_M,
          min_correlation: float = MIN_CORRELATION, min_overlap_m: float = 50.0,
          progress=None) -> Alignment:
    """Find the start offset and odometer scale of a drive on a survey.

    Parameters
    ----------
    drive_m : ndarray (n,)
        Drive distance of each estimate (m, non-decreasing).
    profile_m : ndarray (n, 2)
        The observer's estimated road [left, right] (m).
    survey : RoadProfile
        The surveyed road (as the tires follow it: enveloped).
    start_m : float
        Expected survey distance at drive distance 0 (m); searched +- ``search_m``.
    scale_error : float
        Odometer scale searched in ``1 +- scale_error``.
    min_correlation : float
        Refuse below this best normalised correlation.
    min_overlap_m : float
        Candidates overlapping the survey less than this are ignored (m).
    progress : callable(fraction), optional

    Raises
    ------
    AlignmentError
        No candidate overlaps the survey, or the best correlation is below the threshold.
    """
    drive_m = np.asarray(drive_m, dtype=float)
    x0, e_drive = _drive_signal(drive_m, np.asarray(profile_m, dtype=float), band)
    length = e_drive.shape[0] * GRID_M
    lo_s, hi_s = 1.0 - scale_error, 1.0 + scale_error
    lo, hi = start_m - search_m, start_m + search_m
    if hi + hi_s * (x0 + length) < survey.start_m + min_overlap_m or \
            lo + lo_s * x0 > survey.end_m - min_overlap_m:
        raise AlignmentError(
            f'no overlap: the drive ({drive_m[-1] - drive_m[0]:.0f} m from survey distance '
            f'{lo:g}..{hi:g} m) never covers {min_overlap_m:g} m of the survey '
            f'[{survey.start_m:g}, {survey.end_m:g}] m (see --start-offset)')
    grid, g, mask_g = _survey_signal(survey, band, lo + lo_s * x0,
                                     hi + hi_s * (x0 + length) + GRID_M)
    step = min(1e-3, 0.5 * GRID_M / max(length + x0, 1.0))
    coarse = np.arange(lo_s, hi_s + 1e-12, COARSE_STEPS * step)
    scan = _Scan(g, mask_g, grid, e_drive, x0, lo, hi, min_overlap_m)
    best = scan.best(coarse, progress, 0.0, 0.8)
    fine = np.arange(best[1] - COARSE_STEPS * step, best[1] + COARSE_STEPS * step + 1e-12,
                     step)
    fine = fine[(fine >= lo_s - 1e-12) & (fine <= hi_s + 1e-12)]
    best = max(best, scan.best(fine, progress, 0.8, 0.2))
    count_s = coarse.size + fine.size
    rho, scale, offset, overlap = best
    if rho <= -2.0:
        raise AlignmentError(f'no overlap of at least {min_overlap_m:g} m between the drive and '
                             f'the survey [{survey.start_m:g}, {survey.end_m:g}] m')
    if rho < min_correlation:
        raise AlignmentError(
            f'the drive does not match the survey: best correlation {rho:.2f} < '
            f'{min_correlation:g} (offset {offset:.1f} m, scale {scale:.4f}): not on that road?')
    return Alignment(offset, scale, rho, overlap, (lo, hi), (lo_s, hi_s), count_s)
