"""The whole vehicle's estimate from arrays (``vehicle.model: articulated``, issue 32): every
wheel's vertical load of a tractor and semi-trailer, online (per sample, with or without a
latency) or offline, by the model observer on :mod:`.models.articulated`.

:class:`ArticulatedOnline` takes one sample at a time (the node's path to come) and
:func:`estimate_articulated` a whole drive (``stamps``, the readings of
``/suspension/deflections`` in the model's channel order, the speed); both run the same
:class:`.observer.online.ModelCore` and give the same numbers. ``offline=True`` runs the
smoother (:class:`.smoothing.smoother.Smoother`) over the drive as one run. Readings from a
mechanical zero (``vehicle.deflection_reference: zero_load``) are taken back to the
equilibrium (:func:`equilibrium_readings`). The braking pitch: ``a_x`` from the change of
speed, its response taken off the readings and added to the loads
(:class:`.models.articulated.BrakingResponse`). :func:`fuse_roads` fuses the offline roads
of every axle by distance (the same two wheel paths, each axle ``xi_j`` behind the front
axle; the short waves from the wheels on the ground only); each axle's road holds the
30-100 m band (:data:`.models.articulated_rows.ROAD_CUTOFF_FACTOR`), so does the fusion.
Gaps: a step longer than ``max(gap_threshold_s, 10 typical steps)`` (the front axle's rule,
:class:`.acceptance.StepGaps` per sample, :func:`.acceptance.gap_samples` offline) ends a
run; the next sample restarts the observer at rest on its readings (the braking response
too), offline each run is smoothed on its own (the noise and roughness schedule carried over
runs), the distance continues over the gap (``|v|`` times the step); ``gaps`` counts them.
Online, every wheel's road comes with each row (:class:`.models.articulated_rows.BodyRoads`
at zero latency, :class:`.models.articulated_rows.WheelRoads` with a latency;
the streamed fusion: :mod:`.fused_stream`). Not yet: rejected samples (every sample finite,
stamps increasing), a fusion that tells the bodies' heave and pitch from the road by the
axles' differences.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from road_force_estimator.core.articulated_parameters import ArticulatedParameters
from road_force_estimator.core.parameters import GRAVITY_MPS2, ObserverParameters
from road_force_estimator.estimation.acceptance import GAP_THRESHOLD_S, StepGaps, gap_samples
from road_force_estimator.estimation.models.articulated import ArticulatedObserverModel
from road_force_estimator.estimation.models.articulated_rows import CONV, DIST, columns
from road_force_estimator.estimation.observer.online import ModelCore
from road_force_estimator.estimation.smoothing.smoother import Smoother

__all__ = ['ArticulatedEstimate', 'ArticulatedOnline', 'estimate_articulated', 'run_starts',
           'equilibrium_readings', 'LIFT_OFF_FRACTION', 'FUSION_SPLIT_WAVELENGTH_M',
           'FusedProfile', 'fuse_roads', 'fuse_path']


@dataclass(frozen=True)
class ArticulatedEstimate:
    """A drive's estimate: per sample (m) the distance (m), converged flag, every wheel's
    load and dynamic load (N; (nw, m), wheels ``<axle>_<side>`` of :attr:`wheel_names`),
    each unit's a_y (m/s^2; (2, m), tractor, trailer) and the road under every wheel (m;
    (nw, m), band-limited: offline the smoother's, online the causal one of
    :class:`.models.articulated_rows.BodyRoads` or the fixed-lag one of
    :class:`.models.articulated_rows.WheelRoads`)."""

    stamps_ns: np.ndarray
    distance_m: np.ndarray
    converged: np.ndarray
    wheel_names: tuple
    load_n: np.ndarray
    dynamic_n: np.ndarray
    lateral_mps2: np.ndarray
    road_m: np.ndarray | None = None
    #: samples whose innovation the gate replaced, per channel (the model's channel order)
    innovations_gated: tuple = ()
    #: gaps in the drive (each restarted the estimate; module notes)
    gaps: int = 0

    @classmethod
    def from_rows(cls, stamps_ns, rows: np.ndarray, wheel_names,
                  gated: tuple = (), gaps: int = 0) -> ArticulatedEstimate:
        """From the rows (m, columns) of :mod:`.models.articulated_rows` (the road where the
        rows hold it), the gated counts per channel and the gaps."""
        cols = columns(len(wheel_names))
        road = (rows[:, cols['road']].T.copy() if rows.ndim == 2
                and rows.shape[1] >= cols['road'].stop else None)
        return cls(np.asarray(stamps_ns), rows[:, DIST], rows[:, CONV] > 0.5,
                   tuple(wheel_names), rows[:, cols['load']].T.copy(),
                   rows[:, cols['dynamic']].T.copy(), rows[:, cols['ay']].T.copy(), road,
                   tuple(int(g) for g in gated), int(gaps))


def _wheel_names(vehicle: ArticulatedParameters) -> tuple:
    return tuple(f'{a}_{s}' for a in vehicle.axle_names for s in ('left', 'right'))


def equilibrium_readings(model: ArticulatedObserverModel, readings: np.ndarray) -> np.ndarray:
    """The readings (m, ny) from the equilibrium: as they are, or, read from a mechanical zero
    (``zero_load``), less the zero's reading ``-(S_j,i - F_0,j,i) / k_j,i`` (S the static spring
    load, F_0 ``deflection_zero_load``: the sensors' own formula)."""
    y = np.array(readings, float, copy=True)
    v = model.vehicle
    if not v.zero_load:
        return y
    static = model.static_wheel_load_n.reshape(-1, 2)
    for k, ch in enumerate(model.channels):
        if ch[0] == 'q':
            a = v.axles[ch[1]]
            s_load = static[ch[1], ch[2]] - 0.5 * a.mass_kg * GRAVITY_MPS2
            y[..., k] += (s_load - a.deflection_zero_load_n[ch[2]]) / \
                a.suspension_stiffness_npm[ch[2]]
    return y


class ArticulatedOnline:
    """The online estimate one sample at a time: :meth:`step` returns the rows finalized by
    that sample (``(stamp_ns, row)``, a latency's samples late), :meth:`finish` the rest.
    A step that is a gap (``gap_threshold_s``, module notes) restarts the run (:attr:`gaps`).
    ``imu``: the tractor IMU's a_y (m/s^2) is the readings' last channel
    (:data:`.models.articulated.IMU_CHANNEL`). ``rows`` False: the filter and its innovations
    only, no row made (:attr:`.ModelCore.rows`; :meth:`step` returns none)."""

    def __init__(self, vehicle: ArticulatedParameters, latency_s: float = 0.0,
                 observer: ObserverParameters | None = None, *,
                 gap_threshold_s: float = GAP_THRESHOLD_S, imu: bool = False,
                 rows: bool = True) -> None:
        self.model = ArticulatedObserverModel(vehicle, imu)
        obs = ObserverParameters(latency_s=latency_s) if observer is None else observer
        self.core = ModelCore(self.model, obs)
        self.core.rows = rows
        self.wheel_names = _wheel_names(vehicle)
        self.braking = self.model.braking_response()
        self.clock = StepGaps(gap_threshold_s)
        #: gaps so far (each restarted the run)
        self.gaps = 0
        self._last: int | None = None
        self._x = 0.0
        # the braking response's dynamic loads of held samples (None: at rest, all 0)
        self._held: deque = deque()
        cols = columns(len(self.wheel_names))
        self._load, self._dyn = cols['load'].start, cols['dynamic'].start

    def starts_run(self, stamp_ns: int) -> bool:
        """Whether a sample at ``stamp_ns`` would start a run (the first, or after a gap)."""
        return self._last is None or self.clock.is_gap((int(stamp_ns) - self._last) * 1e-9)

    def step(self, stamp_ns: int, y, speed_mps: float) -> list:
        """One sample: ``y`` the model's channels (m, rad; from the equilibrium), stamps
        increasing.

        ``a_x`` over the step: the change of speed over it (the known input,
        :class:`.models.articulated.BrakingResponse`); its response is taken off the
        readings and added to the loads."""
        core = self.core
        first = self._last is None
        dt = 0.0 if first else (stamp_ns - self._last) * 1e-9
        restart = first or self.clock.is_gap(dt)
        self._x += abs(speed_mps) * dt
        t = 0.0 if restart else dt
        brake = self.braking
        if restart:
            brake.restart()
        brake.feed(t, float(speed_mps))
        rest = brake.at_rest           # its offset and loads 0: nothing to take or add
        y = (tuple(map(float, y)) if rest else
             tuple([float(v) - o for v, o in zip(y, brake.offset.tolist())]))
        if not core.step(int(stamp_ns), y, float(speed_mps), dt, restart, self._x, t, dt):
            raise ValueError(f'sample at {stamp_ns} ns: not finite')
        if not first and self.clock.take(dt):
            self.gaps += 1
        self._last = int(stamp_ns)
        if not core.rows:
            return []
        self._held.append(None if rest else brake.dynamic_n.tolist())
        return self._ready()

    def finish(self) -> list:
        """The samples a latency still held."""
        self.core.finish()
        return self._ready()

    def _ready(self) -> list:
        """The finalized rows, the braking response's dynamic loads added."""
        out = []
        load, dyn = self._load, self._dyn
        held = self._held
        for stamp, row in self.core.ready:
            d = held.popleft()
            if d is None:             # (the response at rest: + 0 changes no load)
                out.append((stamp, row))
                continue
            r = list(row)
            for k, f in enumerate(d):
                r[load + k] += f
                r[dyn + k] += f
            out.append((stamp, tuple(r)))
        self.core.ready.clear()
        return out


def estimate_articulated(vehicle: ArticulatedParameters, stamps_ns, readings, speed_mps, *,
                         latency_s: float = 0.0, offline: bool = False,
                         observer: ObserverParameters | None = None,
                         from_equilibrium: bool = False,
                         gap_threshold_s: float = GAP_THRESHOLD_S,
                         imu: bool = False) -> ArticulatedEstimate:
    """Every wheel's load over a drive (a new run after each gap: module notes).

    Parameters
    ----------
    vehicle : ArticulatedParameters
    stamps_ns : (m,) int, increasing
    readings : (m, ny) the model's channels (``/suspension/deflections``' order: both sides of
        every instrumented axle, the tractor's roll, the trailer's where fitted), m and rad,
        from the vehicle's ``deflection_reference``
    speed_mps : (m,) or float
    latency_s : the online estimate's latency (s; 0: the causal filter)
    offline : the smoother instead (``latency_s`` ignored)
    observer : the observer's settings (default: the package's, with ``latency_s``)
    from_equilibrium : the readings are from the equilibrium already (a ``zero_load``
        vehicle's taken back by the caller, e.g. by the static-load tracker of
        :mod:`.whole_vehicle`): :func:`equilibrium_readings` not applied
    gap_threshold_s : the shortest step that is a gap (s; module notes)
    imu : the readings' last column is the tractor IMU's a_y (m/s^2)
    """
    stamps = np.asarray(stamps_ns, np.int64)
    v = np.broadcast_to(np.asarray(speed_mps, float), stamps.shape)
    online = ArticulatedOnline(vehicle, latency_s, observer, gap_threshold_s=gap_threshold_s,
                               imu=imu)
    y = (np.asarray(readings, float) if from_equilibrium
         else equilibrium_readings(online.model, readings))
    if offline:
        return _offline(online, stamps, y, v, observer, run_starts(stamps, gap_threshold_s))
    rows = []
    for s, yi, vi in zip(stamps.tolist(), y.tolist(), v.tolist()):
        rows += [r for _, r in online.step(s, yi, vi)]
    rows += [r for _, r in online.finish()]
    return ArticulatedEstimate.from_rows(stamps, np.array(rows), online.wheel_names,
                                         tuple(online.core.gated), online.gaps)


def run_starts(stamps_ns, gap_threshold_s: float = GAP_THRESHOLD_S) -> np.ndarray:
    """The first sample of every run of a drive (its stamps, ns, increasing): 0 and each
    sample after a gap (:func:`.acceptance.gap_samples`, the per-sample rule's gaps)."""
    stamps = np.asarray(stamps_ns, np.int64)
    if stamps.size < 2:
        return np.zeros(min(stamps.size, 1), np.int64)
    return np.concatenate([[0], gap_samples(np.diff(stamps) * 1e-9, gap_threshold_s) + 1])


def _offline(online: ArticulatedOnline, stamps: np.ndarray, y: np.ndarray, v: np.ndarray,
             observer: ObserverParameters | None, starts: np.ndarray) -> ArticulatedEstimate:
    """The smoother over each run of the drive (``starts``: the first sample of each)."""
    smoother = Smoother(online.model, ObserverParameters() if observer is None else observer)
    nw = len(online.wheel_names)
    cols = columns(nw)
    rows = np.zeros((stamps.size, cols['size']))
    for a0, b0 in zip(starts.tolist(), starts[1:].tolist() + [stamps.size]):
        t = (stamps[a0:b0] - stamps[a0]) * 1e-9
        off, dyn = online.braking.run(t, v[a0:b0])       # the known a_x (as online)
        for a, b, pc in smoother.pieces(t, y[a0:b0] - off, v[a0:b0]):
            rows[a0 + a:a0 + b] = np.column_stack(pc)
        rows[a0:b0, cols['load']] += dyn.T
        rows[a0:b0, cols['dynamic']] += dyn.T
    steps = np.diff(stamps) * 1e-9
    rows[:, DIST] = np.concatenate([[0.0], np.cumsum(np.abs(v[1:]) * steps)])
    return ArticulatedEstimate.from_rows(stamps, rows, online.wheel_names,
                                         tuple(smoother.gated.tolist()), starts.size - 1)


#: The fused profile: a wheel's reading counts while its estimated load is at least this
#: fraction of its static load (below, it may have lifted off, which the linear model does
#: not carry; class D lifts every wheel at 20 m/s).
LIFT_OFF_FRACTION = 0.1
#: The fused profile's split (m): the waves longer than this are every axle's average, the
#: shorter ones the average of the axles whose wheel is on the ground there (a split keeps
#: an axle's long-wave offset from stepping in and out with it).
FUSION_SPLIT_WAVELENGTH_M = 10.0


@dataclass(frozen=True)
class FusedProfile:
    """Both wheel paths (m) on the front axle's distances ``distance_m`` (m,) of the points
    every axle has passed: ``left``, ``right``, and ``axles`` the number of axles fused."""

    distance_m: np.ndarray
    left: np.ndarray
    right: np.ndarray
    axles: int


def fuse_roads(estimate: ArticulatedEstimate, positions_m) -> FusedProfile:
    """The offline roads of every axle (``estimate.road_m``; axle j ``positions_m[j]`` behind
    the front axle) fused by distance: the point under the front axle at sample k is under
    axle j when that axle has travelled ``xi_j`` further; each axle's road is interpolated
    there (linear, in the front axle's distance), over the points the last axle has passed.
    Per wheel path, the waves longer than :data:`FUSION_SPLIT_WAVELENGTH_M` are the axles'
    average, the shorter ones the average of the axles whose wheel's estimated load is at
    least :data:`LIFT_OFF_FRACTION` of its static load there (every axle's where none is)."""
    if estimate.road_m is None:
        raise ValueError('no road in the estimate: the road comes offline')
    x = estimate.distance_m
    xi = np.asarray(positions_m, float)
    static = estimate.load_n - estimate.dynamic_n
    grounded = (estimate.load_n >= LIFT_OFF_FRACTION * static).astype(float)
    p = x[x + xi.max() <= x[-1]]
    paths = np.zeros((2, p.size))
    for side in (0, 1):
        paths[side] = fuse_path(x, estimate.road_m[side::2], grounded[side::2], xi)
    return FusedProfile(p, paths[0], paths[1], int(xi.size))


def fuse_path(distance_m: np.ndarray, road_m: np.ndarray, grounded: np.ndarray,
              positions_m) -> np.ndarray:
    """One wheel path of :func:`fuse_roads` (its numbers, bit for bit): ``road_m`` (N, m) each
    axle's road on that side (m), ``grounded`` (N, m) whether its wheel carried at least
    :data:`LIFT_OFF_FRACTION` of its static load (bool or 0/1), ``distance_m`` (m,) the front
    axle's distance (m), ``positions_m`` (N,) each axle behind the front axle (m); the fused
    road (m) at the distances the last axle has passed (``distance_m + max(positions_m) <=
    distance_m[-1]``)."""
    x = distance_m
    xi = np.asarray(positions_m, float)
    p = x[x + xi.max() <= x[-1]]
    steps = np.diff(x)
    dx = float(np.median(steps[steps > 0.0])) if np.any(steps > 0.0) else 0.0
    reads = np.array([np.interp(p + lag, x, road_m[j]) for j, lag in enumerate(xi)])
    ok = np.array([np.interp(p + lag, x, np.asarray(grounded[j], float)) > 0.999
                   for j, lag in enumerate(xi)]).astype(float)
    return _fused(reads, ok, _low_pass(p, reads, dx))


def _fused(reads: np.ndarray, ok: np.ndarray, long: np.ndarray) -> np.ndarray:
    """:func:`fuse_path`'s sum at each point: the long waves ``long`` (N, k) averaged, the
    short ones (``reads - long``) averaged over the axles ``ok`` (N, k, 0/1) or every
    axle's where none is."""
    short = reads - long
    n_ok = ok.sum(axis=0)
    return long.mean(axis=0) + np.where(
        n_ok > 0, (ok * short).sum(axis=0) / np.maximum(n_ok, 1.0), short.mean(axis=0))


def _low_pass(p: np.ndarray, reads: np.ndarray, dx: float) -> np.ndarray:
    """The waves of ``reads`` (rows over the distances p, m) longer than
    :data:`FUSION_SPLIT_WAVELENGTH_M`: a zero-phase second-order Butterworth on an even grid
    of dx (m), interpolated back to p (all of them when the grid is too short)."""
    from road_force_estimator.core.scipy_signal import signal as _signal

    if dx <= 0.0 or p[-1] - p[0] < 4.0 * FUSION_SPLIT_WAVELENGTH_M:
        return reads.copy()
    grid = np.arange(p[0], p[-1] + 0.5 * dx, dx)
    even = np.array([np.interp(grid, p, r) for r in reads])
    sos = _signal().butter(2, 1.0 / FUSION_SPLIT_WAVELENGTH_M, fs=1.0 / dx, output='sos')
    smooth = _signal().sosfiltfilt(sos, even, axis=-1)
    return np.array([np.interp(p, grid, r) for r in smooth])


def fuse_path_pieces(n: int, read_x, read, positions_m, folder=None,
                     rows: int | None = None):
    """:func:`fuse_path` (its numbers, bit for bit) from a source read ``rows`` samples at a
    time (:data:`~.core.pieces.PIECE_ROWS`): ``read_x(lo, hi)`` the front axle's distance
    (m, non-decreasing) and ``read(lo, hi, j) -> (road_m, grounded)`` axle j's ((k,) each)
    of the samples ``lo:hi`` of ``n``. Returns ``(m, path)``: the fused road (m) of the first m
    samples (those the last axle has passed) in a :class:`~.core.spill.SpillColumn` (m,) in
    ``folder`` (the caller closes it). Held: a piece's samples and the road ``positions_m``
    ahead of it; the median step by counting passes, the low pass's grid and zero-phase
    filter in pieces over spilled columns (:mod:`~.core.pieces`)."""
    from road_force_estimator.core import pieces
    from road_force_estimator.core.scipy_signal import signal as _signal
    from road_force_estimator.core.spill import SpillColumn

    rows = max(int(rows or pieces.PIECE_ROWS), 1)
    xi = np.asarray(positions_m, float)
    na = xi.size
    path = SpillColumn(float, None, folder)
    if not n:
        return 0, path
    x_end = read_x(n - 1, n)[-1]
    m = sum(int(np.count_nonzero(read_x(lo, min(lo + rows, n)) + xi.max() <= x_end))
            for lo in range(0, n, rows))
    dx = pieces.median_positive_steps(n, read_x, rows)

    def axle(j: int):                         # axle j's road and whether grounded
        def both(lo, hi):
            road, grounded = read(lo, hi, j)
            return read_x(lo, hi), np.array([road, grounded], float)
        return both

    spilled: list = []
    try:
        reads = SpillColumn(float, 2 * na, folder)   # at p + xi_j: the road, grounded
        spilled.append(reads)
        at = [pieces.Interp(n, axle(j), rows) for j in range(na)]
        for lo in range(0, m, rows):
            p = read_x(lo, min(lo + rows, m))
            r = [at[j](p + lag) for j, lag in enumerate(xi)]
            reads.append(np.array([v[0] for v in r] + [v[1] for v in r]).T)
        del at, r
        p0, p1 = read_x(0, 1)[0], read_x(m - 1, m)[-1] if m else read_x(0, 1)[0]
        long = None
        if m and dx > 0.0 and p1 - p0 >= 4.0 * FUSION_SPLIT_WAVELENGTH_M:
            g = pieces.arange_size(p0, p1 + 0.5 * dx, dx)
            even = pieces.Interp(m, lambda lo, hi: (read_x(lo, hi),
                                                    reads.read(lo, hi)[:, :na].T), rows)
            sos = _signal().butter(2, 1.0 / FUSION_SPLIT_WAVELENGTH_M, fs=1.0 / dx,
                                   output='sos')
            smooth = pieces.sosfiltfilt(
                sos, g, lambda lo, hi: even(pieces.arange_piece(p0, dx, lo, hi)), na,
                folder, rows)
            spilled.append(smooth)
            long = pieces.Interp(g, lambda lo, hi: (pieces.arange_piece(p0, dx, lo, hi),
                                                    smooth.read(lo, hi).T), rows)
        for lo in range(0, m, rows):
            r = reads.read(lo, min(lo + rows, m)).T
            own = np.ascontiguousarray(r[:na])
            low = own.copy() if long is None else long(read_x(lo, min(lo + rows, m)))
            path.append(_fused(own, (r[na:] > 0.999).astype(float), low))
    except BaseException:
        path.close()
        raise
    finally:
        for c in spilled:
            c.close()
    return m, path
