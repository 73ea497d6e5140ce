"""Load transfer ratio LTR = (F_n2 - F_n1) / (F_n1 + F_n2) (MODEL.md step 8; right minus left).

A tire cannot pull, so each vertical load enters as ``max(F_n,i, 0)``: an estimate below zero
is a lifted wheel. Then ``|LTR| <= 1``, with ``LTR = +1`` when the left wheel has lifted off
and ``-1`` when the right one has (the rollover limit). The denominator is floored at
``floor_n`` (the estimators use 1 % of the static axle load) so that the ratio stays finite,
and is 0, when both wheels are off the ground.

This module imports numpy only (core).
"""
from __future__ import annotations

import numpy as np

__all__ = ['load_transfer_ratio', 'load_transfer_ratios']


def load_transfer_ratio(fn1_n: float, fn2_n: float, floor_n: float) -> float:
    """LTR of one sample from the left and right vertical loads (N); scalar fast path."""
    a = fn1_n if fn1_n > 0.0 else 0.0
    b = fn2_n if fn2_n > 0.0 else 0.0
    den = a + b
    return (b - a) / (den if den > floor_n else floor_n)


def load_transfer_ratios(fn1_n: np.ndarray, fn2_n: np.ndarray, floor_n: float) -> np.ndarray:
    """:func:`load_transfer_ratio` over arrays (same numbers)."""
    a = np.maximum(np.asarray(fn1_n, dtype=float), 0.0)
    b = np.maximum(np.asarray(fn2_n, dtype=float), 0.0)
    return (b - a) / np.maximum(a + b, floor_n)
