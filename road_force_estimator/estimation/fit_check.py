"""Does the parameter file fit the drive? The ``model_fit`` diagnostic (``ok`` | ``mismatch``).

The model residual of MODEL.md step 9, ``r = I_x dd phi - s cos(phi) (F_b1 - F_b2) - M g h
sin(phi)``, is the roll moment the model cannot explain. With the right parameters on a
straight road it is the observer's estimate of the unknown roll moment ``M_r`` (a random
walk in the model): its error wanders slowly, driven by the sensor noise, and stays within
the filter's own a-posteriori standard deviation ``sigma_M = sqrt(P+[M_r, M_r])`` (the
Riccati solution at the noise level in use). A parameter error (mass, inertia, CG height,
stiffness, damping) makes ``M_r`` follow the body's roll and wheel motion instead, which
lives in the body band. So the statistic is the residual band-passed to :data:`BAND_HZ`
(second-order Butterworth, causal), its RMS over the drive after the convergence skip, over
``sigma_M``: ``mismatch`` above :data:`THRESHOLD`.

Matched drives (ISO A and C, 10 and 30 m/s, noise 0, 1 and 10 um) stay below the threshold and
drives with every parameter off by 10 % (seeded signs) go above it
(test/estimation/test_fit_check.py; the verdict on the real-truck family's drives, each with
the nominal, stated and true files: the model_fit column of ``python -m
bench.accuracy.real_truck``). A common scale of every mass, stiffness and damping
leaves the motion unchanged (MODEL.md, Calibration): no diagnostic of the kinematics sees it.
"""
from __future__ import annotations

import math

import numpy as np

from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
from road_force_estimator.estimation.acceptance import GAP_THRESHOLD_S

__all__ = ['BAND_HZ', 'SETTLE_S', 'THRESHOLD', 'OK', 'MISMATCH', 'ADVICE', 'ModelFitMonitor',
           'moment_std_nm', 'gains_sigma_nm', 'residual_ratio', 'verdict', 'assess']

#: Band of the residual judged (Hz): the body's roll and heave modes.
BAND_HZ = (0.5, 5.0)
#: Start-up of the band-pass left out (s).
SETTLE_S = 1.0
#: Band RMS of the residual over sigma_M above which the parameters do not fit.
THRESHOLD = 0.1
OK = 'ok'
MISMATCH = 'mismatch'
#: The words of a mismatch (diagnostics, report).
ADVICE = ('the parameter file does not fit the drive (model residual in the body band too '
          'large for the noise): calibrate the vehicle (calibrate_vehicle)')


def moment_std_nm(vehicle: VehicleParameters, observer: ObserverParameters, status,
                  dt_s: float, speed_mps: float) -> float:
    """``sigma_M`` (N m): the a-posteriori std of the unknown roll moment of the gains at the
    operating point of ``status`` (its noise and roughness in use, :class:`.EstimatorStatus`),
    the step dt (s) and the speed (m/s)."""
    from dataclasses import replace

    from road_force_estimator.estimation.models.front_axle import FrontAxleModel
    from road_force_estimator.estimation.observer.schedule import GainSchedule, dt_level

    fixed = replace(observer, noise_deflection_m=max(float(status.noise_deflection_m), 1e-12),
                    noise_roll_rad=max(float(status.noise_roll_rad), 1e-12),
                    road_roughness_m3=max(float(status.road_roughness_m3), 1e-12), latency_s=0.0)
    sched = GainSchedule(FrontAxleModel(vehicle), fixed)
    sched.set_speed(float(speed_mps))
    sched.levels['dt'] = dt_level(dt_s)
    return gains_sigma_nm(sched.design(dt_s, 0))


class ModelFitMonitor:
    """The residual's band RMS, one estimate at a time (the node; :func:`residual_ratio`
    runs the same steps over arrays).

    The band-pass (second-order Butterworth at :data:`BAND_HZ`, two biquads in transposed
    direct form II, as :func:`scipy.signal.sosfilt`) is designed at the step to the first
    estimate after ``skip_s`` that is not a gap (a step under :data:`.GAP_THRESHOLD_S`: the
    band's top stays under half the rate) and started there (at its residual); from
    :data:`SETTLE_S` later on its output's squares are summed. After a gap (the core
    restarts there) the band-pass starts again the same way; the sums go on.
    """

    def __init__(self, skip_s: float = 2.0) -> None:
        from road_force_estimator.core.scipy_signal import signal
        # imported here, at the node's start (or rebuild), not in a message callback: the
        # first import of scipy.signal takes 0.5-3 s and stalled the observer's inputs once
        self._signal = signal()
        self.skip_s = float(skip_s)
        self._t0: float | None = None
        self._t_last = math.nan
        self._sos: list | None = None
        self._zi = [0.0] * 4
        self._r0 = 0.0
        self._start = math.inf
        self._dt = 0.0
        self.count = 0           #: squares summed
        self.sum_squares = 0.0   #: (N m)^2

    def update(self, t_s: float, residual_nm: float) -> None:
        """One estimate: its time (s) and residual (N m)."""
        last, self._t_last = self._t_last, t_s
        if self._t0 is None:
            self._t0 = t_s
        if t_s - self._t0 < self.skip_s or not math.isfinite(residual_nm):
            return
        step = t_s - last
        if self._sos is None:
            if not 0.0 < step < GAP_THRESHOLD_S:
                return
            self._dt = step
            self._sos = self._signal.butter(2, BAND_HZ, btype='bandpass', fs=1.0 / self._dt,
                                      output='sos').tolist()
            self._restart(t_s, residual_nm)
        elif not step < GAP_THRESHOLD_S:
            self._restart(t_s, residual_nm)
        x = residual_nm - self._r0
        zi = self._zi
        for j, (b0, b1, b2, _, a1, a2) in enumerate(self._sos):
            z1, z2 = zi[2 * j], zi[2 * j + 1]
            y = b0 * x + z1
            zi[2 * j] = b1 * x - a1 * y + z2
            zi[2 * j + 1] = b2 * x - a2 * y
            x = y
        if t_s >= self._start:
            self.count += 1
            self.sum_squares += x * x

    def _restart(self, t_s: float, residual_nm: float) -> None:
        """The band-pass from rest at this estimate; its squares summed from SETTLE_S on."""
        self._zi = [0.0] * 4
        self._r0 = residual_nm
        self._start = t_s + SETTLE_S

    def ratio(self, sigma_nm: float) -> float:
        """Band RMS over ``sigma_nm``; NaN with less than 2 s summed."""
        if self.count * self._dt < 2.0 or not sigma_nm > 0.0:
            return math.nan
        return math.sqrt(self.sum_squares / self.count) / sigma_nm


def residual_ratio(t_s, residual_nm, sigma_nm: float, *, skip_s: float = 2.0) -> float:
    """Band RMS of the residual (N m, at times t_s (s)) from ``skip_s`` on, over
    ``sigma_nm`` (:class:`ModelFitMonitor` over the arrays); the
    band-pass starts at the skip and its first :data:`SETTLE_S` are left out; NaN when fewer
    than 2 s remain.

    The monitor's steps, vectorised with the same numbers: the samples it takes (past the
    skip, finite), the one it designs the band-pass at (the first of them whose step from the
    sample before is > 0 and not a gap), the restarts at gaps, the biquads by
    :func:`scipy.signal.sosfilt` (the monitor's transposed direct form II, operation for
    operation) and the squares summed in order (``np.add.accumulate``: no pairwise sum).
    """
    t = np.asarray(t_s, dtype=float)
    r = np.asarray(residual_nm, dtype=float)
    if t.size < 16:
        return math.nan
    mon = ModelFitMonitor(skip_s)
    taken = ~(t - t[0] < mon.skip_s) & np.isfinite(r)
    taken[0] = False                  # the monitor's first step has no step before it
    step = np.full(t.size, math.nan)
    step[1:] = t[1:] - t[:-1]
    step_ok = (step > 0.0) & (step < GAP_THRESHOLD_S)
    first = np.flatnonzero(taken & step_ok)
    if first.size == 0:
        return math.nan
    d = int(first[0])
    for k in range(d + 1):            # the monitor up to its design (a few samples)
        mon.update(float(t[k]), float(r[k]))
    rest = np.flatnonzero(taken[d + 1:]) + d + 1
    gaps = np.flatnonzero(~(step[rest] < GAP_THRESHOLD_S))   # the monitor restarts there
    for piece in np.split(rest, gaps):
        if piece.size == 0:
            continue
        if not step[piece[0]] < GAP_THRESHOLD_S:
            mon._restart(float(t[piece[0]]), float(r[piece[0]]))
        _filter_piece(mon, t[piece], r[piece])
    return mon.ratio(sigma_nm)


def _filter_piece(mon: ModelFitMonitor, t, r) -> None:
    """The monitor's steps over a stretch without a gap (its band-pass designed)."""
    x = r - mon._r0
    zi = np.array(mon._zi, dtype=float).reshape(-1, 2)
    y, zf = mon._signal.sosfilt(np.array(mon._sos), x, zi=zi)
    mon._zi = zf.reshape(-1).tolist()
    late = t >= mon._start
    sq = y[late] * y[late]
    if sq.size:
        mon.count += int(sq.size)
        mon.sum_squares = float(np.add.accumulate(np.concatenate(
            [[mon.sum_squares], sq]))[-1])


def gains_sigma_nm(gains) -> float:
    """``sigma_M`` (N m) of a design (:class:`.gains.Gains`): sqrt(P+[M_r, M_r])."""
    from road_force_estimator.estimation.models.front_axle import State
    return math.sqrt(max(float(gains.p_post[State.M_R, State.M_R]), 0.0))


def verdict(ratio: float) -> str:
    """:data:`MISMATCH` above :data:`THRESHOLD`, else :data:`OK` (also when not measured)."""
    return MISMATCH if math.isfinite(ratio) and ratio > THRESHOLD else OK


def assess(est, vehicle: VehicleParameters, observer: ObserverParameters, speed_mps,
           *, skip_s: float = 2.0) -> tuple[float, str]:
    """``(ratio, verdict)`` of a batch estimate (:class:`.EstimateArrays` of the model
    method: ``stamp_ns``, ``valid``, ``residual_nm``, ``status``) at the recorded speeds
    (m/s, per row or one value; the median moving speed sets sigma_M)."""
    valid = np.asarray(est.valid, dtype=bool)
    if np.count_nonzero(valid) < 16 or getattr(est.status, 'method', 'model') != 'model':
        return math.nan, OK
    t = np.asarray(est.stamp_ns, dtype=np.int64)[valid] * 1e-9
    v = np.abs(np.broadcast_to(np.asarray(speed_mps, dtype=float), valid.shape)[valid])
    moving = v[v >= 1.0]
    speed = float(np.median(moving)) if moving.size else 1.0
    dt = float(np.median(np.diff(t)))
    sigma = moment_std_nm(vehicle, observer, est.status, dt, speed)
    ratio = residual_ratio(t, np.asarray(est.residual_nm, dtype=float)[valid], sigma,
                           skip_s=skip_s)
    return ratio, verdict(ratio)
