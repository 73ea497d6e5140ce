"""Calibration of the vehicle parameters from a drive over a surveyed road (MODEL.md
"Calibration from a drive over a known road").

:func:`calibrate` takes the drive's samples (deflections, roll, speed), the survey (a
:class:`~road_force_estimator.core.road.RoadProfile` of the same wheel paths) and the nominal
parameters, and returns a :class:`CalibrationResult`:

1. The drive on a uniform time grid (the accepted samples; rejected ones are missing rows the
   model still runs through), its distance the trapezoidal integral of the speed.
2. Alignment (:mod:`.calibration_alignment`): the observer's estimated profile
   (:func:`~road_force_estimator.estimation.estimator.estimate_batch`, nominal parameters)
   against the survey's: start offset and odometer scale.
3. Identification: an output-error fit (:func:`scipy.optimize.least_squares`, time domain) of
   the simulator's plant (:mod:`.calibration_model`: the linear model plus the nonlinear
   plant's defect, updated between solves until the parameters stop moving; first the linear
   model alone on the correlation's alignment) driven by the aligned survey under the tire
   envelope, to the measured deflections and roll; free: the vehicle parameters of
   :data:`~.calibration_model.SLOTS` not held, the sensor offsets, and a fine alignment. Each
   channel is weighted by its noise level (a first pass with the signal RMS, then the
   residual RMS: the noise levels, a by-product). The initial state and the offsets enter
   linearly and are solved for each vehicle (variable projection, :mod:`.calibration_fit`):
   the true start, never at rest, does not bias the fit.
4. The force scale: the kinematics fix only ratios. One scale-bearing parameter is held during
   the fit (the left tire stiffness, or one the user holds); afterwards every scale-bearing
   value is multiplied by one factor: from the static load (``F_c1 + F_c2 = (M + m_1 + m_2)
   g``), or, without it, so that the mean tire stiffness stays nominal (then the masses,
   stiffnesses and damping rates are known only up to that factor; their ratios are fitted).
5. Parameters the data cannot tell apart (a rank-deficient Jacobian, or a 95 % interval wider
   than +-50 %) are held at their nominal values, named, and the fit repeated.
6. 95 % intervals from the sandwich covariance with the residuals' own auto- and
   cross-covariance (:mod:`.calibration_covariance`: Bartlett lag window by Politis' rule, at
   most :data:`HAC_WINDOW_S`): white residuals give the Gauss-Newton covariance; a model
   error, coloured, widens them.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math
import time
from typing import Callable

import numpy as np

# The core and estimation API the calibration uses (one place, for the lead to re-point).
from road_force_estimator.core.parameters import (
    GRAVITY_MPS2, ObserverParameters, VehicleParameters)
from road_force_estimator.core.road import RoadProfile
from road_force_estimator.estimation.estimator import estimate_batch
from road_force_estimator.estimation.friction_fit import states_friction
from road_force_estimator.calibration.alignment import (
    Alignment, AlignmentError, align)
from road_force_estimator.calibration.fit import (
    FINE_OFFSET_M, FINE_SCALE, MIN_DISTANCE_M, MIN_DURATION_S, CalibrationError, DriveGrid,
    FitProblem, check_survey, drive_grid, solve_without, solve_with_plant, start_vector,
    structural, too_short)
from road_force_estimator.calibration.covariance import (
    covariance, effective_fraction)
from road_force_estimator.calibration.model import (
    CHANNELS, SLOTS, Slot, freed_start, slot_value, vehicle_with)

__all__ = ['CalibrationError', 'AlignmentError', 'CalibrationOptions', 'ParameterEstimate',
           'CalibrationResult', 'calibrate', 'MIN_DURATION_S', 'MIN_DISTANCE_M',
           'check_survey', 'DriveGrid', 'drive_grid']

#: A 95 % interval wider than this relative half-width: not identified (held).
MAX_RELATIVE_HALF_WIDTH = 0.5
Z95 = 1.959963984540054
#: Longest lag window of the intervals' noise covariance (s): the slowest mode's period.
HAC_WINDOW_S = 1.0


@dataclass(frozen=True)
class CalibrationOptions:
    """Settings of :func:`calibrate` (SI units).

    ``static_load_n``: the weighbridge load per wheel [left, right] (N) or None;
    ``hold``: parameter names (``vehicle.*``) kept at their nominal values;
    ``tire_envelope_m``: the envelope the plant's tire follows; ``start_offset_m``: the
    expected survey distance at the drive's start, searched +- ``search_m``; ``scale_error``:
    the odometer scale searched in 1 +- it; ``min_correlation``: the alignment's threshold;
    ``warm_up_s``: time not fitted at the start of the overlap; ``free``: names of
    :data:`~.calibration_model.OPTIONAL` parameters (leaf-spring friction, sensor lag) to fit
    even where the nominal value is 0 (they start from
    :data:`~.calibration_model.FREE_START`, reported as their nominal); without it a 0 stays
    'fixed'.
    """

    static_load_n: tuple[float, float] | None = None
    hold: frozenset[str] = frozenset()
    tire_envelope_m: float = 0.25
    start_offset_m: float | None = None
    search_m: float = 50.0
    scale_error: float = 0.03
    min_correlation: float = 0.5
    warm_up_s: float = 0.0
    max_rounds: int = 3
    free: frozenset[str] = frozenset()


@dataclass(frozen=True)
class ParameterEstimate:
    """One calibrated number: ``status`` is ``'fitted'``, ``'held'`` (by the user),
    ``'not identifiable'`` (held at nominal), ``'scale'`` (set by the force scale) or
    ``'fixed'`` (not a free parameter)."""

    slot: Slot
    nominal: float
    value: float
    low: float
    high: float
    std: float
    status: str

    def as_dict(self) -> dict:
        return {'name': self.slot.label, 'unit': self.slot.unit, 'kind': self.slot.kind,
                'nominal': self.nominal, 'value': self.value, 'ci95_low': self.low,
                'ci95_high': self.high, 'std': self.std, 'status': self.status}


@dataclass
class CalibrationResult:
    """What :func:`calibrate` found; see the module notes."""

    vehicle: VehicleParameters
    nominal: VehicleParameters
    parameters: list[ParameterEstimate]
    alignment: Alignment
    fine_alignment: tuple[float, float]
    noise: np.ndarray
    noise_high_frequency: np.ndarray
    residual_rms: np.ndarray
    scale_known: bool
    scale_note: str
    not_identifiable: list[str]
    correlated: list[tuple[str, str, float]]
    used_samples: int
    used_duration_s: float
    used_distance_m: float
    dt_s: float
    t_s: np.ndarray = field(repr=False)
    measured: np.ndarray = field(repr=False)
    fitted: np.ndarray = field(repr=False)
    timings_s: dict = field(default_factory=dict)
    rejected_samples: int = 0
    nfev: int = 0
    covariance_window_s: float = 0.0

    def values(self) -> dict[str, object]:
        """The calibrated ``vehicle.*`` values by name (pairs as lists)."""
        return self.vehicle.to_parameters()


# --------------------------------------------------------------------------------------------
# The drive on a uniform grid
# The force scale


class _Scale:
    """How the force scale is fixed (module notes, step 4)."""

    def __init__(self, options: CalibrationOptions, nominal: VehicleParameters) -> None:
        self.static = options.static_load_n
        held_scale = [s for s in SLOTS if s.kind == 'scale' and s.name in options.hold]
        self.user = bool(held_scale)
        kt = [s for s in SLOTS if s.name == 'vehicle.tire_stiffness']
        self.reference = None if self.user else kt[0]
        self.tires = kt
        self.nominal_tires = sum(slot_value(nominal, s) for s in kt)
        if self.user:
            self.note = (f'the force scale is that of the held {held_scale[0].label}'
                         + (' (the static load is not used for the scale)' if self.static
                            else ''))
        elif self.static:
            self.note = (f'the force scale is the static load {self.static[0]:.0f} + '
                         f'{self.static[1]:.0f} N = (M + m_1 + m_2) g')
        else:
            self.note = ('no static load: the mean tire stiffness is held at its nominal value '
                         'as the force scale, so the masses, inertia, stiffnesses and damping '
                         'rates are known only up to a common factor (their ratios are fitted)')

    @property
    def known(self) -> bool:
        return self.user or self.static is not None

    def factor(self, values: dict[Slot, float]) -> float:
        """The factor on every scale-bearing value (1 when the user holds one)."""
        if self.user:
            return 1.0
        if self.static is not None:
            masses = sum(v for s, v in values.items()
                         if s.name in ('vehicle.sprung_mass', 'vehicle.unsprung_mass'))
            return (self.static[0] + self.static[1]) / GRAVITY_MPS2 / masses
        return self.nominal_tires / sum(values[s] for s in self.tires)


def _final_values(problem: FitProblem, scale: _Scale, theta: np.ndarray,
                  scaled: set[Slot]) -> dict[Slot, float]:
    """Physical values after the force scale (``scaled``: the slots it multiplies)."""
    values, _ = problem.unpack(theta)
    f = scale.factor(values)
    return {s: (v * f if s in scaled else v) for s, v in values.items()}


def _final_covariance(problem, scale, theta, cov, scaled):
    """Covariance of the log final values of ``scaled`` and free slots (FD on theta)."""
    keys = [s for s in SLOTS if s.physical and (s in scaled or s in problem.free)]
    base = _final_values(problem, scale, theta, scaled)
    g = np.zeros((len(keys), theta.size))
    for j in range(theta.size):
        step = np.zeros(theta.size)
        step[j] = 1e-6
        plus = _final_values(problem, scale, theta + step, scaled)
        minus = _final_values(problem, scale, theta - step, scaled)
        g[:, j] = [(math.log(plus[k]) - math.log(minus[k])) / 2e-6 for k in keys]
    good = np.all(np.isfinite(cov), axis=0)
    out = np.full((len(keys), len(keys)), np.nan)
    gg = g[:, good]
    c = cov[np.ix_(good, good)]
    out[:] = gg @ c @ gg.T
    bad_rows = np.any(g[:, ~good] != 0.0, axis=1)
    out[bad_rows] = np.nan
    out[:, bad_rows] = np.nan
    return keys, base, out


# --------------------------------------------------------------------------------------------
# Rounds: fit, find what is not identifiable, hold it, fit again


def _free_slots(nominal: VehicleParameters, hold: set[str], auto: set[Slot],
                reference: Slot | None) -> list[Slot]:
    """The slots the fit frees: not held (by name, or ``auto``), not the force reference nor
    an offset, a physical value > 0 in ``nominal``, and the friction's ``v_f`` (kind
    ``'velocity'``) only where ``nominal`` states a tanh friction (else it acts on nothing)."""
    free = []
    for slot in SLOTS:
        if slot.name in hold or slot in auto or slot == reference or slot.kind == 'offset':
            continue
        if slot.physical and slot_value(nominal, slot) <= 0.0:
            continue
        if slot.kind == 'velocity' and not states_friction(
                nominal.leaf_spring_friction_model, nominal.leaf_spring_friction_n):
            continue
        free.append(slot)
    return free


def _round(setup: dict, auto: set[Slot], previous, sigma, progress):
    """One fit with the slots ``auto`` held: (problem, result, sigma)."""
    nominal, scale = setup['nominal'], setup['scale']
    free = _free_slots(nominal, setup['hold'], auto, scale.reference)
    fixed = {s: slot_value(nominal, s) for s in SLOTS if s.physical and s not in free}
    problem = FitProblem(setup['grid'], setup['road'], nominal, setup['alignment'], free, fixed,
                       setup['k0'], setup['k1'], setup['warm'])
    theta = start_vector(problem, previous)
    if problem.plant_only:
        problem.update_defect(theta)        # their Jacobian columns come from the plant
    dead = structural(problem, theta)
    if dead:
        auto |= dead
        return _round(setup, auto, previous, sigma, progress)
    if previous is None:
        # First the vehicle alone on the correlation's alignment with the linear model (the
        # fine alignment trades against the parameters far from the optimum), then everything
        # with the plant.
        # (The plant-only slots wait too: the linear model does not see them.)
        fixed_align = [i for i, s in enumerate(free) if s.kind == 'alignment' or s.plant_only]
        theta = solve_without(problem, theta, fixed_align, progress)
    result, sigma = solve_with_plant(problem, theta, progress, sigma)
    return problem, result, sigma


def _unidentified(problem, scale, result, cov, deficient, scaled) -> set[Slot]:
    """Physical slots the data cannot fix: rank-deficient or too wide an interval."""
    bad = {s for s, d in zip(problem.free, deficient) if d and s.physical}
    keys, _, fcov = _final_covariance(problem, scale, result.x, cov, scaled)
    for k, slot in enumerate(keys):
        if slot in problem.free and slot.physical:
            var = fcov[k, k]
            if not np.isfinite(var) or Z95 * math.sqrt(max(var, 0.0)) > MAX_RELATIVE_HALF_WIDTH:
                bad.add(slot)
    return bad


def _correlated(problem: FitProblem, cov: np.ndarray) -> list[tuple[str, str, float]]:
    """Pairs of free slots correlated beyond 0.95."""
    out = []
    sd = np.sqrt(np.abs(np.diag(cov)))
    for i in range(len(problem.free)):
        for j in range(i + 1, len(problem.free)):
            if sd[i] > 0 and sd[j] > 0 and np.isfinite(cov[i, j]):
                r = cov[i, j] / (sd[i] * sd[j])
                if abs(r) > 0.95:
                    out.append((problem.free[i].label, problem.free[j].label, float(r)))
    return out


# --------------------------------------------------------------------------------------------
# The result


def _physical_estimate(slot, nominal, keys, base, fcov, status) -> ParameterEstimate:
    k = keys.index(slot)
    var = fcov[k, k]
    sd = math.sqrt(var) if np.isfinite(var) and var >= 0.0 else math.nan
    value = base[slot]
    return ParameterEstimate(slot, nominal, value, value * math.exp(-Z95 * sd),
                             value * math.exp(Z95 * sd), value * sd, status)


def _estimates(problem, scale, result, cov, scaled, hold, auto) -> list[ParameterEstimate]:
    keys, base, fcov = _final_covariance(problem, scale, result.x, cov, scaled)
    offsets = _offsets(problem, result)
    out = []
    for slot in SLOTS:
        if slot.physical:
            nominal = slot_value(problem.nominal, slot)
            if slot in keys:
                status = 'fitted' if slot in problem.free else 'scale'
                out.append(_physical_estimate(slot, nominal, keys, base, fcov, status))
                continue
            status = ('held' if slot.name in hold else
                      'not identifiable' if slot in auto else 'fixed')
            out.append(ParameterEstimate(slot, nominal, nominal, nominal, nominal, 0.0, status))
            continue
        if slot.kind == 'offset':
            out.append(offsets[CHANNELS.index(slot.name.rsplit('.', 1)[1])])
            continue
        a = problem.alignment
        start = {'alignment.offset': a.offset_m, 'alignment.scale': a.scale}.get(slot.name, 0.0)
        if slot not in problem.free:
            out.append(ParameterEstimate(slot, start, start, start, start, 0.0, 'held'))
            continue
        i = problem.free.index(slot)
        sd = math.sqrt(cov[i, i]) if np.isfinite(cov[i, i]) else math.nan
        value = start + float(result.x[i])
        out.append(ParameterEstimate(slot, start, value, value - Z95 * sd, value + Z95 * sd, sd,
                                     'fitted'))
    return out


def _offsets(problem: FitProblem, result) -> list[ParameterEstimate]:
    """The sensor offsets (linear in the fit) with their conditional 95 % intervals."""
    _, coef, normal = problem.fit_linear(result.x)
    p = normal.shape[0]
    s2 = float(np.sum(result.fun ** 2)) / max(result.fun.size - p - len(problem.free), 1)
    cov = np.linalg.pinv(normal) * s2 / effective_fraction(result.fun)
    out = []
    for c in range(3):
        slot = next(s for s in SLOTS if s.name == 'sensor.offset.' + CHANNELS[c])
        k = p - 3 + c
        sd = math.sqrt(max(cov[k, k], 0.0))
        value = float(coef[k])
        out.append(ParameterEstimate(slot, 0.0, value, value - Z95 * sd, value + Z95 * sd, sd,
                                     'fitted'))
    return out


def _vehicle(nominal: VehicleParameters, estimates, static) -> VehicleParameters:
    values = {e.slot: e.value for e in estimates if e.slot.physical}
    vehicle = vehicle_with(nominal, values)
    if static is not None:
        params = vehicle.to_parameters()
        params['vehicle.static_load'] = [float(static[0]), float(static[1])]
        vehicle = VehicleParameters.from_parameters(params)
    return vehicle


def _high_frequency_noise(measured: np.ndarray) -> np.ndarray:
    """Noise std per channel from second differences of consecutive samples (an upper bound
    where the signal itself curves within three samples)."""
    d2 = measured[2:] - 2.0 * measured[1:-1] + measured[:-2]
    d2 = d2[np.all(np.isfinite(d2), axis=1)]
    if d2.shape[0] == 0:
        return np.full(3, np.nan)
    return np.sqrt(np.mean(d2 ** 2, axis=0) / 6.0)


# --------------------------------------------------------------------------------------------
# The whole calibration


def _check_hold(hold) -> set[str]:
    known = {s.name for s in SLOTS} | {'vehicle.track_width', 'vehicle.tire_damping',
                                        'vehicle.static_load'}
    for name in hold:
        if name not in known:
            raise CalibrationError(f'--hold {name}: not a calibrated parameter (one of '
                                   f'{", ".join(sorted(known))})')
    return set(hold)


def _align_drive(grid, road, nominal, observer, options, tick):
    """The alignment of the drive's estimated profile with the (enveloped) survey; the
    estimator runs over every grid sample, the missing ones interpolated (a gap would restart
    it)."""
    n = grid.good.size
    idx = np.arange(n)
    ok = np.flatnonzero(grid.good)
    filled = np.column_stack([np.interp(idx, ok, grid.measured[ok, c]) for c in range(3)])
    stamps = grid.t0_ns + np.rint(idx * grid.dt_s * 1e9).astype(np.int64)
    est = estimate_batch(stamps, filled[:, :2], filled[:, 2], grid.speed_mps, nominal, observer,
                         progress=lambda k: tick(0.15 * k / max(n, 1)))
    start = road.start_m if options.start_offset_m is None else options.start_offset_m
    return align(grid.distance_m[est.valid], est.road_m[est.valid], road, start_m=start,
                 search_m=options.search_m, scale_error=options.scale_error,
                 min_correlation=options.min_correlation,
                 progress=lambda f: tick(0.001))


def _overlap(grid: DriveGrid, road: RoadProfile, alignment: Alignment, warm_up_s: float):
    """Grid range [k0, k1) on the survey (with a margin for the fine alignment)."""
    x = alignment.survey_m(grid.distance_m)
    margin = FINE_OFFSET_M + FINE_SCALE * float(grid.distance_m[-1]) + 0.1
    inside = (x >= road.start_m + margin) & (x <= road.end_m - margin)
    if not np.any(inside):
        raise CalibrationError(f'no overlap: the aligned drive ({x[0]:.1f}..{x[-1]:.1f} m) '
                               f'misses the survey [{road.start_m:g}, {road.end_m:g}] m')
    k0 = int(np.argmax(inside))
    k1 = int(inside.size - np.argmax(inside[::-1]))
    warm = int(round(warm_up_s / grid.dt_s))
    good = np.count_nonzero(grid.good[k0 + warm:k1])
    too_short("the drive's overlap with the survey is", (good + warm) * grid.dt_s,
               float(x[k1 - 1] - x[k0]), warm_up_s)
    return k0, k1, warm


def calibrate(stamps_ns, q_m, roll_rad, speed_mps, survey: RoadProfile,
              nominal: VehicleParameters, observer: ObserverParameters | None = None,
              options: CalibrationOptions = CalibrationOptions(),
              progress: Callable[[float, str], object] | None = None) -> CalibrationResult:
    """Calibrate the vehicle parameters from a drive over a surveyed road.

    Parameters
    ----------
    stamps_ns, q_m, roll_rad, speed_mps : the drive's accepted samples: stamps (n,) int ns,
        deflections (n, 2) m, roll (n,) rad, speed (n,) m/s (non-finite rows are skipped).
    survey : RoadProfile
        The surveyed profile of the same wheel paths (not enveloped).
    nominal : VehicleParameters
        The starting values; the held ones are kept.
    observer : ObserverParameters, optional
        The estimator's settings for the alignment's profile.
    options : CalibrationOptions
    progress : callable(fraction, stage), optional

    Raises
    ------
    CalibrationError, AlignmentError
        Bad input (one line each): a survey with gaps, a drive too short (the message says how
        long it must be), no overlap, a drive that does not match the survey.
    """
    clock = {'start': time.perf_counter()}
    done = [0.0]

    def tick(step: float, stage: str = 'fit') -> None:
        done[0] = min(done[0] + step, 0.99)
        if progress is not None:
            progress(done[0], stage)

    hold = _check_hold(options.hold)
    if options.free:
        try:
            nominal = freed_start(nominal, options.free - hold)
        except ValueError as exc:
            raise CalibrationError(str(exc)) from None
    check_survey(survey)
    grid = drive_grid(stamps_ns, q_m, roll_rad, speed_mps)
    too_short('the drive is', np.count_nonzero(grid.good) * grid.dt_s,
               float(grid.distance_m[-1]), options.warm_up_s)
    road = survey.enveloped(options.tire_envelope_m)
    alignment = _align_drive(grid, road, nominal, observer, options,
                             lambda f: tick(f, 'alignment'))
    clock['alignment'] = time.perf_counter()
    k0, k1, warm = _overlap(grid, road, alignment, options.warm_up_s)
    scale = _Scale(options, nominal)
    setup = {'nominal': nominal, 'scale': scale, 'hold': hold, 'grid': grid, 'road': road,
             'alignment': alignment, 'k0': k0, 'k1': k1, 'warm': warm}
    return _rounds(setup, options, clock, grid, tick)


def _rounds(setup, options, clock, grid, tick) -> CalibrationResult:
    """Fit, hold what is not identifiable, fit again (at most ``max_rounds`` times)."""
    auto: set[Slot] = set()
    previous, sigma, nfev = None, None, 0
    scale = setup['scale']
    for _ in range(max(1, options.max_rounds)):
        problem, result, sigma = _round(setup, auto, previous, sigma, lambda: tick(0.01))
        nfev += problem.calls
        cov, deficient, lags = covariance(result, int(round(HAC_WINDOW_S / grid.dt_s)))
        scaled = {s for s in SLOTS if s.kind == 'scale'
                  and (s in problem.free or s == scale.reference)}
        bad = _unidentified(problem, scale, result, cov, deficient, scaled)
        if not bad:
            break
        auto |= bad
        previous = {s: t for s, t in zip(problem.free, result.x) if s not in bad}
    clock['fit'] = time.perf_counter()
    estimates = _estimates(problem, scale, result, cov, scaled, setup['hold'], auto)
    fitted = problem.outputs(result.x)[problem.used]
    resid = fitted - problem.measured
    rows = np.flatnonzero(problem.used)
    fine = problem.unpack(result.x)[1]
    return CalibrationResult(
        vehicle=_vehicle(setup['nominal'], estimates, options.static_load_n),
        nominal=setup['nominal'], parameters=estimates, alignment=setup['alignment'],
        fine_alignment=fine, noise=np.sqrt(np.mean(resid ** 2, axis=0)),
        noise_high_frequency=_high_frequency_noise(grid.measured[setup['k0']:setup['k1']]),
        residual_rms=np.sqrt(np.mean(resid ** 2, axis=0)), scale_known=scale.known,
        scale_note=scale.note, not_identifiable=sorted(s.label for s in auto),
        correlated=_correlated(problem, cov), used_samples=int(rows.size),
        used_duration_s=float(rows.size * grid.dt_s),
        used_distance_m=float(grid.distance_m[setup['k1'] - 1]
                              - grid.distance_m[setup['k0'] + setup['warm']]),
        dt_s=grid.dt_s, t_s=(setup['k0'] + rows) * grid.dt_s, measured=problem.measured,
        fitted=fitted, rejected_samples=grid.rejected, nfev=nfev,
        covariance_window_s=lags * grid.dt_s,
        timings_s={'alignment': clock['alignment'] - clock['start'],
                   'fit': clock['fit'] - clock['alignment'],
                   'total': clock['fit'] - clock['start']})
