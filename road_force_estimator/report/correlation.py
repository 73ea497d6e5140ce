"""The estimated profile rated as profilers are: the IRI-filtered cross correlation
(:mod:`road_force_estimator.core.profile_correlation`; ProVAL, AASHTO R56, ASTM E950) of each
wheel path with the truth, over the drive and per segment.

The estimate is placed at the estimator's own distance (what a profiler reports), the truth
at the distance truly travelled (the ground truth's, shifted to agree with the estimate's at
the first accepted sample): an odometer scale error shows as a growing offset, which the +-1 m
offset search absorbs only over short stretches. Without a true distance (a reference profile
aligned by :mod:`.alignment`) both are at the estimate's distance. Judged from 30 m after the
first converged sample (the quarter-car's and the estimator's start-up) to the end.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from road_force_estimator.core import metrics
from road_force_estimator.core import profile_correlation as pc
from road_force_estimator.report.alignment import Aligned

__all__ = ['correlation_figures']


def _true_distance(al: Aligned, drive) -> np.ndarray | None:
    """The truth's own travelled distance at the accepted rows, from the estimate's start."""
    truth = getattr(drive, 'truth', None)
    if truth is None or al.true_road_m is None or not al.rows.size:
        return None
    xt = np.asarray(truth.at(al.stamps_ns).distance_m, dtype=float)
    if not np.isfinite(xt).all():
        return None
    return xt - xt[0] + al.x_m[0]


def correlation_figures(est, al: Aligned, drive=None, edges_m: np.ndarray | None = None, *,
                        segment_length_m: float = 100.0) -> dict[str, Any]:
    """``profile_xcorr`` (left, right), ``profile_xcorr_lag_m`` (the best offsets, m),
    ``profile_xcorr_segments`` (``start_m``, ``end_m``, ``left``, ``right`` lists),
    ``profile_xcorr_segment_min`` and ``profile_xcorr_distance`` ('true' or 'estimated');
    empty when there is nothing to judge (no profile truth, a drive too short)."""
    truth = al.profile_truth
    if truth is None:
        return {}
    up = al.increasing() & np.isfinite(truth).all(axis=1)
    if np.count_nonzero(up) < 10 or not np.any(al.converged[up]):
        return {}
    x = al.x_m[up]
    xt_all = _true_distance(al, drive)
    xt = x if xt_all is None else xt_all[up]
    keep = np.concatenate([[True], np.diff(xt) > 0.0])      # the truth's own standstills
    road = al.pick(est, 'road_m')[up]
    start = float(x[np.argmax(al.converged[up])]) + metrics.BAND_LONG_M
    whole, lags, segs = [], [], []
    try:
        for side in (0, 1):
            res = pc.segment_correlation(x, road[:, side], xt[keep], truth[up][keep, side],
                                         edges_m, segment_length_m=segment_length_m,
                                         start_m=start)
            whole.append(res.whole.rating)
            lags.append(res.whole.lag_m)
            segs.append([c.rating for c in res.segments])
    except ValueError:
        return {}
    edges = res.edges_m
    lowest = np.array(segs, dtype=float)
    return {
        'profile_xcorr': [float(v) for v in whole],
        'profile_xcorr_lag_m': [float(v) for v in lags],
        'profile_xcorr_segments': {'start_m': [float(v) for v in edges[:-1]],
                                   'end_m': [float(v) for v in edges[1:]],
                                   'left': segs[0], 'right': segs[1]},
        'profile_xcorr_segment_min': (float(np.nanmin(lowest)) if np.isfinite(lowest).any()
                                      else math.nan),
        'profile_xcorr_distance': 'estimated' if xt_all is None else 'true',
    }
