"""The model observer of the roll-plane model (``observer.discretization = 'model'``, the
default): a Kalman unknown-input observer on the paper's model, with an optional
sliding-mode injection (off by default, :mod:`.model_core`).

The model (this module) and what is built on it: the gains (:mod:`.gains`, with
:mod:`.riccati` and :mod:`.noise`), the operating point they are designed at
(:mod:`.schedule`), the online observer (:mod:`.model_core`) and the offline smoother
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
The leaf-spring friction ``f_i = -F_f,i tanh(dq_i / v_f)`` (:func:`.vehicle_model.
friction_force`) is added to ``F_bi`` as a known nonlinear input, evaluated on the estimated
``dq_i`` (in the filter's prediction held over the step, the trapezoid of the previous
sample's estimate and the step's end, whose rate the updated state gives: one iterated
update, :mod:`.model_core`; the estimate's own in its outputs): ``dx = A x + B_f f``,
outputs ``H x + D_f f``
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
  50 um (``python -m bench.targets --tune``) and interpolated in between (log-log). Without
  noise the tuned road model is a near random walk of the road velocity (what a 1 ms
  prediction needs); with noise, the envelope's ~0.8 m correlation.
"""
from __future__ import annotations

from dataclasses import dataclass
import enum
import math

import numpy as np

from road_force_estimator.core.parameters import GRAVITY_MPS2, VehicleParameters
# The speed floor of the model (m/s) is the body heave's: one floor for every speed-scheduled
# part of the estimate.
from road_force_estimator.estimation.body_heave import SPEED_FLOOR_MPS

__all__ = [
    'State', 'NX', 'NY', 'OUTPUTS', 'NO', 'ISO_N0', 'SPEED_FLOOR_MPS', 'FORCE_PSD',
    'ROLL_MOMENT_PSD', 'SCHEDULE_NOISE_M', 'SCHEDULE_FORCE_PSD', 'SCHEDULE_CORRELATION_M',
    'SCHEDULE_GD_FACTOR', 'SCHEDULE_ROLL_MOMENT_PSD', 'ROUGHNESS_CORRELATION_M',
    'DEFAULT_NOISE_M', 'DEFAULT_NOISE_RAD', 'DEFAULT_ROAD_GD_M3', 'MIN_ROAD_GD_M3',
    'PROFILE_CUTOFF_RATIO', 'PROFILE_ONLINE_CUTOFF_RATIO', 'PROFILE_ONLINE_GD_RATIO',
    'PROFILE_ONLINE_CORRELATION_M',
    'PROFILE_OFFLINE_FORCE_PSD', 'PROFILE_OFFLINE_ROLL_MOMENT_PSD', 'PROFILE_OFFLINE_GD_RATIO',
    'PROFILE_OFFLINE_ROLL_MOMENT_MIN_PSD', 'ROLL_MOMENT_BLOCK_S', 'offline_roll_moment_psd',
    'profile_scheduled',
    'scheduled', 'road_diffusion', 'ContinuousModel', 'continuous_model', 'rest_state',
    'FRICTION_DAMPING_FACTOR', 'DEFAULT_DQ_STD_MPS', 'friction_damping',
]

#: Reference spatial frequency of ISO 8608 (cycles/m).
ISO_N0 = 0.1
#: Defaults of :func:`continuous_model` / :func:`.gains.design` (the observer uses the schedule):
#: generalised force noise density on each equation of motion (N^2 s; roll: times s^2) and
#: random-walk density of the unknown roll moment ((N m)^2 / s).
FORCE_PSD = 1.0
ROLL_MOMENT_PSD = 1e7
#: Settings scheduled on the deflection-noise level (m): at the levels of
#: SCHEDULE_NOISE_M the generalised force-noise density (N^2 s), the road velocity's
#: correlation length (m) and the factor on the estimated roughness that the filter assumes;
#: log-log interpolation in between, held beyond the ends (see :func:`scheduled`).
#: Tuned on bench.scenarios.TUNING (ISO C, 20 m/s, 1 kHz, road seed 1001, noise seed 1002;
#: no scored drive) at 0, 10 and 50 um: ``python -m bench.targets --tune`` (the procedure of
#: bench.tune: grid, then pattern search, zero-latency load error as the objective; the best
#: of two runs per level: 0.511 %, 17.08 %, 29.54 % on that drive; the optimum is flat: the
#: other run's values, e.g. 200 / 1.35 m / 3.4 at 10 um, give the same to 0.2 %). Without
#: noise the tuned road velocity is a near random walk (force noise and bound-limited
#: roughness factor: what a 1 ms prediction needs); with noise the envelope's correlation.
SCHEDULE_NOISE_M = (1e-9, 1e-5, 5e-5)
SCHEDULE_FORCE_PSD = (1e-8, 238.0, 800.0)
SCHEDULE_CORRELATION_M = (5.38, 0.8, 0.566)
SCHEDULE_GD_FACTOR = (1e4, 1.41, 1.41)
#: Random-walk density of the unknown roll moment ((N m)^2 / s), not tuned (the tuning drive
#: is straight): on clean data large enough to follow a lateral-acceleration step at once
#: (3 m/s^2 step, ISO C, no noise: load error 2.2 % with 1e6, 0.54 % with 1e7, 0.39 % with
#: 1e9), with noise the 1e7 that still follows ~1 m/s^2 per second of lateral acceleration
#: change (M h x 1 m/s^3 over ~1 s) and leaves the straight-drive figures unchanged (10 um:
#: 16.807 % against 16.804 % with 1e6; 1e9 would cost 2.7 %).
SCHEDULE_ROLL_MOMENT_PSD = (1e9, 1e7, 1e7)
#: Correlation length (m) of the road model whose variance the roughness estimate matches:
#: a moving average of 0.25 m (the tire envelope) over a Brownian road has the variance of
#: an Ornstein-Uhlenbeck velocity with this length (pi x 0.25 m).
ROUGHNESS_CORRELATION_M = 0.8
#: Noise and roughness assumed until the first block of data has been seen.
DEFAULT_NOISE_M = 1e-5
DEFAULT_NOISE_RAD = 1e-4
DEFAULT_ROAD_GD_M3 = 256e-6
#: Floor of the estimated roughness (m^3): a quarter of ISO class A's Gd(n0), so that a
#: glass-smooth stretch does not make the observer too slow for the next bump.
MIN_ROAD_GD_M3 = 4e-6

#: The profile's own tuning (issue 21): the road profile comes from a second filter on the same
#: model, the same data and the same noise and roughness estimates, designed for the road
#: instead of the load (the loads never see it). Measured on single benchmark scenarios
#: (``python -m bench.run_benchmark --scenarios ...``): at zero latency the profile wants a
#: filter that trusts the deflections more than the load's does (a rougher road assumed:
#: less lag, which is what the band-passed profile error is made of; A20-1k-10um 13.8 % ->
#: 6.5 %, C20-1k-10um 6.7 -> 2.9, while the load would be 27 -> 50 %), offline the RTS
#: smoother of a near-exact model (force noise tiny) with a slow unknown roll moment: the
#: load tuning's fast roll moment (1e7 (N m)^2/s) passes the roll sensor's noise (s x 1e-4
#: rad = 100 um) into ``s sin(phi)`` at the wheel-hop wavelengths (1-3 m) that IRI weighs.
#: Factor on the load schedule's roughness factor of the zero-latency profile filter (its
#: roll moment is the load's: with wrong parameters and no noise the roll moment takes what
#: the model misses, and a slower one lost the calibration's alignment, test_calibration).
PROFILE_ONLINE_GD_RATIO = 30.0
#: The zero-latency profile filter's road correlation length (m) at the levels of
#: SCHEDULE_NOISE_M (log-log in between, as :func:`scheduled`): the load's but without noise,
#: where the road wants a slower road velocity (D20-1k-0um 0.645 % -> 0.634 %, C20-1k-0um
#: 0.148 -> 0.157; kf-model: 0.637 and 0.162; measured with a 10 x cutoff, see below).
PROFILE_ONLINE_CORRELATION_M = (15.0, 0.8, 0.566)
#: Largest force-noise density (N^2 s) and roll-moment density ((N m)^2 / s) of the offline
#: profile smoother.
PROFILE_OFFLINE_FORCE_PSD = 1e-3
PROFILE_OFFLINE_ROLL_MOMENT_PSD = 1e6
PROFILE_OFFLINE_GD_RATIO = 1.0
#: The offline profile smoother's roll-moment density is the one the run's roll residual
#: shows (:func:`offline_roll_moment_psd`), within this floor and
#: PROFILE_OFFLINE_ROLL_MOMENT_PSD: a straight drive's roll moment hardly moves, and a slow
#: one keeps the roll sensor's noise out of ``s sin(phi)`` (offline profile / IRI per 100 m
#: at 1e4 against 1e6: C10-1k-10um 0.131 / 0.0062 % against 0.147 / 0.0198, C20-1k-50um
#: 1.73 / 0.055 against 1.77 / 0.064; kf-model-rts 0.1465 / 0.0195 and 1.75 / 0.060), while a
#: lateral-acceleration step needs the fast one (C20-lateral profile 1.12 % at 1e4, 0.515 at
#: 1e6, the peer 0.516).
PROFILE_OFFLINE_ROLL_MOMENT_MIN_PSD = 1e4
#: Block (s) and the run's first and last blocks skipped (start-up) of that estimate.
ROLL_MOMENT_BLOCK_S = 1.0
#: The profile's long-wave cutoff (m) is this many times ``observer.profile_cutoff_wavelength``
#: (the body heave's, MODEL.md step 4): the profile's judges see longer waves than the body
#: heave needs (the 0.5-30 m band-pass of order 2 passes 0.8 % at 100 m, where the ISO road's
#: amplitude is ten times that at 10 m; the body heave's 100 m cutoff alone cost 0.34 % of
#: profile error on the noise-free C20-1k-0um: 0.0041 % at 10 km). Longer cutoffs let the
#: double integral's low-frequency error and the zero-phase filter's edges wander further (on
#: a 120 m run after a stale stretch, test_speed_check, true road within 5 cm: 6.6 m at 30 x),
#: so the smoother takes the run's least-squares cubic off (:mod:`.smoother`): then 0.05 m, and
#: C20-1k-0um 0.0039 %.
PROFILE_CUTOFF_RATIO = 100.0
#: The same for the zero-latency profile, whose causal integral follows the speed with a floor
#: of this ratio times the body heave's (1 m/s; never below the body heave's cutoff frequency
#: at its floor). The causal integral wanders further than the zero-phase one (largest |u| on
#: test_speed_check's drive: 0.43 m at 1 x, 0.81 m at 2 x, 1.19 m at 3 x, 2.8 m at 10 x);
#: the profile error on C20-1k-0um: 0.20 % at 2 x, 0.16 % at 10 x (the load filter's road:
#: 0.85 %); 2 x gives 1.03 m after a stale stretch (test_speed_check): 1.
PROFILE_ONLINE_CUTOFF_RATIO = 1.0


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


def road_diffusion(gd_n0_m3: float) -> float:
    """Diffusion constant D (m^2/m) of a Brownian road with ISO 8608 ``Gd(n0)`` (m^3).

    ``Var[u(x + dx) - u(x)] = D dx`` gives the one-sided PSD ``D / (2 pi^2 n^2)``, hence
    ``D = 2 pi^2 Gd(n0) n0^2``.
    """
    return 2.0 * math.pi ** 2 * gd_n0_m3 * ISO_N0 ** 2


@dataclass(frozen=True)
class ContinuousModel:
    """``dx = A x dt + G dW`` (``E[dW dW^T] = Q dt``), ``y = C x``, linear outputs ``H x``."""

    a: np.ndarray     #: (nx, nx); nx = 12 + the lagged channels
    g: np.ndarray     #: (nx, 7): force noise (heave, roll, wheel 1, wheel 2), road 1, 2, moment
    q: np.ndarray     #: (7, 7) densities
    c: np.ndarray     #: (3, nx)
    h: np.ndarray     #: (21, nx), rows :data:`OUTPUTS`
    road_g: np.ndarray  #: (nx, 2) road-noise input columns (unit density), for moment matching
    #: (nx, 2): dx/dt per newton of friction force on side i (added to F_bi)
    friction_b: np.ndarray | None = None
    #: (21, 2): the outputs' direct part per newton of friction force
    friction_d: np.ndarray | None = None
    #: the lagged channels (0 = q_1, 1 = q_2, 2 = phi), their states at NX, NX + 1, ...
    lagged: tuple = ()
    #: the leaf-spring friction F_f,i (N) [left, right]
    friction_n: tuple = (0.0, 0.0)
    #: the friction's equivalent damping c_eq,i (N s/m) in the linear part (the known input
    #: is then the rest, ``-F_f tanh(dq / v_f) + c_eq dq``)
    friction_damping_nspm: tuple = (0.0, 0.0)

    @property
    def nx(self) -> int:
        """Number of states."""
        return self.a.shape[0]

    @property
    def measured(self) -> tuple[int, int, int]:
        """The state measured by each channel (q_1, q_2, phi)."""
        return tuple(int(np.argmax(row)) for row in self.c)


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


#: Equivalent damping of the friction (:func:`friction_damping`): the factor on the
#: statistical linearisation, tuned on bench/truck_effects.py (classes A and C, 20 m/s,
#: 10 um, 1.5 kN; 10 ms load error on A / C: 9.25 / 4.06 % with 1, 8.59 / 3.97 % with 1.5,
#: 9.55 / 3.96 % with 2, 17.65 / 4.11 % with 3).
FRICTION_DAMPING_FACTOR = 1.5
#: The same factor with a latency (``observer.latency`` > 0), where the friction of every
#: step is evaluated again at the smoothed rates (:mod:`.model_friction`, "Delayed
#: correction"): the forward filter's friction errors are then corrected, and the error
#: dynamics want less of the damping they would add (``python -m bench.friction_lag``, 10 ms,
#: friction + 3 ms lag: 1.37 x the matched drive with 1.5, 1.30 with 1.0, 1.28 with 0.5).
FRICTION_DAMPING_FACTOR_LATENCY = 0.5
#: RMS suspension rate (m/s) assumed until the first block of data has been seen.
DEFAULT_DQ_STD_MPS = 0.05


def friction_damping(friction_n, dq_std_mps: float,
                     factor: float | None = None) -> tuple[float, float]:
    """The friction's equivalent damping c_eq,i (N s/m) at an RMS suspension rate (m/s).

    Statistical linearisation of ``-F_f tanh(dq / v_f)`` over a Gaussian dq of std sigma:
    ``E[d f / d dq] ~ F_f sqrt(2 / pi) / sqrt(sigma^2 + 2 v_f^2 / pi)`` (``F_f / v_f`` at
    sigma = 0, ``F_f sqrt(2 / pi) / sigma`` for sigma >> v_f), times
    ``factor`` (default :data:`FRICTION_DAMPING_FACTOR`). The gains are designed with it; the
    friction itself stays the known input, so it changes the gains, not the model.
    """
    from road_force_estimator.core.vehicle_model import FRICTION_VELOCITY_MPS as v_f
    if factor is None:
        factor = FRICTION_DAMPING_FACTOR
    scale = factor * math.sqrt(2.0 / math.pi) / math.sqrt(
        dq_std_mps ** 2 + 2.0 * v_f ** 2 / math.pi)
    return tuple(float(f) * scale for f in friction_n)


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
