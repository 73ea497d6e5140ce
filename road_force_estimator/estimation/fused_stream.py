"""The fused profile streamed (``vehicle.model: articulated``, INTERFACES.md
``/road_profile/fused/*``): both wheel paths fused over every axle's online road by distance,
each point once the last axle has passed it.

The rule is :func:`.articulated.fuse_roads`'s, causal: the point under the front axle at
sample k is under axle j once that axle has travelled ``xi_j`` further (the front axle's
distance ``x_k + xi_j``); each axle's road is interpolated there (linear in the front axle's
distance, between the two finalized samples around it). Per wheel path, the waves longer than
:data:`.articulated.FUSION_SPLIT_WAVELENGTH_M` are every axle's average, the shorter ones the
average of the axles whose wheel's load is at least :data:`.articulated.LIFT_OFF_FRACTION` of
its static load at both samples around the point (every axle's where none is). The long
waves: each axle's read through two first-order lags in distance at that wavelength (the
offline rule's zero-phase Butterworth cannot look ahead); the split only matters while a wheel
is off the ground (with every wheel down the point is the axles' plain average).

The points: a sample is one when the front axle has travelled at least
:data:`FUSED_SPACING_M` since the last point (the first sample is one; none while standing),
emitted with the front axle's stamp and distance at that sample k when the sample whose
distance reaches ``x_k + max(xi)`` comes in: of :func:`.fuse_roads`'s points over a drive
(its ``x + max(xi) <= x[-1]``, one per sample), one every :data:`FUSED_SPACING_M`.
"""
from __future__ import annotations

from bisect import bisect_left
from collections import deque
from dataclasses import dataclass
import math
from typing import Sequence

import numpy as np

from road_force_estimator.estimation.articulated import (
    FUSION_SPLIT_WAVELENGTH_M, LIFT_OFF_FRACTION)

__all__ = ['FusedPoints', 'FusedStream', 'FUSED_SPACING_M']

#: The fused profile's points are this far apart at least (m, the front axle's distance): a
#: point every 5th sample at 1 kHz and 20 m/s (200 Hz), every 3rd to 4th at 30 m/s, for the
#: node's CPU (the fusion and two messages per point; every sample cost the observer node
#: 60.4 % of a core against 48.1 % without the road, ``python -m bench.probes.node_latency
#: --articulated``); the 0.5-30 m band and the IRI (its 0.25 m sampling) need no finer.
FUSED_SPACING_M = 0.1

#: History samples dropped at once when no pending point needs them (bounds the lists).
TRIM_SAMPLES = 4096


@dataclass(frozen=True)
class FusedPoints:
    """Fused points: per point (m,) the stamp of the sample at which the front axle passed it
    (ns), its distance in the front axle's frame (m), the left and right wheel paths (m)."""

    stamps_ns: np.ndarray
    distance_m: np.ndarray
    left_m: np.ndarray
    right_m: np.ndarray

    @classmethod
    def from_points(cls, points: Sequence[tuple]) -> FusedPoints:
        """From ``(stamp_ns, distance_m, left_m, right_m)`` tuples."""
        a = np.array([p[1:] for p in points], float).reshape(-1, 3)
        return cls(np.array([p[0] for p in points], np.int64), a[:, 0].copy(),
                   a[:, 1].copy(), a[:, 2].copy())


class FusedStream:
    """The fused profile one finalized sample at a time (module notes).

    Parameters
    ----------
    positions_m : the axles' distances behind the front axle (m), front first (0)
    spacing_m : the points' least spacing (m, :data:`FUSED_SPACING_M`; 0: every sample that
        moved)
    """

    def __init__(self, positions_m: Sequence[float],
                 spacing_m: float = FUSED_SPACING_M) -> None:
        xi = [float(p) for p in positions_m]
        if not xi or xi[0] != 0.0 or any(b < a for a, b in zip(xi, xi[1:])):
            raise ValueError(f'axle positions {xi!r} m: the front axle at 0, then in order')
        if not spacing_m >= 0.0:
            raise ValueError(f'spacing {spacing_m!r} m: must be >= 0')
        self.spacing = float(spacing_m)
        self._mark: float | None = None   # the last point's distance (m)
        self._points: deque = deque()     # absolute indices of the points not yet emitted
        self.xi = xi
        self.reach = max(xi)
        self.n = len(xi)
        self._x: list = []          # the samples' distances (m)
        self._stamp: list = []
        self._rows: list = []       # per sample the wheels' (roads, loads, static loads)
        self._base = 0              # the absolute index of the lists' first sample
        self._ptr = [0] * self.n    # per axle: the first sample at or past its last read
        self._k = 2.0 * math.pi / FUSION_SPLIT_WAVELENGTH_M   # rad/m
        self._lag1 = [0.0] * (2 * self.n)
        self._lag2 = [0.0] * (2 * self.n)
        self._px: float | None = None    # the last emitted point's distance

    def push(self, stamp_ns: int, distance_m: float, road_m: Sequence[float],
             load_n: Sequence[float], static_n: Sequence[float]) -> list[tuple]:
        """One finalized sample: the wheels' roads (m), loads and static loads (N), two per
        axle (left, right). Returns the points the last axle has now passed, each
        ``(stamp_ns, distance_m, left_m, right_m)``."""
        x = float(distance_m)
        self._x.append(x)
        self._stamp.append(int(stamp_ns))
        self._rows.append((road_m, load_n, static_n))
        mark = self._mark
        if mark is None or x >= mark + self.spacing and x > mark:
            self._mark = x
            self._points.append(self._base + len(self._x) - 1)
        out = []
        xs, base, points = self._x, self._base, self._points
        while points and xs[points[0] - base] + self.reach <= x:
            out.append(self._point(points.popleft() - base))
        if self._ptr[0] - base > TRIM_SAMPLES:
            self._trim()
        return out

    def _point(self, i: int) -> tuple:
        """The point of the sample at list index i (every axle past it)."""
        xs, rows = self._x, self._rows
        p = xs[i]
        last = len(xs) - 1
        reads, ok = [], []
        for j, lag in enumerate(self.xi):
            target = p + lag
            m = self._ptr[j] - self._base
            if m < i:
                m = i
            if m < last and xs[m] < target:    # the first at or past it (xs in order)
                m = bisect_left(xs, target, m, last)
            self._ptr[j] = m + self._base
            x1 = xs[m]
            kl, kr = 2 * j, 2 * j + 1
            r1, f1, s1 = rows[m]
            if m == i or x1 <= target:
                reads.append((r1[kl], r1[kr]))
                ok.append((f1[kl] >= LIFT_OFF_FRACTION * s1[kl],
                           f1[kr] >= LIFT_OFF_FRACTION * s1[kr]))
                continue
            x0 = xs[m - 1]
            a = (target - x0) / (x1 - x0)
            r0, f0, s0 = rows[m - 1]
            reads.append((r0[kl] + a * (r1[kl] - r0[kl]), r0[kr] + a * (r1[kr] - r0[kr])))
            ok.append((f0[kl] >= LIFT_OFF_FRACTION * s0[kl] and
                       f1[kl] >= LIFT_OFF_FRACTION * s1[kl],
                       f0[kr] >= LIFT_OFF_FRACTION * s0[kr] and
                       f1[kr] >= LIFT_OFF_FRACTION * s1[kr]))
        # the long waves: two first-order lags in distance per axle and path
        px = self._px
        if px is None:
            c = 1.0
            for j in range(self.n):
                for s in (0, 1):
                    self._lag1[2 * j + s] = self._lag2[2 * j + s] = reads[j][s]
        else:
            b = self._k * (p - px)
            c = b / (1.0 + b)
        self._px = p
        lag1, lag2 = self._lag1, self._lag2
        paths = []
        for s in (0, 1):
            long_sum = short_ok = 0.0
            n_ok = 0
            all_short = 0.0
            for j in range(self.n):
                k = 2 * j + s
                r = reads[j][s]
                g1 = lag1[k] = lag1[k] + c * (r - lag1[k])
                g2 = lag2[k] = lag2[k] + c * (g1 - lag2[k])
                long_sum += g2
                all_short += r - g2
                if ok[j][s]:
                    short_ok += r - g2
                    n_ok += 1
            short = short_ok / n_ok if n_ok else all_short / self.n
            paths.append(long_sum / self.n + short)
        return self._stamp[i], p, paths[0], paths[1]

    def _trim(self) -> None:
        """Drop the samples no pending point reads."""
        keep_from = min(min(self._ptr) - 1, self._points[0] if self._points else
                        self._base + len(self._x)) - self._base
        if keep_from <= 0:
            return
        for lst in (self._x, self._stamp, self._rows):
            del lst[:keep_from]
        self._base += keep_from
