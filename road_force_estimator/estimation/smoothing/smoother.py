"""The model observer offline: its forward filter and Rauch-Tung-Striebel smoother over each
run of a recording (:class:`Smoother`; :func:`..offline.smooth` runs it over a drive), in
Bierman's modified Bryson-Frazier form (no
inverse of the ill-conditioned a-priori covariance), with the noise and roughness estimated
from the whole run first (:class:`.GainSchedule`; a run with a stop: from its samples at
speed, and its gains per stretch of speed, :mod:`.run_speed`); the same model, gains and
outputs as the online observer (:mod:`..observer.online`), of any vehicle model
(:mod:`..models`). Long evenly sampled runs go through in
overlapping windows (:func:`window_samples`), so that the smoother's own memory does not grow
with the drive; the numbers are those of one piece to ~1e-11 of each field's RMS. The road comes
from a second pass of the same smoother with the profile's tuning (:meth:`Smoother.
_profile`, over the whole run: windowed runs too).
"""
from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Iterator

import numpy as np

from road_force_estimator.core.parameters import ObserverParameters
from road_force_estimator.estimation.body_heave import SPEED_FLOOR_MPS
from road_force_estimator.estimation.chain.zero_phase import zero_phase_derivatives
from road_force_estimator.estimation.models.protocol import VehicleModel, row_layout
from road_force_estimator.estimation.observer.friction import (MeasuredSliders,
                                                                friction_response)
from road_force_estimator.estimation.observer.gains import Gains
from road_force_estimator.estimation.observer.noise import NOISE_DIFF_ORDER
from road_force_estimator.estimation.observer.online import GATE_START_S
from road_force_estimator.estimation.observer.schedule import DEFAULT_ROAD_GD_M3
from road_force_estimator.estimation.outputs import EstimatorStatus
from road_force_estimator.estimation.smoothing.lti import Powers
from road_force_estimator.estimation.smoothing.run_speed import (
    level_segments, run_statistics, speed_segments, unsteady)
from road_force_estimator.estimation.smoothing.rts_pass import smoothed_chunks
from road_force_estimator.estimation.observer.sample_clock import JITTER_MAX_FRACTION, clock_step
from road_force_estimator.estimation.observer.schedule import GainSchedule

__all__ = ['Smoother', 'KeptColumns', 'SpilledColumns', 'grid_steps', 'window_samples',
           'slowest_tau_s', 'WINDOW_SAMPLES', 'WINDOW_OVERLAP_TAUS', 'WINDOWED_RUNS']

#: Long evenly sampled runs (:data:`WINDOWED_RUNS`) are smoothed in windows of this length
#: (samples; at least four overlaps: :func:`window_samples`), so that the smoother's
#: temporaries do not grow with the drive.
WINDOW_SAMPLES = 2 ** 19
#: Overlap of the windows on each side, in time constants of the slowest transient a window
#: edge starts: the smoother's backward pass (the slowest mode of ``A (I - K C)``; the forward
#: pass carries its state from window to window) or the body heave's zero-phase high-pass
#: (slowest pole ``w_c sin(pi / 8)``, ``w_c = 2 pi v / lambda_c``). 16 is where the
#: difference from the one-piece smoother, relative to each field's RMS, reaches rounding
#: (``python -m bench.studies.offline_windows --duration 240 --window 20``: ISO C, 20 m/s, 1 kHz,
#: 10 um / 0.1 mrad noise; docs/notes/offline_windows.md).
WINDOW_OVERLAP_TAUS = 16.0
#: By default, runs are smoothed in windows when longer than this many windows with their
#: overlaps (below, one piece takes less memory than a window's temporaries and the overlaps'
#: extra work: ``python -m bench.probes.long_drive_memory --hours 0.25``).
WINDOWED_RUNS = 4
#: Chunk of the offline smoother (samples): its temporaries (~12 x 8 bytes per sample each)
#: stay in the cache.
_SMOOTH_CHUNK = 16384
#: Offline, the stick friction's stop operator reads each deflection through a zero-phase
#: low-pass at this cut-off (Hz) with its sensor's first-order lag undone, ``l + tau dl/dt``
#: (:meth:`Smoother._stick_readings`). 10 s at 10 um, the file stating 1.5 kN stick: class C
#: with a 3 ms lag 2.09 x the frictionless drive's load error on the raw readings, 1.08 x at
#: 30 Hz, 0.99 x at 60 and 100 Hz; class A without lag 1.05 x raw, 0.99 x at 60 Hz.
STICK_CUTOFF_HZ = 60.0
#: Passes of the offline smoother with leaf-spring friction: the friction input of each pass
#: is evaluated on the previous pass's smoothed dq (the first pass: none).
FRICTION_PASSES = 3


class KeptColumns:
    """The columns of m rows (the model's, ``field_columns`` makes them) of which only
    ``keep`` are held whole, the rest scratch rows of one chunk: what a pass that needs a few
    columns of a long run writes into (:meth:`rows`), in memory that does not grow with the
    run but by those."""

    def __init__(self, m: int, keep, field_columns, chunk: int = _SMOOTH_CHUNK) -> None:
        self.kept = {int(j): np.zeros(m) for j in keep}
        self.scratch = field_columns(chunk)[1]

    def rows(self, k0: int, k1: int) -> list:
        """The columns of rows ``k0:k1`` (at most one chunk of them)."""
        return [self.kept[j][k0:k1] if j in self.kept else col[:k1 - k0]
                for j, col in enumerate(self.scratch)]

    def __getitem__(self, j: int) -> np.ndarray:
        return self.kept[int(j)]


class SpilledColumns(KeptColumns):
    """:class:`KeptColumns` whose ``keep`` columns go to a file in ``folder`` (``file``, a
    :class:`~.core.spill.SpillColumn` (m, len(keep)) in ``keep``'s order) chunk by chunk as
    they are written (in any order: the profile pass's come from the end), none held whole;
    :meth:`flush` after the last chunk."""

    def __init__(self, m: int, keep, field_columns, folder,
                 chunk: int = _SMOOTH_CHUNK) -> None:
        from road_force_estimator.core.spill import SpillColumn

        self.keep = [int(j) for j in keep]
        self.kept = {}
        self.scratch = field_columns(chunk)[1]
        self.file = SpillColumn(float, len(self.keep), folder)
        self._pending: tuple | None = None

    def rows(self, k0: int, k1: int) -> list:
        self.flush()
        self._pending = (k0, k1)
        return [col[:k1 - k0] for col in self.scratch]

    def flush(self) -> None:
        """The last chunk's kept columns into the file."""
        if self._pending is not None:
            k0, k1 = self._pending
            self.file.write(k0, np.column_stack([self.scratch[j][:k1 - k0] for j in self.keep]))
            self._pending = None

    def __getitem__(self, j: int) -> np.ndarray:
        raise TypeError('spilled columns: read them from the file')


def _whole(y):
    """The measurements y (m, ny) as an array: rows in a file (:class:`~.core.spill.
    SpillRows`, what the offline stream in pieces hands over) read whole."""
    return y if isinstance(y, np.ndarray) else y[0:y.shape[0]]


def _rows(out, k0: int, k1: int) -> list:
    """Rows ``k0:k1`` of the columns ``out`` (a list of arrays or :class:`KeptColumns`)."""
    return out.rows(k0, k1) if isinstance(out, KeptColumns) else [col[k0:k1] for col in out]


def grid_steps(dts: np.ndarray, dt: float, *, max_fill: float = 4.0,
               tol: float = 1e-3) -> np.ndarray | None:
    """The steps ``dts`` (s) as whole numbers of grid steps dt (s), when each is one to
    within ``tol`` dt and the grid has at most ``max_fill`` times as many points; else None."""
    k = np.rint(dts / dt)
    if (k.size == 0 or np.min(k) < 1.0 or np.max(np.abs(dts - k * dt)) > tol * dt
            or np.sum(k) > max_fill * k.size):
        return None
    return k.astype(np.int64)


def window_samples(dt_s: float, speed_mps: float, cutoff_wavelength_m: float,
                   filter_tau_s: float, taus: float = WINDOW_OVERLAP_TAUS) -> tuple[int, int]:
    """``(window, overlap)`` in samples of a run smoothed in windows.

    The overlap on each side is ``taus`` times the slower of ``filter_tau_s`` (s, the
    smoother's slowest mode) and the body heave's high-pass time constant
    ``lambda_c / (2 pi v sin(pi / 8))`` (|v| floored at :data:`.SPEED_FLOOR_MPS`); the window
    :data:`WINDOW_SAMPLES`, or four overlaps if longer (a mode that does not fade: no
    windows).
    """
    w_c = 2.0 * math.pi * max(abs(speed_mps), SPEED_FLOOR_MPS) / cutoff_wavelength_m
    tau = max(filter_tau_s, 1.0 / (w_c * math.sin(math.pi / 8.0)))
    if not math.isfinite(tau):                   # a mode that does not fade: one piece
        return 2 ** 62, 0
    overlap = int(math.ceil(taus * tau / dt_s))
    return max(WINDOW_SAMPLES, 4 * overlap), overlap


def slowest_tau_s(g: Gains, dt: float) -> float:
    """Time constant (s) of the slowest mode of the filter's ``Phi = A (I - K C)`` at dt."""
    phi = g.transition(dt) @ (np.eye(g.k.shape[0]) - g.k @ g.model.c)
    r = float(np.max(np.abs(np.linalg.eigvals(phi))))
    return -dt / math.log(r) if 0.0 < r < 1.0 else math.inf


def _clock_grid(dts: np.ndarray, dt: float) -> tuple[float, bool, np.ndarray | None]:
    """``(dt, uniform, steps)`` of a run whose steps ``dts`` (s) are not whole numbers of
    their median ``dt``: on the regular clock under jittered stamps when there is one
    (:func:`.sample_clock.clock_step`: each step a whole number of its periods to within
    :data:`.sample_clock.JITTER_MAX_FRACTION`; the samples are where the clock put them, as
    the online observer steps), else ``(dt, False, None)`` (uneven: step by step). Without
    it, a jittered drive went through the step-by-step path: a Python loop per sample with
    the run's forward states held whole (~120 bytes a sample), 1.61 s of CPU against 0.50 s
    on the clock's grid for a 30 s drive at 1 kHz (about 13 minutes for 4 hours)."""
    clock = clock_step(dts)
    steps = None if clock is None else grid_steps(dts, clock, tol=JITTER_MAX_FRACTION)
    if steps is None:
        return dt, False, None
    if np.all(steps == 1):
        return clock, True, None
    return clock, False, steps


class Smoother:
    """The smoother of a vehicle model's runs (:func:`smooth`'s), run after run (the schedule
    persists over runs); the model (:mod:`..models`) gives the linear model, the channels
    and the reconstruction of the rows (:meth:`.VehicleModel.offline_rows`).

    ``window``: ``(window, overlap)`` (samples) for every even run longer than both; else
    :func:`window_samples`, for runs of :data:`WINDOWED_RUNS` windows' work or, with
    ``eager``, for every run longer than a window and its overlap (the offline stream: a
    run's rows are then never held whole beyond ~11 minutes at 1 kHz; the numbers differ
    from one piece's by the windows' ~1e-11 of each field's RMS)."""

    def __init__(self, model: VehicleModel, observer: ObserverParameters,
                 window: tuple[int, int] | None = None, eager: bool = False) -> None:
        self.model = model
        self.observer = observer
        self.window = window
        self.eager = eager
        #: where a windowed run's road waits for its windows (a folder for a temporary file,
        #: :class:`~.core.spill.SpillColumn`: the same bits, not held in memory), or None
        self.spill = None
        self.schedule = GainSchedule(model, observer)
        self.rows = model.offline_rows(observer)
        cm = model.continuous(1.0, DEFAULT_ROAD_GD_M3)
        self.h = cm.h[self.rows.outputs]
        self.nx = cm.nx
        self.ny = cm.ny
        #: leaf-spring friction F_f,i (N), or None; the outputs' direct part per newton
        self.friction = cm.friction_n if any(cm.friction_n) else None
        self.fd = None if self.friction is None else cm.friction_d[self.rows.outputs]
        nf = len(cm.friction_n)
        self.ceq = np.zeros((nf, 1))     # the equivalent damping in the run's gains (N s/m)
        self._dq = [self.rows.outputs.index(j) for j in model.friction_rate_outputs]
        #: samples whose innovation the gate kept from the filter, per channel (the load
        #: passes whose rows are the estimate)
        self.gated = np.zeros(self.ny, dtype=np.int64)
        self._dq_states = list(model.friction_rate_states)
        #: the stick element from the readings (:class:`..observer.friction.MeasuredSliders`),
        #: or None; its forces of the last run given (``(y, forces)``)
        self.stick = (MeasuredSliders(model) if self.friction is not None
                      and model.friction_sticks else None)
        self._stick_run: tuple | None = None
        self._stick_dt = 1e-3        # the run's median step (s), set by :meth:`_design_run`
        #: per deflection channel its sensor's time constant (s), 0: none (from cm's lags)
        tau = [0.0] * cm.ny
        first = cm.nx - len(cm.lagged)
        for n, ch in enumerate(cm.lagged):
            tau[ch] = -1.0 / float(cm.a[first + n, first + n])
        self._tau = tau

    def _stick_forces(self, y: np.ndarray) -> np.ndarray:
        """Stick: the forces (nf, m) (N) of the samples y (m, ny), from y's first sample (the
        last array's kept: a run's passes take the same)."""
        kept = self._stick_run
        if kept is not None and kept[0] is y:
            return kept[1]
        f = self.stick.run(self._stick_readings(y))
        self._stick_run = (y, f)
        return f

    def _stick_readings(self, y: np.ndarray) -> np.ndarray:
        """The readings the offline stop operator takes: each deflection channel of an element
        through the zero-phase low-pass at :data:`STICK_CUTOFF_HZ` (:func:`..chain.zero_phase.
        zero_phase_derivatives`, steps of the run's median dt), its sensor lag undone."""
        out = np.array(_whole(y), dtype=float)
        chans = sorted(set(self.stick.channels))
        low, rate, _ = zero_phase_derivatives(out[:, chans], self._stick_dt, STICK_CUTOFF_HZ)
        tau = np.array([self._tau[c] for c in chans])
        out[:, chans] = low + tau * rate
        return out

    def _less_stick(self, y: np.ndarray, dt: float) -> np.ndarray:
        """Stick: the readings y (m, ny) less the linear model's response to the operator's
        forces (:func:`..observer.friction.friction_response`, steps of dt, s): what the noise
        and roughness statistics see (as the online observer's)."""
        f = self._stick_forces(y).T
        steps = f.copy()
        steps[1:] = 0.5 * (f[:-1] + f[1:])
        r, _ = friction_response(self.model.continuous(1.0, DEFAULT_ROAD_GD_M3), dt, steps)
        return _whole(y) - r

    @property
    def vehicle(self):
        """The parameters of the model."""
        return self.model.vehicle

    def _forces(self, o: np.ndarray) -> np.ndarray:
        """The known friction input (nf, m) (N) at the rates of the outputs o (the rows of the
        reconstruction's ``outputs``); see :meth:`_forces_at`."""
        return self._forces_at(o[self._dq])

    def _forces_at(self, dq: np.ndarray) -> np.ndarray:
        """The known friction input (N) at the rates dq (nf, ...) (m/s): the model's law less
        the equivalent damping's share that the gains carry (as :mod:`..observer.friction`)."""
        return self.model.friction_forces_array(dq, self.ceq)

    def fill_status(self, status: EstimatorStatus) -> None:
        sched = self.schedule
        status.method = 'model'
        status.noise_deflection_m = sched.noise_deflection_m
        status.noise_roll_rad = sched.noise_roll_rad
        status.road_roughness_m3 = sched.road_gd_m3
        status.statistics_blocks = sched.blocks
        status.gain_designs = sched.design_count
        status.innovations_gated = dict(zip(self.model.channel_names, self.gated.tolist()))

    def pieces(self, t: np.ndarray, y: np.ndarray, v: np.ndarray, out: list | None = None,
               left_out: np.ndarray | None = None) -> Iterator[tuple[int, int, list]]:
        """The estimates of one run (see :func:`smooth`) as ``(a, b, columns of rows a:b)``
        (the model's columns; the distance is the caller's), in order: ``t`` its times (s),
        ``y`` (m, ny) its measurements (or rows in a file, :class:`~.core.spill.SpillRows`:
        a windowed run's statistics, windows and profile pass read them a piece at a time,
        the same bits; any other run reads them whole), ``v`` its model speeds (m/s).

        ``left_out`` (bool (m, ny), or None): the readings not fed (a stuck sensor,
        :func:`.sensor_health.left_out`): each stretch of samples with the same channels left
        out is smoothed with the gains designed without them (:func:`.gains.design`
        ``excluded``, as the online :meth:`.ModelCore.set_excluded`) and their innovations 0
        (:meth:`_pass_matrices`), in the load pass and the profile pass, so that the other
        channels carry the estimate. Not on a run of uneven steps off any grid (fed there).

        A long evenly sampled run (:func:`window_samples`) comes window by window
        (:meth:`_windowed`: its rows are never held whole); any other run in one piece, in
        the columns ``out`` (each (m,)) when given. Evenly sampled runs go through in chunks of
        :data:`_SMOOTH_CHUNK` samples (the forward filter chunk after chunk, then the
        smoother backwards: :func:`.rts_pass.smoothed_chunks`); the body heave and the road,
        which need the whole run, come last.
        """
        m = t.size
        rows = self.rows
        x0 = self.model.rest_state(y[0])
        if m == 1:
            out = rows.field_columns(1)[1] if out is None else out
            rows.columns((self.h @ x0)[:, None], out)
            self._finish(out, t, 0.0, 0.0)
            yield 0, 1, out
            return
        run = self._design_run(t, y, v)
        run.left_out = (left_out if left_out is not None and np.any(left_out) else None)
        if run.windowed:
            yield from self._windowed(run, t, y, v, x0)
            return
        y = _whole(y)
        out = rows.field_columns(m)[1] if out is None else out
        g, dt, speed, dts, steps = run.gains, run.dt, run.speed, run.dts, run.steps
        if run.uniform:
            segs = speed_segments(self.schedule, dt, v, speed)
            if run.left_out is not None:
                segs = self._left_out(segs or [(0, m, g)], run.left_out, dt)
            self._uniform(g, dt, y, x0, out, segments=segs,
                          gate_from=self._gate_start(dt), count=True)
        elif steps is not None:
            self._bridged(g, dt, speed, t, steps, y, x0, out, run.left_out)
        else:
            self._uneven(g, dts, y, x0, out, count=True)
        if steps is None:
            self._finish(out, t, dt, speed)
        if rows.road_columns:
            road = self._profile(dt, speed, dts, run.uniform, steps, y, v, x0,
                                 rows.roll_moment_psd(out, dt), run.left_out)
            for j, u in zip(rows.road_columns, road):
                out[j][:] = u
        yield 0, m, out

    def _design_run(self, t: np.ndarray, y: np.ndarray, v: np.ndarray) -> SimpleNamespace:
        """A run's statistics (:func:`.run_speed.run_statistics`), its design and how it is
        smoothed: ``gains``, ``dt`` and ``speed`` (the medians of its steps, s, and |v|, m/s),
        ``dts`` its steps, ``uniform``, ``steps`` (:func:`grid_steps` or None), ``window``,
        ``overlap`` and ``windowed`` (in windows: by default only where they save memory, a
        run of several windows' work)."""
        m = t.size
        dts = np.diff(t)
        dt = float(np.median(dts))
        speed = float(np.median(np.abs(v)))
        sched = self.schedule
        sched.set_run(dt, speed)
        self._stick_dt = dt
        if m > 8 * NOISE_DIFF_ORDER:
            for hist in (*sched.history, sched.dq_history):
                hist.clear()
            run_statistics(sched, y if self.stick is None else self._less_stick(y, dt), dts,
                           v, speed)
        uniform = float(np.max(np.abs(dts - dt))) <= 1e-6 * dt
        steps = None if uniform else grid_steps(dts, dt)
        if not uniform and steps is None:
            dt, uniform, steps = _clock_grid(dts, dt)
        g = sched.design(dt, 0)
        if self.friction is not None:   # the outputs of the design's model (its c_eq)
            self.ceq = np.asarray(g.model.friction_damping_nspm, dtype=float)[:, None]
            self.h = g.model.h[self.rows.outputs]
        window, overlap = self.window or window_samples(
            dt, speed, self.observer.profile_cutoff_wavelength_m, slowest_tau_s(g, dt))
        longer = (window + overlap if self.window or self.eager
                  else WINDOWED_RUNS * (window + 2 * overlap))
        return SimpleNamespace(gains=g, dt=dt, speed=speed, dts=dts, uniform=uniform,
                               steps=steps, window=window, overlap=overlap,
                               windowed=uniform and m > longer,
                               unsteady=unsteady(v, speed) is not None)

    def _windowed(self, run: SimpleNamespace, t: np.ndarray, y: np.ndarray, v: np.ndarray,
                  x0: np.ndarray) -> Iterator[tuple[int, int, list]]:
        """A long evenly sampled run window by window (:meth:`_windows`): the load pass once
        for its roll residual (the profile pass's roll moment), the road from the profile
        pass over the whole run (:meth:`_profile`), then the load pass again (the same
        windows, the same bits), each window's rows with the road put in (with
        :attr:`spill`, read back from the file it waited in)."""
        recon = self.rows
        if not recon.road_columns:
            yield from self._windows(run, t, y, v)
            return
        kept = {j: np.empty(t.size) for j in recon.moment_columns}
        if kept:
            for a, b, rows in self._windows(run, t, y, v, tuple(kept)):
                for j, col in kept.items():
                    col[a:b] = rows[j]
        run.dts = None                             # an even run's profile does not need them
        psd = recon.roll_moment_psd(kept, run.dt)
        del kept
        road = self._profile(run.dt, run.speed, None, True, None, y, v, x0, psd, run.left_out,
                             spilled=self.spill is not None)
        spilled = None
        if not isinstance(road, tuple):      # the profile pass's own file of roads
            spilled, road = road, None
        elif self.spill is not None:         # the road in a file until its window comes
            from road_force_estimator.core.spill import SpillColumn

            spilled = SpillColumn(float, len(road), self.spill)
            for c0 in range(0, t.size, _SMOOTH_CHUNK):
                spilled.append(np.column_stack([u[c0:c0 + _SMOOTH_CHUNK] for u in road]))
            road = None
        try:
            for a, b, rows in self._windows(run, t, y, v):
                part = road if spilled is None else spilled.read(a, b).T
                lo = 0 if spilled is None else a
                for j, u in zip(recon.road_columns, part):
                    rows[j][:] = u[a - lo:b - lo]
                yield a, b, rows
                del rows, part        # (let go before the next window is computed)
        finally:
            if spilled is not None:
                spilled.close()

    def _profile(self, dt: float, speed: float, dts: np.ndarray, uniform: bool,
                 steps: np.ndarray | None, y: np.ndarray, v: np.ndarray, x0: np.ndarray,
                 roll_moment_psd: float, left_out: np.ndarray | None = None,
                 spilled: bool = False):
        """The road columns of a run from the profile smoother (issue 21): the same model and
        data through the smoother with the profile's tuning (:meth:`.GainSchedule.
        profile_design`, ``'offline'``), the road of its states by the model's
        reconstruction (:meth:`.OfflineRows.road`). Returns the road of each wheel path (m)
        of the run's samples; ``roll_moment_psd`` ((N m)^2 / s) is what the load pass's roll
        residual shows (:meth:`.OfflineRows.roll_moment_psd`), ``left_out`` the readings not
        fed (:meth:`pieces`), the other arguments as :meth:`pieces` made them. ``spilled`` (with
        :attr:`spill`, an evenly sampled run, rows that build the road in pieces:
        ``road_pieces``): the pass's road columns in a file (:class:`SpilledColumns`), the
        road built over them in pieces and returned in a file (a
        :class:`~.core.spill.SpillColumn` (m, wheels)): the same bits, none held whole."""
        # the roll moment as slow as the load pass's roll residual says it is
        g = self.schedule.profile_design(dt, 'offline', roll_moment_psd)
        recon = self.rows
        pos = None
        if steps is not None:               # completed on the grid, as :meth:`_bridged`
            pos = np.concatenate([[0], np.cumsum(steps)])
            grid = np.arange(int(pos[-1]) + 1)
            y = np.column_stack([np.interp(grid, pos, y[:, i]) for i in range(self.ny)])
            left_out = _on_grid(left_out, pos)
        if (spilled and self.spill is not None and uniform and steps is None
                and hasattr(recon, 'road_pieces')):    # the road's columns in a file
            cols = SpilledColumns(y.shape[0], recon.profile_columns, recon.field_columns,
                                  self.spill)
            try:
                segs = (None if left_out is None else self._left_out(
                    [(0, y.shape[0], g)], left_out, dt, roll_moment_psd))
                self._uniform(g, dt, y, x0, cols, segments=segs,
                              gate_from=self._gate_start(dt))
                cols.flush()
                return recon.road_pieces(cols.file, y.shape[0], dt, speed, self.spill, v=v)
            finally:
                cols.file.close()
        if uniform or steps is not None:        # only the road's columns held whole
            cols = KeptColumns(y.shape[0], recon.profile_columns,
                               field_columns=recon.field_columns)
            segs = (None if left_out is None else self._left_out(
                [(0, y.shape[0], g)], left_out, dt, roll_moment_psd))
            self._uniform(g, dt, y, x0, cols, segments=segs, gate_from=self._gate_start(dt))
        else:
            cols = recon.field_columns(y.shape[0])[1]
            self._uneven(g, dts, y, x0, cols)
        return recon.road(cols, dt, speed, dts, uniform, pos, v)

    def _windows(self, run: SimpleNamespace, t: np.ndarray, y: np.ndarray, v: np.ndarray,
                 keep: tuple | None = None) -> Iterator[tuple[int, int, list | dict]]:
        """An evenly sampled run window by window, ``(a, b, columns of rows a:b)``: rows
        ``a:b`` (``run.window`` of them) from the smoother over ``a - overlap : b + overlap``
        with the run's noise, roughness and gains (``run``: :meth:`_design_run`); the forward
        filter starts at the state the previous window's pass had there (the run's first
        window at rest), the backward pass with no information at the window's end; the body
        heave and the quasi-static LTR start at the window's start; the converged flag counts
        from the run's start. What the edges change fades within the overlap: ~1e-11 of each
        field's RMS (:data:`WINDOW_OVERLAP_TAUS`). An unsteady run (a stop) takes its gains
        per stretch of speed in each window (:func:`.run_speed.level_segments`, the levels from
        the window's first sample on: the overlap covers their start). With ``keep`` (slots)
        only those columns, as a dict, without the body heave; ``v`` the model's speeds
        (m/s)."""
        m = t.size
        g, dt, window, overlap = run.gains, run.dt, run.window, run.overlap
        gate_from = self._gate_start(dt)
        x0 = self.model.rest_state(y[0])
        recon = self.rows
        stick = None if self.stick is None else self._stick_forces(y)  # (the whole run's)
        for a in range(0, m, window):
            b = min(m, a + window)
            lo, hi = max(0, a - overlap), min(m, b + overlap)
            nxt = b - overlap if b < m else None        # where the next window starts
            cols = (recon.field_columns(hi - lo)[1] if keep is None else
                    KeptColumns(hi - lo, keep, field_columns=recon.field_columns))
            segs = level_segments(self.schedule, dt, v[lo:hi]) if run.unsteady else None
            if run.left_out is not None:
                segs = self._left_out(segs or [(0, hi - lo, g)], run.left_out[lo:hi], dt)
            carried = self._uniform(g, dt, y[lo:hi], x0, cols,
                                    keep=None if nxt is None else max(0, nxt) - lo,
                                    segments=segs, gate_from=max(0, gate_from - lo),
                                    count=keep is None,
                                    stick=None if stick is None else stick[:, lo:hi])
            if keep is None:
                self._finish(cols, t[lo:hi], dt, run.speed, t[0])
                yield a, b, [col[a - lo:b - lo] for col in cols]
            else:
                yield a, b, {j: cols[j][a - lo:b - lo] for j in keep}
            del cols                  # (let go before the next window's are made)
            x0 = carried

    def _bridged(self, g: Gains, dt: float, speed: float, t: np.ndarray, steps: np.ndarray,
                 y: np.ndarray, x0: np.ndarray, out: list,
                 left_out: np.ndarray | None = None) -> None:
        """A run on a grid of dt (s) with samples missing (rejected, or lost): the run is
        completed on the grid (the measurements of the missing points interpolated linearly
        between their neighbours), smoothed as an evenly sampled run (:meth:`_uniform`, the
        body heave over the whole grid), and the rows of the samples present written to
        ``out``. ``steps``: grid steps between the samples (>= 1); ``left_out`` the readings
        not fed (:meth:`pieces`; a point between two samples left out with either)."""
        pos = np.concatenate([[0], np.cumsum(steps)])
        m = int(pos[-1]) + 1
        grid = np.arange(m)
        yg = np.column_stack([np.interp(grid, pos, y[:, i]) for i in range(self.ny)])
        cols = self.rows.field_columns(m)[1]
        segs = (None if left_out is None else
                self._left_out([(0, m, g)], _on_grid(left_out, pos), dt))
        self._uniform(g, dt, yg, x0, cols, segments=segs, gate_from=self._gate_start(dt),
                      count=True)
        self._finish(cols, t[0] + dt * grid, dt, speed)
        for j, col in enumerate(cols):
            if j != self.rows.distance_column:
                out[j][:] = col[pos]

    def _uneven(self, g: Gains, dts: np.ndarray, y: np.ndarray, x0: np.ndarray,
                out: list, count: bool = False) -> None:
        """Uneven steps: the transition of each step (cached), the run's gains; the
        innovation gate as :class:`.rts_pass.ForwardPass`'s (from the time of
        :meth:`_gate_start`; counted with ``count``). Stick: the operator on the readings
        (not on what the gate feeds: offline the gate's verdicts come later)."""
        m = y.shape[0]
        stick = None if self.stick is None else self._stick_forces(y)
        c = g.model.c
        nx = self.nx
        a_steps = [g.transition(float(d)) for d in dts]     # A_k: sample k-1 -> k
        xf = np.empty((m, nx))
        nus = np.empty((m, self.ny))
        xf[0] = x0
        k_gate = self.observer.innovation_gate
        gate = k_gate * np.sqrt(np.diag(g.s)) if k_gate > 0.0 else None
        t_gate = self._gate_start(float(np.median(dts))) * float(np.median(dts))
        elapsed = np.concatenate([[0.0], np.cumsum(dts)])
        flags = np.zeros(self.ny, dtype=np.int8)
        undo = None             # (the last sample's prediction and innovations before the gate)
        for k in range(1, m):
            xp = self._predict(g, a_steps, dts, xf, k, stick)
            nus[k] = y[k] - c @ xp
            if gate is not None and elapsed[k] >= t_gate:
                outside = np.abs(nus[k]) > gate
                back = outside & (flags == 1)
                if undo is not None and back.any():   # the last sample was real: restored
                    nus[k - 1, back] = undo[1][back]
                    xf[k - 1] = undo[0] + g.k @ nus[k - 1]
                    if count:
                        self.gated -= back
                    xp = self._predict(g, a_steps, dts, xf, k, stick)
                    nus[k] = y[k] - c @ xp
                    outside = np.abs(nus[k]) > gate
                    flags[back] = 2
                undo = None
                gated = outside & (flags == 0)
                flags[:] = np.where(outside, 2, 0)
                if gated.any():          # its prediction instead: innovation 0
                    flags[gated] = 1
                    undo = (xp, nus[k].copy())
                    nus[k, gated] = 0.0
                    if count:
                        self.gated += gated
            xf[k] = xp + g.k @ nus[k]
        cs = c.T @ np.linalg.inv(g.s)
        ikc_t = (np.eye(nx) - g.k @ c).T
        xs = xf.copy()
        lam = np.zeros(nx)
        for k in range(m - 1, 0, -1):
            lam = cs @ nus[k] + (ikc_t @ (a_steps[k].T @ lam) if k < m - 1 else 0.0)
            xs[k - 1] = xf[k - 1] + g.p_post @ (a_steps[k - 1].T @ lam)
        o = self.h @ xs.T
        if self.friction is not None:
            o = o + self.fd @ (self._forces(o) if stick is None else stick)
        self.rows.columns(o, out)

    def _predict(self, g: Gains, a_steps: list, dts: np.ndarray, xf: np.ndarray,
                 k: int, stick: np.ndarray | None = None) -> np.ndarray:
        """The prediction of sample k from ``x+_(k-1)`` over the uneven step (the friction on
        the filtered dq: one pass, the steps uneven; stick: the trapezoid of the forces
        ``stick`` (nf, m) at the step's ends)."""
        xp = a_steps[k - 1] @ xf[k - 1]
        if stick is not None:
            xp = xp + g.friction_input(float(dts[k - 1])) @ (
                0.5 * (stick[:, k - 1] + stick[:, k]))
        elif self.friction is not None:
            dq = xf[k - 1, self._dq_states]
            xp = xp + g.friction_input(float(dts[k - 1])) @ self._forces_at(dq)
        return xp

    def _uniform(self, g: Gains, dt: float, y: np.ndarray, x0: np.ndarray,
                 out: list, keep: int | None = None, segments: list | None = None, *,
                 gate_from: int = 0, count: bool = False,
                 stick: np.ndarray | None = None) -> np.ndarray | None:
        """The steady-state filter and RTS smoother of an evenly sampled run
        (:meth:`_uniform_pass`); with friction, :data:`FRICTION_PASSES` passes, each with the
        friction evaluated on the previous pass's smoothed dq (the first without). With
        ``keep`` the forward state ``x+_keep`` is returned (where the next window starts);
        ``segments`` (:func:`.run_speed.speed_segments`): the gains per stretch of speed;
        the innovation gate on from sample ``gate_from``, its samples counted (:attr:`gated`)
        with ``count`` (the load pass whose rows are the estimate). Stick: one pass with the
        operator's forces ``stick`` (nf, m) (N; None: from y), the trapezoid over each step and
        the sample's own in the direct part."""
        segs = segments or [(0, y.shape[0], g)]
        gating = dict(gate_from=gate_from)
        if self.friction is None:
            return self._uniform_pass(segs, dt, y, x0, out, keep=keep, count=count, **gating)
        if self.stick is not None:
            f = self._stick_forces(y) if stick is None else stick
            forces = f.copy()
            forces[:, :-1] = 0.5 * (f[:, :-1] + f[:, 1:])
            return self._uniform_pass(segs, dt, y, x0, out, forces, keep, count=count,
                                      direct=f, **gating)
        forces = None
        for _ in range(FRICTION_PASSES - 1):
            # (no gate: without the friction input the first pass's innovations exceed it)
            dq = self._uniform_pass(segs, dt, y, x0, None, forces, gate_from=y.shape[0])
            f = self._forces_at(dq)
            # held over step k -> k + 1: the mean of the ends (the trapezoid; the friction is
            # stiff against the step, see .model_core)
            forces = f.copy()
            forces[:, :-1] = 0.5 * (f[:, :-1] + f[:, 1:])
        return self._uniform_pass(segs, dt, y, x0, out, forces, keep, count=count, **gating)

    def _uniform_pass(self, segs: list, dt: float, y: np.ndarray, x0: np.ndarray,
                      out: list | None, forces: np.ndarray | None = None,
                      keep: int | None = None, *, gate_from: int = 0,
                      count: bool = False, direct: np.ndarray | None = None
                      ) -> np.ndarray | None:
        """The steady-state filter and RTS smoother of an evenly sampled run, chunk by chunk.

        Forward: ``x+_k = (I - K C) A x+_(k-1) + K y_k``, innovations ``nu_k = y_k - C A
        x+_(k-1)``. Backward (the adjoint form of the RTS smoother): ``lam_k = Phi^T lam_(k+1)
        + C^T S^-1 nu_k`` with ``Phi = A (I - K C)``, ``lam_m = 0``, and ``x_(k|m) = x+_k +
        P+ A^T lam_(k+1)``. ``segs``: ``(start, end, gains)`` stretches of the run (one: the
        run's gains), each step with the matrices of its sample's stretch. ``x0`` is ``x+_0``.
        With friction forces f (nf, m) (N), the known input ``B_d f_(k-1)`` joins the
        prediction ``A x+_(k-1)``; ``direct`` (nf, m): the forces of the outputs' direct part
        (None: the law at the smoothed rates). ``out`` None: only the smoothed rates (nf, m)
        are returned;
        else,
        with ``keep``, the forward state ``x+_keep`` (where the next window starts).
        """
        m = y.shape[0]
        mats = [self._pass_matrices(g, dt, forces, (a, b)) for a, b, g in segs]
        dq = None if out is not None else np.empty((len(self._dq_states), m))
        fwd = None
        for k0, k1, xs in smoothed_chunks(segs, mats, y, x0, _SMOOTH_CHUNK, gate_from):
            if k0 < 0:
                fwd = xs
                if count:
                    self.gated += fwd.gated
            elif out is None:
                dq[:, k0:k1] = xs[:, self._dq_states].T
            else:
                o = self.h @ xs.T
                if direct is not None:
                    o = o + self.fd @ direct[:, k0:k1]
                elif self.friction is not None:
                    o = o + self.fd @ self._forces(o)
                self.rows.columns(o, _rows(out, k0, k1))
        if out is None:
            return dq
        return None if keep is None else fwd.states(keep, keep + 1)[0][0]

    def _pass_matrices(self, g: Gains, dt: float, forces: np.ndarray | None,
                       rows: tuple[int, int] = (0, 0)) -> tuple:
        """What :meth:`_uniform_pass` needs of the gains g at the step dt (s): the forward
        ``(I - K C) A`` (its powers), ``K^T``, ``(C A)^T``, the backward ``Phi^T`` (powers),
        ``(C^T S^-1)^T``, ``(P+ A^T)^T`` and the friction forces' parts (or None). A
        :class:`_Step` (one sample's gains, ``rows`` its sample): the matrices themselves,
        the friction's parts of that sample only."""
        c = g.model.c
        nx = self.nx
        row_x = row_layout(nx, self.ny)[1]
        a_dt = g.transition(dt)
        gain = g.k
        ex = list(g.excluded)
        step = isinstance(g, _Step)
        if ex:      # left out: the gain's and the backward pass's columns 0 (innovation 0)
            gain = gain.copy()
            gain[:, ex] = 0.0
        if ex or step:
            a_run = np.ascontiguousarray((np.eye(nx) - gain @ c) @ a_dt)
            a_run = a_run if step else Powers(a_run)
        else:
            a_run = Powers(np.ascontiguousarray(g.step_matrix(dt)[:nx, row_x:row_x + nx]))
        kt = np.ascontiguousarray(gain.T)
        ca_t = np.ascontiguousarray((c @ a_dt).T)
        phi_t = np.ascontiguousarray((a_dt @ (np.eye(nx) - gain @ c)).T)
        phi_t = phi_t if step else Powers(phi_t)
        u_t = (c.T @ np.linalg.inv(g.s)).T
        if ex:
            u_t[ex] = 0.0
        u_t = np.ascontiguousarray(u_t)
        pa_t = np.ascontiguousarray((g.p_post @ a_dt.T).T)
        fin = None
        if forces is not None:
            bd = g.friction_input(dt)
            if step:        # the rows rows[0] - 1 .. rows[1] - 2 (the forward's indices)
                part = forces[:, max(rows[0] - 1, 0):max(rows[1] - 1, 0)].T
                fin = (_Offset(part @ (bd - gain @ (c @ bd)).T, rows[0] - 1),
                       _Offset(part @ (c @ bd).T, rows[0] - 1))
            else:
                fin = (forces.T @ (bd - gain @ (c @ bd)).T, forces.T @ (c @ bd).T)
        k = self.observer.innovation_gate
        gate = k * np.sqrt(np.diag(g.s)) if k > 0.0 else None
        if gate is not None and ex:
            gate[ex] = np.inf                # (its innovation is not used)
        return a_run, kt, ca_t, phi_t, u_t, pa_t, fin, gate

    def _left_out(self, segs: list, left_out: np.ndarray, dt: float,
                  profile_psd: float | None = None) -> list:
        """``segs`` (``(start, end, gains)``) cut where the channels left out (``left_out``,
        bool (m, ny)) change; a stretch with channels left out takes the gains of its
        stretch's levels designed without them (:func:`.gains.design` ``excluded``: the
        load pass's at the step dt (s), or with ``profile_psd`` the profile pass's,
        :meth:`.GainSchedule.profile_design`). The schedule's gains in use stay."""
        rows = np.asarray(left_out, dtype=bool)
        cuts = np.flatnonzero(np.any(rows[1:] != rows[:-1], axis=1)) + 1
        sched = self.schedule
        saved = sched.levels['v'], sched.excluded, sched.gains, sched.stale
        out = []
        try:
            for s0, s1, g in segs:
                inner = cuts[(cuts > s0) & (cuts < s1)].tolist()
                for a, b in zip([s0, *inner], [*inner, s1]):
                    channels = tuple(np.flatnonzero(rows[a]).tolist())
                    gains = g
                    if channels:
                        sched.levels['v'] = g.key[1]
                        sched.excluded = channels
                        gains = (sched.design(dt, 0) if profile_psd is None else
                                 sched.profile_design(dt, 'offline', profile_psd))
                    if out and set(out[-1][2].excluded) - set(channels):
                        steps = self._reentry(out[-1][2], gains, dt, b - a)
                        out += [(a + i, a + i + 1, st) for i, st in enumerate(steps)]
                        a += len(steps)
                    if a < b:
                        out.append((a, b, gains))
        finally:
            sched.levels['v'], sched.excluded, sched.gains, sched.stale = saved
        return out

    def _reentry(self, before: Gains, after: Gains, dt: float, most: int) -> list:
        """The gains of the samples where a channel left out comes back (``before`` the
        design of the stretch without it, ``after`` the next stretch's), one :class:`_Step`
        per sample: the Kalman filter's own covariance from ``before``'s to ``after``'s
        (the Riccati recursion with ``after``'s model and noises), until it is ``after``'s to
        :data:`REENTRY_TOLERANCE` (of the largest entry, in the model's state scales), at
        most ``most`` samples and :data:`REENTRY_MAX_SAMPLES`.

        Why: the steady-state smoother of the next stretch takes its first state as known to
        ``after``'s covariance, and the backward pass multiplies what the later readings
        tell by the stretch's own covariance; where a channel was left out the true
        covariance is orders of magnitude larger (the roll's, after a roll sensor's 2 s
        out), and without this a channel's return moved the loads for tens of ms
        (``python -m bench.studies.sensor_faults --only latency --faults stuck --modes
        offline``; docs/sensors.md)."""
        a_dt = after.transition(dt)
        c, r, q = after.model.c, after.r, after.q
        nx = a_dt.shape[0]
        scale = np.asarray(self.model.state_scale(nx), dtype=float)
        norm = np.outer(scale, scale)
        target = after.p_post / norm
        tol = REENTRY_TOLERANCE * float(np.max(np.abs(target)))
        p = before.p_post
        out = []
        for _ in range(min(most, REENTRY_MAX_SAMPLES)):
            pm = a_dt @ p @ a_dt.T + q
            s = c @ pm @ c.T + r
            s = 0.5 * (s + s.T)
            k = np.linalg.solve(s, c @ pm).T
            p = (np.eye(nx) - k @ c) @ pm
            p = 0.5 * (p + p.T)
            out.append(_Step(after, k, s, p))
            if float(np.max(np.abs(p / norm - target))) <= tol:
                break
        return out

    def _gate_start(self, dt: float) -> int:
        """The first sample of a run (steps of dt, s) the innovation gate sees: as the online
        observer's, after :data:`..observer.online.GATE_START_S` and the settling time."""
        return int(math.ceil(max(GATE_START_S, self.schedule.settling_time_s(dt)) / dt))

    def _finish(self, out: list, t: np.ndarray, dt: float, speed: float,
                t_start: float | None = None) -> None:
        """What a run's columns need of the whole run (:meth:`.OfflineRows.finish_run`: the
        body's motion, the quasi-static LTR, the converged flags counted from ``t_start``,
        default ``t[0]``). ``dt`` and ``speed``: the run's median step (s) and |speed| (m/s)."""
        self.rows.finish_run(out, t, dt, speed, self.schedule.settling_time_s(dt), t_start)


#: Where a left-out channel comes back, the smoother's covariance is followed sample by
#: sample (:meth:`Smoother._reentry`) until it is the steady state's to this fraction...
REENTRY_TOLERANCE = 1e-9
#: ... or for at most this many samples.
REENTRY_MAX_SAMPLES = 4096


class _Step:
    """One sample's gains where a left-out channel comes back (:meth:`Smoother._reentry`):
    the stretch's design (its model, transition and friction input) with the Kalman gain
    ``k``, innovation covariance ``s`` and a-posteriori covariance ``p_post`` of that
    sample."""

    def __init__(self, design: Gains, k: np.ndarray, s: np.ndarray, p_post: np.ndarray
                 ) -> None:
        self.design, self.k, self.s, self.p_post = design, k, s, p_post
        self.model = design.model
        self.excluded = design.excluded
        self.key = design.key

    def transition(self, dt_s: float) -> np.ndarray:
        return self.design.transition(dt_s)

    def friction_input(self, dt_s: float) -> np.ndarray:
        return self.design.friction_input(dt_s)


class _Offset:
    """Rows of an array as rows ``offset ..`` of a longer one (slices only)."""

    def __init__(self, rows: np.ndarray, offset: int) -> None:
        self.rows, self.offset = rows, offset

    def __getitem__(self, sl: slice) -> np.ndarray:
        return self.rows[sl.start - self.offset:sl.stop - self.offset]


def _on_grid(left_out: np.ndarray | None, pos: np.ndarray) -> np.ndarray | None:
    """``left_out`` (bool (m, ny)) of samples at the grid points ``pos`` on the whole grid:
    a point between two samples left out with either."""
    if left_out is None:
        return None
    grid = np.arange(int(pos[-1]) + 1)
    before = np.searchsorted(pos, grid, side='right') - 1
    after = np.searchsorted(pos, grid, side='left')
    return left_out[before] | left_out[after]
