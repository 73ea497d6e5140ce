"""IRI of a long profile read a piece at a time, with :mod:`.iri`'s bits (issues 21, 32).

:func:`profile_iri` gives :func:`.iri.iri` and :func:`profile_segment_iri`
:func:`.iri.iri_segments` (per track) with :func:`.iri.interval_counts` of a profile of ``n``
points read ``rows`` at a time (the whole vehicle's spilled fused profile, the streamed
report's spilled profile), evenly spaced or not: the even grid of :func:`.iri.evenly_spaced`
made a piece at a time (:func:`_grid`: a standstill's repeats dropped, the test for even
spacing, the median step by counting, the points interpolated), the golden car's modal
first-order filters a chunk of :data:`CHUNK` intervals at a time with their state carried
(:func:`_filtered`), the sums per segment in interval order and the whole profile's mean by
numpy's pairwise summation (:func:`.pieces.pairwise_sum`): the same steps in the same order,
so the same numbers bit for bit (test_iri_chunks).

This module imports numpy and scipy only (core).
"""
from __future__ import annotations

from typing import Callable, Iterator

import numpy as np

from road_force_estimator.core import iri as iri_mod
from road_force_estimator.core.scipy_signal import signal as _signal

__all__ = ['CHUNK', 'profile_iri', 'profile_segment_iri']

#: Intervals per chunk.
CHUNK = 1 << 18


def _bins_add(acc: np.ndarray, seg: np.ndarray, w: np.ndarray | None) -> None:
    """``acc[j] += w[seg == j]`` (or the count) in order from ``acc``'s values."""
    if seg.size == 0:
        return
    lo, hi = int(seg.min()), int(seg.max()) + 1
    carry = acc[lo:hi]
    ones = np.ones(seg.size) if w is None else w
    acc[lo:hi] = np.bincount(np.concatenate([np.arange(hi - lo), seg - lo]),
                             np.concatenate([carry, ones]), minlength=hi - lo)


def _filtered(read_h: Callable, size: int, dx: float, span_m: float
              ) -> Iterator[tuple[int, int, np.ndarray]]:
    """:func:`.iri.filtered_slope` of an evenly spaced profile of ``size`` points ``dx``
    (m) apart (``read_h(lo, hi)``: their elevations ``lo:hi``, m; ``span_m`` its length):
    ``(a, b, the signed output of intervals a:b)`` a chunk of :data:`CHUNK` intervals at a
    time (the modal filters' state carried), its numbers bit for bit.

    Raises
    ------
    ValueError
        Shorter than the 11 m initialisation plus one slope base (as ``filtered_slope``).
    """
    k_base = max(1, int(round(iri_mod.BASE_LENGTH_M / dx)))
    i11 = int(round(iri_mod.INIT_LENGTH_M / dx))
    if size <= max(i11, k_base):
        raise ValueError(f'profile length {span_m:.3g} m: IRI needs at least '
                         f'{iri_mod.INIT_LENGTH_M:g} m (the initialisation length)')
    head = read_h(0, i11 + 1)
    s0 = (head[i11] - head[0]) / iri_mod.INIT_LENGTH_M
    st, pr = iri_mod.transition(dx)
    lam, vec = np.linalg.eig(st)
    inv = np.linalg.inv(vec)
    beta = inv @ pr
    eta0 = inv @ np.array([s0, 0.0, s0, 0.0])
    out = np.array([1.0, 0.0, -1.0, 0.0]) @ vec
    modes = [j for j in range(4) if not lam[j].imag < 0.0]
    zi = {j: [lam[j] * eta0[j]] for j in modes}
    lfilter = _signal().lfilter
    m = size - k_base
    for a in range(0, m, CHUNK):
        b = min(m, a + CHUNK)
        h = read_h(a, b + k_base)
        slope = (h[k_base:] - h[:b - a]) / (k_base * dx)
        rel = np.zeros(slope.size)
        for j in modes:
            eta, zi[j] = lfilter([beta[j]], [1.0, -lam[j]], slope, zi=zi[j])
            rel += (2.0 if lam[j].imag > 0.0 else 1.0) * (out[j] * eta).real
        yield a, b, rel


def _kept_pieces(n: int, read: Callable, rows: int
                 ) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """The points of a profile ``read(lo, hi) -> (x, z (k, w))`` of ``n`` that
    :func:`.iri.evenly_spaced` keeps (the first of repeated distances), a piece (``rows``
    read) at a time; checked as ``evenly_spaced`` checks (ValueError: a non-finite value,
    a distance that decreases)."""
    last = None
    for lo in range(0, n, rows):
        x, z = read(lo, min(lo + rows, n))
        x = np.asarray(x, dtype=float)
        z = np.asarray(z, dtype=float).reshape(x.size, -1)
        if not (np.isfinite(x).all() and np.isfinite(z).all()):
            raise ValueError('profile has non-finite values: remove them first')
        if not x.size:
            continue
        steps = np.diff(x if last is None else np.concatenate([[last], x]))
        if np.any(steps < 0.0):
            raise ValueError('distance_m decreases: it must be non-decreasing')
        keep = steps > 0.0 if last is not None else np.concatenate([[True], steps > 0.0])
        last = x[-1]
        if keep.any():
            yield x[keep], z[keep]


class _Kept:
    """:func:`_kept_pieces` by their index among the kept: :meth:`__call__` ``(lo, hi) ->
    (x, z (w, k))``, read forward (a read before the last starts over)."""

    def __init__(self, n: int, read: Callable, rows: int) -> None:
        self.n, self.read, self.rows = n, read, rows
        self._start()

    def _start(self) -> None:
        self.pos = 0                              # the kept index of the buffer's first
        self.x, self.z = np.empty(0), None
        self.pieces = _kept_pieces(self.n, self.read, self.rows)

    def __call__(self, lo: int, hi: int) -> tuple[np.ndarray, np.ndarray]:
        if lo < self.pos:
            self._start()
        while self.pos + self.x.size < hi:
            x, z = next(self.pieces, (None, None))
            if x is None:
                break
            self.x = np.concatenate([self.x, x])
            self.z = z if self.z is None else np.concatenate([self.z, z])
        cut = min(lo - self.pos, self.x.size)
        self.x, self.z, self.pos = self.x[cut:], self.z[cut:], self.pos + cut
        return self.x[:hi - lo], self.z[:hi - lo].T


def _grid(n: int, read: Callable, rows: int) -> tuple:
    """The even grid :func:`.iri.evenly_spaced` puts a profile of ``n`` points on, the
    profile read ``rows`` at a time (``read`` as :func:`profile_iri`'s): ``(dx (m), its
    points, the span (m), the first kept distance (m), the tracks, read_h)``;
    ``read_h(track)(lo, hi)``: that track's elevations at the grid's points ``lo:hi``.

    Raises
    ------
    ValueError
        Where ``evenly_spaced`` raises (fewer than 2 points, non-finite values, a distance
        that decreases, no distance covered, a grid too fine for the points).
    """
    from road_force_estimator.core import pieces

    if n < 2:
        raise ValueError(f'profile has {n} sample(s): need at least 2')
    kept = _Kept(n, read, rows)
    count, width, last, first = 0, 0, None, None
    for x, z in _kept_pieces(n, read, rows):     # checked, counted
        count += x.size
        width = z.shape[1]
        first = x[0] if first is None else first
        last = x[-1]
    if count < 2:
        raise ValueError('profile covers no distance')
    span = last - first
    mean_step = span / (count - 1)
    tol = iri_mod.even_spacing_tolerance(mean_step, max(abs(first), abs(last)))
    prev, uniform = None, True
    for x, _ in _kept_pieces(n, read, rows):     # the kept steps
        steps = np.diff(x if prev is None else np.concatenate([[prev], x]))
        prev = x[-1]
        if not np.all(np.abs(steps - mean_step) <= tol):
            uniform = False
            break
    if uniform:
        dx, size = float(mean_step), count

        def read_h(track):
            return lambda lo, hi: kept(lo, hi)[1][track]
    else:
        med = pieces.median_positive_steps(n, lambda lo, hi: read(lo, hi)[0], rows)
        dx = float(min(med, iri_mod.BASE_LENGTH_M))
        size = int(np.floor(span / dx + 1e-9)) + 1
        if size > max(iri_mod.MAX_RESAMPLE_FACTOR * count, iri_mod.MIN_RESAMPLE_BOUND):
            raise ValueError(f'profile of {count} samples would need {size} points on a '
                             f'{dx:g} m grid')
        interp = pieces.Interp(count, kept, rows)

        def read_h(track):
            return lambda lo, hi: interp(first + dx * np.arange(lo, hi))[track]
    return dx, size, span, first, width, read_h


def profile_iri(n: int, read: Callable, rows: int | None = None) -> np.ndarray:
    """:func:`.iri.iri` (m/km per track) of a profile of ``n`` points read ``rows`` at a
    time (default :data:`.pieces.PIECE_ROWS`): ``read(lo, hi) -> (x[lo:hi] (m,
    non-decreasing), z[lo:hi] (k, w) m)``: the same steps (a standstill's repeats dropped,
    the test for even spacing, the median step by counting, the even grid interpolated a
    piece at a time: :func:`_grid`, the filter a chunk at a time, numpy's pairwise sum of the
    rectified slope: :func:`.pieces.pairwise_sum`), so the same bits (test_iri_chunks).

    Raises
    ------
    ValueError
        Where ``iri`` raises (fewer than 2 points, non-finite values, a distance that
        decreases, too short, a grid too fine for the points).
    """
    from road_force_estimator.core import pieces

    rows = max(int(rows or pieces.PIECE_ROWS), 1)
    dx, size, span, _, width, read_h = _grid(n, read, rows)
    out = []
    for track in range(width):
        m = size - max(1, int(round(iri_mod.BASE_LENGTH_M / dx)))
        total = pieces.pairwise_sum(m, (np.abs(rel.real) for _, _, rel in
                                        _filtered(read_h(track), size, dx, float(span))))
        out.append(1000.0 * float(total / m))
    return np.array(out)


def profile_segment_iri(n: int, read: Callable, edges: np.ndarray, rows: int | None = None
                        ) -> tuple[np.ndarray, np.ndarray]:
    """``(IRI (m/km) per segment (k, w), intervals per segment (k,))`` of a profile of ``n``
    points read ``rows`` at a time (``read`` as :func:`profile_iri`'s), segments ``edges``
    (m): :func:`.iri.iri_segments` per track and :func:`.iri.interval_counts`, bit for bit
    (the grid of :func:`_grid`, the filter a chunk at a time, the sums per segment in interval
    order, :func:`_bins_add`), evenly spaced or not (issue 32: the streamed report's
    spilled profile).

    Raises
    ------
    ValueError
        Where ``iri_segments`` raises (fewer than 2 points, non-finite values, a distance
        that decreases, too short, a grid too fine for the points).
    """
    from road_force_estimator.core import pieces

    rows = max(int(rows or pieces.PIECE_ROWS), 1)
    edges = np.asarray(edges, dtype=float)
    dx, size, span, first, width, read_h = _grid(n, read, rows)
    k = edges.size - 1
    total = np.zeros((width, k))
    count = np.zeros(k)
    for track in range(width):
        for a, b, rel in _filtered(read_h(track), size, dx, float(span)):
            position = first + dx * (np.arange(a, b) + 0.5)
            seg = np.searchsorted(edges, position, side='right') - 1
            seg[position == edges[-1]] = k - 1
            inside = (seg >= 0) & (seg < k)
            _bins_add(total[track], seg[inside], np.abs(rel.real)[inside])
            if track == 0:
                _bins_add(count, seg[inside], None)
    with np.errstate(invalid='ignore', divide='ignore'):
        values = np.where(count > 0, 1000.0 * total / count, np.nan)
    return values.T, count.astype(np.int64)
