"""The true load transfer of each unit of the combination (tractor, trailer, combination).

Per unit, the left and right sums of its wheels' vertical loads, L and R (N), give
``LTR = (R - L) / (R + L)`` (right minus left, MODEL.md step 8; each load ``>= 0``, the
denominator floored at 1 % of the unit's static load), and the quasi-static LTR: the same
ratio of L and R low-passed below the wheel-hop band by two equal first-order lags in cascade
(-3 dB at :data:`QUASI_STATIC_CUTOFF_HZ`, exact for loads held over each step), as the
observer low-passes its estimates (``observer.rollover_cutoff_frequency``'s default), started
at the first sample's loads. The batch path (:func:`unit_load_transfer`) and the per-sample
path (:class:`UnitLoadTransfer`) run the same recursion: the same numbers.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

__all__ = ['QUASI_STATIC_CUTOFF_HZ', 'UnitLoadTransfer', 'unit_load_transfer', 'unit_masks']

#: -3 dB frequency (Hz) of the quasi-static LTR's low-pass.
QUASI_STATIC_CUTOFF_HZ = 2.0
_CASCADE_3DB = math.sqrt(math.sqrt(2.0) - 1.0)
_FLOOR_FRACTION = 0.01


def unit_masks(bodies: Sequence[str]) -> list[list[int]]:
    """The axle indices of each unit (tractor, trailer, combination) of axles on ``bodies``."""
    tractor = [j for j, b in enumerate(bodies) if b == 'tractor']
    trailer = [j for j, b in enumerate(bodies) if b == 'trailer']
    return [tractor, trailer, list(range(len(bodies)))]


class UnitLoadTransfer:
    """Per-sample LTR and quasi-static LTR of each unit.

    Parameters
    ----------
    bodies : sequence of str
        The body of each axle ('tractor' or 'trailer'), front first.
    static_load_n : array (N_axles, 2)
        The static wheel loads (N): the LTR floors.
    dt_s : float
        The sample step (s).
    units : sequence of sequences of int, optional
        The axles of each unit (default :func:`unit_masks` of ``bodies``: tractor, trailer,
        combination); e.g. ``[[0]]``: the front axle alone.
    """

    def __init__(self, bodies: Sequence[str], static_load_n, dt_s: float,
                 cutoff_hz: float = QUASI_STATIC_CUTOFF_HZ,
                 units: Sequence[Sequence[int]] | None = None) -> None:
        self.units = (unit_masks(bodies) if units is None
                      else [[int(j) for j in u] for u in units])
        static = np.asarray(static_load_n, float)
        self.floor = [_FLOOR_FRACTION * float(static[u].sum()) for u in self.units]
        #: pole rate (1/s) of each lag of the low-pass
        self.rate = 2.0 * math.pi * cutoff_hz / _CASCADE_3DB
        self.e = math.exp(-dt_s * self.rate)
        self.state: list | None = None
        # per unit (an earlier unit whose axles start its own, or -1; its other left wheels'
        # indices, its right wheels', its floor): the combination's sums go on from the
        # tractor's (the same additions in the same order: the same bits)
        self._plan = []
        for i, (u, f) in enumerate(zip(self.units, self.floor)):
            base = max((p for p in range(i) if self.units[p] == u[:len(self.units[p])]),
                       key=lambda p: len(self.units[p]), default=-1)
            rest = u[len(self.units[base]):] if base >= 0 else u
            self._plan.append((base, [2 * j for j in rest], [2 * j + 1 for j in rest], f))
        self._dt: float | None = None       # the last step given, and its e
        self._e_dt = self.e

    def update(self, loads: Sequence[float], dt_s: float | None = None) -> list[float]:
        """``[LTR, quasi-static LTR]`` per unit (2 numbers a unit) from one sample's wheel
        loads [axle j left, right, ...] (N); ``dt_s``: the step from the previous sample (s;
        None: the step given at construction)."""
        if dt_s is None:
            e = self.e
        elif dt_s == self._dt:
            e = self._e_dt
        else:
            e = self._e_dt = math.exp(-dt_s * self.rate)
            self._dt = dt_s
        g = 1.0 - e
        out = []
        state = self.state
        if state is None:
            state = self.state = [None] * len(self.units)
        sums = []
        for i, (base, lefts, rights, floor) in enumerate(self._plan):
            left, right = sums[base] if base >= 0 else (0.0, 0.0)
            for k in lefts:
                a = loads[k]
                left += a if a > 0.0 else 0.0
            for k in rights:
                b = loads[k]
                right += b if b > 0.0 else 0.0
            sums.append((left, right))
            st = state[i]
            if st is None:
                st = state[i] = (left, left, right, right)
            else:
                l1 = e * st[0] + g * left
                r1 = e * st[2] + g * right
                st = state[i] = (l1, e * st[1] + g * l1, r1, e * st[3] + g * r1)
            den = left + right
            den_qs = st[1] + st[3]
            out.append((right - left) / (den if den > floor else floor))
            out.append((st[3] - st[1]) / (den_qs if den_qs > floor else floor))
        return out


def unit_load_transfer(bodies: Sequence[str], static_load_n, dt_s: float,
                       loads_n: np.ndarray) -> np.ndarray:
    """:class:`UnitLoadTransfer` over a drive: (n, 6) = per unit (LTR, quasi-static LTR)."""
    ltr = UnitLoadTransfer(bodies, static_load_n, dt_s)
    rows = np.asarray(loads_n, float).tolist()
    return np.array([ltr.update(r) for r in rows]).reshape(len(rows), 6)
