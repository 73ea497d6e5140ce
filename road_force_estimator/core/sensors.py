"""Sensor model: the measured channels y = (q_1, q_2, phi) with noise and quantisation.

Each channel gets additive zero-mean Gaussian noise of its own standard deviation
(MODEL.md "Measurements"), then, optionally, rounding to a quantum (an ADC or encoder step).
The noise comes from ``numpy.random.default_rng(seed)``: three standard normals per sample,
in the order q_1, q_2, phi, so the batch path (:meth:`SensorModel.measure`) and the per-sample
path (:meth:`SensorModel.sampler`) give the same numbers for the same seed.

Deflections read from a mechanical zero (``vehicle.deflection_reference: zero_load``) carry
a constant offset per side, ``-(F_s,i - F_0,i) / k_i`` (MODEL.md "Measurements",
:attr:`.VehicleParameters.deflection_offset_m`), added after the noise and before the
quantisation.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Callable

import numpy as np

from road_force_estimator.core.parameters import SimulatorParameters, VehicleParameters

__all__ = ['SensorModel']

#: Standard normals drawn at once by the per-sample path (numbers do not depend on it).
_BLOCK = 1024


@dataclass(frozen=True)
class SensorModel:
    """Noise and quantisation of the deflection and roll sensors.

    Parameters
    ----------
    deflection_std_m : float
        Standard deviation of the noise on q_1 and q_2 (m), >= 0.
    roll_std_rad : float
        Standard deviation of the noise on phi (rad), >= 0.
    deflection_quantum_m : float
        Quantisation step of q (m); 0 = none.
    roll_quantum_rad : float
        Quantisation step of phi (rad); 0 = none.
    seed : int
        Seed of the noise generator, >= 0.
    deflection_offset_m : (float, float)
        Constant added to q_1 and q_2 (m), [left, right]: the reading of the equilibrium
        from a mechanical zero; (0, 0) = read from equilibrium.
    """

    deflection_std_m: float = 0.0
    roll_std_rad: float = 0.0
    deflection_quantum_m: float = 0.0
    roll_quantum_rad: float = 0.0
    seed: int = 1
    deflection_offset_m: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        for name in ('deflection_std_m', 'roll_std_rad', 'deflection_quantum_m',
                     'roll_quantum_rad'):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
                    math.isfinite(value) and value >= 0.0):
                raise ValueError(f'{name} = {value!r} must be a finite number >= 0')
            object.__setattr__(self, name, float(value))
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) \
                or self.seed < 0:
            raise ValueError(f'seed = {self.seed!r} must be an integer >= 0')
        offset = tuple(float(v) for v in self.deflection_offset_m)
        if len(offset) != 2 or not all(math.isfinite(v) for v in offset):
            raise ValueError(f'deflection_offset_m = {self.deflection_offset_m!r} must be two '
                             'finite numbers (m)')
        object.__setattr__(self, 'deflection_offset_m', offset)

    @classmethod
    def from_simulator(cls, sim: SimulatorParameters,
                       vehicle: VehicleParameters | None = None) -> SensorModel:
        """Noise and seed of ``simulator.noise.*`` and ``simulator.seed`` (no quantisation);
        with ``vehicle`` (the truth), its deflection reference
        (:attr:`.VehicleParameters.deflection_offset_m`)."""
        offset = (0.0, 0.0) if vehicle is None else vehicle.deflection_offset_m
        return cls(deflection_std_m=sim.noise_deflection_m, roll_std_rad=sim.noise_roll_rad,
                   seed=sim.seed, deflection_offset_m=offset)

    def measure(self, q_m, roll_rad) -> tuple[np.ndarray, np.ndarray]:
        """Measured channels for a whole trajectory.

        Parameters
        ----------
        q_m : array_like, shape (n, 2)
            True suspension extensions (m).
        roll_rad : array_like, shape (n,)
            True roll angle (rad).

        Returns
        -------
        q_meas : ndarray, shape (n, 2)
        roll_meas : ndarray, shape (n,)
        """
        q = np.asarray(q_m, dtype=np.float64)
        phi = np.asarray(roll_rad, dtype=np.float64)
        if q.ndim != 2 or q.shape[1] != 2 or phi.shape != (q.shape[0],):
            raise ValueError(f'q_m must have shape (n, 2) and roll_rad (n,), got {q.shape} and '
                             f'{phi.shape}')
        noise = np.random.default_rng(self.seed).standard_normal((q.shape[0], 3))
        return self._apply(q, phi, noise)

    def _apply(self, q, phi, noise):
        q_meas = q + self.deflection_std_m * noise[..., 0:2]
        if self.deflection_offset_m != (0.0, 0.0):
            q_meas = q_meas + np.asarray(self.deflection_offset_m)
        roll_meas = phi + self.roll_std_rad * noise[..., 2]
        if self.deflection_quantum_m > 0.0:
            q_meas = np.round(q_meas / self.deflection_quantum_m) * self.deflection_quantum_m
        if self.roll_quantum_rad > 0.0:
            roll_meas = np.round(roll_meas / self.roll_quantum_rad) * self.roll_quantum_rad
        return q_meas, roll_meas

    def sampler(self) -> Callable[..., tuple[np.ndarray, float]]:
        """A per-sample measurement function with its own generator (seeded like
        :meth:`measure`: the k-th call gives row k of ``measure``).

        Returns
        -------
        callable
            ``f(q_m (2,), roll_rad) -> (q_meas (2,) ndarray, roll_meas float)``.
        """
        rng = np.random.default_rng(self.seed)
        block = np.empty((0, 3))
        index = 0

        def measure_one(q_m, roll_rad):
            nonlocal block, index
            if index >= block.shape[0]:
                block = rng.standard_normal((_BLOCK, 3))
                index = 0
            noise = block[index]
            index += 1
            q_meas, roll_meas = self._apply(np.asarray(q_m, dtype=np.float64),
                                            np.float64(roll_rad), noise)
            return q_meas, float(roll_meas)

        return measure_one
