"""A road profile that arrives point by point (``simulator.road = topic``), joined by distance.

The points of the two wheel paths (``/lpa/left``, ``/lpa/right``: distance x (m), elevation
z (m)) come as a bag player publishes an LPA bag, each path in its own order. They are kept
as the LPA bag reader keeps them: in arrival order while the distance increases (a NaN, a
duplicate or a backward point is dropped and counted), and the two paths are joined on equal
distances (a point the other path skipped is dropped and counted). A stream that only ever
brings one path uses it for both once it is closed (:meth:`RoadStream.close`). So the
profile of a whole stream is the profile the reader gives for the bag, and any prefix of it
is a prefix of that profile.
"""
from __future__ import annotations

from collections import Counter, deque
import math

import numpy as np

from road_force_estimator.core.road import RoadProfile

__all__ = ['RoadStream']


class RoadStream:
    """Profile points of the [left, right] wheel paths as they arrive, joined by distance.

    Attributes
    ----------
    dropped : Counter
        Points dropped, by reason: 'nonfinite', 'order' (not beyond the path's last point),
        'unmatched' (no point at that distance on the other path).
    received : list of int
        Points received per path [left, right].
    """

    def __init__(self, name: str = 'topic') -> None:
        self.name = name
        self._pending = (deque(), deque())
        self._last = [-math.inf, -math.inf]
        self._x: list[float] = []
        self._z: list[tuple[float, float]] = []
        self.dropped: Counter = Counter()
        self.received = [0, 0]
        self.closed = False

    def __len__(self) -> int:
        """Joined points (rows of the profile) so far."""
        return len(self._x)

    @property
    def end_m(self) -> float:
        """Distance of the last joined point (m); -inf before the first."""
        return self._x[-1] if self._x else -math.inf

    def add(self, side: int, distance_m: float, elevation_m: float) -> bool:
        """One point of path ``side`` (0 = left, 1 = right); False if it was dropped."""
        self.received[side] += 1
        x, z = float(distance_m), float(elevation_m)
        if self.closed:
            self.dropped['closed'] += 1
            return False
        if not (math.isfinite(x) and math.isfinite(z)):
            self.dropped['nonfinite'] += 1
            return False
        if x <= self._last[side]:
            self.dropped['order'] += 1
            return False
        self._last[side] = x
        self._pending[side].append((x, z))
        self._join()
        return True

    def _join(self) -> None:
        left, right = self._pending
        while left and right:
            (xl, zl), (xr, zr) = left[0], right[0]
            if xl == xr:
                self._x.append(xl)
                self._z.append((zl, zr))
                left.popleft()
                right.popleft()
            elif xl < xr:
                left.popleft()
                self.dropped['unmatched'] += 1
            else:
                right.popleft()
                self.dropped['unmatched'] += 1

    def close(self) -> None:
        """No more points: a stream that brought one path only uses it for both."""
        if self.closed:
            return
        self.closed = True
        if not self._x:
            for side in (0, 1):
                if self._pending[side] and not self._pending[1 - side]:
                    for x, z in self._pending[side]:
                        self._x.append(x)
                        self._z.append((z, z))
                    self._pending[side].clear()

    def profile(self) -> RoadProfile | None:
        """The profile joined so far, or None while it has fewer than 2 points."""
        if len(self._x) < 2:
            return None
        notes = tuple(f'{count} points dropped ({reason})'
                      for reason, count in sorted(self.dropped.items()))
        return RoadProfile(np.array(self._x), np.array(self._z), name=self.name, notes=notes)
