"""Band-limited double integration of the body heave acceleration (MODEL.md step 4).

``z_s = H(s) dd z_s / s^2`` with the high-pass ``H = 1 - G``, ``G = (5 w^4 s + w^5) /
(s + w)^5``: five Tustin lags ``1/(s + w)`` in cascade on ``dd z_s`` (states ``y_1..y_5``), and
``z_s = sum_{k=2..5} (k-1) w^(k-2) y_k``, ``dz_s = sum_{k<5} w^(k-1) y_k - 4 w^4 y_5``. The
cutoff ``w = 2 pi max(|v|, SPEED_FLOOR_MPS) / lambda_c`` follows the speed. In the band the
error falls as ``(w / Omega)^4`` (a second-order high-pass's phase lead would cost tens of %
of the band-passed profile); a constant acceleration bias ``b`` settles at ``10 b / w^2``.

The state is a plain tuple ``(dd z_s of the last step, y_1..y_5, z_s, dz_s)`` so that the
per-sample estimators pay one function call. This module imports nothing but ``math``.
"""
from __future__ import annotations

import math

__all__ = ['SPEED_FLOOR_MPS', 'ORDER', 'cutoff_per_speed', 'start', 'step']

#: Speed floor of the cutoff (m/s): w >= 2 pi v_floor / lambda_c.
SPEED_FLOOR_MPS = 1.0
#: Order n of the filter (n real poles at w); :func:`step` is written out for n = 5.
ORDER = 5


def cutoff_per_speed(cutoff_wavelength_m: float) -> float:
    """``w / v = 2 pi / lambda_c`` (rad/m)."""
    return 2.0 * math.pi / cutoff_wavelength_m


def start(accel: float) -> tuple:
    """State of a (re)start: at rest, ``z_s = dz_s = 0``, remembering ``dd z_s``."""
    return (accel, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def step(state: tuple, accel: float, dt: float, v: float, wc_per_speed: float) -> tuple:
    """Advance by ``dt`` (s) with the new acceleration ``accel`` (m/s^2) at speed ``v`` (m/s).

    Returns the new state; ``state[6]`` is ``z_s`` (m) and ``state[7]`` is ``dz_s`` (m/s).
    """
    a_old, y1, y2, y3, y4, y5, _, _ = state
    av = v if v > 0.0 else -v
    wc = wc_per_speed * (av if av > SPEED_FLOOR_MPS else SPEED_FLOOR_MPS)
    hh = 0.5 * dt
    inv = 1.0 / (1.0 + wc * hh)
    g = (1.0 - wc * hh) * inv
    hh *= inv
    n1 = g * y1 + hh * (a_old + accel)
    n2 = g * y2 + hh * (y1 + n1)
    n3 = g * y3 + hh * (y2 + n2)
    n4 = g * y4 + hh * (y3 + n3)
    n5 = g * y5 + hh * (y4 + n4)
    return (accel, n1, n2, n3, n4, n5, n2 + wc * (2.0 * n3 + wc * (3.0 * n4 + wc * 4.0 * n5)),
            n1 + wc * (n2 + wc * (n3 + wc * (n4 - 4.0 * wc * n5))))
