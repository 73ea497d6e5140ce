"""IRI per segment of a long profile, a chunk of intervals at a time (issue 21).

:func:`segment_iri` gives :func:`.iri.iri_segments` of one track and the intervals per
segment (:func:`.iri.interval_counts`) with temporaries of one chunk instead of several
arrays of the whole profile: the same steps in the same order (the slope over the base, the
golden car's modal first-order filters with their state carried from chunk to chunk, the sums
per segment in interval order), so the same numbers bit for bit (test_iri_chunks). Profiles
that are not evenly spaced (resampled by :func:`.iri.rectified_slope`) go through
:func:`.iri.iri_segments` in one piece.

This module imports numpy and scipy only (core).
"""
from __future__ import annotations

import numpy as np

from road_force_estimator.core import iri as iri_mod
from road_force_estimator.core.scipy_signal import signal as _signal

__all__ = ['CHUNK', 'segment_iri']

#: Intervals per chunk.
CHUNK = 1 << 18


def _uniform_step(x: np.ndarray) -> float | None:
    """The mean spacing (m) of a strictly increasing profile that :func:`.iri.
    _evenly_spaced` keeps as it is, else None (checked a chunk at a time)."""
    if x.size < 2:
        return None
    span = x[-1] - x[0]
    mean_step = span / (x.size - 1)
    tol = iri_mod.EVEN_SPACING_RTOL * max(mean_step, abs(x[-1]))
    for a in range(0, x.size - 1, CHUNK):
        steps = np.diff(x[a:a + CHUNK + 1])
        if np.any(steps <= 0.0) or not np.all(np.abs(steps - mean_step) <= tol):
            return None
    return float(mean_step)


def _bins_add(acc: np.ndarray, seg: np.ndarray, w: np.ndarray | None) -> None:
    """``acc[j] += w[seg == j]`` (or the count) in order from ``acc``'s values."""
    if seg.size == 0:
        return
    lo, hi = int(seg.min()), int(seg.max()) + 1
    carry = acc[lo:hi]
    ones = np.ones(seg.size) if w is None else w
    acc[lo:hi] = np.bincount(np.concatenate([np.arange(hi - lo), seg - lo]),
                             np.concatenate([carry, ones]), minlength=hi - lo)


def segment_iri(x: np.ndarray, z: np.ndarray, edges: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """``(IRI (m/km) per segment, intervals per segment)`` of one track: ``z`` (m) at the
    strictly increasing ``x`` (m), segments ``edges`` (m); as :func:`.iri.iri_segments` and
    :func:`.iri.interval_counts` (ValueError where they raise)."""
    x = np.asarray(x, dtype=float)
    h = np.asarray(z, dtype=float)
    edges = np.asarray(edges, dtype=float)
    dx = _uniform_step(x)
    if dx is None or not np.isfinite(h).all():
        return (iri_mod.iri_segments(x, h, edges), iri_mod.interval_counts(x, edges))
    k_base = max(1, int(round(iri_mod.BASE_LENGTH_M / dx)))
    i11 = int(round(iri_mod.INIT_LENGTH_M / dx))
    if x.size <= max(i11, k_base):
        raise ValueError(f'profile length {x[-1] - x[0]:.3g} m: IRI needs at least '
                         f'{iri_mod.INIT_LENGTH_M:g} m (the initialisation length)')
    s0 = (h[i11] - h[0]) / iri_mod.INIT_LENGTH_M
    st, pr = iri_mod.transition(dx)
    lam, vec = np.linalg.eig(st)
    inv = np.linalg.inv(vec)
    beta = inv @ pr
    eta0 = inv @ np.array([s0, 0.0, s0, 0.0])
    out = np.array([1.0, 0.0, -1.0, 0.0]) @ vec
    modes = [j for j in range(4) if not lam[j].imag < 0.0]
    zi = {j: [lam[j] * eta0[j]] for j in modes}
    lfilter = _signal().lfilter
    k = edges.size - 1
    total = np.zeros(k)
    count = np.zeros(k)
    m = x.size - k_base
    for a in range(0, m, CHUNK):
        b = min(m, a + CHUNK)
        slope = (h[a + k_base:b + k_base] - h[a:b]) / (k_base * dx)
        rel = np.zeros(slope.size)
        for j in modes:
            eta, zi[j] = lfilter([beta[j]], [1.0, -lam[j]], slope, zi=zi[j])
            rel += (2.0 if lam[j].imag > 0.0 else 1.0) * (out[j] * eta).real
        position = x[0] + dx * (np.arange(a, b) + 0.5)
        seg = np.searchsorted(edges, position, side='right') - 1
        seg[position == edges[-1]] = k - 1
        inside = (seg >= 0) & (seg < k)
        _bins_add(total, seg[inside], np.abs(rel.real)[inside])
        _bins_add(count, seg[inside], None)
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.where(count > 0, 1000.0 * total / count, np.nan), count.astype(np.int64)
