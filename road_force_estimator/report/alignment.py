"""Estimate, truth and reference on one grid: the estimate's accepted samples.

:func:`align` puts the drive's ground truth (by stamp) or a reference profile (e.g. an LPA
survey, by distance from an offset found by correlation within +-:data:`REFERENCE_SEARCH_M`)
beside the estimates, and says which samples are judged (the estimator's ``converged``, else
from its settling time on).
"""
from __future__ import annotations

import math

import numpy as np

from road_force_estimator.core import metrics

__all__ = ['REFERENCE_SEARCH_M', 'Aligned', 'align', 'bandpass']

#: A reference profile is aligned with the drive within +- this distance (m).
REFERENCE_SEARCH_M = 10.0


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
    bp_est = bandpass(x, al.pick(est, 'road_m')[up])
    xr = np.asarray(reference.distance_m, dtype=float)
    bp_ref = bandpass(xr, np.asarray(reference.elevation_m, dtype=float))
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


def bandpass(x: np.ndarray, z: np.ndarray) -> np.ndarray | None:
    """Band-passed profile (0.5-30 m), or None when the drive is too short or too coarse."""
    try:
        return metrics.profile_bandpass(x, z)
    except ValueError:
        return None
