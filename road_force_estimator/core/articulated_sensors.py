"""The articulated truck's sensors: the deflections of every instrumented axle, the tractor's
roll, the trailer's roll where fitted, the optional tractor IMU (MODEL.md "The whole vehicle",
"Sensors").

Each channel goes through the front axle's chain (:mod:`.sensors`), with its axle's own
options: the roll sensor's physics (:mod:`.roll_sensors`, roll channels only), a first-order
lag (the axle's ``vehicle.axle.<name>.sensor_time_constant``, the roll sensors' from
``vehicle.sensor_time_constant``), the scale error and offset (``simulator.axle.<name>.
sensor_scale_error`` / ``sensor_offset``; ``simulator.sensor_*.roll``), Gaussian noise
(``simulator.noise.*``: standard normals from ``default_rng(seed)``, one per channel per
sample in channel order), the reading from a mechanical zero (``vehicle.deflection_reference:
zero_load``: ``-(S_j,i - F_0,j,i) / k_j,i``, S from the static loads the outputs carry), and
last the faults (:mod:`.sensor_faults`). The IMU reads, at the tractor's centre of gravity
(INTERFACES.md ``/imu/tractor``): ``a_x``, ``a_y``, the tractor's vertical acceleration + g,
the roll, pitch and yaw rates (yaw = a_y / v, 0 below 0.1 m/s), each with white noise
(``simulator.noise.imu_*``, ``default_rng([seed, 4])``).

The batch path (:meth:`ArticulatedSensors.measure`, :meth:`ArticulatedSensors.imu`) and the
per-sample path (:meth:`ArticulatedSensors.sampler`, :meth:`ArticulatedSensors.imu_sampler`)
give the same numbers.
"""
from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from road_force_estimator.core.articulated_model import ArticulatedModel
from road_force_estimator.core.parameters import GRAVITY_MPS2, SimulatorParameters
from road_force_estimator.core.roll_sensors import RollSensor
from road_force_estimator.core.sensor_faults import FaultPlan, parse_faults
from road_force_estimator.core.sensors import SensorModel, lag_coefficients, lag_step

__all__ = ['ArticulatedSensors', 'channel_layout', 'IMU_FIELDS']

_BLOCK = 1024
#: The IMU's numbers per sample, in /imu/tractor's order.
IMU_FIELDS = ('accel_x', 'accel_y', 'accel_z', 'rate_x', 'rate_y', 'rate_z')
#: Below this speed (m/s) the IMU's yaw rate a_y / v is 0.
_YAW_MIN_SPEED_MPS = 0.1


def channel_layout(model: ArticulatedModel) -> list[tuple]:
    """The channels of /suspension/deflections in the contract's order: ``('q', j, side)``
    for each instrumented axle j (side 0 left, 1 right), ``('roll', 0)`` (tractor) and, where
    fitted, ``('roll', 1)`` (trailer)."""
    out = [('q', j, side) for j, a in enumerate(model.axles) if a.instrumented
           for side in (0, 1)]
    out.append(('roll', 0))
    if model.vehicle.trailer_roll_sensor:
        out.append(('roll', 1))
    return out


class ArticulatedSensors:
    """The sensors of one articulated drive.

    Parameters
    ----------
    model : ArticulatedModel
        The truth (its statics give the zero-load readings).
    sim : SimulatorParameters
        Noise, seed, rate, duration, roll physics, faults, roll scale and offset, jitter.
    names : sequence of str
        The joint name of each channel of :func:`channel_layout` (the contract's: the faults
        are written on them).
    """

    def __init__(self, model: ArticulatedModel, sim: SimulatorParameters,
                 names: Sequence[str]) -> None:
        v = model.vehicle
        self.model = model
        self.layout = channel_layout(model)
        self.names = tuple(names)
        if len(self.names) != len(self.layout):
            raise ValueError(f'{len(self.names)} channel names for {len(self.layout)} channels')
        self.rate_hz, self.seed = sim.rate_hz, sim.seed
        statics = model.statics()
        tau, scale, offset, std, zero = [], [], [], [], []
        self.rolls: list[RollSensor | None] = []
        for i, ch in enumerate(self.layout):
            if ch[0] == 'q':
                _, j, side = ch
                a = model.axles[j]
                tau.append(a.sensor_time_constant_s)
                scale.append(a.sensor_scale_error[side])
                offset.append(a.sensor_offset_m[side])
                std.append(sim.noise_deflection_m)
                s_load = statics.output_wheel_load_n[j, side] - 0.5 * a.mass_kg * GRAVITY_MPS2
                zero.append(-(s_load - a.deflection_zero_load_n[side]) /
                            a.suspension_stiffness_npm[side] if v.zero_load else 0.0)
                self.rolls.append(None)
            else:
                tau.append(v.roll_time_constant_s)
                scale.append(sim.sensor_scale_error_roll)
                offset.append(sim.sensor_offset_roll_rad)
                std.append(sim.noise_roll_rad)
                zero.append(0.0)
                roll = RollSensor.from_simulator(sim, channel=ch[1])
                self.rolls.append(None if roll.ideal else roll)
        self.tau, self.scale, self.offset, self.std, self.zero = tau, scale, offset, std, zero
        self.lags = [lag_coefficients(t, 1.0 / sim.rate_hz) if t > 0.0 else None for t in tau]
        faults = FaultPlan(parse_faults(sim.sensor_faults, self.names), self.names,
                           sim.rate_hz, sim.duration_s, sim.seed)
        self.faults = faults if faults.active else None
        #: the stamps' jitter, as the front axle's sensors have it
        self.stamps = SensorModel(seed=sim.seed, stamp_jitter_s=sim.stamp_jitter_s)
        self._imu_std = None

    def set_imu_noise(self, accel_std: float, rate_std: float) -> None:
        """The IMU's noise (m/s^2, rad/s), ``simulator.noise.imu_*``."""
        self._imu_std = (float(accel_std),) * 3 + (float(rate_std),) * 3

    # ----------------------------------------------------------------------------------------

    def _true(self, data: np.ndarray, index: dict) -> np.ndarray:
        """The true value of every channel (n, C): q (m) and the bodies' roll (rad)."""
        q = data[:, index['q_m']]
        state = data[:, index['state']]
        cols = []
        for ch in self.layout:
            cols.append(q[:, 2 * ch[1] + ch[2]] if ch[0] == 'q' else state[:, 3 * ch[1] + 2])
        return np.column_stack(cols)

    def measure(self, trajectory) -> np.ndarray:
        """The readings of every channel over a drive, (n, C) (m, rad)."""
        data = trajectory.data
        y = self._true(data, trajectory.layout.index)
        n, c = y.shape
        t = np.arange(n) / self.rate_hz
        ay = data[:, trajectory.layout.index['lateral_accel_mps2']][:, 0]
        noise = np.random.default_rng(self.seed).standard_normal((n, c))
        out = np.empty_like(y)
        for ch in range(c):
            col = y[:, ch]
            if self.rolls[ch] is not None:
                col = self.rolls[ch].read(col, t, ay)
            if self.lags[ch] is not None and n:
                values = col.tolist()
                m = prev = values[0]
                res = [m]
                for value in values[1:]:
                    m = lag_step(self.lags[ch], m, prev, value)
                    prev = value
                    res.append(m)
                col = np.asarray(res)
            if self.scale[ch] or self.offset[ch]:
                col = (1.0 + self.scale[ch]) * col + self.offset[ch]
            col = col + self.std[ch] * noise[:, ch]
            if self.zero[ch]:
                col = col + self.zero[ch]
            out[:, ch] = col
        if self.faults is not None:
            out = self.faults.hold(self.faults.apply(out))
        return out

    def sampler(self, layout) -> Callable[[tuple], list]:
        """``f(row) -> readings`` (list of C floats) of an :class:`.ArticulatedPlant` row; the
        k-th call gives ``measure(...)[k]``."""
        index = layout.index
        q0, s0 = index['q_m'].start, index['state'].start
        ay_col = index['lateral_accel_mps2'].start
        cols = [q0 + 2 * ch[1] + ch[2] if ch[0] == 'q' else s0 + 3 * ch[1] + 2
                for ch in self.layout]
        rng = np.random.default_rng(self.seed)
        c = len(cols)
        block: list = []
        memory: list = [None] * c        # per lagged channel: (lag state, previous value)
        count = [0]
        rolls = [None if r is None else r.sampler() for r in self.rolls]
        faults = None if self.faults is None else self.faults.sampler()
        gain = [1.0 + e for e in self.scale]
        distort = [bool(e or b) for e, b in zip(self.scale, self.offset)]

        def measure_one(row: tuple) -> list:
            k = count[0]
            count[0] = k + 1
            if not block:
                block.extend(reversed(rng.standard_normal((_BLOCK, c)).tolist()))
            noise = block.pop()
            t, ay = k / self.rate_hz, row[ay_col]
            out = []
            for ch in range(c):
                v = row[cols[ch]]
                if rolls[ch] is not None:
                    v = rolls[ch](v, t, ay)
                lag = self.lags[ch]
                if lag is not None:
                    if memory[ch] is None:
                        memory[ch] = (v, v)
                    m, prev = memory[ch]
                    m = lag_step(lag, m, prev, v) if k else m
                    memory[ch] = (m, v)
                    v = m
                if distort[ch]:
                    v = gain[ch] * v + self.offset[ch]
                v = v + self.std[ch] * noise[ch]
                if self.zero[ch]:
                    v = v + self.zero[ch]
                out.append(v)
            return out if faults is None else faults(k, out)

        return measure_one

    # ----------------------------------------------------------------------------------------

    def imu(self, trajectory) -> np.ndarray:
        """The IMU's readings over a drive, (n, 6) in :data:`IMU_FIELDS`' order."""
        data, index = trajectory.data, trajectory.layout.index
        true = _imu_true(data, index, self.model.n_dof)
        noise = np.random.default_rng([int(self.seed), 4]).standard_normal(true.shape)
        return true + noise * np.asarray(self._imu_noise())

    def imu_sampler(self, layout) -> Callable[[tuple], list]:
        """``f(row) -> the 6 IMU numbers``; the k-th call gives ``imu(...)[k]``."""
        index, n = layout.index, self.model.n_dof
        rng = np.random.default_rng([int(self.seed), 4])
        std = self._imu_noise()
        block: list = []

        def imu_one(row: tuple) -> list:
            if not block:
                block.extend(reversed(rng.standard_normal((_BLOCK, 6)).tolist()))
            noise = block.pop()
            true = _imu_true(np.asarray([row]), index, n)[0].tolist()
            return [v + s * e for v, s, e in zip(true, std, noise)]

        return imu_one

    def _imu_noise(self) -> tuple:
        return self._imu_std if self._imu_std is not None else (0.0,) * 6

    def stamp_offsets_s(self, n: int) -> np.ndarray:
        """The stamp jitter of n samples (s), as :meth:`.SensorModel.stamp_offsets_s`."""
        return self.stamps.stamp_offsets_s(n)


def _imu_true(data: np.ndarray, index: dict, n_dof: int) -> np.ndarray:
    """(a_x, a_y, dd z_t + g, dphi_t, dtheta_t, a_y / v) per row (SI)."""
    state = data[:, index['state']]
    acc = data[:, index['accel']]
    v = data[:, index['speed_mps']][:, 0]
    ay = data[:, index['lateral_accel_mps2']][:, 0]
    yaw = np.where(v > _YAW_MIN_SPEED_MPS, ay / np.maximum(v, _YAW_MIN_SPEED_MPS), 0.0)
    return np.column_stack([data[:, index['longitudinal_accel_mps2']][:, 0], ay,
                            acc[:, 0] + GRAVITY_MPS2, state[:, n_dof + 2], state[:, n_dof + 1],
                            yaw])
