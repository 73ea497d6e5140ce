"""Is the speed plausible? A standing truck's deflections show no road excitation.

A recorded speed below :data:`STANDING_MPS` while the deflections keep showing road
excitation (a dropped-out CAN speed signal reads 0 while the truck drives on) contradicts
the deflections. The excitation is the wheel-hop band of both deflections: each through a
second-order high-pass at :data:`BAND_HZ` [0] (two first-order sections, so the body modes
at 1-2 Hz and a standing truck's settling drop out) and a first-order low-pass at
:data:`BAND_HZ` [1]; its mean square is averaged (time constant :data:`ENERGY_TAU_S`) only
while the speed reads standing, from 0 :data:`PROBATION_S` after it starts to, so that a
real stop (whose wheel hop has died out by then) never shows it. A band RMS above
:data:`BAND_RMS_MIN_M` then marks the sample *contradicted*: the estimators use the last
trusted speed for the model instead (:data:`FALLBACK_SPEED_MPS` when none was ever trusted),
while the distance still follows the recorded speed (it does not advance while the speed is
unknown); the samples are counted (``speed_contradicted``). During the first
:data:`PROBATION_S` of a standing speed, before the energy is judged, the model keeps the
last trusted speed too (not counted): a drop-out's first samples then never reach the
model's noise and roughness statistics with a standing speed; at a real stop the last
trusted speed is the one just above :data:`STANDING_MPS`.

:class:`SpeedCheck` runs one sample at a time (the per-sample estimator), :func:`check_arrays`
over arrays (the offline smoother) with the same numbers.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ['STANDING_MPS', 'BAND_HZ', 'ENERGY_TAU_S', 'BAND_RMS_MIN_M', 'PROBATION_S',
           'FALLBACK_SPEED_MPS',
           'SpeedCheck', 'check_arrays']

#: A recorded speed below this (m/s) says the truck stands.
STANDING_MPS = 0.5
#: The wheel-hop band (Hz): second-order high-pass, first-order low-pass.
BAND_HZ = (8.0, 30.0)
#: Time constant of the band's mean square (s).
ENERGY_TAU_S = 0.25
#: Band RMS (m, both deflections) above which a standing speed is contradicted.
BAND_RMS_MIN_M = 1e-4
#: Time (s) after the speed starts to read standing during which the model keeps the last
#: trusted speed.
PROBATION_S = 0.25
#: Model speed (m/s) of contradicted samples when no speed was ever trusted.
FALLBACK_SPEED_MPS = 20.0

_W_HP = 2.0 * math.pi * BAND_HZ[0]
_W_LP = 2.0 * math.pi * BAND_HZ[1]
_E_MIN = BAND_RMS_MIN_M * BAND_RMS_MIN_M


class SpeedCheck:
    """The check one sample at a time; ``contradicted`` counts the contradicted samples."""

    def __init__(self) -> None:
        self.contradicted = 0
        self.trusted = math.nan      # last trusted speed (m/s) at or above STANDING_MPS
        self._s = [0.0] * 6          # per side: high-pass lows 1, 2, band low-pass
        self._energy = 0.0
        self._standing_s = 0.0
        self._dt = -1.0
        self._a = (0.0, 0.0, 0.0)

    def restart(self, q1: float, q2: float, v: float) -> float:
        """A new run: the filters start at this sample (the energy at 0); returns v."""
        self._s = [q1, 0.0, 0.0, q2, 0.0, 0.0]
        self._energy = 0.0
        self._standing_s = 0.0
        if v >= STANDING_MPS:
            self.trusted = v
        return v

    def step(self, dt: float, q1: float, q2: float, v: float) -> float:
        """Advance by dt (s) to (q1, q2) (m) at the recorded speed v (m/s); the speed the
        model is to use (v unless contradicted)."""
        s = self._s
        if dt != self._dt:
            self._dt = dt
            self._a = (1.0 - math.exp(-dt * _W_HP), 1.0 - math.exp(-dt * _W_LP),
                       1.0 - math.exp(-dt / ENERGY_TAU_S))
        a_hp, a_lp, a_e = self._a
        e = 0.0
        for i, x in ((0, q1), (3, q2)):
            s[i] += a_hp * (x - s[i])
            h = x - s[i]
            s[i + 1] += a_hp * (h - s[i + 1])
            s[i + 2] += a_lp * (h - s[i + 1] - s[i + 2])
            e += s[i + 2] * s[i + 2]
        if v >= STANDING_MPS:
            self.trusted = v
            self._energy = 0.0
            self._standing_s = 0.0
            return v
        self._standing_s += dt
        if self._standing_s <= PROBATION_S:     # the wheel hop of a real stop dies out
            return v if math.isnan(self.trusted) else self.trusted
        self._energy += a_e * (e - self._energy)
        if self._energy <= _E_MIN:
            return v
        self.contradicted += 1
        return FALLBACK_SPEED_MPS if math.isnan(self.trusted) else self.trusted


def check_arrays(steps_s: np.ndarray, q: np.ndarray, v: np.ndarray, restart: np.ndarray):
    """:class:`SpeedCheck` over the accepted samples of a recording: the step (s) to each
    (the per-sample path's ``dt_ns * 1e-9``; not used at run starts), deflections (m,
    (m, 2)), recorded speeds (m/s), run starts; ``(contradicted (m,) bool, model speed
    (m,))``. Without a standing speed the speeds are returned as they are."""
    m = v.size
    flags = np.zeros(m, bool)
    if not np.any(v < STANDING_MPS):
        return flags, v
    out = v.copy()
    check = SpeedCheck()
    tl, q1, q2, vl = steps_s.tolist(), q[:, 0].tolist(), q[:, 1].tolist(), v.tolist()
    for k in range(m):
        if restart[k]:
            check.restart(q1[k], q2[k], vl[k])
        else:
            before = check.contradicted
            out[k] = check.step(tl[k], q1[k], q2[k], vl[k])
            flags[k] = check.contradicted > before
    return flags, out
