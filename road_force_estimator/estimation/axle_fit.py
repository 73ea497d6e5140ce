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
band: length x bandwidth), so that the noise of a short or slow drive does not raise it.
Offline over more than :data:`WINDOW_M` the least squares go in windows of the grid (each
band-passed and transformed with :data:`WINDOW_OVERLAP_M` more either side, its own points
only counted): the windows' sums ``ref* own``, ``|ref|^2``, ``|own|^2`` and points added, so
``H`` is the power-weighted mean of the windows' gains and the residual the drive's about it
(the same least squares over the same points but for the windows' edges). An
axle whose worst wheel's bound over the bands exceeds :data:`THRESHOLD` does not fit; when
one of its wheels' bound is more than :data:`SENSOR_FACTOR` times the other's, it is that
wheel's deflection sensor (a gain error scales one side), else the axle.

Measured with the plant (``python -m bench.studies.axle_fit``): clean drives stay well below
the threshold, and a 20 % stiffer spring, 30 % less damping, 30 % more axle mass and a
sensor 10 % off each name their axle or sensor; a trailer payload off the file's (a body's
mass) names none. Online (:class:`OnlineAxleFit`, with ``observer.latency``): the same
statistic over the last :data:`ONLINE_WINDOW_M` of the fixed-lag road, at its own threshold
(``python -m bench.studies.axle_fit --online 0.01``). At zero latency (``causal``: the
causal road) the same over the same windows with four changes, each for what the causal
road does (``python -m bench.studies.axle_fit --online 0``): the misfit is the amplitude
``||H| - 1|`` alone (each axle's causal road lags or leads the others' by a phase that grows
as the road gets smoother, at most as large as the faults' own); the roads' slope in
distance is judged, not their level (the causal double integral drifts by metres over a
drive, which the band-pass does not hold out at the window's edges); the points passed
slower than :data:`MIN_SPEED_MPS` or under a speed change above
:data:`CAUSAL_MAX_ACCEL_MPS2` are bridged linearly before the band-pass and left out with
:data:`CAUSAL_EDGE_M` about them and at the window's ends (braking sent the causal roads
tens of mm off); and the worst axle, once above :data:`CAUSAL_THRESHOLD`, is left out of
the others' medians (a tire 20 % stiff raised its neighbours' misfit to 4-7 %).
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Generator

import numpy as np

__all__ = ['BANDS_M', 'GRID_M', 'THRESHOLD', 'SENSOR_FACTOR', 'Z_SCORE', 'ADVICE', 'SKIP_S',
           'MIN_LENGTH_M', 'MIN_SPEED_MPS', 'LIFT_OFF_MARGIN_M', 'ONLINE_MIN_LATENCY_S',
           'ONLINE_WINDOW_M', 'ONLINE_EVERY_M', 'ONLINE_THRESHOLD', 'ONLINE_SLICE_SAMPLES',
           'CAUSAL_THRESHOLD', 'CAUSAL_MAX_ACCEL_MPS2', 'CAUSAL_ACCEL_SPAN_S', 'CAUSAL_EDGE_M',
           'WINDOW_M', 'WINDOW_OVERLAP_M', 'AxleFit', 'OnlineAxleFit',
           'assess_axles', 'assess_steps', 'assess_pieces']

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

#: Offline, a drive judged over more than this (m) is judged in windows of it, each with
#: :data:`WINDOW_OVERLAP_M` more either side for the band-pass's and the analytic signal's
#: edges; the windows' least-squares sums are added (module notes): the grid's arrays held
#: are a window's, not the drive's. The bench's drives are far shorter (one window: the
#: whole grid, as before).
WINDOW_M = 20_000.0
WINDOW_OVERLAP_M = 10.0 * BANDS_M[-1][1]

#: Online: the least ``observer.latency`` (s) for the fixed-lag road's statistic (below it
#: the causal road's, ``causal``: module notes), the window judged and the distance between
#: verdicts (m of the front axle's distance), and the threshold (the fixed-lag road's misfit
#: on clean drives lies above the offline one's).
ONLINE_MIN_LATENCY_S = 0.01
ONLINE_WINDOW_M = 800.0
ONLINE_EVERY_M = 400.0
ONLINE_THRESHOLD = 0.06
#: Online, one slice of the verdict's work (:func:`assess_steps`: about 1-3 ms over an
#: 800 m window) every this many samples, so that a 1 kHz node keeps its pace.
ONLINE_SLICE_SAMPLES = 10
#: At zero latency (``causal``): the threshold on the amplitude misfit's lower bound (clean
#: drives <= 2.0 %, the faults named 5.2 % and more: ``python -m bench.studies.axle_fit
#: --online 0``); a point counts only where the speed changed by at most this (m/s^2) over
#: :data:`CAUSAL_ACCEL_SPAN_S` (s); the distance left out about the points that do not count
#: and at the window's ends (m: twice the longest band's wavelength, the band-pass's tail).
CAUSAL_THRESHOLD = 0.05
CAUSAL_MAX_ACCEL_MPS2 = 1.5
CAUSAL_ACCEL_SPAN_S = 1.0
CAUSAL_EDGE_M = 2.0 * BANDS_M[-1][1]


@dataclass(frozen=True)
class AxleFit:
    """The verdict per axle: ``misfit`` (axles, 2, bands) ``|H - 1|`` per wheel (left,
    right) and band (:data:`BANDS_M`; NaN when not measured), ``spread`` its standard error
    (the residual's power over the reference's per independent point), ``axles`` the names of the
    axles that do not fit (worst first), ``sensors`` the deflection channels
    (``<axle>_<side>_suspension``) among them that one sensor explains, ``length_m`` the
    distance judged, ``threshold`` the one judged at (NaN when not given)."""

    axle_names: tuple
    misfit: np.ndarray
    spread: np.ndarray
    axles: tuple
    sensors: tuple
    length_m: float
    threshold: float = math.nan

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

    def status_values(self) -> dict:
        """The ``/diagnostics`` values of this verdict (none when not :attr:`measured`):
        ``model_fit`` ('ok' | 'mismatch'), ``model_fit_culprits`` (:attr:`culprits`,
        comma-separated; '' when none) and per axle ``model_fit_misfit_<axle>`` (the misfit's
        lower bound, a fraction)."""
        from road_force_estimator.estimation.fit_check import MISMATCH

        if not self.measured:
            return {}
        out = {'model_fit': MISMATCH if self.culprits else 'ok',
               'model_fit_culprits': ', '.join(self.culprits)}
        for name, m in zip(self.axle_names, self.axle_misfit):
            out[f'model_fit_misfit_{name}'] = f'{float(m):.4f}'
        return out

    @property
    def culprits(self) -> tuple:
        """What ``model_fit`` names: each axle that does not fit, or its sensor where one
        explains it."""
        sensors = {s.rsplit('_', 2)[0]: s for s in self.sensors}
        return tuple(sensors.get(a, a) for a in self.axles)


def assess_axles(stamps_ns, distance_m, road_m, load_n, static_n, positions_m, axle_names,
                 *, threshold: float = THRESHOLD, skip_s: float = SKIP_S,
                 grounded: np.ndarray | None = None, window_m: float = WINDOW_M) -> AxleFit:
    """The axles' misfits and verdict (module notes): :func:`assess_steps` run through
    (``grounded``: as it takes it, then ``load_n`` and ``static_n`` are not read).

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
    window_m : the distance judged in one piece at most (m; :data:`WINDOW_M`)
    """
    steps = assess_steps(stamps_ns, distance_m, road_m, load_n, static_n, positions_m,
                         axle_names, threshold=threshold, skip_s=skip_s, grounded=grounded,
                         window_m=window_m)
    while True:
        try:
            next(steps)
        except StopIteration as done:
            return done.value


def assess_steps(stamps_ns, distance_m, road_m, load_n, static_n, positions_m, axle_names,
                 *, threshold: float = THRESHOLD, skip_s: float = SKIP_S,
                 grounded: np.ndarray | None = None, fast_grid: bool = False,
                 causal: bool = False, window_m: float = WINDOW_M
                 ) -> Generator[None, None, AxleFit]:
    """:func:`assess_axles` in slices: a generator that yields after each step over the grid
    (a band of one wheel path, one axle's gain) and returns the :class:`AxleFit`, so that
    a caller that must keep its pace (:class:`OnlineAxleFit` in the node) can spread it.
    ``grounded`` (2 N, m) bool: whether each wheel carried its share at each sample (then
    ``load_n`` and ``static_n`` are not read); ``fast_grid``: the grid's oldest points
    dropped down to a length of factors 2, 3 and 5 (at most a few %: the FFTs of the
    analytic signals several times faster; online); ``causal``: the roads are the causal
    ones (zero latency: module notes); ``window_m``: a grid longer than this judged in
    windows (not ``fast_grid`` nor ``causal``: the online windows are short)."""
    from road_force_estimator.estimation.articulated import LIFT_OFF_FRACTION

    names = tuple(axle_names)
    xi = np.asarray(positions_m, float)
    n = xi.size
    road = np.asarray(road_m, float)
    if road.shape[0] != 2 * n or n < 3:
        raise ValueError(f'{road.shape[0]} roads for {n} axles: need 2 per axle, 3 axles '
                         'or more (a median of the others)')
    t = (np.asarray(stamps_ns, np.int64) - int(np.asarray(stamps_ns)[0])) * 1e-9
    x = np.asarray(distance_m, float)
    start = x[np.searchsorted(t, skip_s)] if t[-1] > skip_s else math.inf
    end = x[-1] - xi.max()
    if not end - start >= MIN_LENGTH_M:
        return _unmeasured(names, start, end, threshold)
    grid = np.arange(start, end, GRID_M)
    if fast_grid:
        grid = grid[grid.size - _smooth_below(grid.size):]
    if grounded is None:
        grounded = (np.asarray(load_n, float)
                    >= LIFT_OFF_FRACTION * np.asarray(static_n, float))
    speed = np.gradient(x, t) if x.size > 1 else np.zeros_like(x)
    steady = speed >= MIN_SPEED_MPS
    if causal:
        steady &= np.abs(_acceleration(t, speed)) <= CAUSAL_MAX_ACCEL_MPS2
    def fast_on(part):
        return np.array([np.interp(part + xi[j], x, steady.astype(float)) > 0.999
                         for j in range(n)])

    def path_on(part):
        def path_of(s: int):
            """The side's roads read on the grid ``part``, whether every wheel on it
            carried its share there."""
            return (np.array([np.interp(part + xi[j], x, road[2 * j + s]) for j in range(n)]),
                    np.all([np.interp(part + xi[j], x, grounded[2 * j + s].astype(float))
                            > 0.999 for j in range(n)], axis=0))
        return path_of

    if not (fast_grid or causal) and _windows(grid.size, window_m) is not None:
        def window(lo, hi):
            return fast_on(grid[lo:hi]), path_on(grid[lo:hi])
        return (yield from _judge_windows(names, xi, start, end, grid.size, window_m, window,
                                          threshold))
    return (yield from _judge(names, xi, start, end, grid, fast_on(grid), path_on(grid),
                              threshold, causal))


def _windows(g: int, window_m: float) -> list | None:
    """The windows of a grid of ``g`` points longer than ``window_m`` (m): ``(lo, hi, a,
    b)`` the grid's points band-passed (``lo:hi``, :data:`WINDOW_OVERLAP_M` either side)
    and counted (``a:b``); None for a grid judged in one piece."""
    size = max(int(round(window_m / GRID_M)), 1)
    if g <= size:
        return None
    over = int(math.ceil(WINDOW_OVERLAP_M / GRID_M))
    return [(max(a - over, 0), min(a + size + over, g), a, min(a + size, g))
            for a in range(0, g, size)]


def _judge_windows(names: tuple, xi: np.ndarray, start: float, end: float, g: int,
                   window_m: float, window, threshold: float
                   ) -> Generator[None, None, AxleFit]:
    """:func:`_judge` over the windows of a grid of ``g`` points (:func:`_windows`):
    ``window(lo, hi) -> (fast, path_of)`` as :func:`_judge` takes them, of the grid's points
    ``lo:hi``; the least-squares sums of each window's own points added (module notes)."""
    from road_force_estimator.core.scipy_signal import signal

    n = xi.size
    shape = (n, 2, len(BANDS_M))
    cross = np.zeros(shape, complex)
    power = np.zeros(shape)
    own_power = np.zeros(shape)
    points = np.zeros(2)
    sig = signal()
    for lo, hi, a, b in _windows(g, window_m):
        fast, path_of = window(lo, hi)
        moving = _eroded(np.all(fast, axis=0), BANDS_M[-1][1])
        counted = np.zeros(hi - lo, bool)
        counted[a - lo:b - lo] = True
        yield
        for side in (0, 1):
            reads, on = path_of(side)
            ok = moving & _eroded(on, LIFT_OFF_MARGIN_M) & counted
            points[side] += np.count_nonzero(ok)
            yield
            if not ok.any():
                continue
            for bb, (short, long) in enumerate(BANDS_M):
                sos = sig.butter(2, (1.0 / long, 1.0 / short), btype='bandpass',
                                 fs=1.0 / GRID_M, output='sos')
                band = np.array([sig.sosfiltfilt(sos, r) for r in reads])
                yield
                for j in range(n):
                    ref = sig.hilbert(np.median(np.delete(band, j, axis=0), axis=0))[ok]
                    own = sig.hilbert(band[j])[ok]
                    cross[j, side, bb] += np.vdot(ref, own)
                    power[j, side, bb] += float(np.vdot(ref, ref).real)
                    own_power[j, side, bb] += float(np.vdot(own, own).real)
                    yield
    misfit = np.full(shape, np.nan)
    spread = np.full(shape, np.nan)
    for side in (0, 1):
        if points[side] * GRID_M < MIN_LENGTH_M:
            continue
        for bb, (short, long) in enumerate(BANDS_M):
            dof = points[side] * GRID_M * (1.0 / short - 1.0 / long)
            for j in range(n):
                p = power[j, side, bb]
                if not p > 0.0:
                    continue
                h = cross[j, side, bb] / p
                rest = max(own_power[j, side, bb] - abs(cross[j, side, bb]) ** 2 / p, 0.0)
                misfit[j, side, bb] = abs(h - 1.0)
                spread[j, side, bb] = math.sqrt(rest / p / dof)
    return _verdict(names, misfit, spread, start, end, threshold)


def _unmeasured(names: tuple, start: float, end: float, threshold: float) -> AxleFit:
    """No verdict: too short a drive."""
    misfit = np.full((len(names), 2, len(BANDS_M)), np.nan)
    return AxleFit(names, misfit, misfit.copy(), (), (), max(end - start, 0.0), threshold)


def _judge(names: tuple, xi: np.ndarray, start: float, end: float, grid: np.ndarray | None,
           fast: np.ndarray, path_of, threshold: float, causal: bool
           ) -> Generator[None, None, AxleFit]:
    """:func:`assess_steps` from the grid on (``grid``'s points read only ``causal``):
    ``fast`` (N, grid) each axle passed at speed,
    ``path_of(side) -> (reads (N, grid), grounded (grid,))`` a wheel path's roads on the
    grid and whether every wheel on it carried its share."""
    from road_force_estimator.core.scipy_signal import signal

    n = xi.size
    misfit = np.full((n, 2, len(BANDS_M)), np.nan)
    spread = np.full_like(misfit, np.nan)
    moving = _eroded(np.all(fast, axis=0), CAUSAL_EDGE_M if causal else BANDS_M[-1][1])
    if causal:
        edge = int(math.ceil(CAUSAL_EDGE_M / GRID_M))
        moving[:edge] = moving[-edge:] = False
    yield
    sig = signal()
    kept: list = []                       # causal: each band's rows for the second pass
    for side in (0, 1):
        reads, on = path_of(side)
        if causal:
            for j in range(n):
                if fast[j].any() and not fast[j].all():
                    reads[j, ~fast[j]] = np.interp(grid[~fast[j]], grid[fast[j]],
                                                   reads[j, fast[j]])
            reads = np.gradient(reads, axis=1) / GRID_M
        yield
        ok = moving & _eroded(on, LIFT_OFF_MARGIN_M)
        if np.count_nonzero(ok) * GRID_M < MIN_LENGTH_M:
            continue
        for b, (short, long) in enumerate(BANDS_M):
            sos = sig.butter(2, (1.0 / long, 1.0 / short), btype='bandpass', fs=1.0 / GRID_M,
                             output='sos')
            band = np.empty_like(reads)
            for j in range(n):            # (row by row: a slice each)
                band[j] = sig.sosfiltfilt(sos, reads[j])
                yield
            dof = np.count_nonzero(ok) * GRID_M * (1.0 / short - 1.0 / long)
            for j in range(n):
                ref = sig.hilbert(np.median(np.delete(band, j, axis=0), axis=0))[ok]
                yield
                misfit[j, side, b], spread[j, side, b] = _gain(band[j], ref, ok, dof, causal)
                yield
            if causal:
                kept.append((side, b, band, ok, dof))
    if causal:        # the worst axle, above the threshold, left out of the others' medians
        worst = AxleFit(names, misfit, spread, (), (), 0.0).axle_misfit
        w = int(np.argmax(np.nan_to_num(worst, nan=-np.inf)))
        if worst[w] > threshold:
            for side, b, band, ok, dof in kept:
                for j in range(n):
                    if j != w:
                        ref = sig.hilbert(np.median(np.delete(band, (j, w), axis=0),
                                                    axis=0))[ok]
                        misfit[j, side, b], spread[j, side, b] = _gain(band[j], ref, ok, dof,
                                                                       causal)
                        yield
    return _verdict(names, misfit, spread, start, end, threshold)


def _verdict(names: tuple, misfit: np.ndarray, spread: np.ndarray, start: float, end: float,
             threshold: float) -> AxleFit:
    """The :class:`AxleFit` of these misfits and spreads: the axles whose worst bound is
    above ``threshold`` (worst first), the sensor where one wheel's is
    :data:`SENSOR_FACTOR` times the other's."""
    fit = AxleFit(names, misfit, spread, (), (), float(end - start), threshold)
    worst = fit.axle_misfit
    bad = [j for j in np.argsort(-np.nan_to_num(worst, nan=-1.0)) if worst[j] > threshold]
    sensors = []
    for j in bad:
        wheel = np.nanmax(fit.bound[j], axis=1)
        hi = int(np.argmax(wheel))
        if wheel[hi] > SENSOR_FACTOR * wheel[1 - hi]:
            sensors.append(f'{names[j]}_{("left", "right")[hi]}_suspension')
    return AxleFit(names, misfit, spread, tuple(names[j] for j in bad), tuple(sensors),
                   float(end - start), threshold)


def assess_pieces(n_samples: int, read_stamps, read_x, read, positions_m, axle_names, *,
                  threshold: float = THRESHOLD, skip_s: float = SKIP_S,
                  rows: int | None = None, window_m: float = WINDOW_M) -> AxleFit:
    """:func:`assess_axles` (its numbers, bit for bit) from a drive's samples read ``rows``
    at a time (:data:`~.core.pieces.PIECE_ROWS`): ``read_stamps(lo, hi)`` (ns),
    ``read_x(lo, hi)`` the front axle's distance (m, non-decreasing) and ``read(lo, hi, w)
    -> (road_m, grounded)`` wheel w's (``2 j + side``, (k,) each) of the samples ``lo:hi``
    of ``n_samples`` (>= 2). The samples' columns are never held whole: the start, the
    speed (:func:`numpy.gradient`'s), the grid's points and every wheel's road on it come a
    piece at a time (:mod:`~.core.pieces`); held whole, as :func:`assess_steps` holds them,
    the grid's arrays (the band-passed roads' analytic signals are FFTs over the grid) of
    one window (``window_m``, as :func:`assess_steps` takes it)."""
    from road_force_estimator.core import pieces

    rows = max(int(rows or pieces.PIECE_ROWS), 1)
    names = tuple(axle_names)
    xi = np.asarray(positions_m, float)
    n, m = xi.size, int(n_samples)
    if n < 3:
        raise ValueError(f'{n} axles: need 3 or more (a median of the others)')
    first = int(np.asarray(read_stamps(0, 1))[0])

    def read_t(lo, hi):
        return (np.asarray(read_stamps(lo, hi), np.int64) - first) * 1e-9

    x_end = np.asarray(read_x(m - 1, m), float)[-1]
    end = x_end - xi.max()
    start = math.inf
    if read_t(m - 1, m)[-1] > skip_s:
        for lo in range(0, m, rows):
            k = int(np.searchsorted(read_t(lo, min(lo + rows, m)), skip_s))
            if k < min(rows, m - lo):
                start = np.asarray(read_x(lo + k, lo + k + 1), float)[0]
                break
    if not end - start >= MIN_LENGTH_M:
        return _unmeasured(names, start, end, threshold)
    g = pieces.arange_size(start, end, GRID_M)
    step = pieces.uniform_step(m, read_t, rows)

    def steady(lo, hi):                  # the samples at speed, and their distances
        x = np.asarray(read_x(lo, hi), float)
        speed = pieces.gradient_piece(read_x, read_t, m, lo, hi, step)
        return x, (speed >= MIN_SPEED_MPS).astype(float)[None, :]

    def on_grid(source, what, a: int, b: int) -> np.ndarray:
        """``what([values (w, k) of each axle]) -> (r, k)``, every axle j's ``source(j)``
        (:class:`~.core.pieces.Interp`'s read) at the grid's points ``a:b`` + xi_j, a piece
        of the grid at a time: (r, b - a)."""
        at = [pieces.Interp(m, source(j), rows) for j in range(n)]
        out = None
        for lo in range(a, b, rows):
            q = pieces.arange_piece(start, GRID_M, lo, min(lo + rows, b))
            v = what([at[j](q + xi[j]) for j in range(n)])
            if out is None:
                out = np.empty(v.shape[:-1] + (b - a,), v.dtype)
            out[..., lo - a:lo - a + q.size] = v
        return out

    def window(a: int, b: int):
        fast = on_grid(lambda j: steady, lambda v: np.array([r[0] > 0.999 for r in v]), a, b)

        def path_of(side: int):
            def wheel(j):
                def read_wheel(lo, hi):
                    road, grounded = read(lo, hi, 2 * j + side)
                    return read_x(lo, hi), np.array([road, grounded], float)
                return read_wheel
            out = on_grid(wheel, lambda v: np.array(
                [r[0] for r in v] + [np.all([r[1] > 0.999 for r in v], axis=0)]), a, b)
            return out[:n], out[n] > 0.5
        return fast, path_of

    if _windows(g, window_m) is not None:
        steps = _judge_windows(names, xi, start, end, g, window_m, window, threshold)
    else:
        steps = _judge(names, xi, start, end, None, *window(0, g), threshold, False)
    while True:
        try:
            next(steps)
        except StopIteration as done:
            return done.value


class OnlineAxleFit:
    """The model fit per axle online (every ``observer.latency``; below
    :data:`ONLINE_MIN_LATENCY_S` ``causal``): :func:`assess_steps` over the last
    :data:`ONLINE_WINDOW_M` of the front axle's distance, started every
    :data:`ONLINE_EVERY_M`, one slice every
    :data:`ONLINE_SLICE_SAMPLES` finalized samples (a 1 kHz node keeps its pace), judged at
    :data:`ONLINE_THRESHOLD`; ``causal`` (zero latency, the causal road: module notes) at
    :data:`CAUSAL_THRESHOLD` unless ``threshold`` is given. A sample's row is kept once the
    front axle has moved :data:`GRID_M` / 2 since the last kept one (a stop keeps nothing),
    in a ring of fixed size: the memory does not grow with the drive.

    Parameters
    ----------
    positions_m : (N,) each axle's distance behind the front axle (m)
    axle_names : (N,) names
    window_m, every_m : the window judged and the distance between verdicts (m)
    threshold : the misfit above which an axle does not fit
    causal : the roads pushed are the causal ones (zero latency)
    """

    def __init__(self, positions_m, axle_names, *, window_m: float = ONLINE_WINDOW_M,
                 every_m: float = ONLINE_EVERY_M, threshold: float | None = None,
                 causal: bool = False) -> None:
        from road_force_estimator.estimation.articulated import LIFT_OFF_FRACTION

        self.positions_m = np.asarray(positions_m, float)
        self.axle_names = tuple(axle_names)
        self.causal = bool(causal)
        if threshold is None:
            threshold = CAUSAL_THRESHOLD if self.causal else ONLINE_THRESHOLD
        if self.positions_m.size != len(self.axle_names) or self.positions_m.size < 3:
            raise ValueError(f'{self.positions_m.size} positions for {len(self.axle_names)} '
                             'axles: need one each, 3 axles or more (a median of the others)')
        if not (window_m >= MIN_LENGTH_M and 0.0 < every_m and threshold > 0.0):
            raise ValueError(f'window {window_m!r} m (>= {MIN_LENGTH_M:g}), every '
                             f'{every_m!r} m (> 0), threshold {threshold!r} (> 0)')
        self.window_m, self.every_m, self.threshold = float(window_m), float(every_m), threshold
        self._fraction = LIFT_OFF_FRACTION
        size = int(math.ceil((window_m + self.positions_m.max() + 1.0) / (0.5 * GRID_M))) + 2
        wheels = 2 * self.positions_m.size
        self._stamp = np.zeros(size, np.int64)
        self._x = np.zeros(size)
        self._road = np.zeros((wheels, size))
        self._grounded = np.zeros((wheels, size), bool)
        self._n = 0                   # rows kept so far (the ring's next is _n % size)
        self._first_ns: int | None = None
        self._last_x = -math.inf
        self._next_x: float | None = None
        self._job = None
        self._wait = 0
        #: the last verdict (None before the first), and how many there were
        self.fit: AxleFit | None = None
        self.verdicts = 0

    def push(self, stamp_ns: int, distance_m: float, road_m, load_n, static_n
             ) -> AxleFit | None:
        """One finalized sample: its stamp (ns), the front axle's distance (m), the
        instrumented wheels' road (m), loads and static loads (N), in ``axle_names``' order,
        left then right. Returns the verdict this sample completed, else None."""
        if not math.isfinite(distance_m):
            return None
        if self._first_ns is None:
            self._first_ns = int(stamp_ns)
            self._next_x = float(distance_m) + self.window_m + self.positions_m.max()
        if distance_m - self._last_x >= 0.5 * GRID_M:
            k = self._n % self._x.size
            self._stamp[k] = stamp_ns
            self._x[k] = self._last_x = distance_m
            self._road[:, k] = road_m
            self._grounded[:, k] = np.greater_equal(load_n, np.multiply(self._fraction,
                                                                        static_n))
            self._n += 1
        if self._job is not None:
            self._wait -= 1
            if self._wait > 0:
                return None
            self._wait = ONLINE_SLICE_SAMPLES
            try:
                next(self._job)
            except StopIteration as done:
                self._job = None
                self.fit = done.value
                self.verdicts += 1
                return self.fit
        elif distance_m >= self._next_x:
            self._next_x = float(distance_m) + self.every_m
            self._job = self.verdict_job()
            self._wait = ONLINE_SLICE_SAMPLES
        return None

    def verdict_job(self):
        """The verdict on the window pushed so far as a job of slices: a generator, each
        ``next`` one slice of :func:`assess_steps`' work, its return value (``StopIteration.
        value``) the :class:`AxleFit` (what :meth:`push` runs one slice at a time)."""
        size = self._x.size
        m = min(self._n, size)
        order = (np.arange(self._n - m, self._n) % size)
        x = self._x[order]
        keep = x >= x[-1] - self.window_m - self.positions_m.max()
        order = order[keep]
        stamps = self._stamp[order]
        skip = max(0.0, SKIP_S - (int(stamps[0]) - self._first_ns) * 1e-9)
        return assess_steps(stamps, x[keep], self._road[:, order], None, None,
                            self.positions_m, self.axle_names, threshold=self.threshold,
                            skip_s=skip, grounded=self._grounded[:, order], fast_grid=True,
                            causal=self.causal)

def _gain(own_band: np.ndarray, ref: np.ndarray, ok: np.ndarray, dof: float,
          causal: bool) -> tuple[float, float]:
    """One wheel's misfit against its reference's analytic signal ``ref`` (over ``ok``) and
    its standard error: ``|H - 1|``, causal ``||H| - 1|`` (module notes); NaN without power."""
    from road_force_estimator.core.scipy_signal import signal

    own = signal().hilbert(own_band)[ok]
    power = float(np.vdot(ref, ref).real)
    if not power > 0.0:
        return math.nan, math.nan
    h = np.vdot(ref, own) / power
    rest = own - h * ref
    return (abs(abs(h) - 1.0) if causal else abs(h - 1.0),
            math.sqrt(float(np.vdot(rest, rest).real) / power / dof))


def _acceleration(t: np.ndarray, speed: np.ndarray) -> np.ndarray:
    """The speed's change over :data:`CAUSAL_ACCEL_SPAN_S` about each sample (m/s^2)."""
    half = 0.5 * CAUSAL_ACCEL_SPAN_S
    return (np.interp(t + half, t, speed) - np.interp(t - half, t, speed)) / (
        np.minimum(t + half, t[-1]) - np.maximum(t - half, t[0])).clip(1e-9)


def _smooth_below(n: int) -> int:
    """The largest number <= ``n`` whose only prime factors are 2, 3 and 5."""
    for k in range(n, 0, -1):
        m = k
        for p in (2, 3, 5):
            while m % p == 0:
                m //= p
        if m == 1:
            return k
    return 0


def _eroded(ok: np.ndarray, margin_m: float) -> np.ndarray:
    """``ok`` less the grid points within ``margin_m`` of a point that is not."""
    edge = int(math.ceil(margin_m / GRID_M))
    if ok.size <= 2 * edge:
        return np.zeros_like(ok)
    return ~np.convolve(~ok, np.ones(2 * edge + 1), mode='same').astype(bool)
