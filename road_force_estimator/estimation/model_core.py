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
(:meth:`ModelCore._road`, its own body-heave integral at the profile's long-wave cutoff)
replaces the row's ``U1``, ``U2``. The loads and every other column are the load filter's.
With a lag (``observer.latency`` > 0) the road stays the load filter's.
"""
from __future__ import annotations

from collections import deque
import math

import numpy as np

from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
import road_force_estimator.estimation.body_heave as body_heave
from road_force_estimator.estimation.differentiator import implicit_step
from road_force_estimator.core.vehicle_model import FRICTION_VELOCITY_MPS
from road_force_estimator.estimation.gains import (
    ROW_RHO, NY, Gains, row_layout, sm_lipschitz)
from road_force_estimator.estimation.model import (
    DEFAULT_ROAD_GD_M3, PROFILE_ONLINE_CUTOFF_RATIO, SPEED_FLOOR_MPS, State,
    continuous_model, rest_state)
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


def _dq_rows(g: Gains, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """The rows of dq_1, dq_2 of the transition A(dt) (2, nx) and of the friction input
    B_d(dt) (2, 2)."""
    rows = [State.DQ1, State.DQ2]
    return g.transition(dt)[rows], g.friction_input(dt)[rows]


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
        self._wc_road = self._wc_per_speed / PROFILE_ONLINE_CUTOFF_RATIO
        self._road_floor = PROFILE_ONLINE_CUTOFF_RATIO * body_heave.SPEED_FLOOR_MPS
        self._s = vehicle.half_track_m
        self.sm_gain = float(observer.sliding_mode_gain)
        lq, lr = sm_lipschitz(vehicle)
        self._sm_lip = (lq, lq ** (1.0 / 3.0), math.sqrt(lq), lr, lr ** (1.0 / 3.0),
                        math.sqrt(lr))
        model = continuous_model(vehicle, 1.0, DEFAULT_ROAD_GD_M3)
        self._h = model.h
        # the buffer row's layout (nx = 12, or more with sensor-lag states) and the slots
        # the sensors measure
        _, self._x0i, _, self._y0i, self._row = row_layout(model.nx)
        self._nx = model.nx
        self._c_slots = model.measured
        # leaf-spring friction, a known input (:mod:`.model`): F_f,i, and the outputs'
        # direct part per newton (rows with a non-zero entry)
        self._ff = model.friction_n if any(model.friction_n) else None
        self._ceq = (0.0, 0.0)       # its equivalent damping in the gains in use
        if self._ff is not None:
            d = model.friction_d
            self._fd = [(j, float(d[j, 0]), float(d[j, 1])) for j in range(d.shape[0])
                        if d[j, 0] != 0.0 or d[j, 1] != 0.0]
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
        lq, lr = sm_lipschitz(vehicle)
        self._sm_lip = (lq, lq ** (1.0 / 3.0), math.sqrt(lq), lr, lr ** (1.0 / 3.0),
                        math.sqrt(lr))
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
        self._gamma = 0.0
        self._m_dt = -1.0
        self._settle = math.inf
        self._hstate = body_heave.start(0.0)
        self._buf = np.zeros((0, self._row))
        self._i = 0
        self._block_start = 0
        self._pending: deque = deque()
        self._sm = [0.0] * 12
        self._sm_rest = True
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
        self._road_state = body_heave.start(0.0)
        self._road_started = False
        self._road_prev = (0.0, 0.0, math.nan)     # the last (u_1, u_2, distance), unheld
        self._road_off = (0.0, 0.0)                # what standing added to the road (m)
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
        self._gamma = self.sm_gain / (1.0 + (g.noise_deflection_m / SM_NOISE_SCALE) ** 2)
        lq, lq13, lq12, lr, lr13, lr12 = self._sm_lip
        dead = [SM_DEAD_ZONE * float(e) for e in g.post_error_std]
        self._sm_ch = ((dead[0], lq, lq13, lq12), (dead[1], lq, lq13, lq12),
                       (dead[2], lr, lr13, lr12))
        self._sm_dead = tuple(dead)
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
        if self._ff is not None:
            self._fm = g.friction_step(dt)
            self._a_dq, self._b_dq = _dq_rows(g, dt)
            self._ceq = g.model.friction_damping_nspm
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
        self._sm = [0.0] * 12
        self._sm_rest = True
        self._pending.clear()
        self._run_y = [(q1, q2, phi)]
        self._dts = []
        self._body_started = False
        self._road_started = False
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
        return self.lag == 0 and self._ff is None

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
        if self._ff is not None:        # the friction over the step (of x+_k)
            sv = self._friction_update(sv, row[x0:y0 - NY], self._fm, self._a_dq, self._b_dq)
        s = sv.tolist()
        if not math.isfinite(sum(s)):
            return False
        i += 1
        nxt = buf[i]
        nxt[x0:y0] = self._sv_x if sv is self._sv else sv[:y0 - x0]   # (friction: a new array)
        rho = None
        if self._gamma > 0.0:
            c1, c2, c3 = self._c_slots
            e1 = q1 - s[c1]
            e2 = q2 - s[c2]
            e3 = phi - s[c3]
            d1, d2, d3 = self._sm_dead
            # a differentiator at rest with a zero (dead-zoned) input stays at rest
            if not (self._sm_rest and -d1 <= e1 <= d1 and -d2 <= e2 <= d2 and -d3 <= e3 <= d3):
                rho = self._sliding(e1, e2, e3, dt)
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

    def _sliding(self, e1: float, e2: float, e3: float, dt: float) -> list | None:
        """Sliding-mode differentiators on the dead-zoned output errors; ``gamma rho`` (9), or
        None when every channel rests at zero (a differentiator at rest with a zero input stays
        at rest: that step is skipped; one within 1e-3 of its dead zone of rest is put there).
        """
        st = self._sm
        active = False
        out = [0.0] * 9
        gm = self._gamma
        for ch, e in enumerate((e1, e2, e3)):
            dz, lip, lip13, lip12 = self._sm_ch[ch]
            f = e - dz if e > dz else (e + dz if e < -dz else 0.0)
            j = 4 * ch
            z0 = st[j]
            z1 = st[j + 1]
            z2 = st[j + 2]
            if f == 0.0:
                if z0 == 0.0 and z1 == 0.0 and z2 == 0.0:
                    continue
                if (abs(z0) + dt * (abs(z1) + dt * abs(z2))) < 1e-3 * dz:
                    st[j] = st[j + 1] = st[j + 2] = st[j + 3] = 0.0
                    continue
            z0, z1, z2 = implicit_step(z0, z1, z2, st[j + 3], f, dt, lip, lip13, lip12)
            st[j] = z0
            st[j + 1] = z1
            st[j + 2] = z2
            st[j + 3] = f
            k = 3 * ch
            out[k] = gm * z0
            out[k + 1] = gm * z1
            out[k + 2] = gm * z2
            active = True
        self._sm_rest = not any(st)
        return out if active else None

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
        """Filter rows 0..i again with the current levels' gains (see :meth:`_compact`)."""
        buf = self._buf
        self._select(dts[-1])
        g = self.schedule.gains
        x0, y0 = self._x0i, self._y0i
        if self._ff is not None:
            self._ceq = g.model.friction_damping_nspm
        for j, dt in enumerate(dts):
            nxt = buf[j + 1]
            sv = g.step_matrix(dt) @ buf[j]
            if self._ff is not None:
                a_dq, b_dq = _dq_rows(g, dt)
                sv = self._friction_update(sv, buf[j, x0:y0 - NY], g.friction_step(dt), a_dq,
                                           b_dq)
            nxt[x0:y0] = sv[:y0 - x0]
            nxt[_R0:_R0 + 9] = 0.0
        if self._profile_on:      # the profile filter too, with its gains of the new levels
            pg = self.schedule.profile_design(dts[-1], 'online')
            prow = self._prow
            prow[:] = 0.0
            prow[x0:x0 + self._nx] = self._x0
            for j, dt in enumerate(dts):
                prow[y0:y0 + NY] = buf[j, y0:y0 + NY]
                prow[x0:y0] = (pg.step_matrix(dt) @ prow)[:y0 - x0]
        self._t_retuned = 0.0
        self._m_dt = -1.0

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

    def _friction_update(self, sv: np.ndarray, x: np.ndarray, fm: np.ndarray, a_dq: np.ndarray,
                         b_dq: np.ndarray) -> np.ndarray:
        """``sv`` (the step without friction) with the friction held over the step from
        x+_k = ``x``: that of :meth:`_held_friction` (end rate predicted), then once more with
        the end rate of that update's x+_(k+1) (one iterated update; README, "Friction").
        ``fm``: :meth:`.Gains.friction_step`; ``a_dq``, ``b_dq``: :func:`_dq_rows`."""
        first = sv + _dot(fm, self._held_friction(x, a_dq, b_dq))
        f0 = self._friction(x[State.DQ1], x[State.DQ2])
        return sv + _dot(fm, 0.5 * (f0 + self._friction(first[State.DQ1], first[State.DQ2])))

    def _held_friction(self, x: np.ndarray, a_dq: np.ndarray, b_dq: np.ndarray) -> np.ndarray:
        """The friction forces (N) held over a step from the state x: the mean of those at
        its start and at its predicted end (Heun's trapezoid: the friction is stiff, a wheel
        time constant ``m_i v_f / F_f`` of ~3 ms against the 1 ms step). ``a_dq``, ``b_dq``:
        the dq rows of the transition and of the friction input (:func:`_dq_rows`)."""
        f0 = self._friction(x[State.DQ1], x[State.DQ2])
        dq = _dot(a_dq, x) + _dot(b_dq, f0)
        return 0.5 * (f0 + self._friction(dq[0], dq[1]))

    def _friction(self, dq1: float, dq2: float) -> np.ndarray:
        """The known friction input (N) at the rates dq_i (m/s): ``-F_f,i tanh(dq_i / v_f)``
        less the equivalent damping's share ``-c_eq,i dq_i`` that the gains' linear model
        carries (:func:`.model.friction_damping`)."""
        f1, f2 = self._ff
        d1, d2 = self._ceq
        return np.array([-f1 * math.tanh(dq1 / FRICTION_VELOCITY_MPS) + d1 * dq1,
                         -f2 * math.tanh(dq2 / FRICTION_VELOCITY_MPS) + d2 * dq2])

    def _emit(self, stamp: int, meta: tuple, o: list, op: list | None = None) -> None:
        """The row of the linear outputs o (:data:`.OUTPUTS`) and the body heave (restarted
        with each run); appended to ready. With the profile filter's outputs ``op`` (zero
        latency), the road is :meth:`_road`'s."""
        if self._ff is not None:
            f1, f2 = self._friction(o[3], o[4]).tolist()
            for j, d1, d2 in self._fd:
                o[j] += d1 * f1 + d2 * f2
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
                             None if op is None else self._road(op, dt, v, x_dist))
        self.last_row = row
        self.ready.append((stamp, row))

    def _road(self, op: list, dt: float, v: float, x: float) -> tuple[float, float]:
        """The road ``(u_1, u_2)`` (m) at distance ``x`` (m) from the profile filter's outputs
        ``op`` (:data:`.OUTPUTS`): ``u_i = z_s +- s sin(phi) - q_i + w_i``, ``z_s`` its body
        acceleration's band-limited double integral at the profile's cutoff
        (:data:`.model.PROFILE_ONLINE_CUTOFF_RATIO` x ``observer.profile_cutoff_wavelength``,
        the speed floored at that ratio times :data:`.body_heave.SPEED_FLOOR_MPS`; restarted
        with each run); held at a stop (the distance stands still, the model's speed ``v``
        (m/s) below that floor)."""
        ddzs = op[10]
        if self._road_started:
            av = v if v > 0.0 else -v
            if body_heave.STANDING_MPS <= av < self._road_floor:
                av = self._road_floor       # (standing, below STANDING_MPS, it holds)
            h = self._road_state = body_heave.step(self._road_state, ddzs, dt, av,
                                                   self._wc_road)
            zs = h[-2]
        else:
            zs = 0.0
            self._road_state = body_heave.start(ddzs)
            self._road_started = True
            self._road_prev = (0.0, 0.0, math.nan)
            self._road_off = (0.0, 0.0)
        ssin = self._s * math.sin(op[2])
        u1 = zs + ssin - op[0] + op[15]
        u2 = zs - ssin - op[1] + op[16]
        p1, p2, px = self._road_prev
        self._road_prev = (u1, u2, x)
        o1, o2 = self._road_off
        if x == px and -body_heave.SPEED_FLOOR_MPS < v < body_heave.SPEED_FLOOR_MPS:
            # a stop: the distance stands still and the model's speed is below the body
            # heave's floor (a dropped-out speed that the deflections contradict keeps the
            # last trusted one, :mod:`.speed_check`); the road at one distance is one value:
            # what the estimate does then (the body heave's drift, or the integral's memory
            # of the rate before the stop) is no road
            o1 += u1 - p1
            o2 += u2 - p2
            self._road_off = (o1, o2)
        return u1 - o1, u2 - o2

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
