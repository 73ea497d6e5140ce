"""numpy's median and mean of a long series handed over in pieces, the same bits as the
whole array's (issue 32: a long drive's statistics taken without the drive, or its
temporaries, held whole).

:func:`medians`: the exact order statistics by counting passes over the pieces (a radix
selection on the values' bits, 16 bits a pass: four passes, each a histogram of 65536 counts
per series), then numpy's rule (:func:`numpy.median`: the middle value, or the mean of the
two middle values of an even count, taken by :func:`numpy.mean`). :func:`pairwise_mean`:
numpy's pairwise summation (``np.add.reduce`` of a contiguous float64 array: blocks of at
most 128 summed eight-wise, larger ones split at half their length rounded down to a
multiple of 8) followed down its split points to ranges of at most ``piece`` values, each
summed by numpy itself, then divided by the count as :func:`numpy.mean` does.
``test/core/test_piecewise.py`` checks both against numpy's whole-array functions.
"""
from __future__ import annotations

from typing import Callable, Iterable, Sequence

import numpy as np

__all__ = ['medians', 'median', 'pairwise_sum', 'pairwise_mean', 'PIECE_VALUES']

#: Values a range is summed in at once by :func:`pairwise_sum` (its largest temporary).
PIECE_VALUES = 1 << 16
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
    values; a series' values are those of all its pieces). Called five times."""
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


def pairwise_sum(read: Callable[[int, int], np.ndarray], n: int,
                 piece: int = PIECE_VALUES) -> float:
    """``np.add.reduce`` of a float64 series of ``n`` values, ``read(lo, hi)`` its values
    ``lo:hi`` (a contiguous float64 array), at most ``piece`` (>= 128) values read at once:
    the same bits (module notes)."""
    piece = max(int(piece), 128)

    def part(lo: int, k: int) -> float:
        if k <= piece:
            return np.add.reduce(np.ascontiguousarray(read(lo, lo + k), np.float64))
        k2 = k // 2
        k2 -= k2 % 8
        return part(lo, k2) + part(lo + k2, k - k2)

    return float(part(0, int(n)))


def pairwise_mean(read: Callable[[int, int], np.ndarray], n: int,
                  piece: int = PIECE_VALUES) -> float:
    """:func:`numpy.mean` of the series of :func:`pairwise_sum` (NaN for no values)."""
    if n <= 0:
        return float('nan')
    return float(np.float64(pairwise_sum(read, n, piece)) / n)
