"""Which axle or sensor does not fit? The whole vehicle's ``model_fit`` per axle (issue 32).

Every axle drives the front axle's two wheel paths, axle j ``xi_j`` behind, so the road each
axle's wheels reconstruct offline (``road_m`` of the smoother, :mod:`.articulated`: each
axle's road is its own input in the model) must be the same function of distance. An axle
whose spring rate, damping or mass is not the file's, or whose sensor reads a gain off,
turns the same road into other readings, and the smoother, fitting the file's axle to them,
reconstructs a road that differs from the other axles' by a transfer function. The unknown
road inputs absorb that error within the axle (no innovation shows it); the other axles'
readings of the same point do not.

The statistic, per wheel and band of :data:`BANDS_M` (wavelengths, m): every wheel's road
read at the front axle's distances (axle j at ``x + xi_j``) on an even grid of
:data:`GRID_M`, band-passed (second-order Butterworth in distance, zero phase), the
reference the median over the other axles of the same wheel path, and the complex gain
``H`` of the wheel's analytic signal over the reference's (least squares over the grid
points where every wheel on that path carries at least :data:`.articulated.LIFT_OFF_FRACTION`
of its static load and every axle passed at :data:`MIN_SPEED_MPS` or faster). The misfit
is ``|H - 1|`` (amplitude and phase), judged by its lower bound: less :data:`Z_SCORE`
standard errors (the residual's power over the reference's, per independent point of the
band: length x bandwidth), so that the noise of a short or slow drive does not raise it. An
axle whose worst wheel's bound over the bands exceeds :data:`THRESHOLD` does not fit; when
one of its wheels' bound is more than :data:`SENSOR_FACTOR` times the other's, it is that
wheel's deflection sensor (a gain error scales one side), else the axle.

Measured with the plant (``python -m bench.studies.axle_fit``): clean drives stay well below
the threshold, and a 20 % stiffer spring, 30 % less damping, 30 % more axle mass and a
sensor 10 % off each name their axle or sensor; a trailer payload off the file's (a body's
mass) names none. Offline only: the road comes from the smoother.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

__all__ = ['BANDS_M', 'GRID_M', 'THRESHOLD', 'SENSOR_FACTOR', 'Z_SCORE', 'ADVICE', 'SKIP_S',
           'MIN_LENGTH_M', 'MIN_SPEED_MPS', 'LIFT_OFF_MARGIN_M', 'AxleFit', 'assess_axles']

#: The wavelength bands judged (m): the axles' own modes (wheel hop, 9-12 Hz) and the
#: bodies' coupling over them at highway speeds. Longer waves are the bodies' motion,
#: which every axle's road shares with the others' errors.
BANDS_M = ((0.5, 2.0), (2.0, 8.0))
#: The even distance grid the roads are read on (m).
GRID_M = 0.05
#: The misfit's lower bound (``|H - 1|``, a fraction) above which an axle does not fit:
#: between the clean drives' and a spring 20 % off (``python -m bench.studies.axle_fit``).
THRESHOLD = 0.015
#: The misfit judged is its lower bound: ``|H - 1|`` less this many standard errors.
Z_SCORE = 3.0
#: A wheel whose misfit is more than this times the other wheel's: its sensor.
SENSOR_FACTOR = 2.0
#: The words after the culprits of a mismatch (diagnostics, report).
ADVICE = ("do(es) not fit the parameter file (the road under it disagrees with the other "
          "axles' at the same distance): check the spring, damper and mass, or the sensor")
#: The smoother's start left out (s).
SKIP_S = 2.0
#: The least distance every axle must have passed for a verdict (m).
MIN_LENGTH_M = 100.0
#: The points this close to a wheel's lift-off are left out too (m): the road the linear
#: model reconstructs there is off, and the band-pass spreads it about a short wavelength.
LIFT_OFF_MARGIN_M = 0.5
#: A point counts when every axle passed it at this speed or faster (m/s), and the points
#: within the longest band's wavelength of a slower one are left out too: through a stop
#: the slow points raised a clean drive's misfit past the threshold (the bench's stop).
MIN_SPEED_MPS = 5.0


@dataclass(frozen=True)
class AxleFit:
    """The verdict per axle: ``misfit`` (axles, 2, bands) ``|H - 1|`` per wheel (left,
    right) and band (:data:`BANDS_M`; NaN when not measured), ``spread`` its standard error
    (the residual's power over the reference's per independent point), ``axles`` the names of the
    axles that do not fit (worst first), ``sensors`` the deflection channels
    (``<axle>_<side>_suspension``) among them that one sensor explains, ``length_m`` the
    distance judged."""

    axle_names: tuple
    misfit: np.ndarray
    spread: np.ndarray
    axles: tuple
    sensors: tuple
    length_m: float

    @property
    def bound(self) -> np.ndarray:
        """The misfit's lower bound ``|H - 1| - Z_SCORE * spread`` (axles, 2, bands): what
        the verdict judges (noise alone does not raise it)."""
        return self.misfit - Z_SCORE * self.spread

    @property
    def axle_misfit(self) -> np.ndarray:
        """Each axle's worst :attr:`bound` over its wheels and the bands (NaN when not
        measured)."""
        m = self.bound.reshape(len(self.axle_names), -1)
        with np.errstate(invalid='ignore'):
            return np.where(np.isnan(m).all(axis=1), np.nan,
                            np.nanmax(np.where(np.isnan(m), -np.inf, m), axis=1))

    @property
    def measured(self) -> bool:
        """Enough distance for a verdict."""
        return bool(np.isfinite(self.misfit).any())

    @property
    def culprits(self) -> tuple:
        """What ``model_fit`` names: each axle that does not fit, or its sensor where one
        explains it."""
        sensors = {s.rsplit('_', 2)[0]: s for s in self.sensors}
        return tuple(sensors.get(a, a) for a in self.axles)


def assess_axles(stamps_ns, distance_m, road_m, load_n, static_n, positions_m, axle_names,
                 *, threshold: float = THRESHOLD, skip_s: float = SKIP_S) -> AxleFit:
    """The axles' misfits and verdict (module notes).

    Parameters
    ----------
    stamps_ns : (m,) int
    distance_m : (m,) the front axle's distance (m), non-decreasing
    road_m : (2 N, m) every wheel's offline road (m; ``<axle>_left``, ``<axle>_right``)
    load_n, static_n : (2 N, m) every wheel's estimated load and static load (N)
    positions_m : (N,) each axle's distance behind the front axle (m)
    axle_names : (N,) names
    threshold : the misfit above which an axle does not fit
    skip_s : the start left out (s)
    """
    from road_force_estimator.core.scipy_signal import signal
    from road_force_estimator.estimation.articulated import LIFT_OFF_FRACTION

    names = tuple(axle_names)
    xi = np.asarray(positions_m, float)
    n = xi.size
    road = np.asarray(road_m, float)
    if road.shape[0] != 2 * n or n < 3:
        raise ValueError(f'{road.shape[0]} roads for {n} axles: need 2 per axle, 3 axles '
                         'or more (a median of the others)')
    misfit = np.full((n, 2, len(BANDS_M)), np.nan)
    spread = np.full_like(misfit, np.nan)
    t = (np.asarray(stamps_ns, np.int64) - int(np.asarray(stamps_ns)[0])) * 1e-9
    x = np.asarray(distance_m, float)
    start = x[np.searchsorted(t, skip_s)] if t[-1] > skip_s else math.inf
    end = x[-1] - xi.max()
    if not end - start >= MIN_LENGTH_M:
        return AxleFit(names, misfit, spread, (), (), max(end - start, 0.0))
    grid = np.arange(start, end, GRID_M)
    grounded = np.asarray(load_n, float) >= LIFT_OFF_FRACTION * np.asarray(static_n, float)
    speed = np.gradient(x, t) if x.size > 1 else np.zeros_like(x)
    moving = _eroded(np.all([np.interp(grid + xi[j], x, (speed >= MIN_SPEED_MPS).astype(float))
                             > 0.999 for j in range(n)], axis=0), BANDS_M[-1][1])
    sig = signal()
    for side in (0, 1):
        reads = np.array([np.interp(grid + xi[j], x, road[2 * j + side]) for j in range(n)])
        ok = moving & _eroded(np.all([np.interp(grid + xi[j], x,
                                                grounded[2 * j + side].astype(float)) > 0.999
                                      for j in range(n)], axis=0), LIFT_OFF_MARGIN_M)
        if np.count_nonzero(ok) * GRID_M < MIN_LENGTH_M:
            continue
        for b, (short, long) in enumerate(BANDS_M):
            sos = sig.butter(2, (1.0 / long, 1.0 / short), btype='bandpass', fs=1.0 / GRID_M,
                             output='sos')
            band = sig.sosfiltfilt(sos, reads, axis=-1)
            for j in range(n):
                ref = sig.hilbert(np.median(np.delete(band, j, axis=0), axis=0))[ok]
                own = sig.hilbert(band[j])[ok]
                power = float(np.vdot(ref, ref).real)
                if power > 0.0:
                    h = np.vdot(ref, own) / power
                    rest = own - h * ref
                    dof = np.count_nonzero(ok) * GRID_M * (1.0 / short - 1.0 / long)
                    misfit[j, side, b] = abs(h - 1.0)
                    spread[j, side, b] = math.sqrt(float(np.vdot(rest, rest).real)
                                                   / power / dof)
    fit = AxleFit(names, misfit, spread, (), (), float(end - start))
    worst = fit.axle_misfit
    bad = [j for j in np.argsort(-np.nan_to_num(worst, nan=-1.0)) if worst[j] > threshold]
    sensors = []
    for j in bad:
        wheel = np.nanmax(fit.bound[j], axis=1)
        hi = int(np.argmax(wheel))
        if wheel[hi] > SENSOR_FACTOR * wheel[1 - hi]:
            sensors.append(f'{names[j]}_{("left", "right")[hi]}_suspension')
    return AxleFit(names, misfit, spread, tuple(names[j] for j in bad), tuple(sensors),
                   float(end - start))


def _eroded(ok: np.ndarray, margin_m: float) -> np.ndarray:
    """``ok`` less the grid points within ``margin_m`` of a point that is not."""
    edge = int(math.ceil(margin_m / GRID_M))
    if ok.size <= 2 * edge:
        return np.zeros_like(ok)
    return ~np.convolve(~ok, np.ones(2 * edge + 1), mode='same').astype(bool)
