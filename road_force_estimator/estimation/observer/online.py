"""The model observer online (``observer.discretization = 'model'``, the default): the
steady-state Kalman filter on a vehicle model (:mod:`..models`; gains of :mod:`.gains` at the
operating point of :mod:`.schedule`), the fixed-lag smoother and the sliding-mode injection,
one accepted sample at a time (:class:`ModelCore`). Nothing here knows which vehicle it
estimates: the model gives the linear model, the channels and the reconstruction of the rows.

Sliding-mode injection (off by default)
---------------------------------------
After the linear update the output error ``e = y - C x+`` goes through a dead zone of
:data:`SM_DEAD_ZONE` times its expected standard deviation (the Kalman filter's own
``(I - C K) S (I - C K)^T``) and into an implicit Levant differentiator per channel (L from
the model, :meth:`.VehicleModel.sm_lipschitz`). Its estimates ``rho = (e, de, dde)`` are an
equivalent output injection (:meth:`.VehicleModel.sm_injection`: e.g. ``dde``, the output
acceleration the model did not explain, as an unknown tire force and roll moment; ``e`` and
``de`` correct the outputs and their rates). It is added to the estimate ``x = x+ + gamma T
rho`` (a cascade: the Kalman recursion does not see it, so it cannot destabilise it), with
``gamma = observer.sliding_mode_gain / (1 + (sigma_q / SM_NOISE_SCALE)^2)``.
``observer.sliding_mode_gain`` is 0 by default since issue 30: the weighted term changed no
figure the benchmark prints, and at full strength it wins only at sharp point-contact events
at low noise and loses on enveloped roads, friction switching, spikes and heavy-tailed noise
(``python -m bench.studies.sliding_mode_events``; the decision: docs/method.md). Fed back into the
recursion (instead of cascaded) it was unstable.

Stamps
------
Each step uses its stamps' dt, but for stamps jittered about a regular sample clock
(:mod:`.sample_clock`, detected per block): from the next block on, the clock's step.

Latency
-------
``observer.latency`` = T: each estimate is that of the sample N = round(T / dt) steps back
(dt: the median of a run's first :data:`LAG_STEPS` steps), with the exact steady-state
fixed-lag correction from the innovations of the N later samples (:mod:`.gains`), applied to
the outputs through ``H`` in one product per sample. At a gap or the end of the data
(:meth:`ModelCore.finish`) the pending samples get the same correction from the innovations
that did arrive (the exact smoother of the shorter window). The outputs become the model's
row (:meth:`.VehicleModel.online_rows`).

Profile
-------
With no lag the road is not the load filter's: a second steady-state Kalman filter on the
same model runs beside it on the same measurements, with the profile's gains
(:meth:`.GainSchedule.profile_design`, ``'online'``: the same noise and roughness estimates,
a rougher road assumed, so less lag; no sliding mode); the model's reconstruction takes the
road from its outputs. The loads and every other column are the load filter's. With a lag
(``observer.latency`` > 0) the road stays the load filter's.
"""
from __future__ import annotations

from collections import deque
import math
from operator import le

import numpy as np

from road_force_estimator.core.parameters import ObserverParameters
from road_force_estimator.estimation.body_heave import SPEED_FLOOR_MPS
from road_force_estimator.estimation.models.protocol import VehicleModel, row_layout
from road_force_estimator.estimation.observer.friction import KnownFriction
from road_force_estimator.estimation.observer.gains import Gains
from road_force_estimator.estimation.observer.sample_clock import JITTER_MAX_FRACTION, clock_step
from road_force_estimator.estimation.observer.schedule import (
    DEFAULT_ROAD_GD_M3, MIN_SETTLE_S, GainSchedule, dt_level)
from road_force_estimator.estimation.observer.sliding_mode import SlidingMode

__all__ = ['BLOCK_SAMPLES', 'FIRST_BLOCK_SAMPLES', 'LAG_STEPS', 'GATE_START_S', 'SM_DEAD_ZONE',
           'SM_NOISE_SCALE', 'ModelCore']

#: Samples per block of the online noise and roughness statistics.
BLOCK_SAMPLES = 256
#: Steps whose median dt sets the lag N = round(latency / dt) of a run.
LAG_STEPS = 5
#: Samples of the very first block (a quick first estimate).
FIRST_BLOCK_SAMPLES = 64
#: Time (s) after a run's (re)start from which the innovation gate is on (the start-up
#: transient's innovations exceed the steady state's spread), besides the settling time.
GATE_START_S = 2.0
#: Sliding-mode injection: dead zone in expected standard deviations of the output error,
#: and the deflection-noise level (m) at which its weight has halved.
SM_DEAD_ZONE = 3.0
SM_NOISE_SCALE = 1e-7

_dot = np.dot     # (a little faster than the @ operator on small arrays)
_R0 = 0           # the row's rho part starts the row (:func:`.protocol.row_layout`)


class ModelCore:
    """The model-based observer, one accepted sample at a time (a core of :class:`.Estimator`).

    :meth:`step` with ``restart`` for the first sample of a run, without for each following
    one; finalized rows ``(stamp_ns, row)`` (slots :class:`.Column`) are appended to
    :attr:`ready` in sample order, :attr:`lag` samples late; :meth:`finish` finalizes the rest
    of the run (end of data, or a gap). Noise and roughness estimates (and the gain cache)
    persist over restarts; :meth:`reset` forgets them.

    Parameters
    ----------
    model : VehicleModel
        The vehicle (:mod:`..models`): its linear model, its channels, its reconstruction
        into rows (:meth:`.VehicleModel.online_rows`).
    observer : ObserverParameters
        ``latency_s`` (with the first step of a run: the lag N), ``sliding_mode_gain``,
        ``noise_deflection_m`` / ``noise_roll_rad`` / ``road_roughness_m3`` (0 = estimate),
        ``road_correlation_length_m``, ``profile_cutoff_wavelength_m``.

    Notes
    -----
    One row of a buffer per sample (layout: :mod:`.gains`): a step writes the new measurement
    into the last row, multiplies that row by the step matrix (the Kalman filter), runs the
    sliding-mode differentiators on the output error and writes the next row; the sample N
    rows back is finalized with one product of the rows' window by the output matrix (the
    fixed-lag correction included) and the model's reconstruction (:class:`.OnlineRows`:
    e.g. body heave, wheel heaves, road, loads, LTR, residual, lift-off).
    """

    method = 'model'

    def __init__(self, model: VehicleModel, observer: ObserverParameters) -> None:
        self.model = model
        self.observer = observer
        self._recon = model.online_rows(observer)
        # the rows read the zero-latency profile filter's outputs (OnlineRows.uses_profile,
        # default True): if not, the filter is not run (nor designed)
        self._rows_profile = bool(getattr(self._recon, 'uses_profile', True))
        self.sm_gain = float(observer.sliding_mode_gain)
        cm = model.continuous(1.0, DEFAULT_ROAD_GD_M3)
        self._h = cm.h
        # the buffer row's layout (nx states, ny channels) and the slots the sensors measure
        self._ny = cm.ny
        _, self._x0i, _, self._y0i, self._row = row_layout(cm.nx, cm.ny)
        self._nx = cm.nx
        self._c_slots = cm.measured
        # leaf-spring friction, a known input (:mod:`.friction`), or None
        self._fr = KnownFriction(model, cm) if any(cm.friction_n) else None
        self.schedule = GainSchedule(model, observer)
        self.ready: deque = deque()
        #: False: no row is made (:attr:`ready` stays empty, :attr:`last_row` None): the
        #: filter and its innovations only (:attr:`nll_terms`, a fit: :mod:`..friction_fit`)
        self.rows = True
        self.reset()

    @property
    def vehicle(self):
        """The parameters of the model in use."""
        return self.model.vehicle

    # -- configuration --------------------------------------------------------------------
    def set_vehicle(self, vehicle) -> None:
        """Take ``vehicle`` from the next sample on (an estimated sprung mass and static
        loads, :mod:`..static_load`): the model, the reconstruction and the sliding mode's L;
        the gains are designed again at the next step (the cache of designs is dropped); the
        state, the run and the noise estimates go on."""
        self.model = self.model.with_vehicle(vehicle)
        self._recon.set_vehicle(vehicle)
        self._slide.set_lipschitz(self.model.sm_lipschitz())
        self._h = self.model.continuous(1.0, DEFAULT_ROAD_GD_M3).h
        self.schedule.set_model(self.model)
        self._m_dt = -1.0

    def set_static_loads(self, *static_n: float) -> None:
        """The static wheel loads (N) of the rows made from now on."""
        self._recon.set_static(*static_n)

    def reset(self) -> None:
        """Forget everything, the noise and roughness estimates included."""
        self._t = 0.0                      # time since the (re)start (s)
        self._t_retuned = 0.0              # ... at the last change of the noise levels
        sched = self.schedule
        sched.reset()
        self.ready.clear()
        self.last_row: tuple | None = None    # the newest finalized row
        self.last_converged = False           # converged flag of the newest sample
        self.lag = 0
        self._profile = self._profile_on
        # (:mod:`.sliding_mode`, off until designed)
        self._slide = SlidingMode(self.model.sm_lipschitz())
        self._m_dt = -1.0
        self._settle = math.inf
        self._gate: list | None = None      # the innovation gate per channel, or None: off
        self._gate_flags = [0] * self._ny   # 0 inside, 1 gated last sample, 2 fed outside
        self._undo: tuple | None = None       # the last sample's gate, to undo if it was real
        self._compactions = 0
        #: samples whose innovation was gated, per channel
        self.gated = [0] * self._ny
        #: when a list, each converged sample's ``(index in the run, its nll)`` appended
        #: (:mod:`..friction_fit`: the sum over the samples every v_f tried converged on)
        self.nll_terms: list | None = None
        self._nll_gains = None
        self._buf = np.zeros((0, self._row))
        self._i = 0
        self._block_start = 0
        self._pending: deque = deque()
        self._running = False
        self._stepped = False
        self._run_y: list = []
        self._dts: list = []
        self._x0 = np.zeros(self._nx)
        self._slow = 0                    # samples of the block below the speed floor
        self._prow = np.zeros(self._row)        # the profile filter's row: [0, x+, 0, y]
        self._pm = None                    # its step matrix (zero latency only)
        # the step products' buffers (:meth:`_select`) and views of their state and outputs
        self._sv = self._sv_x = np.empty(0)
        self._sp = self._sp_x = self._sp_o = np.empty(0)
        self._recon.restart()
        self._clock: float | None = None           # the sample clock's step (s), or None
        self._raw_dts: list = []                   # the stamps' steps of the block (s)

    @property
    def gains(self) -> Gains | None:
        """The gains in use."""
        return self.schedule.gains

    @property
    def noise_deflection_m(self) -> float:
        """Deflection noise std in use (m), estimated or set."""
        return self.schedule.noise_deflection_m

    @property
    def noise_roll_rad(self) -> float:
        """Roll noise std in use (rad)."""
        return self.schedule.noise_roll_rad

    @property
    def road_gd_m3(self) -> float:
        """ISO 8608 ``Gd(n0)`` in use (m^3)."""
        return self.schedule.road_gd_m3

    @property
    def pending(self) -> int:
        """Accepted samples whose estimate has not been taken yet."""
        return len(self._pending) + len(self.ready)

    @property
    def latency_samples(self) -> int:
        """The lag N of the published estimates (samples)."""
        return self.lag

    def fill_status(self, status) -> None:
        """The model's fields of an :class:`.EstimatorStatus`."""
        sched = self.schedule
        status.method = self.method
        status.latency_samples = self.lag
        status.pending = self.pending
        status.noise_deflection_m = sched.noise_deflection_m
        status.noise_roll_rad = sched.noise_roll_rad
        status.road_roughness_m3 = sched.road_gd_m3
        status.statistics_blocks = sched.blocks
        status.gain_designs = sched.design_count
        status.innovations_gated = dict(zip(self.model.channel_names, self.gated))

    def set_excluded(self, channels: tuple) -> None:
        """Leave ``channels`` (indices) out of the filter from the next step on (a stuck
        sensor, :mod:`..sensor_health`): the gains are those of a design without them
        (:func:`.gains.design` ``excluded``, cached per set), and each step takes their
        prediction for their reading (innovation 0), so that no fixed-lag output, under this
        design or the next, is given a reading the filter left out; () feeds every channel."""
        sched = self.schedule
        if tuple(channels) != sched.excluded:
            sched.excluded = tuple(channels)
            sched.stale = True

    def body_rates(self) -> tuple[float, float] | None:
        """The body's heave and roll rates of the newest state (m/s, rad/s; the model's
        ``momentum_states``), or None (:mod:`..sensor_health`)."""
        slots = getattr(self.model, 'momentum_states', None)
        if slots is None or self._buf.shape[0] == 0:
            return None
        row = self._buf[self._i]
        return float(row[self._x0i + slots[0]]), float(row[self._x0i + slots[1]])

    def settling_time_s(self, dt_s: float) -> float:
        """Time after a (re)start after which the estimate counts as converged (s); see
        :meth:`.GainSchedule.settling_time_s`."""
        return self.schedule.settling_time_s(dt_s)

    def converged(self) -> bool:
        """Whether the estimate counts as converged: the noise and roughness are known and
        the settling time has passed since the (re)start or the last change of their levels."""
        sched = self.schedule
        return self._t - self._t_retuned >= self._settle and (sched.blocks > 0
                                                             or sched.all_fixed)

    def _design(self, dt: float) -> Gains:
        """The gains of the current levels (:meth:`.GainSchedule.design`) and what the
        sliding mode takes from them."""
        g = self.schedule.design(dt, self.lag)
        self._m_dt = -1.0
        self._slide.set_gains(self.sm_gain / (1.0 + (g.noise_deflection_m / SM_NOISE_SCALE) ** 2),
                              [SM_DEAD_ZONE * float(e) for e in g.post_error_std])
        self._ht = g.out[:, _R0:_R0 + 3 * self._ny].copy()     # H T: outputs of rho
        self._settle = max(g.settle_s, 20.0 * g.dt_s, MIN_SETTLE_S)
        # the innovation gate: observer.innovation_gate standard deviations of each channel's
        # predicted innovation, once the noise is known (before, the spread is a guess)
        k = self.observer.innovation_gate
        self._gate = ([k * math.sqrt(float(g.s[j, j])) for j in range(self._ny)]
                      if k > 0.0 and self.schedule.estimated else None)
        return g

    def _select(self, dt: float) -> None:
        """Gains of the current levels and of this step's dt level; its step matrix."""
        sched = self.schedule
        lv = sched.levels
        lv['dt'] = dt_level(dt)
        g = sched.gains
        if sched.stale or g is None or g.key[0] != lv['dt']:
            g = self._design(dt)
        self._m = g.step_matrix(dt)
        if self._sv.shape[0] != self._m.shape[0]:    # the product's buffer (and its state)
            self._sv = np.empty(self._m.shape[0])
            self._buffer_views()
        if self._fr is not None:
            self._fr.select(g, dt)
        self._m_dt = dt
        if self._profile_on:
            self._pm = sched.profile_design(dt, 'online').step_matrix(dt)
            if self._sp.shape[0] != self._pm.shape[0]:
                self._sp = np.empty(self._pm.shape[0])
                self._buffer_views()

    def _buffer_views(self) -> None:
        """The views of the step products' buffers: their state and outputs parts."""
        n = self._y0i - self._x0i
        self._sv_x = self._sv[:n]
        self._sp_x, self._sp_o = self._sp[:n], self._sp[n:]

    def __getstate__(self) -> dict:
        """Pickled (a streamed run's snapshot) without the buffers' views: a pickled view
        is a copy of its own, no longer the buffer the products write into."""
        state = self.__dict__.copy()
        for name in ('_sv_x', '_sp_x', '_sp_o'):
            state.pop(name, None)
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._buffer_views()

    # -- the run --------------------------------------------------------------------------
    def step(self, stamp: int, y: tuple, v: float, dt: float, restart: bool, x: float,
             t_run: float, dt_typ: float) -> bool:
        """One sample ``y`` (the model's channels; a restart: the first of a run); False,
        state untouched, if non-finite.

        ``x`` distance (m) carried to the estimate; ``t_run``, ``dt_typ`` are not used (the
        model's own settling decides ``converged``).
        """
        if restart:
            self._restart(stamp, y, (x, dt, v, False))
            self.last_converged = False
            return True
        self._raw_dts.append(dt)
        clock = self._clock      # a regular clock under jittered stamps (.sample_clock)
        if clock is not None and -JITTER_MAX_FRACTION * clock <= dt - clock <= (
                JITTER_MAX_FRACTION * clock):
            dt = clock
        sched = self.schedule       # (converged(), inline: once per sample)
        conv = self._t - self._t_retuned >= self._settle and (sched.blocks > 0
                                                              or sched.all_fixed)
        if not self._advance(stamp, dt, y, v, (x, dt, v, conv)):
            return False
        self.last_converged = conv
        return True

    def _restart(self, stamp: int, y: tuple, meta: tuple) -> None:
        """First sample of a run: the state at rest that reproduces it (:func:`.rest_state`).

        With no latency its estimate is final at once.
        """
        self.finish()
        x = self._x0 = self.model.rest_state(y)
        self._t = 0.0
        self._t_retuned = 0.0
        self._running = True
        self._stepped = False
        self._slide.restart()
        self._gate_flags = [0] * self._ny
        self._undo = None
        self._n = 0                      # the newest sample's index in the run
        if self._fr is not None:
            self._fr.restart(y, stamp)
        self._pending.clear()
        self._run_y = [y]
        self._dts = []
        self._recon.restart()
        self._prow[:] = 0.0
        self._prow[self._x0i:self._x0i + self._nx] = x
        if self.observer.latency_s > 0.0:
            self._pending.append((stamp, meta))
        else:
            o = (self._h @ x).tolist()
            self._emit(stamp, meta, o, o if self._profile_on else None)

    @property
    def _profile_on(self) -> bool:
        """The zero-latency profile filter runs: no latency, and no friction (whose known
        input it does not carry: then the road is the load filter's); kept in ``_profile``
        for the per-sample step; and not when the rows do not read it."""
        return self.lag == 0 and self._fr is None and self._rows_profile

    def _set_lag(self, dt: float) -> None:
        """The lag N = round(latency / dt) (samples) for a typical step dt (s)."""
        latency = self.observer.latency_s
        lag = int(round(latency / dt)) if latency > 0.0 else 0
        if lag != self.lag:
            self.lag = lag
            self._profile = self._profile_on
            self.schedule.invalidate()

    def _first_step(self, dt: float) -> None:
        """At the first step of a run: a provisional lag (final after :data:`LAG_STEPS`
        steps, from their median) and the sample buffer."""
        self._set_lag(dt)
        cap = self.lag + 1 + BLOCK_SAMPLES
        self._first_block = max(FIRST_BLOCK_SAMPLES, self.lag + 1)
        self._lag_final = self.observer.latency_s == 0.0
        if self._buf.shape[0] != cap:
            self._buf = np.zeros((cap, self._row))
        else:
            self._buf[0] = 0.0
        self._buf[0, self._x0i:self._x0i + self._nx] = self._x0
        self._i = 0
        self._block_start = 0
        self._stepped = True

    def _advance(self, stamp: int, dt: float, y: tuple, v: float, meta: tuple) -> bool:
        """Advance by dt (s) to the sample y at speed v; False if non-finite.

        The gains are those of dt's level (2 % grid) and the transition that of dt itself
        (0.1 % grid). ``meta`` = (distance (m), dt (s), speed (m/s), converged) of this
        sample, carried to its estimate.
        """
        if not self._stepped:
            self._first_step(dt)
        sched = self.schedule
        lo, hi = sched.v_band
        # |v| against the band (the band of the floor level starts at -inf: testing -v
        # there would keep the floor's gains for any speed once the truck has stopped)
        if not lo <= (v if v > 0.0 else -v) <= hi:
            sched.set_speed(v)
        if dt != self._m_dt or sched.stale:
            self._select(dt)
        buf = self._buf
        i = self._i
        row = buf[i]
        x0, y0 = self._x0i, self._y0i
        ny = self._ny
        row[y0:y0 + ny] = y
        # (into a buffer: the same numbers; the method skips np.dot's dispatch in Python)
        sv = self._m.dot(row, self._sv)
        fr = self._fr
        if fr is not None:        # the friction over the step (of x+_k)
            sv = fr.update(sv, row[x0:y0 - ny], row[y0:y0 + ny])
        s = sv.tolist()
        if not math.isfinite(sum(s)):
            return False
        excluded = sched.excluded
        if excluded:            # left out: its prediction in the row (its innovation 0)
            y = list(y)
            for ch in excluded:
                y[ch] -= s[self._nx + ch]
            row[y0:y0 + ny] = y
            sv = _dot(self._m, row, out=self._sv)
            if fr is not None:
                sv = fr.update(sv, row[x0:y0 - ny], row[y0:y0 + ny])
            s = sv.tolist()
            y = tuple(y)
        if self._gate is not None and self._t >= GATE_START_S and meta[3]:
            # innovations far outside their spread: not fed (not in a run's start-up
            # transient, whose innovations the steady-state spread does not describe)
            undo, self._undo = self._undo, None
            if undo is not None and self._undo_gate(undo, s, row):   # it was real: again
                sv = _dot(self._m, row, out=self._sv)
                if fr is not None:
                    sv = fr.update(sv, row[x0:y0 - ny], row[y0:y0 + ny])
                s = sv.tolist()
            raw = y
            clean = self._innovation_gate(y, s)
            if clean is not None:
                y = clean
                row[y0:y0 + ny] = y
                sv = _dot(self._m, row, out=self._sv)
                if fr is not None:
                    sv = fr.update(sv, row[x0:y0 - ny], row[y0:y0 + ny])
                s = sv.tolist()
                self._undo = (i, self._compactions, row.copy(), raw, self._m,
                              None if fr is None else fr.fm,
                              self._prow.copy() if self._profile else None)
        if meta[3] and self.nll_terms is not None:
            self._add_nll(s)                      # the innovations' likelihood (a fit)
        if fr is not None:
            fr.record(self._n, self.lag + 1, stamp)
        self._n += 1
        i += 1
        nxt = buf[i]
        nxt[x0:y0] = self._sv_x if sv is self._sv else sv[:y0 - x0]   # (friction: a new array)
        rho = None
        slide = self._slide
        if slide.gamma > 0.0:       # the sliding mode on the output errors
            rho = slide.inject([yk - s[c] for yk, c in zip(y, self._c_slots)], dt)
            if rho is not None:
                nxt[_R0:_R0 + 3 * ny] = rho
        self._i = i
        self._dts.append(dt)
        if -SPEED_FLOOR_MPS < v < SPEED_FLOOR_MPS:
            self._slow += 1
        if not self._lag_final and len(self._dts) >= LAG_STEPS:
            self._finalise_lag()
        lag = self.lag
        if lag == 0 and not self.rows:
            pass                        # (nothing to emit: the outputs not made either)
        elif lag == 0:
            o = s[y0 - x0:]
            if rho is not None:
                o = [a + b for a, b in zip(o, _dot(self._ht, rho).tolist())]
            # (the row holds y as fed: the profile filter copies it from there)
            self._emit(stamp, meta, o, self._profile_step(row[y0:y0 + ny]) if self._profile
                       else None)
        else:
            pending = self._pending
            pending.append((stamp, meta))
            if len(pending) == lag + 1:     # the steady state: the sample N back is due
                item = pending.popleft()
                gains = sched.gains
                delayed = fr is not None and not fr.sticks
                if fr is not None and fr.sticks:   # stick: from de-lagged readings (.friction)
                    self._stick_correction(gains, dt, i, lag)
                if delayed:   # the friction at its smoothed rates (.model_friction)
                    stage = fr.stage_lag(dt, lag)
                    if stage:
                        self._friction_correction(gains, dt, i, stage, None)
                o = _dot(gains.out, buf[i - lag:i + 1].reshape(-1)).tolist()
                if delayed:
                    self._friction_correction(gains, dt, i, lag, o)
                self._emit(item[0], item[1], o)
            while len(pending) > lag:
                first = i - len(pending) + 1
                self._finalize(pending.popleft(), first, first + lag)
        self._t += dt
        if i + 1 == buf.shape[0] or (sched.blocks == 0 and i == self._first_block):
            self._compact()
        return True

    def _add_nll(self, s: list) -> None:
        """Add this sample's negative log-likelihood ``(nu^T S^-1 nu + log det S) / 2`` of
        its innovation (``s``: the step's product) under the gains in use to
        :attr:`nll_terms`."""
        g = self.schedule.gains
        if g is not self._nll_gains:
            self._nll_gains = g
            self._nll_si = np.linalg.inv(g.s)
            self._nll_logdet = float(np.linalg.slogdet(g.s)[1])
        nu = np.array(s[self._nx:self._nx + self._ny])
        self.nll_terms.append((self._n, 0.5 * (float(nu @ self._nll_si @ nu)
                                               + self._nll_logdet)))

    def _innovation_gate(self, y: tuple, s: list) -> tuple | None:
        """The sample with each channel whose innovation (in ``s``, the step's product) lies
        beyond :attr:`gate` standard deviations of its predicted spread replaced by its
        prediction (its innovation then 0: the measurement is not fed to the filter), or None
        when none is. A channel is gated for one sample at a time: when the next sample is
        outside too, the step is real (a pothole, not a spike) and the channel is fed until
        it comes back inside. Counted per channel (:attr:`gated`)."""
        nu0 = self._nx
        flags = self._gate_flags
        if not any(flags) and all(map(le, map(abs, s[nu0:nu0 + self._ny]), self._gate)):
            return None       # every channel inside, as it was (the loop's outcome, in C)
        clean = None
        for ch, g in enumerate(self._gate):
            e = s[nu0 + ch]
            if -g <= e <= g:
                flags[ch] = 0
            elif flags[ch] == 0:          # a lone excursion: its prediction instead
                flags[ch] = 1
                if clean is None:
                    clean = list(y)
                clean[ch] = y[ch] - e
                self.gated[ch] += 1
            else:                         # outside again: real; fed until back inside
                flags[ch] = 2
        return None if clean is None else tuple(clean)

    def _undo_gate(self, undo: tuple, s: list, row: np.ndarray) -> bool:
        """The last sample's gated channels that are outside the gate again now (``s``:
        this step's product) were a real excursion, not a spike: their measurement is
        restored and the last step made again with it (into ``row``, the row it wrote; the
        estimate published at zero latency stays), uncounted; True when there were some.
        Not with friction across a change of the step's matrices (then the gate stands)."""
        j, compactions, prev, raw, m, fm, prow = undo
        fr = self._fr
        if fr is not None and fr.fm is not fm:
            return False
        nu0 = self._nx
        x0, y0 = self._x0i, self._y0i
        back = [ch for ch, g in enumerate(self._gate)
                if self._gate_flags[ch] == 1 and not -g <= s[nu0 + ch] <= g]
        if not back:
            return False
        for ch in back:
            prev[y0 + ch] = raw[ch]
            self.gated[ch] -= 1
            self._gate_flags[ch] = 2
        if compactions == self._compactions:      # the measurement in its row too
            self._buf[j, y0:y0 + self._ny] = prev[y0:y0 + self._ny]
        sv = _dot(m, prev)
        if fr is not None:
            fr.redo()
            sv = fr.update(sv, prev[x0:y0 - self._ny], prev[y0:y0 + self._ny])
            fr.rerecord()
        row[x0:y0] = sv[:y0 - x0]
        if prow is not None:       # the profile filter's step again, with the same data
            self._prow[:] = prow
            self._profile_step(tuple(prev[y0:y0 + self._ny].tolist()))
        return True

    def _friction_correction(self, gains: Gains, dt: float, i: int, lag: int,
                             o: list | None) -> None:
        """The delayed friction correction (:mod:`.friction`) of the rows from the
        sample ``lag`` rows back on, from its rates estimated there: ``o`` its outputs (the
        fixed-lag estimate), or None: its rates from the first ``lag + 1`` rows' columns of
        the output matrix (the same fixed-lag estimate with ``lag`` innovations)."""
        buf = self._buf
        rates = self.model.friction_rate_outputs
        if o is None:
            dq = _dot(gains.out[list(rates), :(lag + 1) * self._row],
                      buf[i - lag:i + 1].reshape(-1)).tolist()
        else:
            dq = [o[j] for j in rates]
        w = self._fr.correction(gains, dt, lag, self._n - lag, dq)
        if w is not None:
            buf[i - lag:i + 1, self._x0i:self._y0i] += w

    def _stick_correction(self, gains: Gains, dt: float, i: int, lag: int) -> None:
        """Stick: the delayed correction (:meth:`.KnownFriction.stick_correction`) of the
        rows from the sample :meth:`.KnownFriction.stage_lag` rows back on, then of those from
        the sample ``lag`` rows back (the one due now, before its output) on."""
        fr = self._fr
        stage = fr.stage_lag(dt, lag)
        for n in (stage, lag) if stage else (lag,):
            w = fr.stick_correction(gains, dt, n, self._n - n, n == lag)
            if w is not None:
                self._buf[i - n:i + 1, self._x0i:self._y0i] += w

    def _profile_step(self, y) -> list:
        """One step of the zero-latency profile filter (issue 21: the same data, the
        profile's gains) on the channels ``y`` (a sequence or an array): its outputs (the
        model's)."""
        x0, y0 = self._x0i, self._y0i
        prow = self._prow
        prow[y0:y0 + self._ny] = y
        self._pm.dot(prow, self._sp)
        prow[x0:y0] = self._sp_x
        return self._sp_o.tolist()

    def _finalise_lag(self) -> None:
        """The lag from the median of the run's first steps; the buffer is resized if needed
        (the rows so far are kept)."""
        self._lag_final = True
        self._undo = None               # (the rows may move)
        lag_before = self.lag
        self._set_lag(float(np.median(self._dts[:LAG_STEPS])))
        if self.lag != lag_before:
            cap = self.lag + 1 + BLOCK_SAMPLES
            buf = np.zeros((cap, self._row))
            n = min(self._i + 1, cap)
            buf[:n] = self._buf[self._i + 1 - n:self._i + 1]
            self._i = n - 1
            self._buf = buf
            self._first_block = max(FIRST_BLOCK_SAMPLES, self.lag + 1)
            self._select(self._dts[-1])

    def _compact(self) -> None:
        """Run the block statistics; move the last lag + 1 rows to the front.

        After the first block of the observer's life the run so far is filtered again with
        the gains of the estimated noise (the rows hold every measurement since the restart),
        so that the switch from the assumed noise level leaves no transient.
        """
        self._compactions += 1          # (the rows move)
        buf = self._buf
        i = self._i
        y = buf[self._block_start:i, self._y0i:self._y0i + self._ny]
        first_run_block = bool(self._run_y)
        if first_run_block:
            y = np.vstack([np.array(self._run_y), y])
            self._run_y = []
            dts = self._dts
        else:
            dts = self._dts[1:]    # the first step led to the block's first sample
        sched = self.schedule
        first_ever = sched.blocks == 0
        fr = self._fr
        if fr is not None and fr.sticks:     # the readings less the stick forces' response
            r = fr.response(sched.gains.model, float(np.median(dts)) if dts else self._m_dt)
            if r.shape[0] >= y.shape[0]:
                y = y - r[r.shape[0] - y.shape[0]:]
        if sched.statistics(y, dts, self._slow == 0):
            self._t_retuned = self._t
        self._clock = clock_step(self._raw_dts)
        self._raw_dts = []
        self._slow = 0
        if first_ever and first_run_block and sched.stale and len(dts) == i:
            self._replay(dts)
        self._dts = []
        keep = self.lag + 1
        buf[:keep] = buf[i + 1 - keep:i + 1]
        buf[keep:, _R0:_R0 + 3 * self._ny] = 0.0    # rho stays 0 where the sliding mode does
        # not write
        self._i = keep - 1
        self._block_start = keep - 1

    def _replay(self, dts: list) -> None:
        """Filter rows 0..i again with the current levels' gains (see :meth:`_compact`), each
        step with the gains of its own dt level, as :meth:`_select` gives them (the gains of
        one level with the transition of a step several times longer are not stable: a
        stream that lost samples then diverged)."""
        buf = self._buf
        self._select(dts[-1])
        sched = self.schedule
        g = sched.gains
        x0, y0 = self._x0i, self._y0i
        fr = self._fr
        if fr is not None:
            fr.restart()
        for j, dt in enumerate(dts):
            nxt = buf[j + 1]
            g = self._gains_at(g, dt)
            sv = g.step_matrix(dt) @ buf[j]
            if fr is not None:
                fr.select(g, dt)
                sv = fr.update(sv, buf[j, x0:y0 - self._ny], buf[j, y0:y0 + self._ny])
                fr.record(j, self.lag + 1)
            nxt[x0:y0] = sv[:y0 - x0]
            nxt[_R0:_R0 + 3 * self._ny] = 0.0
        if self._profile_on:      # the profile filter too, with its gains of the new levels
            pg = self.schedule.profile_design(dts[-1], 'online')
            prow = self._prow
            prow[:] = 0.0
            prow[x0:x0 + self._nx] = self._x0
            for j, dt in enumerate(dts):
                prow[y0:y0 + self._ny] = buf[j, y0:y0 + self._ny]
                pg = self._gains_at(pg, dt, profile=True)
                prow[x0:y0] = (pg.step_matrix(dt) @ prow)[:y0 - x0]
        self._select(dts[-1])         # the gains in use: those of the last step's level
        self._t_retuned = 0.0
        self._m_dt = -1.0

    def _gains_at(self, g: Gains, dt: float, profile: bool = False) -> Gains:
        """``g``, or the gains (load or profile filter) of the current levels at the dt level
        of ``dt`` when ``g``'s is another (cached designs)."""
        sched = self.schedule
        level = dt_level(dt)
        if g.key[0] == level:
            return g
        sched.levels['dt'] = level
        return sched.profile_design(dt, 'online') if profile else sched.design(dt, self.lag)

    def _finalize(self, item: tuple, first: int, last: int) -> None:
        """Estimate of the sample in row ``first`` from rows first..last (missing: zeros)."""
        stamp, meta = item
        n = self.lag + 1
        avail = min(last, self._i) - first + 1
        if avail == n:
            window = self._buf[first:last + 1].reshape(-1)
        else:
            w = np.zeros((n, self._row))
            w[:avail] = self._buf[first:first + avail]
            window = w.reshape(-1)
        self._emit(stamp, meta, (self.schedule.gains.out @ window).tolist())

    def _emit(self, stamp: int, meta: tuple, o: list, op: list | None = None) -> None:
        """The row of the linear outputs o (the model's, friction's direct part added) by the
        model's reconstruction (:class:`.OnlineRows`); appended to ready. ``op``: the
        zero-latency profile filter's outputs, or None. None without :attr:`rows`."""
        if not self.rows:
            return
        fr = self._fr
        if fr is not None:
            fr.add_direct(o, stamp)
        row = self._recon.row(o, meta, op)
        self.last_row = row
        self.ready.append((stamp, row))

    def finish(self) -> bool:
        """Finalize every pending sample of the run (end of data, or before a restart);
        True if a run was ended (the next sample restarts)."""
        if not self._running:
            return False
        pending = self._pending
        if not self._stepped:
            if pending:   # a run of one sample, with latency: its rest state
                stamp, meta = pending.popleft()
                self._emit(stamp, meta, (self._h @ self._x0).tolist())
        else:
            last = self._i
            while pending:
                first = last - len(pending) + 1
                self._finalize(pending.popleft(), first, last)
        self._run_y = []
        self._running = False
        self._stepped = False
        return True
