"""Profiles compared as profilers are judged: the IRI-filtered cross correlation.

The method of ProVAL's profile comparison, with which AASHTO R56 and ASTM E950 rate the
repeatability and the accuracy of inertial profilers (Karamihas, S. M., 2004, "Development of
cross correlation for objective comparison of profiles", International Journal of Vehicle
Design 36(2/3), 173-193; the FHWA's ProVAL implements it):

1. both profiles go through the IRI filter at their own sample interval: the golden
   quarter-car's signed output with its 250 mm slope base (ASTM E1926,
   :func:`road_force_estimator.core.iri.filtered_slope`), so that the comparison weighs the
   wavelengths the way the IRI does (and a grade or an offset counts for nothing);
2. the filtered signals, p (the profile judged) and q (the reference), are compared over the
   reference's window at each offset delta of p, and the rating is the largest value:

       rho = max_delta  sum (p_i(delta) - p_mean) (q_i - q_mean)
                        / max( sum (p_i(delta) - p_mean)^2, sum (q_i - q_mean)^2 )

   that is, the correlation coefficient ``r = cov / (sigma_p sigma_q)`` times the ratio of the
   smaller standard deviation to the larger, Karamihas' penalty on a difference in amplitude:
   a profile scaled by k rates min(k, 1/k) against its original, a copy rates 1, a copy
   shifted by an offset inside the search rates 1, an independent profile about 0 and an
   inverted copy -1 at zero offset (the search over offsets then finds the best, positive or
   not, of the negated autocorrelation).

The offset search: ProVAL shifts one profile against the other to the offset of best
agreement; the +-1 m window is issue 21's (a synchronised recording is not off by more). The
offsets step by the common grid's spacing: both filtered signals are linearly interpolated
onto a grid of the finer of their two sample intervals (not below :data:`MIN_GRID_M`).

This module imports numpy only, with :mod:`.iri` and :mod:`.segments` (core).
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from road_force_estimator.core.iri import filtered_slope
from road_force_estimator.core.segments import segment_bounds

__all__ = ['MAX_LAG_M', 'MIN_GRID_M', 'Correlation', 'SegmentCorrelations', 'iri_filter',
           'rating_at_lags', 'cross_correlation', 'segment_correlation']

#: Offset search window (m): +-1 m (issue 21).
MAX_LAG_M = 1.0
#: The finest common grid (m): bounds the work on very fine recordings.
MIN_GRID_M = 0.01


@dataclass(frozen=True)
class Correlation:
    """The rating of one profile against a reference over one window.

    Attributes
    ----------
    rating : float
        rho at the best offset (dimensionless, at most 1).
    lag_m : float
        The best offset (m): p read ``lag_m`` further along than q matches q best.
    correlation : float
        The correlation coefficient r at that offset (no amplitude penalty).
    spread_ratio : float
        sigma_p / sigma_q at that offset (1 when the amplitudes agree).
    """

    rating: float
    lag_m: float
    correlation: float
    spread_ratio: float


_NAN = Correlation(math.nan, math.nan, math.nan, math.nan)


def iri_filter(distance_m, elevation_m, *, dx_m: float | None = None
               ) -> tuple[np.ndarray, np.ndarray, float]:
    """A profile through the IRI filter at its sample interval: ``(position_m, filtered, dx_m)``.

    ``filtered`` is the signed quarter-car output (m/m) at the midpoints ``position_m`` of its
    intervals, ``dx_m`` the interval used (:func:`road_force_estimator.core.iri.filtered_slope`,
    which resamples an uneven profile at min(median spacing, 0.25 m)).
    """
    out = filtered_slope(distance_m, elevation_m, dx_m=dx_m)
    return out.position_m, out.slope, out.dx_m


def rating_at_lags(p: np.ndarray, q: np.ndarray, max_shift: int
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """rho, r and sigma_p / sigma_q at every offset: each (2 max_shift + 1,).

    Parameters
    ----------
    p : ndarray (m + 2 max_shift,)
        The signal judged on the common grid, ``max_shift`` extra samples at each end
        (``p[i + max_shift]`` is at ``q[i]``'s position).
    q : ndarray (m,), m >= 2
        The reference on the same grid.
    max_shift : int
        Offsets -max_shift .. max_shift samples; entry j is the offset j - max_shift.
    """
    m = q.size
    qc = q - np.mean(q)
    sqq = float(qc @ qc)
    cp = np.concatenate([[0.0], np.cumsum(p)])
    cp2 = np.concatenate([[0.0], np.cumsum(p * p)])
    j = np.arange(2 * max_shift + 1)
    sp = cp[j + m] - cp[j]
    spp = cp2[j + m] - cp2[j] - sp * sp / m
    # sum (p - p_mean)(q - q_mean) = sum p (q - q_mean): q - q_mean sums to zero
    cov = np.array([p[k:k + m] @ qc for k in j.tolist()])
    with np.errstate(invalid='ignore', divide='ignore'):
        rho = cov / np.maximum(spp, sqq)
        r = cov / np.sqrt(spp * sqq)
        ratio = np.sqrt(spp / sqq)
    return rho, r, ratio


def _common_grid(xp: np.ndarray, fp: np.ndarray, dxp: float, xq: np.ndarray, fq: np.ndarray,
                 dxq: float, start_m: float, end_m: float, max_lag_m: float
                 ) -> tuple[np.ndarray, np.ndarray, int, np.ndarray]:
    """p and q interpolated onto the common grid over [start, end] (p with the lag margin)."""
    dx = max(min(dxp, dxq), MIN_GRID_M)
    shift = int(math.floor(max_lag_m / dx + 1e-9))
    m = int(math.floor((end_m - start_m) / dx + 1e-9)) + 1
    grid = start_m + dx * np.arange(m)
    ext = start_m + dx * np.arange(-shift, m + shift)
    return np.interp(ext, xp, fp), np.interp(grid, xq, fq), shift, grid


def _window(xp: np.ndarray, xq: np.ndarray, max_lag_m: float, start_m: float | None,
            end_m: float | None) -> tuple[float, float]:
    """The judged window: inside q, and inside p by the lag window at each end."""
    lo = max(float(xq[0]), float(xp[0]) + max_lag_m)
    hi = min(float(xq[-1]), float(xp[-1]) - max_lag_m)
    lo = lo if start_m is None else max(lo, float(start_m))
    hi = hi if end_m is None else min(hi, float(end_m))
    if not hi > lo:
        raise ValueError(f'no overlap to judge: window [{lo:g}, {hi:g}] m (the profile judged '
                         f'must cover the reference +-{max_lag_m:g} m)')
    return lo, hi


def _best(p: np.ndarray, q: np.ndarray, shift: int, dx: float) -> Correlation:
    """The rating at the best offset (NaN when no offset gives a finite rating)."""
    rho, r, ratio = rating_at_lags(p, q, shift)
    if not np.isfinite(rho).any():
        return _NAN
    j = int(np.nanargmax(rho))
    return Correlation(float(rho[j]), (j - shift) * dx, float(r[j]), float(ratio[j]))


def cross_correlation(distance_m, elevation_m, reference_distance_m, reference_elevation_m,
                      *, max_lag_m: float = MAX_LAG_M, start_m: float | None = None,
                      end_m: float | None = None) -> Correlation:
    """The IRI-filtered cross correlation of one wheel path against its reference.

    Parameters
    ----------
    distance_m, elevation_m : array_like (n,)
        The profile judged (m), distance non-decreasing (a standstill's repeats are dropped).
    reference_distance_m, reference_elevation_m : array_like (n_ref,)
        The reference (the true profile), on its own samples (m).
    max_lag_m : float
        Offset search +-``max_lag_m`` (m), >= 0; 0 compares at zero offset only.
    start_m, end_m : float, optional
        The window judged, in the reference's distance (m); default: all of it where the
        profile judged covers it +-``max_lag_m``.

    Returns
    -------
    Correlation

    Raises
    ------
    ValueError
        A profile too short for the IRI filter (11 m), or no overlap to judge.
    """
    if not (max_lag_m >= 0.0 and math.isfinite(max_lag_m)):
        raise ValueError(f'max_lag_m = {max_lag_m!r}: must be >= 0')
    xp, fp, dxp = iri_filter(distance_m, elevation_m)
    xq, fq, dxq = iri_filter(reference_distance_m, reference_elevation_m)
    lo, hi = _window(xp, xq, max_lag_m, start_m, end_m)
    p, q, shift, grid = _common_grid(xp, fp, dxp, xq, fq, dxq, lo, hi, max_lag_m)
    if grid.size < 2:
        return _NAN
    return _best(p, q, shift, float(grid[1] - grid[0]))


@dataclass(frozen=True)
class SegmentCorrelations:
    """The rating of a drive and of its segments (:func:`segment_correlation`)."""

    whole: Correlation                #: over the whole judged window
    edges_m: np.ndarray               #: segment edges (m), (k + 1,)
    segments: tuple[Correlation, ...]  #: per segment, (k,)


def segment_correlation(distance_m, elevation_m, reference_distance_m,
                        reference_elevation_m, edges_m=None, *,
                        segment_length_m: float = 100.0, max_lag_m: float = MAX_LAG_M,
                        start_m: float | None = None, end_m: float | None = None
                        ) -> SegmentCorrelations:
    """The cross correlation of the whole window and per segment.

    Both profiles are filtered once over their whole length; the window and each segment (in
    the reference's distance) are rated with their own offset search. Segments as
    :func:`road_force_estimator.core.segments.segment_bounds` cuts the judged window (a
    remainder under half a segment joins the one before) unless ``edges_m`` are given (they
    are clipped to the judged window; a segment left with under 2 grid points is NaN). Other
    arguments as :func:`cross_correlation`.
    """
    if not (max_lag_m >= 0.0 and math.isfinite(max_lag_m)):
        raise ValueError(f'max_lag_m = {max_lag_m!r}: must be >= 0')
    xp, fp, dxp = iri_filter(distance_m, elevation_m)
    xq, fq, dxq = iri_filter(reference_distance_m, reference_elevation_m)
    lo, hi = _window(xp, xq, max_lag_m, start_m, end_m)
    edges = (segment_bounds(lo, hi, segment_length_m) if edges_m is None
             else np.asarray(edges_m, dtype=float))
    p, q, shift, grid = _common_grid(xp, fp, dxp, xq, fq, dxq, lo, hi, max_lag_m)
    if grid.size < 2:
        return SegmentCorrelations(_NAN, edges, (_NAN,) * (edges.size - 1))
    dx = float(grid[1] - grid[0])
    idx = np.searchsorted(grid, np.clip(edges, lo, hi), side='left')
    idx[-1] = grid.size if edges[-1] >= hi else idx[-1]
    idx = np.maximum.accumulate(idx)
    out = tuple(_best(p[a:b + 2 * shift], q[a:b], shift, dx) if b - a >= 2 else _NAN
                for a, b in zip(idx[:-1].tolist(), idx[1:].tolist()))
    return SegmentCorrelations(_best(p, q, shift, dx), edges, out)
