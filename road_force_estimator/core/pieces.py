"""A long series' whole-array numbers a piece at a time, with the whole-array call's bits
(issue 32: the whole vehicle's fused profile, model fit and statistics offline from spilled
columns, without the drive, or its temporaries, held whole).

Each helper here reproduces one numpy or scipy call on an array that is never held whole:
:class:`Interp` is :func:`numpy.interp` over a source read in pieces (the same bracketing
samples, so the same formula on the same numbers), :func:`arange_size` / :func:`arange_piece`
the points of a float :func:`numpy.arange` (numpy's own fill: ``start + i * delta``),
:func:`medians` / :func:`median` :func:`numpy.median` (the exact order statistics by counting
passes over the pieces: a radix selection on the values' bits, 16 bits a pass, four passes,
each a histogram of 65536 counts per series; then numpy's rule, the middle value or the
:func:`numpy.mean` of the two middle values of an even count), :func:`steps`
:func:`numpy.diff` in pieces, :func:`median_positive_steps` that median of a column's
positive steps, :func:`sosfiltfilt`
:func:`scipy.signal.sosfiltfilt` (odd padding, its default pad length: the forward pass with
its state carried over the pieces and its output spilled, the backward pass over the pieces
in reverse, as ``sosfiltfilt`` runs both over the padded array), :func:`gradient_piece`
:func:`numpy.gradient` (its test for even spacing over the whole series first,
:func:`uniform_step`), :func:`pairwise_sum` / :func:`pairwise_mean` :func:`numpy.add.reduce`
and :func:`numpy.mean` (numpy's pairwise summation followed down its split points to ranges
summed by numpy itself). What cannot go in pieces with the same bits (an FFT over the whole
series) is not here.

A source is ``read(lo, hi)``: the rows ``lo:hi`` of a series of ``n``.
"""
from __future__ import annotations

import math
from typing import Callable, Iterable, Iterator, Sequence

import numpy as np

__all__ = ['Interp', 'arange_size', 'arange_piece', 'medians', 'median', 'steps',
           'median_positive_steps', 'sosfiltfilt', 'uniform_step', 'gradient_piece',
           'pairwise_sum', 'pairwise_mean', 'PIECE_ROWS', 'PAIRWISE_BLOCK']

#: The samples read at a time by default (a few MB of pieces held).
PIECE_ROWS = 1 << 14


class Interp:
    """``np.interp(q, x, f[r])`` for every row r, ``x`` (n,) non-decreasing and ``f`` (w, n)
    read from ``read(lo, hi) -> (x[lo:hi], f[:, lo:hi])`` ``rows`` samples at a time: the
    bits of the whole arrays' call (each query interpolated between the same two samples).
    Held: from the last sample at or before the first query on, up to the first past the
    last; queries that go back before it read the source again from its start."""

    def __init__(self, n: int, read: Callable, rows: int = PIECE_ROWS) -> None:
        self.n, self.read, self.rows = int(n), read, max(int(rows), 1)
        self._start()

    def _start(self) -> None:
        self.lo = self.hi = 0                    # the samples held: lo:hi
        self.x = np.empty(0)
        self.f: np.ndarray | None = None

    def _cut(self, q0: float) -> None:
        """The samples before the last at or before ``q0`` let go."""
        cut = int(np.searchsorted(self.x, q0, side='right')) - 1
        if cut > 0:
            self.x, self.f = self.x[cut:], self.f[:, cut:]
            self.lo += cut

    def __call__(self, q: np.ndarray) -> np.ndarray:
        """(w, len(q)) the rows of ``f`` at ``q`` (non-decreasing)."""
        q = np.asarray(q, float)
        if self.lo and q.size and q[0] < self.x[0]:
            self._start()                        # back before the samples held
        while self.hi < self.n and (self.f is None or (q.size and not self.x[-1] > q[-1])):
            x, f = self.read(self.hi, min(self.hi + self.rows, self.n))
            self.hi += len(x)
            f = np.asarray(f, float)
            self.x = np.concatenate([self.x, x])
            self.f = f if self.f is None else np.concatenate([self.f, f], axis=1)
            if q.size:
                self._cut(q[0])
        if not q.size:
            return np.empty((self.f.shape[0], 0))
        self._cut(q[0])
        return np.array([np.interp(q, self.x, r) for r in self.f]).reshape(-1, q.size)


def arange_size(start: float, stop: float, step: float) -> int:
    """``np.arange(start, stop, step).size`` (floats: ``ceil((stop - start) / step)``)."""
    return max(0, math.ceil((stop - start) / step))


def arange_piece(start: float, step: float, lo: int, hi: int) -> np.ndarray:
    """``np.arange(start, stop, step)[lo:hi]`` for any ``stop`` past them: numpy sets the
    first two points and fills the others with ``start + i * (points[1] - points[0])``."""
    start, step = float(start), float(step)
    out = start + np.arange(lo, hi) * ((start + step) - start)
    if lo <= 0 < hi:
        out[-lo] = start
    if lo <= 1 < hi:
        out[1 - lo] = start + step
    return out


_DIGIT_BITS = 16
_SIGN = np.uint64(1 << 63)


def _keys(x: np.ndarray) -> np.ndarray:
    """Unsigned 64-bit keys in the order of the float64 values x (NaN-free; -0.0 as +0.0)."""
    u = (np.asarray(x, np.float64).reshape(-1) + 0.0).view(np.uint64)
    neg = (u & _SIGN) != 0
    return np.where(neg, ~u, u | _SIGN)


def _value(key: int) -> float:
    """The float64 of a key of :func:`_keys`."""
    u = np.uint64(key)
    u = (u & ~_SIGN) if (u & _SIGN) else ~u
    return float(np.array([u], np.uint64).view(np.float64)[0])


def medians(passes: Callable[[], Iterable[Sequence[np.ndarray]]], series: int
            ) -> list[float]:
    """:func:`numpy.median` of each of ``series`` float64 series (NaN if it holds a NaN or
    nothing), without the series held whole: ``passes()`` yields, each time it is called, the
    series' pieces in turn, a piece being one array per series (any length, any order of the
    values; a series' values are those of all its pieces). Called four times."""
    counts = np.zeros(series, np.int64)
    nan = np.zeros(series, bool)
    # the ranks wanted per series: numpy's kth ([n // 2 - 1, n // 2] or [(n - 1) // 2])
    targets: list[list] = []
    first = True
    for shift in range(64 - _DIGIT_BITS, -1, -_DIGIT_BITS):
        hists: list[dict] = [dict() for _ in range(series)]
        for piece in passes():
            for s, x in enumerate(piece):
                if first:
                    x = np.asarray(x, np.float64).reshape(-1)
                    counts[s] += x.size
                    nan[s] |= bool(np.isnan(x).any())
                if nan[s]:
                    continue
                keys = _keys(x)
                prefixes = ({None} if first else {p for p, _ in targets[s]})
                for p in prefixes:
                    k = keys if p is None else keys[(keys >> np.uint64(shift + _DIGIT_BITS))
                                                    == np.uint64(p)]
                    h = np.bincount(((k >> np.uint64(shift)) & np.uint64(0xFFFF)).astype(
                        np.intp), minlength=1 << _DIGIT_BITS)
                    hists[s][p] = hists[s][p] + h if p in hists[s] else h
        if first:
            targets = [[(None, r) for r in ((n // 2 - 1, n // 2) if n % 2 == 0 else
                                             ((n - 1) // 2,))] if n and not bad else []
                       for n, bad in zip(counts.tolist(), nan.tolist())]
        for s in range(series):
            step = []
            for p, r in targets[s]:
                cum = np.cumsum(hists[s][p])
                d = int(np.searchsorted(cum, r, side='right'))
                below = int(cum[d - 1]) if d else 0
                step.append(((0 if p is None else p) << _DIGIT_BITS | d, r - below))
            targets[s] = step
        first = False
    out = []
    for s in range(series):
        if not targets[s]:
            out.append(float('nan'))
            continue
        # numpy's median: the mean of the middle value(s)
        out.append(float(np.mean(np.array([_value(p) for p, _ in targets[s]]))))
    return out


def median(passes: Callable[[], Iterable[np.ndarray]]) -> float:
    """:func:`medians` of one series: ``passes()`` yields its pieces (arrays)."""
    return medians(lambda: ((x,) for x in passes()), 1)[0]


def steps(n: int, read: Callable, rows: int = PIECE_ROWS) -> Iterator[np.ndarray]:
    """``np.diff(x)`` of ``x`` (n,) from ``read(lo, hi)`` (float64), in consecutive pieces
    (``rows`` read at a time; each piece's first step from the last value before it)."""
    last = None
    for lo in range(0, n, rows):
        x = np.asarray(read(lo, min(lo + rows, n)), float)
        yield np.diff(x if last is None else np.concatenate([[last], x]))
        last = x[-1] if x.size else last


def median_positive_steps(n: int, read: Callable, rows: int = PIECE_ROWS) -> float:
    """``np.median(s[s > 0])`` of ``s = np.diff(x)``, ``x`` (n,) from ``read(lo, hi)``
    (``rows`` at a time); 0.0 without a positive step. Exact: :func:`median`."""
    def positive():
        for s in steps(n, read, rows):
            yield s[s > 0.0]

    out = median(positive)
    return 0.0 if math.isnan(out) else out        # NaN: no positive step (s > 0 has no NaN)


def sosfiltfilt(sos: np.ndarray, n: int, read: Callable, width: int, folder=None,
                rows: int = PIECE_ROWS):
    """``scipy.signal.sosfiltfilt(sos, X, axis=-1)`` (odd padding, its default pad length)
    of ``X`` (width, n) from ``read(lo, hi) -> X[:, lo:hi]``, ``rows`` at a time: the output
    in a :class:`~.spill.SpillColumn` (n, width) in ``folder`` (returned; the caller closes
    it). The same bits.

    Raises
    ------
    ValueError
        ``n`` not above the pad length (as ``sosfiltfilt``).
    """
    from road_force_estimator.core.scipy_signal import signal
    from road_force_estimator.core.spill import SpillColumn

    sig = signal()
    sos = np.asarray(sos, float)
    ntaps = 2 * sos.shape[0] + 1 - min(int((sos[:, 2] == 0).sum()),
                                       int((sos[:, 5] == 0).sum()))
    edge = 3 * ntaps
    if n <= edge:
        raise ValueError('The length of the input vector x must be greater than padlen, '
                         f'which is {edge}.')
    head, tail = read(0, edge + 1), read(n - edge - 1, n)
    left = 2 * head[:, 0:1] - head[:, edge:0:-1]
    right = 2 * tail[:, -1:] - tail[:, -2:-(edge + 2):-1]
    zi0 = sig.sosfilt_zi(sos)[:, None, :]                  # (sections, 1, 2)
    bounds = [(lo, min(lo + rows, n)) for lo in range(0, n, max(int(rows), 1))]
    fwd = SpillColumn(float, width, folder)
    out = SpillColumn(float, width, folder)
    try:
        zi = zi0 * left[:, 0:1]
        y, zi = sig.sosfilt(sos, left, axis=-1, zi=zi)
        fwd.append(y.T)
        for lo, hi in bounds:
            y, zi = sig.sosfilt(sos, read(lo, hi), axis=-1, zi=zi)
            fwd.append(y.T)
        y, zi = sig.sosfilt(sos, right, axis=-1, zi=zi)
        fwd.append(y.T)
        zi = zi0 * y[:, -1:]
        _, zi = sig.sosfilt(sos, y[:, ::-1], axis=-1, zi=zi)
        for lo, hi in reversed(bounds):
            f = fwd.read(edge + lo, edge + hi).T
            z, zi = sig.sosfilt(sos, f[:, ::-1], axis=-1, zi=zi)
            out.write(lo, z[:, ::-1].T)
    except BaseException:
        out.close()
        raise
    finally:
        fwd.close()
    return out


def uniform_step(n: int, read: Callable, rows: int = PIECE_ROWS):
    """:func:`numpy.gradient`'s test of its coordinates ``x`` (n,) from ``read(lo, hi)``:
    every step equal to the first: that step (a numpy float), else None."""
    first = None
    for s in steps(n, read, rows):
        if s.size and first is None:
            first = s[0]
        if s.size and not (s == first).all():
            return None
    return first


def gradient_piece(read_f: Callable, read_x: Callable, n: int, lo: int, hi: int, step
                   ) -> np.ndarray:
    """``np.gradient(f, x)[lo:hi]`` (edge order 1) of ``f`` and ``x`` (n,) from
    ``read_f(lo, hi)``, ``read_x(lo, hi)``; ``step``: :func:`uniform_step` of ``x``. numpy's
    formulas on the same numbers (a sample either side read with the piece)."""
    a, b = max(lo - 1, 0), min(hi + 1, n)
    f = np.asarray(read_f(a, b), float)
    d = np.diff(np.asarray(read_x(a, b), float))
    out = np.empty(hi - lo)
    i0, i1 = max(lo, 1), min(hi, n - 1)          # the interior points of lo:hi
    if i1 > i0:
        fm, f0, fp = f[i0 - 1 - a:i1 - 1 - a], f[i0 - a:i1 - a], f[i0 + 1 - a:i1 + 1 - a]
        if step is not None:
            out[i0 - lo:i1 - lo] = (fp - fm) / (2. * step)
        else:
            dx1, dx2 = d[i0 - 1 - a:i1 - 1 - a], d[i0 - a:i1 - a]
            out[i0 - lo:i1 - lo] = (-(dx2) / (dx1 * (dx1 + dx2)) * fm
                                    + (dx2 - dx1) / (dx1 * dx2) * f0
                                    + dx1 / (dx2 * (dx1 + dx2)) * fp)
    if lo == 0:
        out[0] = (f[1] - f[0]) / (step if step is not None else d[0])
    if hi == n:
        out[-1] = (f[-1] - f[-2]) / (step if step is not None else d[-1])
    return out


#: numpy's pairwise summation: blocks of at most this many summed eight-wise.
PAIRWISE_BLOCK = 128


def pairwise_sum(n: int, pieces: Iterable[np.ndarray], hold: int = PIECE_ROWS
                 ) -> np.float64:
    """``np.add.reduce(a)`` of a float64 ``a`` (n,) given as consecutive ``pieces`` (any
    sizes): numpy's pairwise summation (a contiguous array halved, the first half a multiple
    of 8, down to blocks of :data:`PAIRWISE_BLOCK` or fewer, the halves' sums added)
    followed down its split points to ranges of at most ``hold`` (>= 128) values, each summed
    by ``np.add.reduce`` itself (which splits them the same way), so the same bits; held:
    such a range and a piece."""
    hold = max(int(hold), PAIRWISE_BLOCK)
    it = iter(pieces)
    buf = np.empty(0)

    def take(k: int) -> np.ndarray:
        nonlocal buf
        while buf.size < k:
            buf = np.concatenate([buf, np.asarray(next(it), float).reshape(-1)])
        out, buf = buf[:k], buf[k:]
        return out

    def node(k: int) -> np.float64:
        if k <= hold:
            return np.add.reduce(np.ascontiguousarray(take(k)))
        half = k // 2
        half -= half % 8
        return node(half) + node(k - half)

    try:
        return node(int(n))
    finally:
        it = buf = None                          # let go (node's closure is a cycle)


def pairwise_mean(n: int, pieces: Iterable[np.ndarray], hold: int = PIECE_ROWS) -> float:
    """:func:`numpy.mean` of the series of :func:`pairwise_sum` (NaN for no values)."""
    if n <= 0:
        return float('nan')
    return float(np.float64(pairwise_sum(n, pieces, hold)) / n)
