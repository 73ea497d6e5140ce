"""The sliding-mode injection of the model core (:mod:`.model_core`, its notes: "Sliding-mode
injection"): an implicit Levant differentiator (:func:`.differentiator.implicit_step`) per
output channel (q_1, q_2, phi) on the dead-zoned output error, its estimates ``rho = (e, de,
dde)`` weighted by ``gamma``.
"""
from __future__ import annotations

import math

from road_force_estimator.core.parameters import VehicleParameters
from road_force_estimator.estimation.chain.differentiator import implicit_step
from road_force_estimator.estimation.observer.gains import sm_lipschitz

__all__ = ['SlidingMode']


class SlidingMode:
    """The three differentiators and their weight.

    Parameters
    ----------
    vehicle : VehicleParameters
        Sets the differentiators' L (:func:`.gains.sm_lipschitz`; again by
        :meth:`set_vehicle`).

    Notes
    -----
    :meth:`set_gains` takes the weight ``gamma`` and the dead zones (m, m, rad) of the gains
    in use (0 until then: off); :meth:`inject` steps with one sample's output errors;
    :meth:`restart` puts every channel at rest (a run's start).
    """

    def __init__(self, vehicle: VehicleParameters) -> None:
        self.set_vehicle(vehicle)
        self.gamma = 0.0
        self.restart()

    def set_vehicle(self, vehicle: VehicleParameters) -> None:
        """The differentiators' L of ``vehicle`` (used from the next :meth:`set_gains`)."""
        lq, lr = sm_lipschitz(vehicle)
        self._lip = (lq, lq ** (1.0 / 3.0), math.sqrt(lq), lr, lr ** (1.0 / 3.0),
                     math.sqrt(lr))

    def set_gains(self, gamma: float, dead: list) -> None:
        """The weight ``gamma`` of rho and the dead zones of the output errors (m, m, rad)."""
        self.gamma = gamma
        lq, lq13, lq12, lr, lr13, lr12 = self._lip
        self._ch = ((dead[0], lq, lq13, lq12), (dead[1], lq, lq13, lq12),
                    (dead[2], lr, lr13, lr12))
        self._dead = tuple(dead)

    def restart(self) -> None:
        """Every channel at rest."""
        self._st = [0.0] * 12
        self._rest = True

    def inject(self, e1: float, e2: float, e3: float, dt: float) -> list | None:
        """One step (dt, s) with the output errors e_i (m, m, rad): ``gamma rho`` (9), or None
        when every channel rests at zero (a differentiator at rest with a zero, dead-zoned,
        input stays at rest: that step is skipped; one within 1e-3 of its dead zone of rest is
        put there)."""
        d1, d2, d3 = self._dead
        if self._rest and -d1 <= e1 <= d1 and -d2 <= e2 <= d2 and -d3 <= e3 <= d3:
            return None
        st = self._st
        active = False
        out = [0.0] * 9
        gm = self.gamma
        for ch, e in enumerate((e1, e2, e3)):
            dz, lip, lip13, lip12 = self._ch[ch]
            f = e - dz if e > dz else (e + dz if e < -dz else 0.0)
            j = 4 * ch
            z0 = st[j]
            z1 = st[j + 1]
            z2 = st[j + 2]
            if f == 0.0:
                if z0 == 0.0 and z1 == 0.0 and z2 == 0.0:
                    continue
                if (abs(z0) + dt * (abs(z1) + dt * abs(z2))) < 1e-3 * dz:
                    st[j] = st[j + 1] = st[j + 2] = st[j + 3] = 0.0
                    continue
            z0, z1, z2 = implicit_step(z0, z1, z2, st[j + 3], f, dt, lip, lip13, lip12)
            st[j] = z0
            st[j + 1] = z1
            st[j + 2] = z2
            st[j + 3] = f
            k = 3 * ch
            out[k] = gm * z0
            out[k + 1] = gm * z1
            out[k + 2] = gm * z2
            active = True
        self._rest = not any(st)
        return out if active else None
