"""The calibration's plant: the free-parameter vector and the linear model's simulation.

The model is :class:`road_force_estimator.core.vehicle_model.VehicleModel` (its
:meth:`~road_force_estimator.core.vehicle_model.VehicleModel.linearised` state matrices and the
output kinematics of :meth:`~road_force_estimator.core.vehicle_model.VehicleModel.evaluate`),
never the equations written again: what the core model gains (the gravity moment, leaf-spring
friction, a sensor lag) reaches the calibration.

The free parameters are one table, :data:`SLOTS`: one row per fitted number (a name, the index
in a ``[left, right]`` pair, and a kind). ``'scale'`` values (masses, inertia, stiffnesses,
damping rates, forces) all scale with the one force factor the kinematics cannot see (MODEL.md
"Calibration"); ``'geometry'`` values (the CG height) and ``'time'`` values (a sensor time
constant) do not; ``'offset'`` values are the sensor offsets (m, m, rad) and ``'alignment'``
the fine start offset (m) and odometer scale refined by the fit. Positive physical values are
fitted as ``log(value / nominal)``. ``vehicle.leaf_spring_friction`` (kind ``'scale'``),
``vehicle.sensor_time_constant`` (kind ``'time'``) and the tanh friction's
``vehicle.leaf_spring_friction_velocity`` (kind ``'velocity'``, not scaled; freed only where
the file states a tanh friction, ``calibrate._free_slots``) are in :data:`OPTIONAL`: they join
:data:`SLOTS` (one row per side) as soon as :data:`road_force_estimator.core.parameters.SPECS`
has them, as ``plant_only`` slots: the linear model does not see them, the plant does (its
defect's derivative is their Jacobian column, :meth:`.calibration_fit.FitProblem.update_defect`),
so freeing them needs the plant's support only. A nominal value of zero (no friction, no lag)
is not fitted (log scale): give a positive nominal to fit one.

Simulation: the linear plant, started at its equilibrium on the road under the first sample
(as :mod:`road_force_estimator.core.plant` starts), is integrated exactly in modal coordinates
with the road linear in time between samples (first-order hold), one
:func:`scipy.signal.lfilter` per mode. The fit is that of the simulator's nonlinear plant
(:func:`road_force_estimator.core.plant.simulate`: the roll kinematics ``sin(phi)``,
``cos(phi)``, the gravity moment ``M g h sin(phi)``, the tire's lift-off, the road linearly
interpolated in distance under the RK4 stages): :func:`plant_defect` is what that plant's
outputs differ by from the linear simulation on the same road, added to the linear model (a
defect correction, updated as the parameters move). On a class C road with 10 mrad of roll the
defect is 2-4 um and 4 urad RMS, below 5 Hz: a bias of many standard errors on a 60 s drive
if left out.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np
from scipy import signal

# The core API the calibration uses (one place, for the lead to re-point).
from road_force_estimator.core.parameters import SPECS, VehicleParameters
from road_force_estimator.core.plant import simulate
from road_force_estimator.core.road import RoadProfile
from road_force_estimator.core.sensors import SensorModel
from road_force_estimator.core.vehicle_model import VehicleModel

__all__ = ['Slot', 'SLOTS', 'OPTIONAL', 'FREE_START', 'optional_slots', 'freed_start',
           'CHANNELS', 'vehicle_with',
           'LinearPlant', 'linear_plant', 'simulate_outputs', 'slot_value', 'free_response',
           'plant_outputs', 'plant_defect']

#: Measured channels, in order: deflections left, right (m), roll (rad).
CHANNELS = ('left_suspension', 'right_suspension', 'roll')


@dataclass(frozen=True)
class Slot:
    """One free number of the fit.

    ``name`` is the parameter (``vehicle.*``) or a pseudo-name (``sensor.offset.*``,
    ``alignment.*``); ``index`` 0/1 picks a side of a pair (None for a scalar); ``kind`` is
    ``'scale'``, ``'geometry'``, ``'time'``, ``'velocity'``, ``'offset'`` or ``'alignment'``;
    ``unit`` for
    reports; ``plant_only``: the linear model does not depend on it (its effect, and its
    Jacobian column, come from the plant's defect).
    """

    name: str
    index: int | None
    kind: str
    unit: str
    plant_only: bool = False

    @property
    def label(self) -> str:
        """``name`` or ``name[left]`` / ``name[right]``."""
        if self.index is None:
            return self.name
        return f'{self.name}[{("left", "right")[self.index]}]'

    @property
    def physical(self) -> bool:
        """True for a vehicle parameter (fitted in log scale)."""
        return self.kind in ('scale', 'geometry', 'time', 'velocity')


def _pair(name: str, kind: str, unit: str) -> tuple[Slot, Slot]:
    return Slot(name, 0, kind, unit), Slot(name, 1, kind, unit)


#: Parameters of the plant the linear model lacks: (name, kind, unit); fitted once
#: core.parameters' table has them (``double`` one slot, ``double_pair`` one per side).
OPTIONAL: tuple[tuple[str, str, str], ...] = (
    ('vehicle.leaf_spring_friction', 'scale', 'N'),
    ('vehicle.sensor_time_constant', 'time', 's'),
    ('vehicle.leaf_spring_friction_velocity', 'velocity', 'm/s'),
)


#: Start values of the :data:`OPTIONAL` parameters freed from a nominal 0 on request
#: (``CalibrationOptions.free``, ``calibrate_vehicle --free``): the log-scale fit reaches
#: a factor of 10 either way (:func:`log_bounds`): 50-5000 N of friction, 0.2-20 ms of lag.
FREE_START: dict[str, float] = {
    'vehicle.leaf_spring_friction': 500.0,
    'vehicle.sensor_time_constant': 2e-3,
}


def optional_slots(specs=SPECS) -> tuple[Slot, ...]:
    """The :data:`OPTIONAL` parameters that ``specs`` has, as ``plant_only`` slots."""
    out: list[Slot] = []
    for name, kind, unit in OPTIONAL:
        spec = specs.get(name)
        if spec is None:
            continue
        indices = (0, 1) if spec.kind == 'double_pair' else (None,)
        out += [Slot(name, i, kind, unit, plant_only=True) for i in indices]
    return tuple(out)


#: Every number the fit can free.
SLOTS: tuple[Slot, ...] = (
    Slot('vehicle.sprung_mass', None, 'scale', 'kg'),
    Slot('vehicle.roll_inertia', None, 'scale', 'kg m^2'),
    Slot('vehicle.cg_height_above_roll_axis', None, 'geometry', 'm'),
    *_pair('vehicle.unsprung_mass', 'scale', 'kg'),
    *_pair('vehicle.suspension_stiffness', 'scale', 'N/m'),
    *_pair('vehicle.suspension_damping', 'scale', 'N s/m'),
    *_pair('vehicle.tire_stiffness', 'scale', 'N/m'),
    *optional_slots(),
    Slot('sensor.offset.left_suspension', None, 'offset', 'm'),
    Slot('sensor.offset.right_suspension', None, 'offset', 'm'),
    Slot('sensor.offset.roll', None, 'offset', 'rad'),
    Slot('alignment.offset', None, 'alignment', 'm'),
    Slot('alignment.scale', None, 'alignment', ''),
)


def slot_value(vehicle: VehicleParameters, slot: Slot) -> float:
    """The value of a physical slot in ``vehicle`` (SI)."""
    value = vehicle.to_parameters(every=True)[slot.name]
    return float(value if slot.index is None else value[slot.index])


def vehicle_with(vehicle: VehicleParameters, values: dict[Slot, float]) -> VehicleParameters:
    """``vehicle`` with the physical slots set to ``values`` (SI); validated as any file is.

    Raises
    ------
    ValueError
        A value outside the parameter's range (the message names it).
    """
    params = vehicle.to_parameters(every=True)
    for slot, value in values.items():
        if slot.index is None:
            params[slot.name] = float(value)
        else:
            pair = list(params[slot.name])
            pair[slot.index] = float(value)
            params[slot.name] = pair
    return VehicleParameters.from_parameters(params)


def freed_start(vehicle: VehicleParameters, names) -> VehicleParameters:
    """``vehicle`` with each side of the :data:`OPTIONAL` parameters ``names`` that is 0 set to
    its :data:`FREE_START` value (a nominal 0 is not fitted in log scale); others unchanged.

    Raises
    ------
    ValueError
        A name that is not one of :data:`OPTIONAL` (the message lists them).
    """
    unknown = sorted(set(names) - set(FREE_START))
    if unknown:
        raise ValueError(f'--free {unknown[0]}: only {", ".join(FREE_START)} can be freed '
                         '(the other parameters are free unless held)')
    values = {s: FREE_START[s.name] for s in SLOTS
              if s.name in names and s.plant_only and slot_value(vehicle, s) <= 0.0}
    return vehicle_with(vehicle, values) if values else vehicle


def log_bounds(slot: Slot, nominal: float, span: float = math.log(10.0)) -> tuple[float, float]:
    """Bounds of ``log(value / nominal)``: the parameter's range, within a factor of 10."""
    spec = SPECS[slot.name]
    low = math.log(spec.low / nominal) if spec.low > 0.0 else -math.inf
    high = math.log(spec.high / nominal) if math.isfinite(spec.high) else math.inf
    return max(low, -span), min(high, span)


@dataclass(frozen=True)
class LinearPlant:
    """The linear model in modal form: ``x = Re(V xi)``, ``y = C x``.

    ``eig`` (8,) continuous-time poles (1/s), ``vectors`` V (8, 8), ``inputs`` V^-1 B for the
    road and its rate (8, 4: u_1, u_2, du_1, du_2), ``outputs`` C V (3, 8); ``model`` the
    :class:`VehicleModel` (for the equilibrium).
    """

    eig: np.ndarray
    vectors: np.ndarray
    inputs: np.ndarray
    outputs: np.ndarray
    model: VehicleModel


def output_matrix(model: VehicleModel) -> np.ndarray:
    """``C`` (3, 8): (q_1, q_2, phi) of a small state, from the model's own kinematics."""
    eps = 1e-7
    cols = []
    for j in range(8):
        x = np.zeros(8)
        x[j] = eps
        plus = model.evaluate(x, (0.0, 0.0))
        minus = model.evaluate(-x, (0.0, 0.0))
        cols.append(np.concatenate([(plus.q_m - minus.q_m), [x[1] * 2.0]]) / (2.0 * eps))
    return np.column_stack(cols)


def linear_plant(vehicle: VehicleParameters) -> LinearPlant:
    """The modal form of ``VehicleModel(vehicle).linearised()``."""
    model = VehicleModel(vehicle)
    a, b = model.linearised().state_matrices()
    eig, vectors = np.linalg.eig(a)
    inv = np.linalg.inv(vectors)
    return LinearPlant(eig, vectors, inv @ b[:, :4], output_matrix(model) @ vectors, model)


def simulate_outputs(plant: LinearPlant, road_m: np.ndarray, road_rate_mps: np.ndarray,
                     dt_s: float, *, at_rest: bool = False, every: int = 1) -> np.ndarray:
    """The outputs (q_1, q_2, phi) over a uniform time grid.

    Parameters
    ----------
    plant : LinearPlant
    road_m, road_rate_mps : ndarray, shape (n, 2)
        Road under each tire (m) and its rate (m/s) at the samples.
    dt_s : float
        Sample period (s).
    at_rest : bool
        Start from the zero state instead of the equilibrium on the road at sample 0 (add
        :func:`free_response` columns for any other start).
    every : int
        Return every ``every``-th sample only (the road given on a finer grid).

    Returns
    -------
    ndarray, shape (n, 3)
        Row 0 is the start; the road is linear in time between samples (exact integration of
        the linear model under that hold).
    """
    rate = np.any(plant.inputs[:, 2:] != 0.0)          # tire damping: the road rate acts
    w = np.ascontiguousarray((np.concatenate([road_m, road_rate_mps], axis=1) if rate
                              else road_m).T)            # (4 or 2, n)
    x0 = plant.model.equilibrium(road_m[0], road_rate_mps[0])
    xi0 = np.linalg.solve(plant.vectors, x0.astype(complex)) * (0.0 if at_rest else 1.0)
    # One mode of each complex-conjugate pair (weight 2 on the real part), real modes once.
    lam = plant.eig
    keep = lam.imag >= 0.0
    lam, weight = lam[keep], np.where(lam[keep].imag > 0.0, 2.0, 1.0)
    b, c, xi0 = plant.inputs[keep, :w.shape[0]], plant.outputs[:, keep] * weight, xi0[keep]
    lh = lam * dt_s
    e = np.exp(lh)
    phi1 = np.expm1(lh) / lam                                    # int_0^h e^(lam (h - t)) dt
    phi2 = (np.expm1(lh) - lh) / (lam * lh)                     # ... times t / h
    bw = b.real @ w + 1j * (b.imag @ w)                          # (modes, n)
    d = bw[:, :-1] * (phi1 - phi2)[:, None] + bw[:, 1:] * phi2[:, None]
    xi = np.empty((lam.size, w.shape[1]), dtype=complex)
    xi[:, 0] = xi0
    for j in range(lam.size):
        xi[j, 1:], _ = signal.lfilter([1.0], [1.0, -e[j]], d[j], zi=[e[j] * xi0[j]])
    xi = xi[:, ::every]
    return np.ascontiguousarray((c.real @ xi.real - c.imag @ xi.imag).T)


def free_response(plant: LinearPlant, t_s: np.ndarray) -> np.ndarray:
    """The outputs' response to every initial state, as real columns.

    Parameters
    ----------
    plant : LinearPlant
    t_s : ndarray (m,)
        Times since the start (s).

    Returns
    -------
    ndarray, shape (m, 3, 8)
        Columns spanning the free (unforced) responses of (q_1, q_2, phi) from any initial
        state: the real and imaginary parts of each complex mode pair, each real mode once.
    """
    lam = plant.eig
    keep = lam.imag >= 0.0
    cols = []
    for j in np.flatnonzero(keep):
        z = np.exp(lam[j] * t_s)[:, None] * plant.outputs[:, j][None, :]
        cols.append(z.real)
        if lam[j].imag > 0.0:
            cols.append(z.imag)
    return np.stack(cols, axis=2)



def plant_outputs(vehicle: VehicleParameters, road: RoadProfile, start_m: float,
                  speed_mps: np.ndarray, dt_s: float) -> np.ndarray:
    """The simulator's nonlinear plant (:func:`road_force_estimator.core.plant.simulate`) over
    ``road`` (already enveloped), from its equilibrium at ``start_m`` (m), read through the
    sensors' lag (``vehicle.sensor_time_constant``, :class:`.SensorModel`; none at 0).

    Parameters
    ----------
    speed_mps : ndarray (n,)
        Speed at the samples (m/s, >= 0; linear between them, as the plant's speed profile).
    dt_s : float
        Sample period (s).

    Returns
    -------
    ndarray, shape (n, 3)
        (q_1, q_2, phi) at the samples (m, m, rad); rows past the end of the road are NaN.
    """
    n = int(speed_mps.size)
    v = np.asarray(speed_mps, dtype=float)
    constant = bool(np.all(v == v[0]))
    profile = None if constant else (np.arange(n) * dt_s, np.maximum(v, 0.0))
    traj = simulate(vehicle, road, speed_mps=float(max(np.mean(v), 1e-3)), rate_hz=1.0 / dt_s,
                    duration_s=(n - 1) * dt_s, start_m=start_m, speed_profile=profile)
    out = np.full((n, 3), np.nan)
    m = min(n, len(traj))
    q, roll = traj.q_m[:m], traj.roll_rad[:m]
    if max(vehicle.sensor_time_constant_s) > 0.0:
        # The sensors' first-order lag (vehicle.sensor_time_constant), noise-free: the
        # simulator's own sensor model (core.sensors), started at the first reading.
        q, roll = SensorModel(time_constant_s=vehicle.sensor_time_constant_s,
                              rate_hz=1.0 / dt_s).measure(q, roll)
    out[:m, :2] = q
    out[:m, 2] = roll
    return out


def plant_defect(vehicle: VehicleParameters, road: RoadProfile, start_m: float,
                 speed_mps: np.ndarray, dt_s: float, road_m: np.ndarray,
                 road_rate_mps: np.ndarray, every: int) -> np.ndarray:
    """What the nonlinear plant's outputs differ by from the linear simulation (n, 3).

    Both start at the same equilibrium; the linear one on ``road_m``, ``road_rate_mps`` (the
    fit's road input, ``every`` points per sample, :func:`simulate_outputs`), the plant on
    ``road`` from ``start_m`` at ``speed_mps`` (:func:`plant_outputs`). Zero past the road's
    end (never reached inside a fit's overlap).
    """
    plant = plant_outputs(vehicle, road, start_m, speed_mps, dt_s)
    linear = simulate_outputs(linear_plant(vehicle), road_m, road_rate_mps, dt_s / every,
                              every=every)
    return np.nan_to_num(plant - linear, nan=0.0)
