"""Competitors ("peers") of the benchmark: what a capable user would do instead of our observer.

Every peer is a function ``peer(t_s, q_m, roll_rad, speed_mps, vehicle, **tuning)`` that takes
the measurements (uniformly sampled time ``t_s`` (n,) in s, measured suspension deflections
``q_m`` (n, 2) in m, measured roll ``roll_rad`` (n,) in rad, speed in m/s, scalar or (n,)), the
vehicle parameters the *observer* believes (:class:`VehicleParameters`) and its tuning knobs,
and returns a :class:`PeerResult`: vertical wheel loads, road profile (long waves drift: the
benchmark band-passes it), load transfer ratio. Row ``j`` of every array is the estimate *for
sample j*; ``latency_samples`` says how many samples later it was available (0 = causal,
``L`` = fixed-lag smoother, ``-1`` = offline, the whole record).

Peers (:data:`PEERS`):

``paper-euler``
    The paper's chain: the package's estimator with ``observer.discretization = 'euler'``.
``lowpass-fd``
    Causal Butterworth low-pass + backward differences, then :func:`reconstruct`.
``kf-jerk``
    Causal Kalman filter per channel with an integrated-random-walk (constant-jerk) model, then
    :func:`reconstruct`.
``zero-phase-offline``
    Zero-phase Butterworth (``sosfiltfilt``) + central differences, then :func:`reconstruct`.
``kf-model``, ``kf-model-lag5ms``, ``kf-model-lag10ms``, ``kf-model-rts``
    A Kalman filter on the linearised roll-plane model of MODEL.md with the road elevations as
    augmented (slightly leaky) random-walk states, its exact fixed-lag smoother and its exact
    Rauch-Tung-Striebel smoother. Loads come from the state:
    ``dF_i = kt_i (u_i - z_ui) + ct_i (du_i - dz_ui)``.

The Kalman filters run with the steady-state (converged) covariance from the first sample on,
i.e. they are the exact Kalman filter / smoothers for a prior whose covariance is the
stationary one; the gains are constant, so the filters are fast linear recursions.

Signs and axes as in MODEL.md (REP-103; phi > 0 when the left side goes up; index 0 = left).
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import Any, Callable

import numpy as np
from scipy import linalg, signal

from road_force_estimator.core.parameters import GRAVITY_MPS2, VehicleParameters
from road_force_estimator.estimation.observer.riccati import van_loan

__all__ = [
    'PeerResult', 'reconstruct', 'paper_euler', 'lowpass_fd', 'kf_jerk', 'zero_phase_offline',
    'lowpass_differences', 'zero_phase_differences',
    'kf_model', 'kf_model_lag', 'kf_model_rts', 'RollPlaneKalman', 'SteadyStateKalman', 'PEERS',
    'DEFAULT_TUNING', 'USES_SENSOR_NOISE', 'call_peer', 'iso_road_diffusion', 'van_loan',
    'filter_riccati',
]

#: Reference spatial frequency of ISO 8608 (cycles/m).
ISO_N0 = 0.1
#: Largest measurement-noise floor the Kalman peers raise their floor to (m), see
#: :class:`RollPlaneKalman`.
MAX_NOISE_FLOOR_M = 1e-6


@dataclass
class PeerResult:
    """What a peer returns; row j of every array is the estimate for sample j.

    Attributes
    ----------
    wheel_load_n : (n, 2) vertical wheel loads F_n (N), [left, right].
    road_m : (n, 2) road elevation under each tire (m); long waves may drift.
    ltr : (n,) load transfer ratio (F_n2 - F_n1) / (F_n1 + F_n2).
    distance_m : (n,) travelled distance (m), integral of the speed.
    latency_samples : 0 causal, L > 0 fixed lag, -1 offline (non-causal over the record).
    extra : anything else worth inspecting (intermediate signals).
    """

    wheel_load_n: np.ndarray
    road_m: np.ndarray
    ltr: np.ndarray
    distance_m: np.ndarray
    latency_samples: int = 0
    extra: dict[str, Any] = field(default_factory=dict)


# ----------------------------------------------------------------------------------------------
# helpers


def _inputs(t_s, q_m, roll_rad, speed_mps):
    t_s = np.asarray(t_s, dtype=float)
    q_m = np.asarray(q_m, dtype=float)
    roll_rad = np.asarray(roll_rad, dtype=float)
    n = t_s.shape[0]
    if t_s.ndim != 1 or n < 3:
        raise ValueError(f't_s: expected shape (n,) with n >= 3, got {t_s.shape}')
    if q_m.shape != (n, 2):
        raise ValueError(f'q_m: expected shape ({n}, 2), got {q_m.shape}')
    if roll_rad.shape != (n,):
        raise ValueError(f'roll_rad: expected shape ({n},), got {roll_rad.shape}')
    speed = np.broadcast_to(np.asarray(speed_mps, dtype=float), (n,)).copy()
    dt = np.diff(t_s)
    dt_s = float(np.median(dt))
    if not dt_s > 0 or np.max(np.abs(dt - dt_s)) > 1e-6 * dt_s + 1e-12:
        raise ValueError('t_s: the peers need uniformly sampled, increasing time stamps')
    return t_s, q_m, roll_rad, speed, dt_s


def _distance(t_s: np.ndarray, speed: np.ndarray) -> np.ndarray:
    d = np.zeros_like(t_s)
    d[1:] = np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(t_s))
    return d


def _ltr(wheel_load_n: np.ndarray) -> np.ndarray:
    total = wheel_load_n.sum(axis=1)
    with np.errstate(divide='ignore', invalid='ignore'):
        ltr = (wheel_load_n[:, 1] - wheel_load_n[:, 0]) / total
    return np.where(np.abs(total) > 0, ltr, 0.0)


def iso_road_diffusion(gd_n0_m3: float, n0_cpm: float = ISO_N0) -> float:
    """Diffusion constant D (m^2/m) of a random-walk road with ISO 8608 PSD Gd(n0) (n/n0)^-2.

    A Brownian road, ``Var[u(x + dx) - u(x)] = D dx``, has the one-sided displacement PSD
    ``D / (2 pi^2 n^2)``, hence ``D = 2 pi^2 Gd(n0) n0^2``; in time at speed v the road
    velocity is white with two-sided spectral density ``D v`` (m^2/s).
    """
    return 2.0 * math.pi ** 2 * gd_n0_m3 * n0_cpm ** 2


def _run_lti(f: np.ndarray, drive: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """x_k = F x_{k-1} + drive_k for k = 0..n-1 with x_{-1} = x0; returns (n, nx)."""
    n, nx = drive.shape
    out = np.empty((n, nx))
    x = np.asarray(x0, dtype=float).copy()
    ft = np.ascontiguousarray(f.T)
    for k in range(n):
        x = x @ ft
        x += drive[k]
        out[k] = x
    return out


def _run_lti_backward(g: np.ndarray, drive: np.ndarray, x_last: np.ndarray) -> np.ndarray:
    """x_k = G x_{k+1} + drive_k for k = n-2..0 with x_{n-1} = x_last; returns (n, nx)."""
    n, nx = drive.shape
    out = np.empty((n, nx))
    out[-1] = x_last
    x = np.asarray(x_last, dtype=float).copy()
    gt = np.ascontiguousarray(g.T)
    for k in range(n - 2, -1, -1):
        x = x @ gt
        x += drive[k]
        out[k] = x
    return out


# ----------------------------------------------------------------------------------------------
# the MODEL.md reconstruction (steps 1-9), shared by the signal-processing peers


def reconstruct(t_s: np.ndarray, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray,
                phi: np.ndarray, dphi: np.ndarray, ddphi: np.ndarray, speed_mps,
                vehicle: VehicleParameters, *, cutoff_wavelength_m: float = 100.0,
                min_cutoff_hz: float = 0.01, zero_phase: bool = False,
                latency_samples: int = 0) -> PeerResult:
    """MODEL.md reconstruction from the deflections and roll and their first two derivatives.

    Parameters
    ----------
    t_s : (n,) uniform sample times (s).
    q, dq, ddq : (n, 2) deflections (m), rates (m/s), accelerations (m/s^2), [left, right].
    phi, dphi, ddphi : (n,) roll (rad, > 0 left up) and its rates (rad/s, rad/s^2).
    speed_mps : scalar or (n,) speed (m/s).
    vehicle : the parameters the observer believes.
    cutoff_wavelength_m : cutoff of the leaky double integration of the body heave (step 4),
        applied as a second-order (Butterworth-damped) high-pass at ``v / lambda_c`` Hz
        (mean speed; floor ``min_cutoff_hz``).
    zero_phase : False: causal leaky double integrator (bilinear transform of
        ``1 / (s^2 + sqrt(2) w s + w^2)``). True (offline): trapezoidal double integration,
        linear detrend, then the same high-pass run forward and backward (no phase error).

    Returns
    -------
    PeerResult
        Loads (steps 1-3, drift-free), road (steps 4-6), distance (7), LTR (8); ``extra``
        holds the body and wheel accelerations and the roll residual (step 9).
    """
    t_s = np.asarray(t_s, dtype=float)
    n = t_s.shape[0]
    speed = np.broadcast_to(np.asarray(speed_mps, dtype=float), (n,))
    dt_s = float(np.median(np.diff(t_s)))
    s = vehicle.half_track_m
    k = np.asarray(vehicle.suspension_stiffness_npm)
    c = np.asarray(vehicle.suspension_damping_nspm)
    m = np.asarray(vehicle.unsprung_mass_kg)
    kt = np.asarray(vehicle.tire_stiffness_npm)
    ct = np.asarray(vehicle.tire_damping_nspm)
    fc = np.asarray(vehicle.static_load_n)
    # 1. body heave acceleration from the suspension forces on the body (upward)
    fb = -(k * q + c * dq)
    ddzs = fb.sum(axis=1) / vehicle.sprung_mass_kg
    # 2. wheel accelerations from the kinematics differentiated twice
    roll_term = s * (np.cos(phi) * ddphi - np.sin(phi) * dphi ** 2)
    ddzu = np.column_stack([ddzs + roll_term - ddq[:, 0], ddzs - roll_term - ddq[:, 1]])
    # 3. dynamic tire forces from each wheel's equation of motion
    dfi = m * ddzu + fb
    wheel_load = fc + dfi
    # 4. body heave: leaky double integration (band-limited, as inertial profilometers do)
    zs = _body_heave(ddzs, dt_s, float(np.mean(np.abs(speed))), cutoff_wavelength_m,
                     min_cutoff_hz, zero_phase)
    # 5. wheel heaves from the kinematics
    roll_lever = s * np.sin(phi)
    zu = np.column_stack([zs + roll_lever - q[:, 0], zs - roll_lever - q[:, 1]])
    # 6. road under each tire: kt e + ct de = dF with e = u - z_u
    e = np.empty_like(dfi)
    for i in range(2):
        if ct[i] > 0.0:
            be, ae = signal.bilinear([1.0], [ct[i], kt[i]], fs=1.0 / dt_s)
            e[:, i] = signal.lfilter(be, ae, dfi[:, i])
        else:
            e[:, i] = dfi[:, i] / kt[i]
    road = zu + e
    # 9. roll-equation residual (= M h a_y cos(phi) without other faults)
    residual = (vehicle.roll_inertia_kgm2 * ddphi - s * np.cos(phi) * (fb[:, 0] - fb[:, 1])
                - vehicle.sprung_mass_kg * GRAVITY_MPS2 * vehicle.cg_height_m * np.sin(phi))
    return PeerResult(wheel_load, road, _ltr(wheel_load), _distance(t_s, np.asarray(speed)),
                      latency_samples,
                      {'body_accel_mps2': ddzs, 'wheel_accel_mps2': ddzu, 'body_heave_m': zs,
                       'residual_nm': residual})


def _body_heave(ddzs: np.ndarray, dt_s: float, speed_mps: float, cutoff_wavelength_m: float,
                min_cutoff_hz: float = 0.01, zero_phase: bool = False) -> np.ndarray:
    """Body heave from its acceleration, high-passed at ``v / cutoff_wavelength_m`` Hz."""
    f_cut = max(speed_mps / cutoff_wavelength_m, min_cutoff_hz)
    w = 2.0 * math.pi * f_cut
    if not zero_phase:
        b, a = signal.bilinear([1.0], [1.0, math.sqrt(2.0) * w, w * w], fs=1.0 / dt_s)
        return signal.lfilter(b, a, ddzs, axis=0)
    vel = np.zeros_like(ddzs)
    vel[1:] = np.cumsum(0.5 * (ddzs[1:] + ddzs[:-1]) * dt_s, axis=0)
    pos = np.zeros_like(ddzs)
    pos[1:] = np.cumsum(0.5 * (vel[1:] + vel[:-1]) * dt_s, axis=0)
    return _highpass(signal.detrend(pos, axis=0), dt_s, f_cut, zero_phase=True)


def _highpass(x: np.ndarray, dt_s: float, f_cut_hz: float, *, zero_phase: bool) -> np.ndarray:
    """Second-order Butterworth high-pass (causal, or forward-backward when zero_phase)."""
    f_cut_hz = min(f_cut_hz, 0.4 / dt_s)
    sos = signal.butter(2, f_cut_hz, btype='highpass', fs=1.0 / dt_s, output='sos')
    if zero_phase:
        return signal.sosfiltfilt(sos, x, axis=0)
    return signal.sosfilt(sos, x, axis=0)


def _reconstruct_channels(t_s, d: np.ndarray, speed, vehicle, cutoff_wavelength_m,
                          latency_samples) -> PeerResult:
    """d: (n, 3, 3) = [value, rate, acceleration] x [q_left, q_right, phi]."""
    return reconstruct(t_s, d[:, 0, :2], d[:, 1, :2], d[:, 2, :2], d[:, 0, 2], d[:, 1, 2],
                       d[:, 2, 2], speed, vehicle, cutoff_wavelength_m=cutoff_wavelength_m,
                       zero_phase=latency_samples < 0, latency_samples=latency_samples)


def _stack(q_m, roll_rad) -> np.ndarray:
    return np.column_stack([q_m, roll_rad])


# ----------------------------------------------------------------------------------------------
# peer 1: the paper's chain (the package's estimator, explicit Euler)


def paper_euler(t_s, q_m, roll_rad, speed_mps, vehicle: VehicleParameters, *,
                lipschitz_deflection_mps3: float = 5000.0, lipschitz_roll_radps3: float = 50.0,
                discretization: str = 'euler',
                profile_cutoff_wavelength_m: float = 100.0) -> PeerResult:
    """The package's own estimator with the paper's explicit-Euler differentiator.

    No re-implementation: :func:`estimation.estimator.estimate_batch` is called once.
    """
    from road_force_estimator.estimation import estimate_batch
    from road_force_estimator.core.parameters import ObserverParameters

    t_s, q_m, roll_rad, speed, _ = _inputs(t_s, q_m, roll_rad, speed_mps)
    observer = ObserverParameters(lipschitz_deflection_mps3=lipschitz_deflection_mps3,
                                  lipschitz_roll_radps3=lipschitz_roll_radps3,
                                  discretization=discretization,
                                  profile_cutoff_wavelength_m=profile_cutoff_wavelength_m)
    stamps_ns = np.round(t_s * 1e9).astype(np.int64)
    est = estimate_batch(stamps_ns, q_m, roll_rad, speed, vehicle, observer)
    wheel_load = np.asarray(est.wheel_load_n, dtype=float)
    road = np.asarray(est.road_m, dtype=float)
    ltr = np.asarray(est.ltr, dtype=float)
    dist = getattr(est, 'distance_m', None)
    dist = _distance(t_s, speed) if dist is None else np.asarray(dist, dtype=float)
    return PeerResult(wheel_load, road, ltr, dist, 0, {'estimate': est})


# ----------------------------------------------------------------------------------------------
# peer 2: causal low-pass + backward differences


def _butter_sos(order: int, cutoff_hz: float, dt_s: float) -> np.ndarray:
    nyquist = 0.5 / dt_s
    if not 0 < cutoff_hz:
        raise ValueError(f'cutoff_hz = {cutoff_hz!r}: must be > 0 Hz')
    if not 1 <= int(order) <= 10:
        raise ValueError(f'order = {order!r}: must be in [1, 10]')
    return signal.butter(int(order), min(cutoff_hz, 0.9 * nyquist), fs=1.0 / dt_s,
                         output='sos')


def lowpass_differences(x: np.ndarray, dt_s: float, order: int, cutoff_hz: float,
                        differences: str = 'backward') -> np.ndarray:
    """Causal Butterworth low-pass of each column of ``x`` (n, c), then one-sided differences.

    Returns (n, 3, c): [filtered value, first derivative, second derivative]. The filter starts
    in its steady state for the first sample (``sosfilt_zi``). ``differences``: ``'backward'``:
    ``(y_k - y_{k-1}) / dt`` and ``(y_k - 2 y_{k-1} + y_{k-2}) / dt^2`` (half a sample and one
    sample late); ``'backward2'``: the second-order one-sided formulas
    ``(3 y_k - 4 y_{k-1} + y_{k-2}) / (2 dt)`` and
    ``(2 y_k - 5 y_{k-1} + 4 y_{k-2} - y_{k-3}) / dt^2`` (exact at t_k on quadratics, noisier).
    The cutoff is clipped to 0.9 x Nyquist.
    """
    sos = _butter_sos(order, cutoff_hz, dt_s)
    zi = signal.sosfilt_zi(sos)[:, :, None] * x[0][None, None, :]
    y, _ = signal.sosfilt(sos, x, axis=0, zi=zi)
    # pad with the first value (the filter's initial steady state) so that every row is defined
    yp = np.concatenate([np.repeat(y[:1], 3, axis=0), y])
    d = np.empty((x.shape[0], 3, x.shape[1]))
    d[:, 0] = y
    if differences == 'backward':
        d[:, 1] = (yp[3:] - yp[2:-1]) / dt_s
        d[:, 2] = (yp[3:] - 2.0 * yp[2:-1] + yp[1:-2]) / dt_s ** 2
    elif differences == 'backward2':
        d[:, 1] = (3.0 * yp[3:] - 4.0 * yp[2:-1] + yp[1:-2]) / (2.0 * dt_s)
        d[:, 2] = (2.0 * yp[3:] - 5.0 * yp[2:-1] + 4.0 * yp[1:-2] - yp[:-3]) / dt_s ** 2
    else:
        raise ValueError(f"differences = {differences!r}: must be 'backward' or 'backward2'")
    return d


def lowpass_fd(t_s, q_m, roll_rad, speed_mps, vehicle: VehicleParameters, *,
               order: int = 2, cutoff_hz: float = 30.0, differences: str = 'backward',
               roll_cutoff_hz: float | None = None,
               profile_cutoff_wavelength_m: float = 100.0) -> PeerResult:
    """Causal Butterworth low-pass + one-sided differences (:func:`lowpass_differences`) +
    :func:`reconstruct`.

    ``cutoff_hz`` for the deflections, ``roll_cutoff_hz`` for the roll channel (None: the
    same): the roll sensor is another sensor with other dynamics, and its noise enters the
    wheel accelerations through the half track (``s ddphi``), so a user filters it on its own.
    """
    t_s, q_m, roll_rad, speed, dt_s = _inputs(t_s, q_m, roll_rad, speed_mps)
    dq = lowpass_differences(q_m, dt_s, order, cutoff_hz, differences)
    dr = lowpass_differences(roll_rad[:, None], dt_s, order,
                             cutoff_hz if roll_cutoff_hz is None else roll_cutoff_hz,
                             differences)
    d = np.concatenate([dq, dr], axis=2)
    return _reconstruct_channels(t_s, d, speed, vehicle, profile_cutoff_wavelength_m, 0)


# ----------------------------------------------------------------------------------------------
# peer 4: zero-phase low-pass + central differences (offline)


def zero_phase_differences(x: np.ndarray, dt_s: float, order: int,
                           cutoff_hz: float) -> np.ndarray:
    """Zero-phase Butterworth (``sosfiltfilt``, effective order 2 x ``order``) of each column of
    ``x`` (n, c), then central differences; returns (n, 3, c) as :func:`lowpass_differences`.
    """
    sos = _butter_sos(order, cutoff_hz, dt_s)
    y = signal.sosfiltfilt(sos, x, axis=0)
    d = np.empty((x.shape[0], 3, x.shape[1]))
    d[:, 0] = y
    d[:, 1] = np.gradient(y, dt_s, axis=0)
    d[1:-1, 2] = (y[2:] - 2.0 * y[1:-1] + y[:-2]) / dt_s ** 2
    d[0, 2] = d[1, 2]
    d[-1, 2] = d[-2, 2]
    return d


def zero_phase_offline(t_s, q_m, roll_rad, speed_mps, vehicle: VehicleParameters, *,
                       order: int = 2, cutoff_hz: float = 30.0,
                       roll_cutoff_hz: float | None = None,
                       profile_cutoff_wavelength_m: float = 100.0) -> PeerResult:
    """Offline: :func:`zero_phase_differences` + :func:`reconstruct` (body heave zero-phase).

    ``roll_cutoff_hz``: the roll channel's own cutoff (None: ``cutoff_hz``), as in
    :func:`lowpass_fd`.
    """
    t_s, q_m, roll_rad, speed, dt_s = _inputs(t_s, q_m, roll_rad, speed_mps)
    d = np.concatenate([
        zero_phase_differences(q_m, dt_s, order, cutoff_hz),
        zero_phase_differences(roll_rad[:, None], dt_s, order,
                               cutoff_hz if roll_cutoff_hz is None else roll_cutoff_hz)],
        axis=2)
    return _reconstruct_channels(t_s, d, speed, vehicle, profile_cutoff_wavelength_m, -1)


# ----------------------------------------------------------------------------------------------
# generic steady-state Kalman filter and smoothers (linear, time-invariant)


def filter_riccati(a: np.ndarray, c: np.ndarray, q: np.ndarray, r: np.ndarray, *,
                   rtol: float = 1e-13, max_iter: int = 200) -> np.ndarray:
    """Stabilising solution P of ``P = A P A^T - A P C^T (C P C^T + R)^-1 C P A^T + Q``.

    Structured doubling algorithm (SDA-1, Chu, Fan & Lin 2005, Linear Algebra Appl. 396): with
    ``A_0 = A^T``, ``G_0 = C^T R^-1 C``, ``H_0 = Q`` and ``W = I + G_k H_k``::

        A_{k+1} = A_k W^-1 A_k
        G_{k+1} = G_k + A_k W^-1 G_k A_k^T
        H_{k+1} = H_k + A_k^T H_k W^-1 A_k      -> P

    Each iteration doubles the number of Riccati steps it covers, so slow modes (the road's
    leak, eigenvalues within 1e-6 of the unit circle) converge in a few dozen iterations where
    the QZ method of ``scipy.linalg.solve_discrete_are`` reports an ill-conditioned pencil.
    ``R`` must be positive definite.
    """
    nx = a.shape[0]
    lr = np.linalg.cholesky(r)
    cw = linalg.solve_triangular(lr, c, lower=True)          # whitened measurement
    ak = a.T.copy()
    gk = cw.T @ cw
    hk = 0.5 * (q + q.T)
    eye = np.eye(nx)
    for _ in range(max_iter):
        w = eye + gk @ hk
        aw = np.linalg.solve(w.T, ak.T).T                   # A_k W^-1
        a_next = aw @ ak
        g_next = gk + aw @ gk @ ak.T
        h_next = hk + ak.T @ hk @ np.linalg.solve(w, ak)
        g_next = 0.5 * (g_next + g_next.T)
        h_next = 0.5 * (h_next + h_next.T)
        done = np.max(np.abs(h_next - hk)) <= rtol * np.max(np.abs(h_next))
        ak, gk, hk = a_next, g_next, h_next
        if done:
            return hk
    raise ValueError(f'Riccati equation: no convergence in {max_iter} doubling steps')


class SteadyStateKalman:
    """Kalman filter and smoothers for ``x_{k+1} = A x_k + w_k``, ``y_k = C x_k + v_k``.

    ``w ~ N(0, Q)``, ``v ~ N(0, R)``. The a-priori covariance ``P`` is the stabilising solution
    of the discrete algebraic Riccati equation, the gain ``K = P C^T (C P C^T + R)^-1``, the
    a-posteriori covariance ``P_f = (I - K C) P`` and the RTS gain ``G = P_f A^T P^-1``
    (Rauch, Tung & Striebel 1965). With the prior covariance equal to ``P`` these constant-gain
    recursions are the exact filter and smoothers.
    """

    def __init__(self, a: np.ndarray, c: np.ndarray, q: np.ndarray, r: np.ndarray,
                 scale: np.ndarray | None = None):
        nx = a.shape[0]
        # work in scaled states xs = x / S (comparable magnitudes), convert the gains back
        sc = np.ones(nx) if scale is None else np.asarray(scale, dtype=float)
        s_inv = 1.0 / sc
        a_s = (a * s_inv[:, None]) * sc[None, :]
        c_s = c * sc[None, :]
        q_s = q * np.outer(s_inv, s_inv)
        p_s = filter_riccati(a_s, c_s, q_s, r)
        innov = c_s @ p_s @ c_s.T + r
        k_s = np.linalg.solve(innov, c_s @ p_s).T
        pf_s = (np.eye(nx) - k_s @ c_s) @ p_s
        pf_s = 0.5 * (pf_s + pf_s.T)
        # G = P_f A^T P^-1, by least squares (P may be nearly singular on noise-free data)
        g_s = np.linalg.lstsq(p_s, a_s @ pf_s, rcond=None)[0].T
        self.a, self.c, self.q, self.r = a, c, q, r
        self.p_prior = p_s * np.outer(sc, sc)
        self.p_post = pf_s * np.outer(sc, sc)
        self.k = k_s * sc[:, None]
        self.g = (g_s * sc[:, None]) * s_inv[None, :]
        self.f_closed = (np.eye(nx) - self.k @ c) @ a
        radius = float(np.max(np.abs(np.linalg.eigvals(self.f_closed))))
        if not radius < 1.0:
            raise ValueError(f'Kalman filter not stable (spectral radius {radius:.6g}): the '
                             'Riccati solution is not stabilising for these noise settings')

    def filter(self, y: np.ndarray, x0_prior: np.ndarray) -> np.ndarray:
        """A-posteriori estimates x_{k|k}, (n, nx); ``x0_prior`` is the prior mean of x_0."""
        drive = y @ self.k.T
        # x_{0|0} = x0 + K (y_0 - C x0) = F x_{-1} + K y_0 with A x_{-1} := x0
        x_m1 = np.linalg.lstsq(self.a, x0_prior, rcond=None)[0]
        return _run_lti(self.f_closed, drive, x_m1)

    def rts(self, xf: np.ndarray) -> np.ndarray:
        """Fixed-interval (RTS) smoothed estimates x_{k|n-1} from the filtered ones."""
        xp_next = xf @ self.a.T                       # x_{k+1|k}
        drive = xf - xp_next @ self.g.T               # x_{k|k} - G x_{k+1|k}
        return _run_lti_backward(self.g, drive, xf[-1])

    def fixed_lag(self, xf: np.ndarray, lag: int) -> np.ndarray:
        """Exact fixed-lag estimates: row j = x_{j|j+lag} (the last rows: x_{j|n-1}).

        RTS identity over the window: ``x_{j|k} = x_{j|j} + G (x_{j+1|k} - A x_{j|j})``, run
        ``lag`` times, each time vectorised over every end sample ``k``.
        """
        xp_next = xf @ self.a.T
        s = xf.copy()                                  # s[j] = x_{j|j+m}, m = 0
        for _ in range(int(lag)):
            new = s.copy()                             # last rows keep the shorter lag
            new[:-1] = xf[:-1] + (s[1:] - xp_next[:-1]) @ self.g.T
            s = new
        return s


# ----------------------------------------------------------------------------------------------
# peer 3: per-channel integrated random walk ("constant jerk")


def _irw_model(states: int, psd: float, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Integrated random walk of order ``states``: the last derivative is a random walk."""
    a_c = np.diag(np.ones(states - 1), 1)
    g_c = np.zeros((states, 1))
    g_c[-1, 0] = 1.0
    return van_loan(a_c, g_c, np.array([[psd]]), dt_s)


def kf_jerk(t_s, q_m, roll_rad, speed_mps, vehicle: VehicleParameters, *,
            jerk_psd: float = 1e3, states: int = 4, noise_deflection_m: float = 1e-5,
            noise_roll_rad: float = 1e-4, noise_floor_m: float = 1e-7,
            roll_jerk_psd: float | None = None,
            profile_cutoff_wavelength_m: float = 100.0) -> PeerResult:
    """Causal Kalman filter per channel on an integrated random walk, then reconstruction.

    ``states = 4``: (f, df, ddf, dddf) with the jerk dddf a random walk (constant-jerk model),
    ``d dddf / dt`` white with two-sided spectral density ``jerk_psd`` (m^2/s^7 for the
    deflections; the roll channel uses ``roll_jerk_psd``, in rad^2/s^7, or ``jerk_psd / s^2``
    when None). ``states = 3``: (f, df, ddf), the jerk
    white (``jerk_psd`` then in m^2/s^5). Measurement variance: the known sensor variance plus
    ``noise_floor_m^2`` (``(noise_floor_m / s)^2`` for roll), so that noise-free data stays
    well posed.
    """
    t_s, q_m, roll_rad, speed, dt_s = _inputs(t_s, q_m, roll_rad, speed_mps)
    states = int(states)
    if states not in (3, 4):
        raise ValueError(f'states = {states!r}: must be 3 or 4')
    s = vehicle.half_track_m
    x = _stack(q_m, roll_rad)
    d = np.empty((x.shape[0], 3, 3))
    for ch in range(3):
        psd = (jerk_psd if ch < 2 else jerk_psd / s ** 2 if roll_jerk_psd is None
               else roll_jerk_psd)
        a_d, q_d = _irw_model(states, psd, dt_s)
        c = np.zeros((1, states))
        c[0, 0] = 1.0
        floor = noise_floor_m
        while True:
            r = (noise_deflection_m ** 2 + floor ** 2 if ch < 2
                 else noise_roll_rad ** 2 + (floor / s) ** 2)
            scale = np.array([1.0, 1.0 / dt_s, 1.0 / dt_s ** 2, 1.0 / dt_s ** 3][:states])
            try:
                kf = SteadyStateKalman(a_d, c, q_d, np.array([[r]]),
                                       scale * max(r, 1e-30) ** 0.5)
                break
            except (ValueError, np.linalg.LinAlgError):
                if floor >= MAX_NOISE_FLOOR_M:
                    raise
                floor = min(10.0 * max(floor, 1e-12), MAX_NOISE_FLOOR_M)
        x0 = np.zeros(states)
        x0[0] = x[0, ch]
        xf = kf.filter(x[:, ch:ch + 1], x0)
        d[:, :, ch] = xf[:, :3]
    return _reconstruct_channels(t_s, d, speed, vehicle, profile_cutoff_wavelength_m, 0)


# ----------------------------------------------------------------------------------------------
# peers 5-7: model-based Kalman filter on the linearised roll-plane model


class RollPlaneKalman:
    """Linearised roll-plane model of MODEL.md with the road as augmented states.

    States: ``[z_s, phi, z_u1, z_u2, dz_s, dphi, dz_u1, dz_u2, u_1, u_2]`` and, with
    ``road_model = 'velocity'``, ``[du_1, du_2]``. Measurements ``[q_1, q_2, phi]``.

    Road models
    -----------
    ``'position'`` (default): ``du_i/dt = -w_l u_i + w_i``, w white with two-sided density
    ``D v`` (m^2/s), ``D = 2 pi^2 Gd(n0) n0^2``: exactly the ISO 8608 slope (Gd ~ n^-2 means a
    white road velocity), with a leak at wavelength ``leak_wavelength_m`` so that the common
    vertical offset of body, wheels and road (unobservable from deflections) stays bounded.
    ``'velocity'``: the road velocity ``du_i`` is a state, an Ornstein-Uhlenbeck process
    ``d du_i/dt = -w_v du_i + w_i`` with ``w_v = 2 pi v / road_velocity_wavelength_m`` and density
    ``D v w_v^2``: white (ISO slope) below ``w_v``, rolled off above it as the tire envelope
    does; u_i then integrates du_i (with the same leak as above).

    Process noise also enters each equation of motion as a white generalised force of two-sided
    density ``force_psd`` (N^2 s), for unmodelled forces (parameter errors, nonlinearity, tire
    envelope); roll gets ``force_psd s^2``. With ``roll_moment_psd`` > 0 an unknown roll moment
    (N m; e.g. ``M h a_y`` of an unmeasured lateral acceleration) is one more state, a random
    walk of that density ((N m)^2 / s).

    Measurement noise: the known sensor variances plus ``noise_floor_m^2`` (roll:
    ``(noise_floor_m / s)^2``). Where the Riccati equation cannot be solved in double precision
    (noise-free data, a floor of ~1e-10 m), the floor is raised tenfold until it can (at most
    :data:`MAX_NOISE_FLOOR_M`); :attr:`noise_floor_m` is the floor used.

    Sensor lag: where the file states one (``vehicle.sensor_time_constant`` [deflection, roll],
    s), each lagged channel has a first-order lag state ``tau dl_j = y_j - l_j`` that its
    sensor measures (as the observer's model, but built here independently): the filter of
    the same information.

    The model is discretized exactly at the sample step (matrix exponential; Van Loan for the
    process noise) for one (mean) speed.
    """

    def __init__(self, vehicle: VehicleParameters, dt_s: float, speed_mps: float, *,
                 road_gd_m3: float = 256e-6, force_psd: float = 1.0,
                 noise_deflection_m: float = 1e-5, noise_roll_rad: float = 1e-4,
                 noise_floor_m: float = 1e-7, leak_wavelength_m: float = 500.0,
                 road_model: str = 'position', road_velocity_wavelength_m: float = 0.5,
                 roll_moment_psd: float = 0.0):
        if road_model not in ('position', 'velocity'):
            raise ValueError(f"road_model = {road_model!r}: must be 'position' or 'velocity'")
        self.vehicle = vehicle
        self.road_model = road_model
        s = vehicle.half_track_m
        mass = np.array([vehicle.sprung_mass_kg, vehicle.roll_inertia_kgm2,
                         *vehicle.unsprung_mass_kg])
        k = np.diag(vehicle.suspension_stiffness_npm)
        c = np.diag(vehicle.suspension_damping_nspm)
        kt = np.diag(vehicle.tire_stiffness_npm)
        ct = np.diag(vehicle.tire_damping_nspm)
        d = np.array([[1.0, s, -1.0, 0.0], [1.0, -s, 0.0, -1.0]])   # q = D p
        sw = np.array([[0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])  # z_u = Sw p
        n_road = 2 if road_model == 'position' else 4
        n_dist = 1 if roll_moment_psd > 0 else 0
        nx = 8 + n_road + n_dist
        iu = 8                       # u_1, u_2
        idu = 10 if road_model == 'velocity' else None
        idist = 8 + n_road if n_dist else None
        minv = 1.0 / mass
        stiff = d.T @ k @ d + sw.T @ kt @ sw
        # the gravity moment M g h sin(phi) of MODEL.md's roll equation, linearised
        stiff[1, 1] -= vehicle.sprung_mass_kg * GRAVITY_MPS2 * vehicle.cg_height_m
        damp = d.T @ c @ d + sw.T @ ct @ sw
        a = np.zeros((nx, nx))
        a[0:4, 4:8] = np.eye(4)
        a[4:8, 0:4] = -minv[:, None] * stiff
        a[4:8, 4:8] = -minv[:, None] * damp
        a[4:8, iu:iu + 2] = minv[:, None] * (sw.T @ kt)
        w_leak = 2.0 * math.pi * abs(speed_mps) / leak_wavelength_m
        diffusion = iso_road_diffusion(road_gd_m3) * abs(speed_mps)
        n_w = 4 + 2 + n_dist
        g = np.zeros((nx, n_w))
        g[4:8, 0:4] = np.diag(minv)
        qc = np.zeros((n_w, n_w))
        qc[0:4, 0:4] = np.diag([force_psd, force_psd * s * s, force_psd, force_psd])
        if road_model == 'position':
            a[iu:iu + 2, iu:iu + 2] = -w_leak * np.eye(2)
            g[iu:iu + 2, 4:6] = np.eye(2)
            qc[4:6, 4:6] = diffusion * np.eye(2)
        else:
            a[4:8, idu:idu + 2] = minv[:, None] * (sw.T @ ct)
            w_vel = 2.0 * math.pi * abs(speed_mps) / road_velocity_wavelength_m
            a[iu:iu + 2, iu:iu + 2] = -w_leak * np.eye(2)
            a[iu:iu + 2, idu:idu + 2] = np.eye(2)
            a[idu:idu + 2, idu:idu + 2] = -w_vel * np.eye(2)
            g[idu:idu + 2, 4:6] = np.eye(2)
            qc[4:6, 4:6] = diffusion * w_vel ** 2 * np.eye(2)
        if n_dist:
            # roll moment disturbance (e.g. M h a_y), random walk, N m
            a[5, idist] = 1.0 / vehicle.roll_inertia_kgm2
            g[idist, 6] = 1.0
            qc[6, 6] = roll_moment_psd
        cm = np.zeros((3, nx))
        cm[0:2, 0:4] = d
        cm[2, 1] = 1.0
        # state scales for the Riccati solver: metres ~ 1e-2, rates ~ 1e-1, road ~ 1e-2
        scale = np.full(nx, 1e-2)
        scale[4:8] = 1e-1
        if idu is not None:
            scale[idu:idu + 2] = 1e-1
        if n_dist:
            scale[idist] = 1e3
        a, g, cm, scale = _with_sensor_lag(a, g, cm, scale, vehicle.sensor_time_constant_s)
        nx = a.shape[0]
        #: the continuous model ``dx = A x dt + G dW``, ``E[dW dW^T] = Qc dt`` (lag states
        #: included), the deflection map ``q = D p`` (2 x 4, p = [z_s, phi, z_u1, z_u2]) and the
        #: generalised masses [M, I_x, m_u1, m_u2] (kg, kg m^2): what a nonlinear model on this
        #: one needs
        self.a_continuous, self.g_continuous, self.q_continuous = a, g, qc
        self.deflection_map, self.masses = d, mass
        a_d, q_d = van_loan(a, g, qc, dt_s)
        #: measurement-noise floor actually used (raised x10 while the Riccati equation is too
        #: ill-conditioned to solve in double precision, as a user would)
        self.noise_floor_m = noise_floor_m
        while True:
            r = np.diag([noise_deflection_m ** 2 + self.noise_floor_m ** 2] * 2
                        + [noise_roll_rad ** 2 + (self.noise_floor_m / s) ** 2])
            try:
                self.kf = SteadyStateKalman(a_d, cm, q_d, r, scale)
                break
            except (ValueError, np.linalg.LinAlgError):
                if self.noise_floor_m >= MAX_NOISE_FLOOR_M:
                    raise
                self.noise_floor_m = min(10.0 * max(self.noise_floor_m, 1e-12),
                                         MAX_NOISE_FLOOR_M)
        self.nx = nx
        self.iu, self.idu = iu, idu
        # tire force output: dF = Kt (u - z_u) + Ct (du - dz_u)
        hf = np.zeros((2, nx))
        hf[:, iu:iu + 2] = kt
        hf[:, 0:4] -= kt @ sw
        hf[:, 4:8] -= ct @ sw
        if idu is not None:
            hf[:, idu:idu + 2] = ct
        self.h_force = hf
        # body heave acceleration (F_b1 + F_b2) / M, F_b = -(K q + C dq), q = D p
        hb = np.zeros(nx)
        hb[0:4] = -np.ones(2) @ k @ d / vehicle.sprung_mass_kg
        hb[4:8] = -np.ones(2) @ c @ d / vehicle.sprung_mass_kg
        self.h_body_accel = hb

    def prior(self, y0: np.ndarray) -> np.ndarray:
        """Prior mean from the first measurement: static equilibrium, body heave 0 (a lagged
        sensor's state: its reading)."""
        x0 = np.zeros(self.nx)
        s = self.vehicle.half_track_m
        x0[1] = y0[2]
        x0[2] = s * y0[2] - y0[0]
        x0[3] = -s * y0[2] - y0[1]
        x0[self.iu:self.iu + 2] = x0[2:4]
        lagged = [j for j, tau in enumerate(_channel_lags(self.vehicle)) if tau > 0.0]
        x0[self.nx - len(lagged):] = [y0[j] for j in lagged]
        return x0

    def outputs(self, x: np.ndarray, t_s, speed, latency_samples: int,
                profile_cutoff_wavelength_m: float = 0.0) -> PeerResult:
        """Loads, road and LTR from state estimates ``x`` (n, nx).

        The road is the road state. With ``profile_cutoff_wavelength_m`` > 0 its absolute
        level, the body heave z_s (unobservable from deflections but for the slow leak), is
        replaced by MODEL.md step 4 applied to the filter's body acceleration
        ``(F_b1 + F_b2) / M``: ``u = (u - z_s) + z_s,4`` with ``z_s,4`` the leaky double
        integral (:func:`_body_heave`; causal, or zero-phase for the offline smoother,
        ``latency_samples < 0``).
        """
        wheel_load = np.asarray(self.vehicle.static_load_n) + x @ self.h_force.T
        road = x[:, self.iu:self.iu + 2].copy()
        if profile_cutoff_wavelength_m > 0.0:
            dt_s = float(np.median(np.diff(t_s)))
            zs = x[:, 0]
            ddzs = x @ self.h_body_accel
            zs_4 = _body_heave(ddzs, dt_s, float(np.mean(np.abs(speed))),
                               profile_cutoff_wavelength_m, zero_phase=latency_samples < 0)
            road += (zs_4 - zs)[:, None]
        return PeerResult(wheel_load, road, _ltr(wheel_load), _distance(t_s, speed),
                          latency_samples, {'states': x})


def _channel_lags(vehicle: VehicleParameters) -> tuple[float, float, float]:
    """The first-order lag (s) of each channel (q_1, q_2, phi): ``vehicle.sensor_time_constant``
    [deflection, roll]."""
    tau = tuple(getattr(vehicle, 'sensor_time_constant_s', (0.0, 0.0)))
    return float(tau[0]), float(tau[0]), float(tau[1])


def _with_sensor_lag(a, g, cm, scale, time_constant_s):
    """The model with a first-order lag state per lagged channel, ``tau dl_j = C_j x - l_j``
    (no process noise: the sensor's own dynamics), appended; the sensor then measures
    ``l_j``. ``time_constant_s``: [deflection, roll] (s); unchanged where both are 0."""
    tau = (float(time_constant_s[0]), float(time_constant_s[0]), float(time_constant_s[1]))
    lagged = [j for j in range(3) if tau[j] > 0.0]
    if not lagged:
        return a, g, cm, scale
    nx, n = a.shape[0], len(lagged)
    a2 = np.zeros((nx + n, nx + n))
    a2[:nx, :nx] = a
    c2 = np.zeros((3, nx + n))
    c2[:, :nx] = cm
    for i, j in enumerate(lagged):
        a2[nx + i, :nx] = cm[j] / tau[j]
        a2[nx + i, nx + i] = -1.0 / tau[j]
        c2[j] = 0.0
        c2[j, nx + i] = 1.0
    g2 = np.vstack([g, np.zeros((n, g.shape[1]))])
    return a2, g2, c2, np.concatenate([scale, np.full(n, 1e-2)])


def _kf_model_states(t_s, q_m, roll_rad, speed_mps, vehicle, tuning):
    t_s, q_m, roll_rad, speed, dt_s = _inputs(t_s, q_m, roll_rad, speed_mps)
    tuning = dict(tuning)
    profile_cut = float(tuning.pop('profile_cutoff_wavelength_m', 0.0))
    model = RollPlaneKalman(vehicle, dt_s, float(np.mean(np.abs(speed))), **tuning)
    y = _stack(q_m, roll_rad)
    xf = model.kf.filter(y, model.prior(y[0]))
    return t_s, speed, model, xf, profile_cut


def kf_model(t_s, q_m, roll_rad, speed_mps, vehicle: VehicleParameters,
             **tuning) -> PeerResult:
    """Causal model-based Kalman filter (:class:`RollPlaneKalman`), filtered estimates.

    ``tuning``: the keyword arguments of :class:`RollPlaneKalman` and
    ``profile_cutoff_wavelength_m`` (see :meth:`RollPlaneKalman.outputs`).
    """
    t_s, speed, model, xf, cut = _kf_model_states(t_s, q_m, roll_rad, speed_mps, vehicle, tuning)
    return model.outputs(xf, t_s, speed, 0, cut)


def kf_model_lag(t_s, q_m, roll_rad, speed_mps, vehicle: VehicleParameters, *,
                 lag_s: float = 0.01, **tuning) -> PeerResult:
    """Exact fixed-lag smoother of :func:`kf_model`: row j = estimate of sample j given data
    up to sample j + round(lag_s / dt) (the last rows: given all data)."""
    t_s, speed, model, xf, cut = _kf_model_states(t_s, q_m, roll_rad, speed_mps, vehicle, tuning)
    dt_s = float(np.median(np.diff(t_s)))
    lag = int(round(lag_s / dt_s))
    return model.outputs(model.kf.fixed_lag(xf, lag), t_s, speed, lag, cut)


def kf_model_rts(t_s, q_m, roll_rad, speed_mps, vehicle: VehicleParameters,
                 **tuning) -> PeerResult:
    """Offline Rauch-Tung-Striebel smoother of :func:`kf_model`."""
    t_s, speed, model, xf, cut = _kf_model_states(t_s, q_m, roll_rad, speed_mps, vehicle, tuning)
    return model.outputs(model.kf.rts(xf), t_s, speed, -1, cut)


# ----------------------------------------------------------------------------------------------
# registry

PeerFunction = Callable[..., PeerResult]

#: The peers of the benchmark, by name: (function, fixed keyword arguments).
PEERS: dict[str, tuple[PeerFunction, dict[str, Any]]] = {
    'paper-euler': (paper_euler, {}),
    'lowpass-fd': (lowpass_fd, {}),
    'kf-jerk': (kf_jerk, {}),
    'zero-phase-offline': (zero_phase_offline, {}),
    'kf-model': (kf_model, {}),
    'kf-model-lag5ms': (kf_model_lag, {'lag_s': 0.005}),
    'kf-model-lag10ms': (kf_model_lag, {'lag_s': 0.010}),
    'kf-model-rts': (kf_model_rts, {}),
}

#: Peers that take the known sensor noise (``noise_deflection_m``, ``noise_roll_rad``).
USES_SENSOR_NOISE = frozenset({'kf-jerk', 'kf-model', 'kf-model-lag5ms', 'kf-model-lag10ms',
                               'kf-model-rts'})

#: Untuned starting points (the tuned values live in bench/accuracy/tuned_peers.json).
#: The model Kalman peers carry an unknown roll moment (e.g. M h a_y of an unmeasured lateral
#: acceleration) as a random-walk state of density ROLL_MOMENT_PSD ((N m)^2 / s): it costs
#: nothing on straight drives and keeps the filter honest in curves (fixed, not tuned: the
#: tuning drive is straight).
ROLL_MOMENT_PSD = 1e6
_KF_DEFAULT = {'road_model': 'position', 'road_gd_m3': 64e-6, 'force_psd': 1.0,
               'noise_floor_m': 1e-7, 'leak_wavelength_m': 500.0,
               'roll_moment_psd': ROLL_MOMENT_PSD, 'profile_cutoff_wavelength_m': 0.0}
DEFAULT_TUNING: dict[str, dict[str, Any]] = {
    'paper-euler': {'lipschitz_deflection_mps3': 5000.0, 'lipschitz_roll_radps3': 50.0,
                    'profile_cutoff_wavelength_m': 100.0},
    'lowpass-fd': {'order': 2, 'cutoff_hz': 30.0, 'differences': 'backward',
                   'profile_cutoff_wavelength_m': 100.0},
    'kf-jerk': {'jerk_psd': 1e3, 'states': 4, 'noise_floor_m': 1e-7,
                'profile_cutoff_wavelength_m': 100.0},
    'zero-phase-offline': {'order': 2, 'cutoff_hz': 30.0, 'profile_cutoff_wavelength_m': 100.0},
    'kf-model': dict(_KF_DEFAULT),
    'kf-model-lag5ms': dict(_KF_DEFAULT),
    'kf-model-lag10ms': dict(_KF_DEFAULT),
    'kf-model-rts': dict(_KF_DEFAULT),
}


def call_peer(name: str, t_s, q_m, roll_rad, speed_mps, vehicle: VehicleParameters,
              settings: dict[str, Any] | None = None, *, noise_deflection_m: float = 0.0,
              noise_roll_rad: float = 0.0) -> PeerResult:
    """Run peer ``name`` with its ``settings`` (default :data:`DEFAULT_TUNING`).

    The known sensor noise (standard deviations) goes to the peers that use it.
    """
    try:
        fn, fixed = PEERS[name]
    except KeyError:
        raise ValueError(f'peer {name!r}: unknown; one of {", ".join(PEERS)}') from None
    kwargs = dict(DEFAULT_TUNING[name] if settings is None else settings)
    kwargs.update(fixed)
    if name in USES_SENSOR_NOISE:
        kwargs.update(noise_deflection_m=noise_deflection_m, noise_roll_rad=noise_roll_rad)
    return fn(t_s, q_m, roll_rad, speed_mps, vehicle, **kwargs)
