"""Sensor-noise level of a sampled signal from its high-order differences (robust).

White noise dominates the ``n``-th (divided) differences of a densely sampled smooth signal;
their median absolute value gives its standard deviation, blind to events.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ['NOISE_DIFF_ORDER', 'MAD_GAUSSIAN', 'noise_std', 'normalised_differences', 'mad_std']

#: Order of the differences of the noise estimate.
NOISE_DIFF_ORDER = 6
#: The median absolute value of a zero-mean Gaussian, in standard deviations.
MAD_GAUSSIAN = 0.6744897501960817


def noise_std(x, t_s=None, order: int = NOISE_DIFF_ORDER) -> float:
    """White-noise standard deviation of a sampled signal from its ``order``-th differences.

    On an even grid ``Var(Delta^n y) = C(2n, n) sigma^2`` for white noise, while a smooth
    signal's n-th difference is ``y^(n) dt^n``, negligible at the sample rates of interest;
    the median absolute value makes it robust to events:
    ``sigma = median|Delta^n y| / 0.6745 / sqrt(C(2n, n))``. On an uneven grid (``t_s``) the
    n-th divided differences ``sum_j w_j y_j``, normalised by ``sqrt(sum_j w_j^2)``, take the
    place of ``Delta^n y / sqrt(C(2n, n))`` (the same numbers on an even grid).

    Parameters
    ----------
    x : array_like, shape (m,) or (m, c)
        Samples (c channels pooled).
    t_s : array_like, shape (m,), optional
        Sample times (s), increasing; None = evenly sampled.
    order : int

    Returns
    -------
    float
        The estimate (units of x); 0 for fewer than ``order + 2`` samples.
    """
    return mad_std(normalised_differences(x, t_s, order))


def normalised_differences(x, t_s=None, order: int = NOISE_DIFF_ORDER) -> np.ndarray:
    """``order``-th (divided) differences of x normalised to unit white-noise gain, flattened.

    See :func:`noise_std`; x (m,) or (m, c), the channels' differences concatenated.
    """
    x = np.asarray(x, dtype=float)
    x2 = x[:, None] if x.ndim == 1 else x
    m = x2.shape[0]
    if m < order + 2:
        return np.zeros(0)
    if t_s is None:
        d = np.diff(x2, order, axis=0) / math.sqrt(math.comb(2 * order, order))
        return d.T.reshape(-1)
    t = np.asarray(t_s, dtype=float)
    t = (t - t[0]) / max(float(np.median(np.diff(t))), 1e-300)   # steps of ~1
    win = np.lib.stride_tricks.sliding_window_view(t, order + 1)   # (m - n, n + 1)
    diff = win[:, :, None] - win[:, None, :]
    idx = np.arange(order + 1)
    diff[:, idx, idx] = 1.0
    w = 1.0 / np.prod(diff, axis=2)                                 # divided-difference weights
    w /= np.sqrt(np.sum(w * w, axis=1))[:, None]
    ys = np.lib.stride_tricks.sliding_window_view(x2, order + 1, axis=0)   # (m - n, c, n + 1)
    return np.einsum('kcj,kj->ck', ys, w).reshape(-1)


def mad_std(d: np.ndarray) -> float:
    """Standard deviation from the median absolute value (zero-mean Gaussian data)."""
    return float(np.median(np.abs(d)) / MAD_GAUSSIAN)

