"""The model's gains at one operating point: the discretized model, the steady-state Kalman
filter, the fixed-lag smoother's gains, the sliding-mode injection (:func:`design`).

The model is discretized exactly at the sample step (:func:`.riccati.van_loan`); the gain is
the steady-state Kalman gain of the discrete algebraic Riccati equation
(:func:`.riccati.solve_dare`; where double precision cannot give a stabilising solution the
noise is raised threefold until it can). Fixed lag N (Anderson & Moore, Optimal Filtering,
1979, ch. 7): ``x_{t|t+N} = x_{t|t} + sum_{i=1..N} P+ A^T (Phi^T)^(i-1) C^T S^-1 nu_{t+i}``
with ``Phi = A (I - K C)``, applied to the outputs through ``H`` (:attr:`Gains.out`).

The model is the vehicle model's (:mod:`..models`: its linear state space at the operating
point, :meth:`.VehicleModel.continuous`); nothing here knows which vehicle it is. The online
observer keeps one row per sample (nx states, ny measured channels: :func:`row_layout`)::

    [rho_k (3 ny) | x+_k (nx) | nu_k (ny) | y_{k+1} (ny)]

``rho_k`` the sliding-mode differentiator's (e, de, dde) per channel, whose
injection ``T rho_k`` is part of the state estimate ``x_k = x+_k + T rho_k``; ``x+_k`` the
state after the linear (Kalman) update; ``nu_k`` the innovation; ``y_{k+1}`` the next
measurement, written when it arrives, so that one matrix product of a row
(:meth:`Gains.step_matrix`) gives the next ``[x+; nu]``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math

import numpy as np
from scipy import linalg

from road_force_estimator.estimation.models.protocol import (
    FORCE_PSD, ROLL_MOMENT_PSD, ContinuousModel, VehicleModel, row_layout)
from road_force_estimator.estimation.observer.riccati import solve_dare, van_loan

__all__ = [
    'NOISE_FLOOR_M', 'MAX_NOISE_FLOOR_M', 'DT_QUANTUM', 'MAX_STEP_MATRICES',
    'EXCLUDED_VARIANCE_FACTOR', 'Gains', 'design',
    'row_layout',
]

#: Floor of the deflection-noise level (m); roll: this over s (rad).
NOISE_FLOOR_M = 1e-9
#: Largest floor a design raises the noise to when the Riccati equation needs it (m).
MAX_NOISE_FLOOR_M = 1e-6
#: Relative quantum of the per-step transition matrices.
DT_QUANTUM = 1e-3
MAX_STEP_MATRICES = 512
#: A channel left out of a design (:func:`design`, ``excluded``): its noise variance times this.
EXCLUDED_VARIANCE_FACTOR = 1e12


@dataclass
class Gains:
    """The discretized model and its gains at one operating point (see :func:`design`)."""

    key: tuple
    dt_s: float
    speed_mps: float
    noise_deflection_m: float
    noise_roll_rad: float
    road_gd_m3: float
    lag: int
    model: ContinuousModel
    a: np.ndarray            #: (nx, nx) transition at dt
    q: np.ndarray            #: (nx, nx) process-noise covariance at dt
    r: np.ndarray            #: (ny, ny)
    p_prior: np.ndarray      #: a-priori covariance P (DARE)
    p_post: np.ndarray       #: a-posteriori covariance (I - K C) P
    s: np.ndarray            #: innovation covariance C P C^T + R
    k: np.ndarray            #: (nx, ny) Kalman gain P C^T S^-1
    lag_gains: np.ndarray    #: (lag, nx, ny): B_i = P+ A^T (Phi^T)^(i-1) C^T S^-1
    out: np.ndarray          #: (no, row size (lag + 1)): outputs from the rows t..t+lag
    post_error_std: np.ndarray  #: (ny,) std of y - C x+ (a-posteriori output error)
    settle_s: float          #: 5 x the slowest closed-loop time constant
    t_sm: np.ndarray         #: (nx, 3 ny) sliding-mode injection matrix T
    step_cache: dict = field(default_factory=dict)
    a_cache: dict = field(default_factory=dict)
    friction_cache: dict = field(default_factory=dict)
    #: the channels the design leaves out (``excluded`` of :func:`design`)
    excluded: tuple = ()

    @property
    def nx(self) -> int:
        """Number of states."""
        return self.a.shape[0]

    @property
    def layout(self) -> tuple[int, int, int, int, int]:
        """The buffer row's layout (:func:`row_layout`)."""
        return row_layout(self.nx, self.model.ny)

    def friction_input(self, dt_s: float) -> np.ndarray:
        """``B_d(dt)`` (nx, nf): the state change over a step of dt (s) per newton of friction
        force held over the step (zero-order hold: ``int_0^dt expm(A s) ds B_f``); cached as
        :meth:`transition`."""
        key = round(math.log(dt_s / self.dt_s) / DT_QUANTUM)
        bd = self.friction_cache.get(('b', key))
        if bd is None:
            if len(self.friction_cache) >= MAX_STEP_MATRICES:
                self.friction_cache.clear()
            nx = self.nx
            nf = self.model.friction_b.shape[1]
            big = np.zeros((nx + nf, nx + nf))
            big[:nx, :nx] = self.model.a
            big[:nx, nx:] = self.model.friction_b
            step = self.dt_s * math.exp(key * DT_QUANTUM)
            bd = linalg.expm(big * step)[:nx, nx:]
            self.friction_cache[('b', key)] = bd
        return bd

    def friction_step(self, dt_s: float) -> np.ndarray:
        """The rows of :meth:`step_matrix` per newton of friction force (nx + ny [+ no], nf):
        ``x+_{k+1} += (I - K C) B_d f``, ``nu_{k+1} -= C B_d f`` [and the outputs ``H``
        of the former]."""
        key = round(math.log(dt_s / self.dt_s) / DT_QUANTUM)
        m = self.friction_cache.get(('m', key))
        if m is None:
            bd = self.friction_input(dt_s)
            c = self.model.c
            top = bd - self.k @ (c @ bd)
            m = np.vstack([top, -c @ bd])
            if self.lag == 0:
                m = np.vstack([m, self.model.h @ top])
            self.friction_cache[('m', key)] = m
        return m

    def transition(self, dt_s: float) -> np.ndarray:
        """A(dt) = expm(A_c dt) (cached per 0.1 % of dt, as :meth:`step_matrix`)."""
        key = round(math.log(dt_s / self.dt_s) / DT_QUANTUM)
        if key == 0:
            return self.a
        a = self.a_cache.get(key)
        if a is None:
            if len(self.a_cache) >= MAX_STEP_MATRICES:
                self.a_cache.clear()
            a = linalg.expm(self.model.a * (self.dt_s * math.exp(key * DT_QUANTUM)))
            self.a_cache[key] = a
        return a

    def step_matrix(self, dt_s: float) -> np.ndarray:
        """M (nx + ny, row size) with ``[x+_{k+1}; nu_{k+1}] = M row_k`` for a step of dt (s);
        with no lag (nx + ny + no, row size): then also the linear outputs ``H x+_{k+1}``.

        ``row_k = [rho_k, x+_k, nu_k, y_{k+1}]`` (see :class:`.ModelCore`); with
        ``x_k = x+_k + T rho_k``: ``x+_{k+1} = (I - K C) A(dt) x_k + K y_{k+1}`` and
        ``nu_{k+1} = y_{k+1} - C A(dt) x_k``. Cached per 0.1 % of dt.
        """
        key = round(math.log(dt_s / self.dt_s) / DT_QUANTUM)
        m = self.step_cache.get(key)
        if m is None:
            if len(self.step_cache) >= MAX_STEP_MATRICES:
                self.step_cache.clear()
            a = self.transition(dt_s)
            c = self.model.c
            nx = self.nx
            ny = c.shape[0]
            _, row_x, _, row_y, row_size = row_layout(nx, ny)
            ikc_a = (np.eye(nx) - self.k @ c) @ a
            m = np.zeros((nx + ny, row_size))
            m[:nx, row_x:row_x + nx] = ikc_a
            m[:nx, row_y:row_y + ny] = self.k
            m[nx:, row_x:row_x + nx] = -c @ a
            m[nx:, row_y:row_y + ny] = np.eye(ny)
            if self.lag == 0:    # and the outputs H x+ of the new state, in the same product
                m = np.vstack([m, self.model.h @ m[:nx]])
            self.step_cache[key] = m
        return m


def design(model: VehicleModel, *, dt_s: float, speed_mps: float,
           noise_deflection_m: float, noise_roll_rad: float, road_gd_m3: float,
           lag: int = 0, correlation_length_m: float = 0.8, force_psd: float = FORCE_PSD,
           roll_moment_psd: float = ROLL_MOMENT_PSD, key: tuple = (),
           friction_damping_nspm: tuple = (), excluded: tuple = ()) -> Gains:
    """Discretize the model and design the steady-state Kalman filter and smoothers.

    Parameters
    ----------
    model : VehicleModel
        The vehicle (:mod:`..models`): its linear model at this operating point.
    dt_s : float
        Sample step (s).
    speed_mps : float
        Speed (m/s).
    noise_deflection_m, noise_roll_rad : float
        Sensor noise standard deviations (m, rad); floored at :data:`NOISE_FLOOR_M` (the roll:
        the model's floor for it, :meth:`.VehicleModel.roll_noise_floor`).
    road_gd_m3 : float
        ``Gd(n0)`` of the road (m^3).
    lag : int
        Fixed lag N (samples) of the smoothed output matrix.
    correlation_length_m : float
        ``lambda_v`` (m).
    force_psd, roll_moment_psd : float
        Process-noise densities (see :meth:`.VehicleModel.continuous`).
    friction_damping_nspm : tuple
        The leaf-spring friction's equivalent damping (N s/m) per element in the design.
    excluded : tuple of int
        Channels not fed (a stuck sensor): designed as missing, their noise variance
        :data:`EXCLUDED_VARIANCE_FACTOR` times larger (their gains about 0).

    Returns
    -------
    Gains
    """
    cm = model.continuous(speed_mps, road_gd_m3, correlation_length_m=correlation_length_m,
                          force_psd=force_psd, roll_moment_psd=roll_moment_psd,
                          friction_damping_nspm=friction_damping_nspm)
    a, q = van_loan(cm.a, cm.g, cm.q, dt_s)
    c = cm.c
    sq = max(noise_deflection_m, NOISE_FLOOR_M)
    sp = max(noise_roll_rad, model.roll_noise_floor(NOISE_FLOOR_M))
    nx, ny = cm.nx, cm.ny
    scale = model.state_scale(nx)
    sq, sp, r, p, s, k, ikc = _stable_gain(model, a, c, q, sq, sp, noise_deflection_m, dt_s,
                                           scale, excluded)
    pf = ikc @ p @ ikc.T + k @ r @ k.T          # Joseph form, symmetric
    pf = 0.5 * (pf + pf.T)
    lag = int(lag)
    lag_gains = _lag_gains(a, c, s, ikc, pf, lag)
    t_sm = model.sm_injection(nx)
    out = _output_matrix(cm.h, t_sm, lag_gains)
    # a-posteriori output error y - C x+ = (I - C K) nu: covariance (I - CK) S (I - CK)^T
    ick = np.eye(ny) - c @ k
    post = ick @ s @ ick.T
    f_closed = ikc @ a
    settle = _settling_time(f_closed, cm.h[list(model.load_outputs)], dt_s, pf, scale)
    return Gains(key, dt_s, abs(speed_mps), sq, sp, road_gd_m3, lag, cm, a, q, r, p, pf, s, k,
                 lag_gains, out, np.sqrt(np.maximum(np.diag(post), 0.0)), settle, t_sm,
                 excluded=tuple(int(j) for j in excluded))


def _stable_gain(model: VehicleModel, a, c, q, sq: float, sp: float, noise_deflection_m: float,
                 dt_s: float, scale: np.ndarray, excluded: tuple = ()):
    """The Kalman gain at the noise levels sq (m), sp (rad), raised threefold until the
    filter is stable; ``(sq, sp, R, P, S, K, I - K C)``."""
    while True:
        # Where double precision cannot give a stabilising solution (noise-free data: the
        # measured states known to ~1e-9 against road states of ~1), the noise levels are
        # raised threefold until it can (the measurement-noise floor a user would add).
        r = np.diag(model.measurement_variances(sq, sp))
        for j in excluded:
            r[j, j] *= EXCLUDED_VARIANCE_FACTOR
        nx = a.shape[0]
        try:
            p = solve_dare(a, c, q, r, scale=scale)
            s = c @ p @ c.T + r
            s = 0.5 * (s + s.T)
            k = np.linalg.solve(s, c @ p).T
            ikc = np.eye(nx) - k @ c
            radius = float(np.max(np.abs(np.linalg.eigvals(ikc @ a))))
        except (ValueError, np.linalg.LinAlgError):
            radius = math.inf
        # (a spectral radius of 1 to rounding is the grade mode: body, wheels and road rising
        # together, which no deflection sees and no load depends on)
        if radius <= 1.0 + 1e-9:
            return sq, sp, r, p, s, k, ikc
        if sq >= MAX_NOISE_FLOOR_M:
            raise ValueError(f'Kalman filter not stable (spectral radius {radius:.6g}) for '
                             f'noise {noise_deflection_m:g} m, dt {dt_s:g} s')
        sq *= 3.0
        sp *= 3.0


def _lag_gains(a, c, s, ikc, pf, lag: int) -> np.ndarray:
    """``B_i = P+ A^T (Phi^T)^(i-1) C^T S^-1`` (lag, nx, ny), ``Phi = A (I - K C)``."""
    sinv = np.linalg.inv(s)
    phi = a @ ikc
    lag_gains = np.zeros((lag, a.shape[0], c.shape[0]))
    mpow = pf @ a.T
    for i in range(lag):
        lag_gains[i] = mpow @ c.T @ sinv
        mpow = mpow @ phi.T
    return lag_gains


def _output_matrix(h: np.ndarray, t_sm: np.ndarray, lag_gains: np.ndarray) -> np.ndarray:
    """Outputs of sample t from the buffer rows t..t+N: the state estimate x+_t + T rho_t
    through H, the innovations nu_{t+i} through H B_i; (no, row size (N + 1))."""
    lag = lag_gains.shape[0]
    nx = h.shape[1]
    ny = t_sm.shape[1] // 3
    row_rho, row_x, row_nu, _, row_size = row_layout(nx, ny)
    out = np.zeros((h.shape[0], row_size * (lag + 1)))
    out[:, row_rho:row_rho + 3 * ny] = h @ t_sm
    out[:, row_x:row_x + nx] = h
    for i in range(lag):
        col = row_size * (i + 1) + row_nu
        out[:, col:col + ny] = h @ lag_gains[i]
    return out


def _settling_time(f_closed: np.ndarray, h_load: np.ndarray, dt_s: float,
                   p_post: np.ndarray, scale: np.ndarray, *,
                   fraction: float = 0.05, horizon_s: float = 5.0) -> float:
    """Time (s) after which a start-up error of the typical state magnitudes (the error
    dynamics ``F^k``) leaves on the tire forces at most ``fraction`` of its initial effect or
    the filter's own steady-state error std (``H P+ H^T``), whichever is larger."""
    e = np.diag(scale)
    ref = float(np.max(np.abs(h_load @ e)))
    # (a covariance a hair below zero by rounding, at a step the design barely handles: 0)
    floor = math.sqrt(max(0.0, float(np.max(np.diag(h_load @ p_post @ h_load.T)))))
    tol = max(fraction * ref, floor)
    last_big = 0
    steps = int(horizon_s / dt_s)
    for k in range(1, steps + 1):
        e = f_closed @ e
        if float(np.max(np.abs(h_load @ e))) > tol:
            last_big = k
        elif k > 2 * last_big + 50:
            break
    return (last_big + 1) * dt_s
