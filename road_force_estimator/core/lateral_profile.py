"""A lateral acceleration over time (``simulator.lateral_profile``): a curve, a step or a file.

a_y (m/s^2, > 0 to the left, REP-103) is linearly interpolated between knots ``(time_s,
a_y)`` and 0 outside them (before the first knot and after the last). The forms:

- ``curve:start=T,ramp=R,hold=H,ay=A``: a curve entered at T s over R s (a_y rising linearly,
  as on a clothoid at constant speed), held at A for H s and left over R s;
- a CSV path with the header ``time_s,lateral_accel_mps2``;
- :meth:`LateralProfile.step` (simulate_bag's ``--lateral-acceleration A@T``): A from T on.

Both plants evaluate it at their stage times (:meth:`LateralProfile.at` over arrays, a call
with one time for a float).
"""
from __future__ import annotations

import csv
from dataclasses import dataclass
import math
from pathlib import Path

import numpy as np

__all__ = ['LateralProfile', 'parse_lateral_profile']

#: |a_y| limit of a profile (m/s^2): beyond any truck's rollover threshold.
MAX_LATERAL_MPS2 = 20.0


@dataclass(frozen=True)
class LateralProfile:
    """Knots ``time_s`` (strictly increasing, s) and ``accel_mps2`` (m/s^2); ``hold_last``:
    keep the last value after the last knot (a step), else 0 there."""

    time_s: tuple
    accel_mps2: tuple
    hold_last: bool = False
    text: str = ''

    def __post_init__(self) -> None:
        t = np.asarray(self.time_s, float)
        a = np.asarray(self.accel_mps2, float)
        if t.ndim != 1 or t.size < 1 or t.shape != a.shape:
            raise ValueError('lateral profile: time_s and accel_mps2 must be equal, non-empty')
        if not (np.isfinite(t).all() and np.isfinite(a).all()) or np.any(np.diff(t) <= 0.0):
            raise ValueError('lateral profile: finite knots with strictly increasing times')
        if np.any(np.abs(a) > MAX_LATERAL_MPS2) or t[0] < 0.0:
            raise ValueError(f'lateral profile: |a_y| <= {MAX_LATERAL_MPS2:g} m/s^2 and '
                             'times >= 0 s')
        object.__setattr__(self, 'time_s', tuple(t.tolist()))
        object.__setattr__(self, 'accel_mps2', tuple(a.tolist()))

    @classmethod
    def step(cls, accel_mps2: float, t_on_s: float = 0.0) -> LateralProfile:
        """a_y = 0 before ``t_on_s``, ``accel_mps2`` from it on."""
        if t_on_s > 0.0:
            return cls((0.0, t_on_s, math.nextafter(t_on_s, math.inf)),
                       (0.0, 0.0, accel_mps2), hold_last=True)
        return cls((0.0,), (accel_mps2,), hold_last=True)

    @classmethod
    def curve(cls, start_s: float, ramp_s: float, hold_s: float, accel_mps2: float,
              text: str = '') -> LateralProfile:
        """A curve entered over ``ramp_s``, held ``hold_s`` at ``accel_mps2``, left over
        ``ramp_s`` (s, m/s^2)."""
        if not (start_s >= 0.0 and ramp_s > 0.0 and hold_s >= 0.0):
            raise ValueError(f'lateral profile {text!r}: start >= 0 s, ramp > 0 s, hold >= 0 s')
        t = [start_s, start_s + ramp_s, start_s + ramp_s + hold_s,
             start_s + 2 * ramp_s + hold_s]
        a = [0.0, accel_mps2, accel_mps2, 0.0]
        if hold_s == 0.0:
            t, a = [t[0], t[1], t[3]], [0.0, accel_mps2, 0.0]
        return cls(tuple(t), tuple(a), text=text)

    def at(self, t_s) -> np.ndarray:
        """a_y (m/s^2) at time(s) ``t_s`` (s)."""
        t = np.asarray(t_s, dtype=float)
        right = self.accel_mps2[-1] if self.hold_last else 0.0
        return np.interp(t, self.time_s, self.accel_mps2, left=0.0 if self.time_s[0] > 0.0
                         else self.accel_mps2[0], right=right)

    def __call__(self, t_s: float) -> float:
        return float(self.at(t_s))


def parse_lateral_profile(text: str) -> LateralProfile | None:
    """The profile of ``simulator.lateral_profile`` (None for ``""``).

    Raises
    ------
    ValueError
        One line: an unknown form, a bad or missing key, an unreadable or bad CSV.
    """
    text = str(text).strip()
    if not text:
        return None
    if text.lower().startswith('curve:'):
        keys = {}
        for item in text.split(':', 1)[1].split(','):
            key, sep, value = item.partition('=')
            try:
                keys[key.strip()] = float(value)
            except ValueError:
                raise ValueError(f'simulator.lateral_profile = {text!r}: {item!r} is not '
                                 'KEY=NUMBER') from None
        unknown = set(keys) - {'start', 'ramp', 'hold', 'ay'}
        missing = {'ay'} - set(keys)
        if unknown or missing:
            extra = f'; unknown {", ".join(sorted(unknown))}' if unknown else ''
            raise ValueError(f'simulator.lateral_profile = {text!r}: keys start, ramp, hold, '
                             f'ay (ay required){extra}')
        return LateralProfile.curve(keys.get('start', 0.0), keys.get('ramp', 2.0),
                                    keys.get('hold', 0.0), keys['ay'], text)
    return _read_csv(Path(text))


def _read_csv(path: Path) -> LateralProfile:
    try:
        with path.open(newline='') as f:
            rows = list(csv.reader(f))
    except OSError as exc:
        raise ValueError(f'simulator.lateral_profile = {str(path)!r}: not "curve:..." and not '
                         f'a readable CSV ({exc.strerror})') from None
    if not rows or [c.strip() for c in rows[0][:2]] != ['time_s', 'lateral_accel_mps2']:
        raise ValueError(f'{path}: a lateral profile needs the header '
                         'time_s,lateral_accel_mps2')
    try:
        data = np.array([[float(r[0]), float(r[1])] for r in rows[1:] if r], dtype=float)
        return LateralProfile(tuple(data[:, 0]), tuple(data[:, 1]), text=str(path))
    except (ValueError, IndexError) as exc:
        raise ValueError(f'{path}: {exc}') from None
