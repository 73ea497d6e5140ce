"""The model observer of the roll-plane model (``observer.discretization = 'model'``, the
default): a Kalman unknown-input observer on the paper's model, with an optional
sliding-mode injection (off by default, :mod:`.observer.online`).

The model (this module) and what is built on it: the gains (:mod:`.gains`, with
:mod:`.riccati` and :mod:`.noise`), the operating point they are designed at
(:mod:`.schedule`), the online observer (:mod:`.observer.online`) and the offline smoother
(:mod:`.smoother`).

The observer runs the linearised roll-plane model of MODEL.md (:mod:`.vehicle_model`) with the
unknown inputs (road, roll moment) as augmented states and corrects it with a linear output
injection (the steady-state Kalman gain). With ``observer.sliding_mode_gain`` > 0 it also runs
the Levant differentiator (:mod:`.differentiator`, implicit scheme) per message on the output
error that the linear injection leaves: its estimates of that error and of its rate and
acceleration are an equivalent output injection (an unknown tire force and roll moment),
weighted by the measured noise level. Loads, road and LTR come from the states; the same
observer gives a fixed-lag (``observer.latency``) and an offline (:func:`.smoother.smooth`)
estimate.

State (SI; :class:`State`; index 1/2 of MODEL.md = left/right)::

    x = [q_1, q_2, phi, dq_1, dq_2, dphi, dz_s, w_1, w_2, du_1, du_2, M_r]

``q_i`` the suspension extensions and ``phi`` the roll (the measured outputs, so ``C = [I 0]``),
``dz_s`` the body heave rate, ``w_i = u_i - z_ui`` the tire deflections, ``du_i`` the road
velocities under the tires and ``M_r`` an unknown roll moment (N m; ``M h a_y`` of an
unmeasured lateral acceleration, a cross wind ...). Equations (linear, phi small)::

    F_bi = -(k_i q_i + c_i dq_i)             dz_ui = dz_s +- s dphi - dq_i
    dd z_s = (F_b1 + F_b2) / M               dd phi = (s (F_b1 - F_b2) + M g h phi + M_r) / I_x
    dw_i = du_i - dz_ui                      dF_i = kt_i w_i + ct_i dw_i
    dd z_ui = (dF_i - F_bi) / m_i            dd q_i = dd z_s +- s dd phi - dd z_ui
    d du_i = -w_v du_i + xi_i                d M_r = eta

The body heave ``z_s`` and the road level ``u_i`` are not states: nothing measured tells their
absolute level (gravity and grades move body, wheels and road together), so the state has no
unobservable integrator and the Riccati equation is well posed down to tiny noise levels (one
mode, body and road rising together, is seen only through the road model's mean reversion: it
is the ``spectral radius ~ 1`` a design may show; no load depends on it). The profile is
rebuilt as the estimator's chain does (MODEL.md step 4): ``z_s`` is the band-limited double
integral of ``dd z_s`` (:mod:`.body_heave`), ``u_i = z_s +- s sin(phi) - q_i + w_i``; but from
the states of a second filter on the same model and data, tuned for the road (the PROFILE_*
constants, :func:`profile_scheduled`: at zero latency and offline; with a latency the load
filter's states), and with its own long-wave cutoff (:data:`PROFILE_CUTOFF_RATIO`); the body
heave published stays the load filter's at ``observer.profile_cutoff_wavelength``.

Friction and sensor lag (``vehicle.leaf_spring_friction``, ``vehicle.sensor_time_constant``)
-------------------------------------------------------------------------------------------
The leaf-spring friction ``f_i = -F_f,i tanh(dq_i / v_f)`` (``v_f`` =
``vehicle.leaf_spring_friction_velocity``; :mod:`.observer.friction`; the ``stick`` element:
its force from the measured ``q_i``, :mod:`.leaf_friction`) is added to ``F_bi``
as a known nonlinear input, evaluated on the estimated ``dq_i`` (in the filter's prediction
held over the step, the trapezoid of the previous sample's estimate and the step's end,
whose rate the updated state gives: one iterated update, :mod:`.observer.online`; the
estimate's own in its outputs): ``dx = A x + B_f f``, outputs ``H x + D_f f``
(:attr:`ContinuousModel.friction_b`, :attr:`ContinuousModel.friction_d`). A sensor lag is a
first-order state per lagged channel, ``tau dl_j = y_j - l_j``, appended after ``M_R``
(:attr:`ContinuousModel.lagged`); the sensors then measure ``l_j`` (``C``), the outputs stay
those of the unlagged quantities. Without friction and lag the model is the 12 states above.

Road model (the unknown input)
------------------------------
An ISO 8608 road has the displacement PSD ``Gd(n0) (n/n0)^-2``: its slope is white, with the
diffusion constant ``D = 2 pi^2 Gd(n0) n0^2`` (m^2/m), so in time at speed v the road velocity
is white with two-sided density ``D v``. The tire envelopes the road over its contact patch
(~0.25 m), which makes the velocity it feels continuous and correlated over about that
length: ``du_i`` is an Ornstein-Uhlenbeck process, white (density ``D v``) below
``w_v = 2 pi v / lambda_v`` and rolled off above. A generalised force noise on each equation
of motion stands for what the linear model misses (nonlinearity, parameter errors, the
envelope's exact shape), and ``M_r`` is a random walk (density scheduled on the noise level).
Gains: derived from the data, never tuned per drive
---------------------------------------------------
The model is discretized exactly at the sample step (matrix exponential, Van Loan for the
process noise); the gain is the steady-state Kalman gain of the discrete algebraic Riccati
equation (structured doubling, :func:`.riccati.solve_dare`; where double precision cannot give a
stabilising solution the noise is raised threefold until it can). Gains depend on the
operating point ``(dt, v, sigma_q, sigma_phi, Gd)``; each is tracked on a logarithmic grid
with hysteresis, which only decides *when* to design again: a design (a few ms) uses the
estimates of that moment and is cached, never per sample.

- ``dt``: each step's own transition matrix (cached per 0.1 % of dt) with the gain of its
  10 % level (a regular stream: one design at its exact step; irregular streams a few).
- ``v``: the speed input (10 % levels, floored at :data:`SPEED_FLOOR_MPS`).
- Sensor noise ``sigma``: ``observer.noise.deflection`` / ``observer.noise.roll`` when > 0, else
  estimated online per block of :data:`.model_core.BLOCK_SAMPLES` samples (the very first block:
  :data:`.model_core.FIRST_BLOCK_SAMPLES`) from the median absolute sixth (divided) difference of
  each channel (:func:`.noise.noise_std`): white noise has ``Var(Delta^6 y) = 924 sigma^2`` while a
  road-excited signal's sixth difference at the rates of interest is far below (measured: ~2 um of
  apparent noise at 200 Hz on ISO class C without noise, ~1 nm at 1 kHz), and the median makes it
  blind to events (pothole, step). The estimate is the median of the last
  :data:`.schedule.HISTORY_BLOCKS` blocks, the larger of the two deflections'; a floor of
  :data:`.gains.NOISE_FLOOR_M` (roll: that over s) keeps noise-free data well posed. After the very
  first block the run so far is filtered again with the new gains (no switching transient).
- Road roughness ``Gd(n0)``: ``observer.road_roughness`` when > 0, else estimated per block
  by moment matching: the robust (MAD) variance of the first difference of the deflections,
  minus the noise's ``2 sigma^2``, divided by the variance the model predicts per unit ``Gd``
  at that speed and step (stationary discrete Lyapunov solution, road velocity correlation
  :data:`ROUGHNESS_CORRELATION_M`); median of the last :data:`.schedule.ROUGHNESS_HISTORY_BLOCKS`
  blocks, floored at :data:`MIN_ROAD_GD_M3`. (The innovations cannot tell the roughness at
  high rates: the one-step prediction error is far below the sensor noise.)
- What the data cannot tell, the schedule on the noise level (:func:`scheduled`) sets: the
  force-noise density, the road velocity's correlation length (``observer.
  road_correlation_length`` when > 0) and the factor between the estimated roughness and the
  one the filter assumes, tuned once on the benchmark's separate tuning drive at 0, 10 and
  50 um (``python -m bench.accuracy.targets --tune``) and interpolated in between (log-log).
  Without noise the tuned road model is a near random walk of the road velocity (what a 1 ms
  prediction needs); with noise, the envelope's ~0.8 m correlation.
"""
from __future__ import annotations

import enum
import math

import numpy as np

from road_force_estimator.core.parameters import GRAVITY_MPS2, VehicleParameters
from road_force_estimator.estimation.models.protocol import (
    FORCE_PSD, ISO_N0, ROLL_MOMENT_PSD, ContinuousModel, road_diffusion)
# The speed floor of the model (m/s) is the body heave's: one floor for every speed-scheduled
# part of the estimate.
from road_force_estimator.estimation.body_heave import SPEED_FLOOR_MPS
from road_force_estimator.estimation.models.leaf_friction import (
    FRICTION_DAMPING_FACTOR, FRICTION_DAMPING_FACTOR_LATENCY, LeafSpringFriction,
    friction_damping)
from road_force_estimator.estimation.models.front_axle_rows import (
    PROFILE_CUTOFF_RATIO, PROFILE_ONLINE_CUTOFF_RATIO, OfflineRows, OnlineRows)

__all__ = [
    'State', 'NX', 'NY', 'OUTPUTS', 'NO', 'ISO_N0', 'SPEED_FLOOR_MPS', 'FORCE_PSD',
    'ROLL_MOMENT_PSD', 'SCHEDULE_NOISE_M', 'SCHEDULE_FORCE_PSD', 'SCHEDULE_CORRELATION_M',
    'SCHEDULE_GD_FACTOR', 'SCHEDULE_ROLL_MOMENT_PSD',
    'PROFILE_CUTOFF_RATIO', 'PROFILE_ONLINE_CUTOFF_RATIO', 'PROFILE_ONLINE_GD_RATIO',
    'PROFILE_ONLINE_CORRELATION_M',
    'PROFILE_OFFLINE_FORCE_PSD', 'PROFILE_OFFLINE_ROLL_MOMENT_PSD', 'PROFILE_OFFLINE_GD_RATIO',
    'PROFILE_OFFLINE_ROLL_MOMENT_MIN_PSD', 'ROLL_MOMENT_BLOCK_S', 'offline_roll_moment_psd',
    'profile_scheduled',
    'scheduled', 'road_diffusion', 'ContinuousModel', 'continuous_model', 'rest_state',
    'FRICTION_DAMPING_FACTOR', 'FRICTION_DAMPING_FACTOR_LATENCY', 'friction_damping',
    'STATE_SCALE', 'LOAD_OUTPUTS',
    'CHANNEL_NAMES', 'FRICTION_RATE_STATES', 'FRICTION_RATE_OUTPUTS', 'sm_lipschitz',
    'sm_injection', 'FrontAxleModel',
]

#: Settings scheduled on the deflection-noise level (m): at the levels of
#: SCHEDULE_NOISE_M the generalised force-noise density (N^2 s), the road velocity's
#: correlation length (m) and the factor on the estimated roughness that the filter assumes;
#: log-log interpolation in between, held beyond the ends (see :func:`scheduled`).
#: Tuned on bench.accuracy.scenarios.TUNING (ISO C, 20 m/s, 1 kHz, road seed 1001, noise seed 1002;
#: no scored drive) at 0, 10 and 50 um: ``python -m bench.accuracy.targets --tune`` (the procedure
#: of bench.accuracy.tune: grid, then pattern search, zero-latency load error as the objective; the
#: best of two runs per level, the command prints their scores; the optimum is flat: the other
#: run's values, e.g. 200 / 1.35 m / 3.4 at 10 um, give nearly the same). Without
#: noise the tuned road velocity is a near random walk (force noise and bound-limited
#: roughness factor: what a 1 ms prediction needs); with noise the envelope's correlation.
SCHEDULE_NOISE_M = (1e-9, 1e-5, 5e-5)
SCHEDULE_FORCE_PSD = (1e-8, 238.0, 800.0)
SCHEDULE_CORRELATION_M = (5.38, 0.8, 0.566)
SCHEDULE_GD_FACTOR = (1e4, 1.41, 1.41)
#: Random-walk density of the unknown roll moment ((N m)^2 / s), not tuned (the tuning drive
#: is straight): on clean data large enough to follow a lateral-acceleration step at once
#: (a 3 m/s^2 step on ISO C without noise: the load error falls from 1e6 to 1e7 and little
#: beyond), with noise the 1e7 that still follows ~1 m/s^2 per second of lateral acceleration
#: change (M h x 1 m/s^3 over ~1 s) and leaves the straight drives' figures as 1e6 does (1e9
#: would cost some). The benchmark's C20-lateral is that step with 10 um of noise, beside the
#: straight C20-1k-10um: ``python -m bench.accuracy.run_benchmark --scenarios C20-lateral
#: C20-1k-10um``.
SCHEDULE_ROLL_MOMENT_PSD = (1e9, 1e7, 1e7)

#: The profile's own tuning (issue 21): the road profile comes from a second filter on the same
#: model, the same data and the same noise and roughness estimates, designed for the road
#: instead of the load (the loads never see it). Measured on single benchmark scenarios
#: (``python -m bench.accuracy.run_benchmark --scenarios ...``): at zero latency the profile wants
#: a filter that trusts the deflections more than the load's does (a rougher road assumed:
#: less lag, which is what the band-passed profile error is made of; on A20-1k-10um and
#: C20-1k-10um it halves the profile error, where the load's error would nearly double),
#: offline the RTS smoother of a near-exact model (force noise tiny) with a slow unknown roll
#: moment: the load tuning's fast roll moment (1e7 (N m)^2/s) passes the roll sensor's noise
#: (s x 1e-4 rad = 100 um) into ``s sin(phi)`` at the wheel-hop wavelengths (1-3 m) that IRI
#: weighs.
#: Factor on the load schedule's roughness factor of the zero-latency profile filter (its
#: roll moment is the load's: with wrong parameters and no noise the roll moment takes what
#: the model misses, and a slower one lost the calibration's alignment, test_calibration).
PROFILE_ONLINE_GD_RATIO = 30.0
#: The zero-latency profile filter's road correlation length (m) at the levels of
#: SCHEDULE_NOISE_M (log-log in between, as :func:`scheduled`): the load's but without noise,
#: where the road wants a slower road velocity (D20-1k-0um a little better, C20-1k-0um a
#: little worse, both beside kf-model; measured with a 10 x cutoff, see below).
PROFILE_ONLINE_CORRELATION_M = (15.0, 0.8, 0.566)
#: Largest force-noise density (N^2 s) and roll-moment density ((N m)^2 / s) of the offline
#: profile smoother.
PROFILE_OFFLINE_FORCE_PSD = 1e-3
PROFILE_OFFLINE_ROLL_MOMENT_PSD = 1e6
PROFILE_OFFLINE_GD_RATIO = 1.0
#: The offline profile smoother's roll-moment density is the one the run's roll residual
#: shows (:func:`offline_roll_moment_psd`), within this floor and
#: PROFILE_OFFLINE_ROLL_MOMENT_PSD: a straight drive's roll moment hardly moves, and a slow
#: one keeps the roll sensor's noise out of ``s sin(phi)`` (the offline profile and IRI of
#: C10-1k-10um and C20-1k-50um better at 1e4 than at 1e6, beside kf-model-rts), while a
#: lateral-acceleration step needs the fast one (C20-lateral's profile); ``python -m
#: bench.accuracy.run_benchmark --scenarios C10-1k-10um C20-1k-50um C20-lateral``.
PROFILE_OFFLINE_ROLL_MOMENT_MIN_PSD = 1e4
#: Block (s) and the run's first and last blocks skipped (start-up) of that estimate.
ROLL_MOMENT_BLOCK_S = 1.0


class State(enum.IntEnum):
    """Slots of the observer's state (see the module notes)."""

    Q1 = 0
    Q2 = 1
    PHI = 2
    DQ1 = 3
    DQ2 = 4
    DPHI = 5
    DZ_S = 6
    W1 = 7
    W2 = 8
    DU1 = 9
    DU2 = 10
    M_R = 11


NX = len(State)
NY = 3
#: Linear outputs ``H x`` (rows), in this order.
OUTPUTS = ('q1', 'q2', 'phi', 'dq1', 'dq2', 'dphi', 'ddq1', 'ddq2', 'ddphi', 'dzs', 'ddzs',
           'dzu1', 'dzu2', 'ddzu1', 'ddzu2', 'w1', 'w2', 'df1', 'df2', 'fb1', 'fb2')
NO = len(OUTPUTS)


def scheduled(noise_deflection_m: float, *, roll_moment: bool = False):
    """(force PSD (N^2 s), road correlation length (m), roughness factor) at a deflection
    noise level (m): log-log interpolation of the SCHEDULE_* tables, held beyond the ends;
    with ``roll_moment``: the roll-moment density ((N m)^2 / s) too, as a fourth value."""
    x = math.log(max(noise_deflection_m, SCHEDULE_NOISE_M[0]))
    xs = [math.log(v) for v in SCHEDULE_NOISE_M]
    tables = [SCHEDULE_FORCE_PSD, SCHEDULE_CORRELATION_M, SCHEDULE_GD_FACTOR]
    if roll_moment:
        tables.append(SCHEDULE_ROLL_MOMENT_PSD)
    out = []
    for table in tables:
        ys = [math.log(v) for v in table]
        out.append(math.exp(float(np.interp(x, xs, ys))))
    return tuple(out)


def profile_scheduled(noise_deflection_m: float, mode: str):
    """(force PSD, road correlation length, roughness factor, roll-moment density) of the
    profile filter (mode ``'online'``: zero latency, ``'offline'``: the smoother) at a
    deflection-noise level (m): :func:`scheduled`'s values changed as the PROFILE_* constants
    say."""
    force, corr, gd, moment = scheduled(noise_deflection_m, roll_moment=True)
    if mode == 'online':
        x = math.log(max(noise_deflection_m, SCHEDULE_NOISE_M[0]))
        corr = math.exp(float(np.interp(x, [math.log(v) for v in SCHEDULE_NOISE_M],
                                        [math.log(v) for v in PROFILE_ONLINE_CORRELATION_M])))
        return force, corr, gd * PROFILE_ONLINE_GD_RATIO, moment
    if mode == 'offline':
        return (min(force, PROFILE_OFFLINE_FORCE_PSD), corr, gd * PROFILE_OFFLINE_GD_RATIO,
                min(moment, PROFILE_OFFLINE_ROLL_MOMENT_PSD))
    raise ValueError(f"mode = {mode!r}: 'online' or 'offline'")


def offline_roll_moment_psd(residual_nm, dt_s: float) -> float:
    """The random-walk density ((N m)^2 / s) of the unknown roll moment that a run's roll
    residual (MODEL.md step 9, ``M h a_y cos(phi)`` under a lateral acceleration; N m,
    evenly sampled at dt_s s) shows: 3 / 2 of the mean square change of its means over blocks
    of :data:`ROLL_MOMENT_BLOCK_S` per block (a random walk of density q changes its block
    means by ``2 q T / 3`` in the mean square; the first two blocks and the last skipped), within
    [:data:`PROFILE_OFFLINE_ROLL_MOMENT_MIN_PSD`, :data:`PROFILE_OFFLINE_ROLL_MOMENT_PSD`];
    the upper end when fewer than four blocks are left or the residual is not finite."""
    r = np.asarray(residual_nm, dtype=float)
    nb = max(1, int(round(ROLL_MOMENT_BLOCK_S / dt_s)))
    blocks = r[:r.size // nb * nb].reshape(-1, nb).mean(axis=1)[2:-1]
    if blocks.size < 4 or not np.all(np.isfinite(blocks)):
        return PROFILE_OFFLINE_ROLL_MOMENT_PSD
    psd = 1.5 * float(np.mean(np.square(np.diff(blocks)))) / ROLL_MOMENT_BLOCK_S
    return min(max(psd, PROFILE_OFFLINE_ROLL_MOMENT_MIN_PSD), PROFILE_OFFLINE_ROLL_MOMENT_PSD)


def continuous_model(vehicle: VehicleParameters, speed_mps: float, road_gd_m3: float, *,
                     correlation_length_m: float = 0.8, force_psd: float = FORCE_PSD,
                     roll_moment_psd: float = ROLL_MOMENT_PSD,
                     friction_damping_nspm: tuple = (0.0, 0.0)) -> ContinuousModel:
    """The augmented roll-plane model of the module notes at one speed and roughness.

    Parameters
    ----------
    vehicle : VehicleParameters
    speed_mps : float
        Speed (m/s); its magnitude is used, floored at :data:`SPEED_FLOOR_MPS`.
    road_gd_m3 : float
        ISO 8608 ``Gd(n0)`` (m^3) of the road.
    correlation_length_m : float
        ``lambda_v`` (m): the road velocity's correlation length.
    force_psd, roll_moment_psd : float
        Process-noise densities (N^2 s, (N m)^2 / s).
    friction_damping_nspm : (left, right)
        With leaf-spring friction: its equivalent damping c_eq,i (N s/m), carried in the linear
        part (:func:`friction_damping`); the known input is the rest.
    """
    v = vehicle
    mass, ix, s = v.sprung_mass_kg, v.roll_inertia_kgm2, v.half_track_m
    m, k, c = v.unsprung_mass_kg, v.suspension_stiffness_npm, v.suspension_damping_nspm
    friction = tuple(float(f) for f in v.leaf_spring_friction_n)
    ceq = tuple(float(d) for d in friction_damping_nspm) if any(friction) else (0.0, 0.0)
    if any(ceq):      # the friction's equivalent damping in the linear part
        c = tuple(ci + di for ci, di in zip(c, ceq))
    kt, ct = v.tire_stiffness_npm, v.tire_damping_nspm
    speed = max(abs(float(speed_mps)), SPEED_FLOOR_MPS)
    w_v = 2.0 * math.pi * speed / correlation_length_m
    sig = (1.0, -1.0)
    mgh = mass * GRAVITY_MPS2 * v.cg_height_m     # the gravity moment's stiffness (N m/rad)
    tau = (v.sensor_time_constant_s[0], v.sensor_time_constant_s[0],
           v.sensor_time_constant_s[1])
    lagged = tuple(j for j in range(NY) if tau[j] > 0.0)
    nx = NX + len(lagged)
    measured_slot = (State.Q1, State.Q2, State.PHI)

    def derivative(x, f=None):
        # The equations of the module notes, on the columns of x (exactly linear); f: the
        # friction forces' columns.
        q, dq = (x[State.Q1], x[State.Q2]), (x[State.DQ1], x[State.DQ2])
        fb = [-(k[i] * q[i] + c[i] * dq[i]) for i in range(2)]
        if f is not None:
            fb = [fb[i] + f[i] for i in range(2)]
        ddzs = (fb[0] + fb[1]) / mass
        ddphi = (s * (fb[0] - fb[1]) + mgh * x[State.PHI] + x[State.M_R]) / ix
        dzu = [x[State.DZ_S] + sig[i] * s * x[State.DPHI] - dq[i] for i in range(2)]
        w, du = (x[State.W1], x[State.W2]), (x[State.DU1], x[State.DU2])
        dw = [du[i] - dzu[i] for i in range(2)]
        df = [kt[i] * w[i] + ct[i] * dw[i] for i in range(2)]
        ddzu = [(df[i] - fb[i]) / m[i] for i in range(2)]
        ddq = [ddzs + sig[i] * s * ddphi - ddzu[i] for i in range(2)]
        dx = np.zeros_like(x)
        dx[State.Q1], dx[State.Q2], dx[State.PHI] = dq[0], dq[1], x[State.DPHI]
        dx[State.DQ1], dx[State.DQ2], dx[State.DPHI] = ddq[0], ddq[1], ddphi
        dx[State.DZ_S] = ddzs
        dx[State.W1], dx[State.W2] = dw[0], dw[1]
        dx[State.DU1], dx[State.DU2] = -w_v * du[0], -w_v * du[1]
        for n, j in enumerate(lagged):      # tau dl = y - l
            dx[NX + n] = (x[measured_slot[j]] - x[NX + n]) / tau[j]
        out = np.array([q[0], q[1], x[State.PHI], dq[0], dq[1], x[State.DPHI], ddq[0], ddq[1],
                        ddphi, x[State.DZ_S], ddzs, dzu[0], dzu[1], ddzu[0], ddzu[1], w[0],
                        w[1], df[0], df[1], fb[0], fb[1]])
        return dx, out

    a, h = derivative(np.eye(nx))
    g = _noise_inputs(v, nx)
    diffusion = road_diffusion(road_gd_m3) * speed
    qc = np.diag([force_psd, force_psd * s * s, force_psd, force_psd,
                  diffusion * w_v ** 2, diffusion * w_v ** 2, roll_moment_psd])
    cm = _measurement(nx, lagged)
    road_g = g[:, 4:6] * (math.sqrt(speed) * w_v)   # road input of unit diffusion D = 1 m^2/m
    fb_, fd_ = None, None
    if any(friction):
        zero = np.zeros((nx, 2))
        fb_, fd_ = derivative(zero, np.eye(2))
    return ContinuousModel(a, g, qc, cm, h, road_g, fb_, fd_, lagged, friction, ceq)


def _measurement(nx: int, lagged: tuple) -> np.ndarray:
    """C (3, nx): q_1, q_2, phi; a lagged sensor measures its lag state."""
    cm = np.zeros((NY, nx))
    cm[0, State.Q1] = cm[1, State.Q2] = cm[2, State.PHI] = 1.0
    for n, j in enumerate(lagged):
        cm[j] = 0.0
        cm[j, NX + n] = 1.0
    return cm


def _noise_inputs(v: VehicleParameters, nx: int) -> np.ndarray:
    """G (nx, 7): generalised forces (heave f_s: dd z_s += f_s / M; roll moment f_p; wheel
    forces f_ui), the road velocities' noise, the roll moment's random walk."""
    mass, ix, s, m = v.sprung_mass_kg, v.roll_inertia_kgm2, v.half_track_m, v.unsprung_mass_kg
    g = np.zeros((nx, 7))
    g[State.DZ_S, 0] = g[State.DQ1, 0] = g[State.DQ2, 0] = 1.0 / mass
    g[State.DPHI, 1] = 1.0 / ix
    g[State.DQ1, 1], g[State.DQ2, 1] = s / ix, -s / ix
    g[State.DQ1, 2] = -1.0 / m[0]
    g[State.DQ2, 3] = -1.0 / m[1]
    g[State.DU1, 4] = g[State.DU2, 5] = 1.0
    g[State.M_R, 6] = 1.0
    return g


def rest_state(vehicle: VehicleParameters, q1: float, q2: float, phi: float) -> np.ndarray:
    """The state at rest that reproduces a sample (m, m, rad): no acceleration.

    ``q`` and ``phi`` as measured (lag states too, when the sensors lag), every rate 0, the
    tire deflections that give the wheels the body's acceleration (so ``dd q = 0``) and the
    roll moment that holds the roll still.
    """
    v = vehicle
    s = v.half_track_m
    k1, k2 = v.suspension_stiffness_npm
    m1, m2 = v.unsprung_mass_kg
    kt1, kt2 = v.tire_stiffness_npm
    fb1, fb2 = -k1 * q1, -k2 * q2
    ddzs = (fb1 + fb2) / v.sprung_mass_kg
    tau = (v.sensor_time_constant_s[0], v.sensor_time_constant_s[0],
           v.sensor_time_constant_s[1])
    lag_values = [y for y, t in zip((q1, q2, phi), tau) if t > 0.0]
    x = np.zeros(NX + len(lag_values))
    x[NX:] = lag_values
    x[State.Q1], x[State.Q2], x[State.PHI] = q1, q2, phi
    x[State.W1] = (fb1 + m1 * ddzs) / kt1
    x[State.W2] = (fb2 + m2 * ddzs) / kt2
    x[State.M_R] = -s * (fb1 - fb2) - v.sprung_mass_kg * GRAVITY_MPS2 * v.cg_height_m * phi
    return x


#: Typical state magnitudes (m, rad, m/s, rad/s, N m) of :class:`State`, the Riccati
#: equation's scaling; a sensor's lag state as the measured ones (1e-2).
STATE_SCALE = np.array([1e-2, 1e-2, 1e-2, 1e-1, 1e-1, 1e-1, 1e-1, 1e-3, 1e-3, 1e-1, 1e-1, 1e3])
#: The measured channels, by the joint names of ``/suspension/deflections``.
CHANNEL_NAMES = ('left_suspension', 'right_suspension', 'roll')
#: The outputs of the dynamic tire forces (the loads): the settling time's.
LOAD_OUTPUTS = (OUTPUTS.index('df1'), OUTPUTS.index('df2'))
#: The rates of the friction elements (left, right spring): their states and outputs.
FRICTION_RATE_STATES = (int(State.DQ1), int(State.DQ2))
FRICTION_RATE_OUTPUTS = (OUTPUTS.index('dq1'), OUTPUTS.index('dq2'))


def sm_lipschitz(vehicle: VehicleParameters) -> tuple[float, float]:
    """L of the sliding-mode differentiator on the output error (m/s^3, rad/s^3).

    The output error's third derivative is what the model cannot predict of ``dddq``: the
    rate of the tire force it misses over m, bounded by a tire-deflection rate of 1 m/s
    (``kt / m`` x 1 m/s), and its roll counterpart over the half track.
    """
    v = vehicle
    lq = max(kt / m for kt, m in zip(v.tire_stiffness_npm, v.unsprung_mass_kg)) * 1.0  # m/s
    return lq, lq / v.half_track_m


def sm_injection(vehicle: VehicleParameters, nx: int = NX) -> np.ndarray:
    """T (nx, 9): the state correction of the sliding-mode estimates ``rho``.

    ``rho = (e, de, dde)`` per output channel (q_1, q_2, phi) of the output error: ``e`` and
    ``de`` correct the output and its rate; ``dde``, the output acceleration the model did not
    explain, is an unknown roll moment ``I_x dde_phi`` and tire forces: the wheel must take
    ``dd z_ui = -(dde_i -+ s dde_phi)``, i.e. ``w_i += -m_i (dde_i -+ s dde_phi) / kt_i``.
    """
    v = vehicle
    s = v.half_track_m
    m1, m2 = v.unsprung_mass_kg
    kt1, kt2 = v.tire_stiffness_npm
    t = np.zeros((nx, 9))
    for ch, (pos, rate) in enumerate(((State.Q1, State.DQ1), (State.Q2, State.DQ2),
                                      (State.PHI, State.DPHI))):
        t[pos, 3 * ch] = 1.0
        t[rate, 3 * ch + 1] = 1.0
    t[State.W1, 2] = -m1 / kt1
    t[State.W1, 8] = m1 * s / kt1
    t[State.W2, 5] = -m2 / kt2
    t[State.W2, 8] = -m2 * s / kt2
    t[State.M_R, 8] = v.roll_inertia_kgm2
    return t


class FrontAxleModel(LeafSpringFriction):
    """MODEL.md's roll-plane front axle as the observer's vehicle model
    (:class:`.protocol.VehicleModel`): the functions of this module bound to one
    :class:`VehicleParameters`.

    Channels ``y = (q_1, q_2, phi)`` (deflections 0, 1; roll 2); the state and outputs of
    the module notes; the leaf-spring friction of each spring a known input; the rows of
    :class:`.outputs.Column` (:mod:`.front_axle_rows`).
    """

    outputs = OUTPUTS
    #: the channels' names (INTERFACES.md's joint names of /suspension/deflections)
    channel_names = CHANNEL_NAMES
    #: the states of the body's heave and roll rates (:mod:`..sensor_health`'s momentum)
    momentum_states = (State.DZ_S, State.DPHI)
    #: channels the filter can do without (a stuck sensor left out): every one. A stuck roll
    #: sensor left out costs almost nothing over 30 s (the roll moment's model carries the
    #: roll; ``python -m bench.studies.sensor_faults --only latency``), fed it cost 4-15 x
    droppable_channels = (0, 1, 2)
    deflection_channels = (0, 1)
    roll_channels = (2,)
    load_outputs = LOAD_OUTPUTS
    friction_rate_states = FRICTION_RATE_STATES
    friction_rate_outputs = FRICTION_RATE_OUTPUTS
    #: each spring's deflection channel and sign (the channels read q_1, q_2)
    friction_channels = ((0, 1.0), (1, 1.0))

    def __init__(self, vehicle: VehicleParameters | None = None) -> None:
        self.vehicle = VehicleParameters() if vehicle is None else vehicle
        #: the friction elements' F_f (N), left and right spring, and the tanh law's v_f (m/s,
        #: ``vehicle.leaf_spring_friction_velocity``); the ``stick`` element's k_f (N/m)
        #: (:class:`.leaf_friction.LeafSpringFriction`)
        v = self.vehicle
        self.friction_n = tuple(float(f) for f in v.leaf_spring_friction_n)
        self.friction_velocity_mps = float(v.leaf_spring_friction_velocity_mps)
        self.friction_model = v.leaf_spring_friction_model
        self.stick_stiffness_npm = tuple(v.leaf_spring_friction_stiffness_ratio * float(k)
                                         for k in v.suspension_stiffness_npm)

    def with_vehicle(self, vehicle: VehicleParameters) -> FrontAxleModel:
        """The model of other parameters (an estimated sprung mass)."""
        return FrontAxleModel(vehicle)

    # -- design ----------------------------------------------------------------------------
    def continuous(self, speed_mps: float, road_gd_m3: float, **kwargs) -> ContinuousModel:
        """:func:`continuous_model` of this vehicle."""
        return continuous_model(self.vehicle, speed_mps, road_gd_m3, **kwargs)

    @staticmethod
    def measurement_variances(noise_deflection_m: float, noise_roll_rad: float) -> list:
        """``diag(R)`` (m^2, m^2, rad^2)."""
        return [noise_deflection_m * noise_deflection_m, noise_deflection_m * noise_deflection_m,
                noise_roll_rad * noise_roll_rad]

    def roll_noise_floor(self, deflection_floor_m: float) -> float:
        """The roll's noise floor (rad): the deflection's over the half track."""
        return deflection_floor_m / self.vehicle.half_track_m

    @staticmethod
    def state_scale(nx: int) -> np.ndarray:
        """:data:`STATE_SCALE`, with a lag state (m, rad) per lagged sensor."""
        return np.concatenate([STATE_SCALE, np.full(nx - NX, 1e-2)])

    def rest_state(self, y) -> np.ndarray:
        """:func:`rest_state` of one measurement ``(q_1, q_2, phi)``."""
        return rest_state(self.vehicle, y[0], y[1], y[2])

    def sm_injection(self, nx: int) -> np.ndarray:
        """:func:`sm_injection` of this vehicle."""
        return sm_injection(self.vehicle, nx)

    def sm_lipschitz(self) -> tuple[float, float, float]:
        """L per channel (m/s^3, m/s^3, rad/s^3): :func:`sm_lipschitz`."""
        lq, lr = sm_lipschitz(self.vehicle)
        return lq, lq, lr

    @staticmethod
    def stationary_states(cm: ContinuousModel) -> list[int]:
        """The states whose variance the roughness's moment matching solves for: all but the
        roll (it follows the road's cross level, a random walk: nothing depends on it), the
        roll moment (a random walk the road does not drive) and the roll sensor's lag state
        (it follows the roll)."""
        drop = {State.PHI, State.M_R, cm.measured[2]}
        return [j for j in range(cm.nx) if j not in drop]

    # -- tuning ----------------------------------------------------------------------------
    @staticmethod
    def scheduled(noise_deflection_m: float, *, roll_moment: bool = False) -> tuple:
        """:func:`scheduled`."""
        return scheduled(noise_deflection_m, roll_moment=roll_moment)

    @staticmethod
    def profile_scheduled(noise_deflection_m: float, mode: str) -> tuple:
        """:func:`profile_scheduled`."""
        return profile_scheduled(noise_deflection_m, mode)

    # -- reconstruction --------------------------------------------------------------------
    def online_rows(self, observer) -> OnlineRows:
        """The rows of :class:`.outputs.Column`, sample by sample
        (:class:`.front_axle_rows.OnlineRows`)."""
        return OnlineRows(self.vehicle, observer)

    def offline_rows(self, observer) -> OfflineRows:
        """The rows of :class:`.outputs.Column` of smoothed runs
        (:class:`.front_axle_rows.OfflineRows`, with :func:`offline_roll_moment_psd`)."""
        return OfflineRows(self.vehicle, observer, OUTPUTS, offline_roll_moment_psd)
