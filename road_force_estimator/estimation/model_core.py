"""The model-based sliding-mode observer online (``observer.discretization = 'model'``, the
default): the steady-state Kalman filter on the roll-plane model (:mod:`.model`, gains of
:mod:`.gains` at the operating point of :mod:`.schedule`), the sliding-mode injection and the
fixed-lag smoother, one accepted sample at a time.

Sliding-mode injection
----------------------
After the linear update the output error ``e = y - C x+`` goes through a dead zone of
:data:`SM_DEAD_ZONE` times its expected standard deviation (the Kalman filter's own
``(I - C K) S (I - C K)^T``) and into an implicit Levant differentiator per channel (L from
the model, :func:`.gains.sm_lipschitz`). Its estimates ``rho = (e, de, dde)`` are the
equivalent output injection (:func:`.gains.sm_injection`): ``dde``, the output acceleration
the model did not explain, is an unknown tire force ``-m_i (dde_i -+ s dde_phi)`` (on ``w_i``
through ``kt_i``) and roll moment ``I_x dde_phi``; ``e`` and ``de`` correct the outputs and
their rates. It is added to the estimate ``x = x+ + gamma T rho`` (a cascade: the Kalman
recursion does not see it, so it cannot destabilise it), with ``gamma =
observer.sliding_mode_gain / (1 + (sigma_q / SM_NOISE_SCALE)^2)``: sliding-mode-like on clean
data, Kalman-like (gamma ~ 1e-4 at 10 um) on noisy data. ``observer.sliding_mode_gain = 0``
switches it off (the ablation). Measured (``bench/targets.py``): on every benchmark scenario
the Kalman part leaves no output error outside the dead zone worth correcting, so the
injection changes no figure at the precision the benchmark prints; fed back into the
recursion (instead of cascaded) it was unstable, and without the noise weighting it added 1 %
(dead zone 3 sigma) to 100 % (no dead zone) to the load error on the 10 um drive.

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
that did arrive (the exact smoother of the shorter window). The outputs become the row of
:mod:`.reconstruction` (body heave: :mod:`.body_heave`, restarted with each run).

Profile
-------
With no lag the road is not the load filter's: a second steady-state Kalman filter on the
same model runs beside it on the same measurements, with the profile's gains
(:meth:`.GainSchedule.profile_design`, ``'online'``: the same noise and roughness estimates,
a rougher road assumed, so less lag; no sliding mode), and the road of its states
(:class:`.model_road.OnlineRoad`, its own body-heave integral at the profile's long-wave cutoff)
replaces the row's ``U1``, ``U2``. The loads and every other column are the load filter's.
With a lag (``observer.latency`` > 0) the road stays the load filter's.
"""
from __future__ import annotations

from collections import deque
import math

import numpy as np

from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
import road_force_estimator.estimation.body_heave as body_heave
from road_force_estimator.estimation.gains import (
    ROW_RHO, NY, Gains, row_layout)
from road_force_estimator.estimation.model import (
    DEFAULT_ROAD_GD_M3, SPEED_FLOOR_MPS, continuous_model, rest_state)
from road_force_estimator.estimation.model_friction import KnownFriction
from road_force_estimator.estimation.model_road import OnlineRoad
from road_force_estimator.estimation.model_sliding import SlidingMode
from road_force_estimator.estimation.reconstruction import Reconstruction
from road_force_estimator.estimation.sample_clock import JITTER_MAX_FRACTION, clock_step
from road_force_estimator.estimation.schedule import MIN_SETTLE_S, GainSchedule, dt_level

__all__ = ['BLOCK_SAMPLES', 'FIRST_BLOCK_SAMPLES', 'LAG_STEPS', 'SM_DEAD_ZONE',
           'SM_NOISE_SCALE', 'ModelCore']

#: Samples per block of the online noise and roughness statistics.
BLOCK_SAMPLES = 256
#: Steps whose median dt sets the lag N = round(latency / dt) of a run.
LAG_STEPS = 5
#: Samples of the very first block (a quick first estimate).
FIRST_BLOCK_SAMPLES = 64
#: Sliding-mode injection: dead zone in expected standard deviations of the output error,
#: and the deflection-noise level (m) at which its weight has halved.
SM_DEAD_ZONE = 3.0
SM_NOISE_SCALE = 1e-7

_dot = np.dot     # (a little faster than the @ operator on small arrays)
_R0 = ROW_RHO


class ModelCore:
    """The model-based observer, one accepted sample at a time (a core of :class:`.Estimator`).

    :meth:`step` with ``restart`` for the first sample of a run, without for each following
    one; finalized rows ``(stamp_ns, row)`` (slots :class:`.Column`) are appended to
    :attr:`ready` in sample order, :attr:`lag` samples late; :meth:`finish` finalizes the rest
    of the run (end of data, or a gap). Noise and roughness estimates (and the gain cache)
    persist over restarts; :meth:`reset` forgets them.

    Parameters
    ----------
    vehicle : VehicleParameters
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
    fixed-lag correction included) and the reconstruction (body heave, wheel heaves, road,
    loads, LTR, residual, lift-off).
    """

    method = 'model'

    def __init__(self, vehicle: VehicleParameters, observer: ObserverParameters) -> None:
        self.vehicle = vehicle
        self.observer = observer
        self._rows = Reconstruction(vehicle, observer.rollover_cutoff_frequency_hz)
        self._wc_per_speed = body_heave.cutoff_per_speed(observer.profile_cutoff_wavelength_m)
        # the profile filter's road (:mod:`.model_road`)
        self._road = OnlineRoad(self._wc_per_speed, vehicle.half_track_m)
        self.sm_gain = float(observer.sliding_mode_gain)
        model = continuous_model(vehicle, 1.0, DEFAULT_ROAD_GD_M3)
        self._h = model.h
        # the buffer row's layout (nx = 12, or more with sensor-lag states) and the slots
        # the sensors measure
        _, self._x0i, _, self._y0i, self._row = row_layout(model.nx)
        self._nx = model.nx
        self._c_slots = model.measured
        # leaf-spring friction, a known input (:mod:`.model_friction`), or None
        self._fr = KnownFriction(model) if any(model.friction_n) else None
        self.schedule = GainSchedule(vehicle, observer)
        self.ready: deque = deque()
        self.reset()

    # -- configuration --------------------------------------------------------------------
    def set_vehicle(self, vehicle: VehicleParameters) -> None:
        """Take ``vehicle`` from the next sample on (an estimated sprung mass and static
        loads, :mod:`.static_load`): the model, the reconstruction and the sliding mode's L;
        the gains are designed again at the next step (the cache of designs is dropped); the
        state, the run and the noise estimates go on."""
        self.vehicle = vehicle
        self._rows.set_vehicle(vehicle)
        self._slide.set_vehicle(vehicle)
        self._h = continuous_model(vehicle, 1.0, DEFAULT_ROAD_GD_M3).h
        self.schedule.set_vehicle(vehicle)
        self._m_dt = -1.0

    def set_static_loads(self, fc1: float, fc2: float) -> None:
        """The static wheel loads F_c,i (N) of the rows made from now on."""
        self._rows.set_static(fc1, fc2)

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
        self._slide = SlidingMode(self.vehicle)   # (:mod:`.model_sliding`, off until designed)
        self._m_dt = -1.0
        self._settle = math.inf
        self._hstate = body_heave.start(0.0)
        self._buf = np.zeros((0, self._row))
        self._i = 0
        self._block_start = 0
        self._pending: deque = deque()
        self._running = False
        self._stepped = False
        self._run_y: list = []
        self._dts: list = []
        self._x0 = np.zeros(self._nx)
        self._body_started = False
        self._slow = 0                    # samples of the block below the speed floor
        self._prow = np.zeros(self._row)        # the profile filter's row: [0, x+, 0, y]
        self._pm = None                    # its step matrix (zero latency only)
        # the step products' buffers (:meth:`_select`) and views of their state and outputs
        self._sv = self._sv_x = np.empty(0)
        self._sp = self._sp_x = self._sp_o = np.empty(0)
        self._road.restart()
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
        self._ht = g.out[:, _R0:_R0 + 9].copy()     # H T: outputs of rho
        self._settle = max(g.settle_s, 20.0 * g.dt_s, MIN_SETTLE_S)
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
    def step(self, stamp: int, q1: float, q2: float, phi: float, v: float, dt: float,
             restart: bool, x: float, t_run: float, dt_typ: float) -> bool:
        """One sample (a restart: the first of a run); False, state untouched, if non-finite.

        ``x`` distance (m) carried to the estimate; ``t_run``, ``dt_typ`` are not used (the
        model's own settling decides ``converged``).
        """
        if restart:
            self._restart(stamp, q1, q2, phi, (x, dt, v, False))
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
        if not self._advance(stamp, dt, q1, q2, phi, v, (x, dt, v, conv)):
            return False
        self.last_converged = conv
        return True

    def _restart(self, stamp: int, q1: float, q2: float, phi: float, meta: tuple) -> None:
        """First sample of a run: the state at rest that reproduces it (:func:`.rest_state`).

        With no latency its estimate is final at once.
        """
        self.finish()
        x = self._x0 = rest_state(self.vehicle, q1, q2, phi)
        self._t = 0.0
        self._t_retuned = 0.0
        self._running = True
        self._stepped = False
        self._slide.restart()
        self._pending.clear()
        self._run_y = [(q1, q2, phi)]
        self._dts = []
        self._body_started = False
        self._road.restart()
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
        for the per-sample step."""
        return self.lag == 0 and self._fr is None

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

    def _advance(self, stamp: int, dt: float, q1: float, q2: float, phi: float, v: float,
                 meta: tuple) -> bool:
        """Advance by dt (s) to the sample (q1, q2, phi) at speed v; False if non-finite.

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
        row[y0] = q1
        row[y0 + 1] = q2
        row[y0 + 2] = phi
        sv = _dot(self._m, row, out=self._sv)       # (into a buffer: the same numbers)
        fr = self._fr
        if fr is not None:        # the friction over the step (of x+_k)
            sv = fr.update(sv, row[x0:y0 - NY])
        s = sv.tolist()
        if not math.isfinite(sum(s)):
            return False
        i += 1
        nxt = buf[i]
        nxt[x0:y0] = self._sv_x if sv is self._sv else sv[:y0 - x0]   # (friction: a new array)
        rho = None
        slide = self._slide
        if slide.gamma > 0.0:       # the sliding mode on the output errors
            c1, c2, c3 = self._c_slots
            rho = slide.inject(q1 - s[c1], q2 - s[c2], phi - s[c3], dt)
            if rho is not None:
                nxt[_R0:_R0 + 9] = rho
        self._i = i
        self._dts.append(dt)
        if -SPEED_FLOOR_MPS < v < SPEED_FLOOR_MPS:
            self._slow += 1
        if not self._lag_final and len(self._dts) >= LAG_STEPS:
            self._finalise_lag()
        lag = self.lag
        if lag == 0:
            o = s[y0 - x0:]
            if rho is not None:
                o = [a + b for a, b in zip(o, _dot(self._ht, rho).tolist())]
            self._emit(stamp, meta, o, self._profile_step(q1, q2, phi) if self._profile
                       else None)
        else:
            pending = self._pending
            pending.append((stamp, meta))
            if len(pending) == lag + 1:     # the steady state: the sample N back is due
                item = pending.popleft()
                self._emit(item[0], item[1],
                           _dot(sched.gains.out, buf[i - lag:i + 1].reshape(-1)).tolist())
            while len(pending) > lag:
                first = i - len(pending) + 1
                self._finalize(pending.popleft(), first, first + lag)
        self._t += dt
        if i + 1 == buf.shape[0] or (sched.blocks == 0 and i == self._first_block):
            self._compact()
        return True

    def _profile_step(self, q1: float, q2: float, phi: float) -> list:
        """One step of the zero-latency profile filter (issue 21: the same data, the
        profile's gains): its outputs (:data:`.OUTPUTS`)."""
        x0, y0 = self._x0i, self._y0i
        prow = self._prow
        prow[y0] = q1
        prow[y0 + 1] = q2
        prow[y0 + 2] = phi
        _dot(self._pm, prow, out=self._sp)
        prow[x0:y0] = self._sp_x
        return self._sp_o.tolist()

    def _finalise_lag(self) -> None:
        """The lag from the median of the run's first steps; the buffer is resized if needed
        (the rows so far are kept)."""
        self._lag_final = True
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
        buf = self._buf
        i = self._i
        y = buf[self._block_start:i, self._y0i:self._y0i + NY]
        first_run_block = bool(self._run_y)
        if first_run_block:
            y = np.vstack([np.array(self._run_y), y])
            self._run_y = []
            dts = self._dts
        else:
            dts = self._dts[1:]    # the first step led to the block's first sample
        sched = self.schedule
        first_ever = sched.blocks == 0
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
        buf[keep:, _R0:_R0 + 9] = 0.0    # rho stays 0 where the sliding mode does not write
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
        for j, dt in enumerate(dts):
            nxt = buf[j + 1]
            g = self._gains_at(g, dt)
            sv = g.step_matrix(dt) @ buf[j]
            if fr is not None:
                fr.select(g, dt)
                sv = fr.update(sv, buf[j, x0:y0 - NY])
            nxt[x0:y0] = sv[:y0 - x0]
            nxt[_R0:_R0 + 9] = 0.0
        if self._profile_on:      # the profile filter too, with its gains of the new levels
            pg = self.schedule.profile_design(dts[-1], 'online')
            prow = self._prow
            prow[:] = 0.0
            prow[x0:x0 + self._nx] = self._x0
            for j, dt in enumerate(dts):
                prow[y0:y0 + NY] = buf[j, y0:y0 + NY]
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
        """The row of the linear outputs o (:data:`.OUTPUTS`) and the body heave (restarted
        with each run); appended to ready. With the profile filter's outputs ``op`` (zero
        latency), the road is :class:`.OnlineRoad`'s."""
        fr = self._fr
        if fr is not None:
            fr.add_direct(o)
        (q1, q2, phi, dq1, dq2, dphi, ddq1, ddq2, ddphi, _, ddzs, _, _, ddzu1, ddzu2, w1, w2,
         df1, df2, fb1, fb2) = o
        x_dist, dt, v, conv = meta
        if self._body_started:
            h = self._hstate = body_heave.step(self._hstate, ddzs, dt, v, self._wc_per_speed)
            zs = h[-2]
            dzs = h[-1]
        else:
            zs = dzs = 0.0
            self._hstate = body_heave.start(ddzs)
            self._body_started = True
            self._rows.restart()
        row = self._rows.row(x_dist, q1, q2, dq1, dq2, ddq1, ddq2, phi, dphi, ddphi, zs, dzs,
                             ddzs, ddzu1, ddzu2, w1, w2, df1, df2, fb1, fb2, conv, dt,
                             None if op is None else self._road.road(op, dt, v, x_dist))
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
