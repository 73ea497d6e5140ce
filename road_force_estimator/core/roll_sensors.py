"""Roll-sensor physics (``simulator.roll_sensor``, MODEL.md "Sensor faults"): what a real roll
sensor reads of the body's roll angle phi (rad, > 0 left side up), for both plants.

``ideal``
    phi (the package's sensors until now).
``pendulum``
    An inclinometer (a pendulum or an accelerometer at rest in the body) aligns with the
    apparent gravity: it reads ``phi + a_y / g`` (a_y > 0 to the left, m/s^2): in a curve the
    lateral acceleration reads as roll.
``gyro``
    A rate gyro integrated to an angle: phi plus ``b t`` (the rate bias b,
    ``simulator.roll_gyro_drift``, rad/s) plus an angle random walk of ``sigma_w sqrt(t)``
    (``simulator.roll_gyro_random_walk``, rad/s^0.5; the integral of white rate noise,
    independent increments of ``sigma_w sqrt(dt)`` per sample from
    ``numpy.random.default_rng([seed, 3, channel])``).

The road's crossfall or bank (``simulator.road_crossfall``) is no sensor effect: it tilts the
road plane in the plant, and every roll sensor reads the body's roll relative to gravity.
The reading goes on to the lag, scale, offset and noise of :mod:`.sensors`. The batch
(:meth:`RollSensor.read`) and per-sample (:meth:`RollSensor.sampler`) paths give the same
numbers.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Callable

import numpy as np

from road_force_estimator.core.parameters import GRAVITY_MPS2

__all__ = ['RollSensor', 'KINDS']

KINDS = ('ideal', 'pendulum', 'gyro')
_BLOCK = 4096


@dataclass(frozen=True)
class RollSensor:
    """One roll sensor: ``kind``, the gyro's ``drift_radps`` and ``random_walk``
    (rad/s^0.5), the sample ``rate_hz`` and the noise stream (``seed``, ``channel``)."""

    kind: str = 'ideal'
    drift_radps: float = 0.0
    random_walk: float = 0.0
    rate_hz: float = 1000.0
    seed: int = 1
    channel: int = 0

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f'simulator.roll_sensor = {self.kind!r}: must be one of '
                             f'{", ".join(KINDS)}')

    @classmethod
    def from_simulator(cls, sim, channel: int = 0) -> RollSensor:
        """From :class:`.SimulatorParameters` (``roll_sensor``, ``roll_gyro_*``)."""
        return cls(sim.roll_sensor, sim.roll_gyro_drift_radps, sim.roll_gyro_random_walk,
                   sim.rate_hz, sim.seed, channel)

    @property
    def ideal(self) -> bool:
        return self.kind == 'ideal' or (self.kind == 'gyro' and self.drift_radps == 0.0
                                        and self.random_walk == 0.0)

    def _walk(self, rng, n: int) -> np.ndarray:
        return self.random_walk * math.sqrt(1.0 / self.rate_hz) * rng.standard_normal(n)

    def read(self, roll_rad, t_s, lateral_accel_mps2=0.0) -> np.ndarray:
        """What the sensor reads over a drive (rad): arrays over the samples (t from the
        drive's start, s; sample k at ``k / rate_hz``)."""
        phi = np.asarray(roll_rad, dtype=np.float64)
        if self.kind == 'pendulum':
            return phi + np.asarray(lateral_accel_mps2, dtype=np.float64) / GRAVITY_MPS2
        if self.ideal:
            return phi
        out = phi + self.drift_radps * np.asarray(t_s, dtype=np.float64)
        if self.random_walk > 0.0:
            rng = np.random.default_rng([int(self.seed), 3, int(self.channel)])
            steps = np.concatenate([self._walk(rng, _BLOCK) for _ in range(
                -(-(phi.size) // _BLOCK))])[:phi.size] if phi.size else np.zeros(0)
            if steps.size:
                steps[0] = 0.0                  # 0 at the start (the per-sample sum's order)
            out = out + np.cumsum(steps)
        return out

    def sampler(self) -> Callable[[float, float, float], float]:
        """``f(phi, t_s, a_y) -> reading``: the k-th call gives ``read(...)[k]``."""
        if self.kind == 'pendulum':
            return lambda phi, t, ay: phi + ay / GRAVITY_MPS2
        if self.ideal:
            return lambda phi, t, ay: phi
        rng = np.random.default_rng([int(self.seed), 3, int(self.channel)])
        block: list = []
        state = {'sum': None}
        drift, walk = self.drift_radps, self.random_walk > 0.0

        def read(phi: float, t: float, ay: float) -> float:
            v = phi + drift * t
            if walk:
                if not block:
                    block.extend(reversed(self._walk(rng, _BLOCK).tolist()))
                step = block.pop()
                state['sum'] = 0.0 if state['sum'] is None else state['sum'] + step
                v = v + state['sum']
            return v

        return read
