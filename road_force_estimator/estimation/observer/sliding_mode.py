"""The sliding-mode injection of the model core (:mod:`.online`, its notes: "Sliding-mode
injection"): an implicit Levant differentiator (:func:`..chain.differentiator.implicit_step`)
per measured channel on the dead-zoned output error, its estimates ``rho = (e, de, dde)``
weighted by ``gamma``.
"""
from __future__ import annotations

import math

from road_force_estimator.estimation.chain.differentiator import implicit_step

__all__ = ['SlidingMode']


class SlidingMode:
    """One differentiator per channel and their weight.

    Parameters
    ----------
    lipschitz : sequence of float
        L per channel (the vehicle model's :meth:`.VehicleModel.sm_lipschitz`; again by
        :meth:`set_lipschitz`).

    Notes
    -----
    :meth:`set_gains` takes the weight ``gamma`` and the dead zones (per channel) of the gains
    in use (0 until then: off); :meth:`inject` steps with one sample's output errors;
    :meth:`restart` puts every channel at rest (a run's start).
    """

    def __init__(self, lipschitz) -> None:
        self.set_lipschitz(lipschitz)
        self.gamma = 0.0
        self.restart()

    def set_lipschitz(self, lipschitz) -> None:
        """The differentiators' L per channel (used from the next :meth:`set_gains`)."""
        self._lip = [(lip, lip ** (1.0 / 3.0), math.sqrt(lip)) for lip in lipschitz]

    def set_gains(self, gamma: float, dead: list) -> None:
        """The weight ``gamma`` of rho and the dead zones of the output errors (per
        channel)."""
        self.gamma = gamma
        self._ch = tuple((d, *lip) for d, lip in zip(dead, self._lip))
        self._dead = tuple(dead)

    def restart(self) -> None:
        """Every channel at rest."""
        self._st = [0.0] * (4 * len(self._lip))
        self._rest = True

    def inject(self, errors, dt: float) -> list | None:
        """One step (dt, s) with the output errors (per channel): ``gamma rho`` (3 per
        channel), or None when every channel rests at zero (a differentiator at rest with a
        zero, dead-zoned, input stays at rest: that step is skipped; one within 1e-3 of its
        dead zone of rest is put there)."""
        if self._rest and all(-d <= e <= d for e, d in zip(errors, self._dead)):
            return None
        st = self._st
        active = False
        out = [0.0] * (3 * len(self._dead))
        gm = self.gamma
        for ch, e in enumerate(errors):
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
