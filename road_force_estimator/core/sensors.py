"""Sensor model: the measured channels y = (q_1, q_2, phi) with lag, scale, offset, noise and
quantisation, and the stamps' jitter.

In this order, per channel: a first-order lag ``tau dm/dt = y - m`` (``vehicle.
sensor_time_constant``; m starts at y(0), the drive starts at rest), exact for the true
signal linearly interpolated between samples (:func:`lag_step`); then the scale error and
offset ``(1 + e) m + b`` (``simulator.sensor_scale_error.*``, ``simulator.sensor_offset.*``);
then the noise and the quantisation below. Each channel gets additive zero-mean Gaussian
noise of its own standard deviation (MODEL.md "Measurements"), then, optionally, rounding to
a quantum (an ADC or encoder step).
The noise comes from ``numpy.random.default_rng(seed)``: three standard normals per sample,
in the order q_1, q_2, phi, so the batch path (:meth:`SensorModel.measure`) and the per-sample
path (:meth:`SensorModel.sampler`) give the same numbers for the same seed.

Deflections read from a mechanical zero (``vehicle.deflection_reference: zero_load``) carry
a constant offset per side, ``-(F_s,i - F_0,i) / k_i`` (MODEL.md "Measurements",
:attr:`.VehicleParameters.deflection_offset_m`), added after the noise and before the
quantisation.
Stamp jitter (``simulator.stamp_jitter`` j): the samples stay at their true times, their
stamps move by ``j (2 r - 1)``, r uniform in [0, 1) from ``default_rng([seed, 1])`` (a stream
of its own: the noise does not change with it), one per sample (:meth:`SensorModel.
stamp_offsets_s`, :meth:`SensorModel.stamp_sampler`).

Options of issue 30, off by default (the readings are then those above, bit for bit): the
roll sensor's physics (:mod:`.roll_sensors`: a pendulum reading ``phi + a_y / g``, a gyro's
drift) on the true roll before the lag, and the sensor faults (:mod:`.sensor_faults`:
spikes, a stuck sensor, a drift) on the readings last of all.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Callable

import numpy as np

from road_force_estimator.core.parameters import SimulatorParameters, VehicleParameters
from road_force_estimator.core.roll_sensors import RollSensor
from road_force_estimator.core.sensor_faults import FaultPlan, parse_faults

__all__ = ['SensorModel', 'lag_step', 'lag_coefficients']

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
    time_constant_s : (deflection, roll)
        First-order lag of the sensors (s), >= 0; 0 = none. Needs ``rate_hz``.
    rate_hz : float
        Sample rate (Hz) of the channels (only the lag uses it).
    scale_error : (q_1, q_2, phi)
        Relative scale errors e (reading ``(1 + e) y``).
    offset : (q_1, q_2, phi)
        Offsets b (m, m, rad).
    stamp_jitter_s : float
        Half-width j of the uniform stamp jitter (s), >= 0.
    roll_sensor : RollSensor, optional
        The roll sensor's physics (None: ideal).
    faults : FaultPlan, optional
        Sensor faults on the channels (q_1, q_2, phi) (None: none).
    """

    deflection_std_m: float = 0.0
    roll_std_rad: float = 0.0
    deflection_quantum_m: float = 0.0
    roll_quantum_rad: float = 0.0
    seed: int = 1
    deflection_offset_m: tuple[float, float] = (0.0, 0.0)
    time_constant_s: tuple = (0.0, 0.0)
    rate_hz: float = 0.0
    scale_error: tuple = (0.0, 0.0, 0.0)
    offset: tuple = (0.0, 0.0, 0.0)
    stamp_jitter_s: float = 0.0
    roll_sensor: RollSensor | None = None
    faults: FaultPlan | None = None

    def __post_init__(self) -> None:
        for name, size in (('time_constant_s', 2), ('scale_error', 3), ('offset', 3)):
            value = tuple(float(v) for v in getattr(self, name))
            if len(value) != size or not all(math.isfinite(v) for v in value):
                raise ValueError(f'{name} = {getattr(self, name)!r} must be {size} finite numbers')
            object.__setattr__(self, name, value)
        if min(self.time_constant_s) < 0.0:
            raise ValueError(f'time_constant_s = {self.time_constant_s!r} must be >= 0 s')
        if max(self.time_constant_s) > 0.0 and not self.rate_hz > 0.0:
            raise ValueError(f'rate_hz = {self.rate_hz!r}: a sensor lag needs the sample rate')
        for name in ('deflection_std_m', 'roll_std_rad', 'deflection_quantum_m',
                     'roll_quantum_rad', 'stamp_jitter_s', 'rate_hz'):
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
                       vehicle: VehicleParameters | None = None,
                       channels: tuple[str, str, str] | None = None) -> SensorModel:
        """Noise and seed of ``simulator.noise.*`` and ``simulator.seed`` (no quantisation),
        scale, offset and stamp jitter of ``simulator.*``; with ``vehicle`` (the truth), the
        lag and the deflection reference (:attr:`.VehicleParameters.deflection_offset_m`);
        the roll sensor's physics and the faults of ``simulator.roll_sensor`` and
        ``simulator.sensor_faults``, whose channels are the joint names ``channels`` of
        (q_1, q_2, phi) (the contract's: :data:`.interfaces.DEFLECTION_JOINTS`)."""
        tau = (0.0, 0.0) if vehicle is None else vehicle.sensor_time_constant_s
        zero = (0.0, 0.0) if vehicle is None else vehicle.deflection_offset_m
        roll = RollSensor.from_simulator(sim, channel=0)
        faults = None
        if sim.sensor_faults.strip():
            if channels is None:
                raise ValueError('simulator.sensor_faults: the sensor model needs the channel '
                                 'names')
            faults = FaultPlan(parse_faults(sim.sensor_faults, channels), channels, sim.rate_hz,
                               sim.duration_s, sim.seed)
        return cls(deflection_std_m=sim.noise_deflection_m, roll_std_rad=sim.noise_roll_rad,
                   seed=sim.seed, deflection_offset_m=zero, time_constant_s=tau,
                   rate_hz=sim.rate_hz,
                   scale_error=(*sim.sensor_scale_error_deflection, sim.sensor_scale_error_roll),
                   offset=(*sim.sensor_offset_deflection_m, sim.sensor_offset_roll_rad),
                   stamp_jitter_s=sim.stamp_jitter_s,
                   roll_sensor=None if roll.ideal else roll,
                   faults=faults if faults is not None and faults.active else None)

    @property
    def lagged(self) -> bool:
        """True when a channel has a lag."""
        return max(self.time_constant_s) > 0.0

    @property
    def distorted(self) -> bool:
        """True when a channel has a scale error or an offset."""
        return any(self.scale_error) or any(self.offset)

    def _lags(self):
        """Per channel (q_1, q_2, phi): the lag coefficients, or None."""
        tq, tp = self.time_constant_s
        return [lag_coefficients(t, 1.0 / self.rate_hz) if t > 0.0 else None
                for t in (tq, tq, tp)]

    def stamp_offsets_s(self, n: int) -> np.ndarray:
        """The stamp offsets (s) of n samples (zeros without jitter), see the module notes."""
        if self.stamp_jitter_s <= 0.0:
            return np.zeros(n)
        r = np.random.default_rng([self.seed, 1]).random(n)
        return self.stamp_jitter_s * (2.0 * r - 1.0)

    def stamp_sampler(self) -> Callable[[], float]:
        """Per-sample stamp offsets (s): the k-th call gives ``stamp_offsets_s(n)[k]``."""
        if self.stamp_jitter_s <= 0.0:
            return lambda: 0.0
        rng = np.random.default_rng([self.seed, 1])
        block: list = []
        j = self.stamp_jitter_s

        def offset() -> float:
            if not block:
                block.extend(reversed((j * (2.0 * rng.random(_BLOCK) - 1.0)).tolist()))
            return block.pop()

        return offset

    def measure(self, q_m, roll_rad, lateral_accel_mps2=0.0) -> tuple[np.ndarray, np.ndarray]:
        """Measured channels for a whole trajectory (sample k at ``k / rate_hz``).

        Parameters
        ----------
        q_m : array_like, shape (n, 2)
            True suspension extensions (m).
        roll_rad : array_like, shape (n,)
            True roll angle (rad).
        lateral_accel_mps2 : float or array_like, shape (n,)
            a_y (m/s^2): what a pendulum roll sensor also reads.

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
        if self.roll_sensor is not None:
            phi = self.roll_sensor.read(phi, np.arange(phi.size) / self.rate_hz,
                                        np.broadcast_to(lateral_accel_mps2, phi.shape))
        if self.lagged or self.distorted:
            q, phi = self._distort(q, phi)
        q_meas, roll_meas = self._apply(q, phi, noise)
        if self.faults is None:
            return q_meas, roll_meas
        y = self.faults.hold(self.faults.apply(np.column_stack([q_meas, roll_meas])))
        return y[:, :2].copy(), y[:, 2].copy()

    def _distort(self, q: np.ndarray, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Lag, scale and offset of whole channels (the per-sample recursion, sample by
        sample: the same numbers as :meth:`sampler`)."""
        y = np.column_stack([q, phi])
        out = np.empty_like(y)
        for ch, coef in enumerate(self._lags()):
            col = y[:, ch].tolist()
            if coef is not None and col:
                m, prev = col[0], col[0]
                res = [m]
                for v in col[1:]:
                    m = lag_step(coef, m, prev, v)
                    prev = v
                    res.append(m)
                col = res
            out[:, ch] = (1.0 + self.scale_error[ch]) * np.asarray(col) + self.offset[ch]
        return out[:, :2], out[:, 2]

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
            ``f(q_m (2,), roll_rad[, a_y]) -> (q_meas (2,) ndarray, roll_meas float)``.
        """
        rng = np.random.default_rng(self.seed)
        roll_read = None if self.roll_sensor is None else self.roll_sensor.sampler()
        faults = None if self.faults is None else self.faults.sampler()
        count = [0]
        block = np.empty((0, 3))
        index = 0
        lags = self._lags()
        distorted = self.lagged or self.distorted
        scale = [1.0 + e for e in self.scale_error]
        memory: list = []        # per channel: (lag state m, previous true value)

        def distort(q_m, roll_rad):
            y = (float(q_m[0]), float(q_m[1]), float(roll_rad))
            if not memory:
                memory.extend((v, v) for v in y)
            out = []
            for ch, v in enumerate(y):
                m, prev = memory[ch]
                m = lag_step(lags[ch], m, prev, v) if lags[ch] is not None else v
                memory[ch] = (m, v)
                out.append(scale[ch] * m + self.offset[ch])
            return np.array(out[:2]), np.float64(out[2])

        def measure_one(q_m, roll_rad, lateral_accel_mps2=0.0):
            nonlocal block, index
            k = count[0]
            count[0] = k + 1
            if roll_read is not None:
                roll_rad = roll_read(float(roll_rad), k / self.rate_hz,
                                     float(lateral_accel_mps2))
            if distorted:
                q_m, roll_rad = distort(q_m, roll_rad)
            if index >= block.shape[0]:
                block = rng.standard_normal((_BLOCK, 3))
                index = 0
            noise = block[index]
            index += 1
            q_meas, roll_meas = self._apply(np.asarray(q_m, dtype=np.float64),
                                            np.float64(roll_rad), noise)
            if faults is not None:
                y = faults(k, [float(q_meas[0]), float(q_meas[1]), float(roll_meas)])
                return np.array(y[:2]), y[2]
            return q_meas, float(roll_meas)

        return measure_one


def lag_coefficients(tau_s: float, dt_s: float) -> tuple[float, float, float]:
    """``(a, b, c)`` of :func:`lag_step` for a time constant tau (s) and step dt (s):
    ``a = exp(-dt / tau)``, ``b = 1 - a`` and ``c = 1 - (tau / dt) (1 - a)``."""
    a = math.exp(-dt_s / tau_s)
    return a, 1.0 - a, 1.0 - (tau_s / dt_s) * (1.0 - a)


def lag_step(coef: tuple[float, float, float], m: float, y0: float, y1: float) -> float:
    """One sample step of the first-order lag ``tau dm/dt = y - m``, exact for y linear from
    y0 to y1 over the step: ``m' = a m + b y0 + c (y1 - y0)``."""
    a, b, c = coef
    return a * m + b * y0 + c * (y1 - y0)
