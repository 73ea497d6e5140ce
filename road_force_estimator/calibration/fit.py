"""The calibration's output-error problem: the drive on its sample grid, the residuals of the
plant against it, the solver and the rank test (used by :mod:`.calibration`, see there; the
covariance is :mod:`.calibration_covariance`).

The residuals (:class:`FitProblem`) are those of a variable-projection fit: for each vector of
nonlinear parameters (log vehicle values, the fine alignment) the initial state and the sensor
offsets, on which the outputs depend linearly, are solved by linear least squares, so that the
fit needs no warm-up and the true start (never at rest on a real drive) does not bias it.
The model is the simulator's nonlinear plant: the linear simulation plus the plant's defect
(:func:`~.calibration_model.plant_defect`, :meth:`FitProblem.update_defect`), held fixed
within a solve and updated between solves until the parameters stop moving
(:func:`solve_with_plant`).
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np
from scipy import linalg, optimize

# The core API the fit uses (one place, for the lead to re-point).
from road_force_estimator.core.parameters import VehicleParameters
from road_force_estimator.core.road import RoadProfile
from road_force_estimator.calibration.alignment import Alignment
from road_force_estimator.calibration.covariance import RANK_TOLERANCE
from road_force_estimator.calibration.model import (
    Slot, free_response, linear_plant, log_bounds, plant_defect, simulate_outputs, slot_value,
    vehicle_with)

__all__ = ['CalibrationError', 'DriveGrid', 'drive_grid', 'check_survey', 'too_short',
           'FitProblem', 'start_vector', 'solve', 'solve_without', 'solve_with_plant',
           'structural',
           'MIN_DURATION_S',
           'MIN_DISTANCE_M', 'SURVEY_GAP_M', 'RANK_TOLERANCE', 'FINE_OFFSET_M', 'FINE_SCALE',
           'SUBSTEP_M']

#: A drive needs at least this much time on the survey, besides the warm-up (s)...
MIN_DURATION_S = 5.0
#: ... and this much distance (m).
MIN_DISTANCE_M = 100.0
#: A survey step longer than this (and than 20 median steps) is a gap (m).
SURVEY_GAP_M = 1.0
#: Fine alignment range of the fit around the correlation's result (m, relative scale).
FINE_OFFSET_M = 0.5
FINE_SCALE = 1e-3
#: Longest road step between two points of the linear simulation (m): samples are subdivided.
#: Its road's first-order hold in time differs from the plant's (linear in distance under the
#: RK4 stages): the plant's defect takes that up too, so this only sets how well the linear
#: model's Jacobian stands for the plant's (the tire envelope of 0.25 m leaves little
#: above the 5 cm sampling).
SUBSTEP_M = 0.05
#: Plant-defect updates stop when no log parameter moves by more than this...
DEFECT_TOLERANCE = 1e-7
#: ... or after this many (:data:`PLANT_ONLY_UPDATES` with plant-only slots free, which a
#: least squares on the plant itself then finishes, :func:`_polish`).
MAX_DEFECT_UPDATES = 4
PLANT_ONLY_UPDATES = 2


class CalibrationError(ValueError):
    """Bad input for a calibration (the message is one line)."""




@dataclass(frozen=True)
class DriveGrid:
    """Accepted samples on a uniform grid: ``measured`` (m, 3) NaN where no sample,
    ``good`` (m,), ``speed_mps`` and ``distance_m`` (m,), ``dt_s``, ``t0_ns``; ``rejected``
    counts the samples skipped (non-finite) and the grid rows with no sample."""

    measured: np.ndarray
    good: np.ndarray
    speed_mps: np.ndarray
    distance_m: np.ndarray
    dt_s: float
    t0_ns: int
    index: np.ndarray
    rejected: int


def drive_grid(stamps_ns, q_m, roll_rad, speed_mps) -> DriveGrid:
    """The accepted samples on their uniform sample grid.

    Raises
    ------
    CalibrationError
        No usable sample, stamps off a uniform grid (jitter beyond 5 % of the period).
    """
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    y = np.column_stack([np.asarray(q_m, float), np.asarray(roll_rad, float)])
    v = np.broadcast_to(np.asarray(speed_mps, float), stamps.shape)
    ok = np.all(np.isfinite(y), axis=1) & np.isfinite(v)
    if np.count_nonzero(ok) < 3:
        raise CalibrationError(f'the drive has {np.count_nonzero(ok)} usable samples '
                               '(deflections, roll and speed): nothing to calibrate on')
    stamps, y, v = stamps[ok], y[ok], v[ok]
    period = int(np.median(np.diff(stamps)))
    rel = (stamps - stamps[0]) / period
    index = np.rint(rel).astype(np.int64)
    if np.max(np.abs(rel - index)) > 0.05 or np.any(np.diff(index) < 1):
        raise CalibrationError("the drive's stamps are not on a uniform grid (jitter beyond "
                               '5 % of the sample period): not supported')
    m = int(index[-1]) + 1
    measured = np.full((m, 3), np.nan)
    measured[index] = y
    good = np.zeros(m, bool)
    good[index] = True
    speed = np.interp(np.arange(m), index, v)
    dt = period * 1e-9
    distance = np.concatenate(([0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * dt)))
    # Rows of the grid with no usable sample: the skipped ones and those never received.
    return DriveGrid(measured, good, speed, distance, dt, int(stamps[0]), index,
                     m - int(index.size))


def check_survey(survey: RoadProfile) -> None:
    """Refuse a survey with a gap (a step over :data:`SURVEY_GAP_M` and 20 median steps)."""
    steps = np.diff(survey.distance_m)
    limit = max(SURVEY_GAP_M, 20.0 * float(np.median(steps)))
    if np.any(steps > limit):
        i = int(np.argmax(steps))
        raise CalibrationError(
            f'the survey has a gap of {steps[i]:.2f} m at {survey.distance_m[i]:.2f} m (no '
            f'profile there): calibrate on a survey without gaps')


def too_short(what: str, duration_s: float, distance_m: float, warm_up_s: float) -> None:
    if duration_s < MIN_DURATION_S + warm_up_s or distance_m < MIN_DISTANCE_M:
        raise CalibrationError(
            f'{what} too short for a calibration: {duration_s:.1f} s and {distance_m:.0f} m; '
            f'it must be at least {MIN_DURATION_S + warm_up_s:g} s (with {warm_up_s:g} s of '
            f'warm-up) and {MIN_DISTANCE_M:g} m long')


# --------------------------------------------------------------------------------------------
# The fit


class FitProblem:
    """The output-error residuals over the overlap [k0, k1) of the grid."""

    def __init__(self, grid: DriveGrid, road: RoadProfile, nominal: VehicleParameters,
                 alignment: Alignment, free: list[Slot], fixed: dict[Slot, float],
                 k0: int, k1: int, warm: int) -> None:
        self.grid, self.road, self.nominal = grid, road, nominal
        self.alignment, self.free, self.fixed = alignment, free, fixed
        self.k0, self.k1 = k0, k1
        used = np.zeros(k1 - k0, bool)
        used[warm:] = grid.good[k0 + warm:k1]
        self.used = used
        self.measured = grid.measured[k0:k1][used]
        self.sigma = np.nanstd(self.measured, axis=0)
        self.nominal_values = {s: slot_value(nominal, s) for s in free if s.physical}
        self.t_s = np.arange(k1 - k0) * grid.dt_s
        self.full_measured = grid.measured[k0:k1]
        self._road_key = None
        x0 = alignment.offset_m + alignment.scale * grid.distance_m[k0]
        self.datum_m = float(np.mean(road.elevation_at(np.array([x0]))))
        self.calls = 0
        step = float(np.max(np.abs(grid.speed_mps[k0:k1]))) * alignment.scale * grid.dt_s
        self.substeps = max(1, int(math.ceil(step / SUBSTEP_M)))
        self.defect = np.zeros((k1 - k0, 3))
        # Plant-only slots: the defect's derivative (n, 3, k) at their log values ``defect_at``.
        self.plant_only = [s for s in free if s.plant_only]
        self.defect_jac = np.zeros((k1 - k0, 3, len(self.plant_only)))
        self.defect_at = np.zeros(len(self.plant_only))
        self.plant_road = RoadProfile(road.distance_m, road.elevation_m - self.datum_m)
        #: True: every residual evaluation runs the plant (the defect at that very point, no
        #: extrapolation): the plant's own least squares (:func:`solve_with_plant`'s polish).
        self.exact = False

    def unpack(self, theta: np.ndarray) -> tuple[dict, tuple[float, float]]:
        """(physical slot values, (fine offset m, fine scale))."""
        values = dict(self.fixed)
        fine = [0.0, 0.0]
        for slot, t in zip(self.free, theta):
            if slot.physical:
                values[slot] = self.nominal_values[slot] * math.exp(t)
            else:
                fine[0 if slot.name == 'alignment.offset' else 1] = t
        return values, (fine[0], fine[1])

    def road_input(self, fine: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
        """Road and its rate under the tires on the sub-sample grid (``substeps`` per
        sample, so that the tire moves at most :data:`SUBSTEP_M` between points)."""
        a = self.alignment
        d = self.grid.distance_m[self.k0:self.k1]
        v = self.grid.speed_mps[self.k0:self.k1]
        if self.substeps > 1:
            at = np.arange((d.size - 1) * self.substeps + 1) / self.substeps
            d = np.interp(at, np.arange(d.size), d)
            v = np.interp(at, np.arange(v.size), v)
        x = a.offset_m + fine[0] + (a.scale + fine[1]) * d
        v = (a.scale + fine[1]) * v
        # Less one elevation common to both tracks (a survey's absolute height): the outputs
        # do not see it, and the start at rest plus free responses then stay small numbers.
        return self.road.elevation_at(x) - self.datum_m, self.road.slope_at(x) * v[:, None]

    def fit_linear(self, theta: np.ndarray):
        """For the vehicle of ``theta``: the best initial state and sensor offsets (linear
        least squares, normal equations: the free responses live in the first seconds only),
        and the outputs over the whole overlap with them.

        Returns
        -------
        outputs (k1 - k0, 3), coefficients (the last three: offsets), normal matrix
        """
        values, fine = self.unpack(theta)
        plant = linear_plant(vehicle_with(self.nominal, values))
        if self._road_key != fine:
            self._road = self.road_input(fine)
            self._road_key = fine
        u, du = self._road
        forced = simulate_outputs(plant, u, du, self.grid.dt_s / self.substeps, at_rest=True,
                                  every=self.substeps)
        slowest = float(np.min(-plant.eig.real))
        head = min(forced.shape[0], int(math.ceil(30.0 / max(slowest, 1e-3) / self.grid.dt_s)))
        basis = free_response(plant, self.t_s[:head]) / self.sigma[None, :, None]
        used = self.used[:head]
        w2 = 1.0 / self.sigma ** 2
        nb = basis.shape[2]
        if self.exact:
            forced = forced + self.plant_defect_at(values, fine)
        else:
            forced = forced + self.defect
        if self.plant_only and not self.exact:
            moved = [math.log(values[s] / self.nominal_values[s]) for s in self.plant_only]
            forced = forced + self.defect_jac @ (np.array(moved) - self.defect_at)
        target = (self.full_measured - forced) / self.sigma            # NaN where not used
        target[~self.used] = 0.0
        normal = np.zeros((nb + 3, nb + 3))
        rhs = np.zeros(nb + 3)
        bu = basis[used].reshape(-1, nb)
        normal[:nb, :nb] = bu.T @ bu
        rhs[:nb] = bu.T @ target[:head][used].ravel()
        cross = basis[used].sum(axis=0) / self.sigma[:, None]         # (3, nb)
        normal[nb:, :nb] = cross
        normal[:nb, nb:] = cross.T
        normal[nb:, nb:] = np.diag(self.used.sum() * w2)
        rhs[nb:] = target.sum(axis=0) / self.sigma
        scale = np.sqrt(np.maximum(np.diag(normal), 1e-300))
        coef = np.linalg.solve(normal / np.outer(scale, scale), rhs / scale) / scale
        full = forced + coef[nb:]
        full[:head] += (basis * self.sigma[None, :, None]) @ coef[:nb]
        return full, coef, normal

    def plant_defect_at(self, values: dict, fine: tuple[float, float]) -> np.ndarray:
        """The plant's defect (:func:`~.calibration_model.plant_defect`) for the physical
        ``values`` and the fine alignment ``fine`` (one plant run)."""
        a = self.alignment
        scale = a.scale + fine[1]
        start = a.offset_m + fine[0] + scale * float(self.grid.distance_m[self.k0])
        if self._road_key != fine:
            self._road, self._road_key = self.road_input(fine), fine
        u, du = self._road
        return plant_defect(vehicle_with(self.nominal, values), self.plant_road, start,
                            scale * self.grid.speed_mps[self.k0:self.k1], self.grid.dt_s,
                            u, du, self.substeps)

    def update_defect(self, theta: np.ndarray) -> None:
        """The plant's defect (:meth:`plant_defect_at`) at ``theta``, and for each plant-only
        slot its derivative (forward difference of 1e-4 in log value: one more plant run
        each), with which the defect is extrapolated linearly in those slots."""
        values, fine = self.unpack(theta)
        self.defect = self.plant_defect_at(values, fine)
        step = 1e-4
        for j, slot in enumerate(self.plant_only):
            self.defect_at[j] = math.log(values[slot] / self.nominal_values[slot])
            bumped = dict(values)
            bumped[slot] = values[slot] * math.exp(step)
            self.defect_jac[:, :, j] = (self.plant_defect_at(bumped, fine) - self.defect) / step

    def outputs(self, theta: np.ndarray) -> np.ndarray:
        """Model outputs (best start and offsets) over the whole overlap, (k1 - k0, 3)."""
        return self.fit_linear(theta)[0]

    def residuals(self, theta: np.ndarray) -> np.ndarray:
        self.calls += 1
        return ((self.outputs(theta)[self.used] - self.measured) / self.sigma).ravel()

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = [], []
        for slot in self.free:
            if slot.physical:
                b = log_bounds(slot, self.nominal_values[slot])
            else:
                b = (-FINE_OFFSET_M, FINE_OFFSET_M) if slot.name == 'alignment.offset' \
                    else (-FINE_SCALE, FINE_SCALE)
            lo.append(b[0])
            hi.append(b[1])
        return np.array(lo), np.array(hi)


def start_vector(problem: FitProblem, previous: dict[Slot, float] | None) -> np.ndarray:
    """Start vector: previous results where there are, nominal else."""
    theta = np.zeros(len(problem.free))
    if previous:
        for i, slot in enumerate(problem.free):
            theta[i] = previous.get(slot, 0.0)
    lo, hi = problem.bounds()
    return np.clip(theta, lo + 1e-9, hi - 1e-9)


def solve(problem: FitProblem, theta0: np.ndarray, progress) -> optimize.OptimizeResult:
    """Trust-region least squares from ``theta0`` within the bounds."""
    calls = [0]

    def fun(theta):
        calls[0] += 1
        if progress is not None and calls[0] % 8 == 0:
            progress()
        return problem.residuals(theta)

    lo, hi = problem.bounds()
    return optimize.least_squares(fun, theta0, jac='2-point', bounds=(lo, hi), method='trf',
                                  x_scale='jac', ftol=1e-12, xtol=1e-12, gtol=1e-12,
                                  max_nfev=100 * (len(theta0) + 1))


def solve_with_plant(problem: FitProblem, theta: np.ndarray, progress,
                     sigma: np.ndarray | None = None):
    """:func:`solve` with the plant's defect and the noise levels updated at each result.

    Each pass: the defect at ``theta`` (:meth:`FitProblem.update_defect`), the channel weights
    ``sigma`` (the previous pass's residual RMS; the problem's own at first, unless given),
    a solve. Stops when no entry of ``theta`` moves by more than :data:`DEFECT_TOLERANCE` and
    the noise levels by less than 1 % (at most :data:`MAX_DEFECT_UPDATES` passes).

    Returns
    -------
    (result, sigma): the last solve and the noise levels of its residuals (per channel).
    """
    if sigma is not None:
        problem.sigma = sigma
    for _ in range(PLANT_ONLY_UPDATES if problem.plant_only else MAX_DEFECT_UPDATES):
        problem.update_defect(theta)
        result = solve(problem, theta, progress)
        res = result.fun.reshape(-1, 3) * problem.sigma
        new = np.maximum(np.sqrt(np.mean(res ** 2, axis=0)), 1e-6 * problem.sigma)
        moved = float(np.max(np.abs(result.x - theta))) if theta.size else 0.0
        steady = bool(np.all(np.abs(new / problem.sigma - 1.0) < 0.01))
        theta = result.x
        if moved <= DEFECT_TOLERANCE and steady:
            break
        problem.sigma = new
    if problem.plant_only:
        result = _polish(problem, result.x, progress)
    return result, problem.sigma


def _polish(problem: FitProblem, theta: np.ndarray, progress) -> optimize.OptimizeResult:
    """The plant's own least squares from ``theta`` (:attr:`FitProblem.exact`: one plant run
    per residual evaluation), for fits with plant-only slots.

    The defect updates converge to a point where the *linear* model's Jacobian is orthogonal
    to the residuals; with a leaf-spring friction (``F_f tanh(dq / v_f)``, v_f = 0.01 m/s: at
    small rates a damping of ``F_f / v_f``, 1.5e5 N s/m at 1500 N, ten times the dampers')
    the linear model's Jacobian is far from the plant's, and the updates crawl (measured:
    12 updates leave 0.3 % errors and 16-24 % on the sensor lags on a noise-free drive). A
    Gauss-Newton on the plant itself, started there, converges in a few iterations.
    """
    problem.exact = True
    result = solve(problem, theta, progress)
    res = result.fun.reshape(-1, 3) * problem.sigma
    problem.sigma = np.maximum(np.sqrt(np.mean(res ** 2, axis=0)), 1e-6 * problem.sigma)
    return result


def structural(problem: FitProblem, theta: np.ndarray) -> set[Slot]:
    """Physical slots whose Jacobian column is zero or in the span of the others (at the
    start): the model does not depend on them, or only through a combination of others."""
    base = problem.residuals(theta)
    cols = []
    for j in range(theta.size):
        step = np.zeros(theta.size)
        step[j] = 1e-6
        cols.append((problem.residuals(theta + step) - base) / 1e-6)
    jac = np.column_stack(cols)
    norms = np.linalg.norm(jac, axis=0)
    dead = norms <= 1e-12 * max(float(norms.max()), 1e-300)
    if np.any(~dead):
        _, r, piv = linalg.qr(jac[:, ~dead] / norms[~dead], mode='economic', pivoting=True)
        diag = np.abs(np.diag(r))
        alive = np.flatnonzero(~dead)
        dead[alive[piv[diag < RANK_TOLERANCE * diag[0]]]] = True
    return {s for s, d in zip(problem.free, dead) if d and s.physical}


def solve_without(problem: FitProblem, theta: np.ndarray, held: list[int], progress):
    """``theta`` after a fit with the entries ``held`` kept."""
    keep = [i for i in range(theta.size) if i not in held]
    free = problem.free
    sub = FitProblem.__new__(FitProblem)
    sub.__dict__.update(problem.__dict__)
    sub.free = [free[i] for i in keep]
    full = theta.copy()

    def expand(t):
        out = full.copy()
        out[keep] = t
        return out

    sub.unpack = lambda t: problem.unpack(expand(t))
    result = solve(sub, theta[keep], progress)
    return expand(result.x)
