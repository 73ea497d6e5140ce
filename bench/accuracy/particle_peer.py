"""A near-optimal nonlinear reference: a Rao-Blackwellised particle fixed-lag smoother on the
truth's own roll-plane model with the leaf-spring friction (issue 30, ``friction_lag_bound``).

Model: :class:`bench.accuracy.peers.RollPlaneKalman`'s (its states, road model, roll moment and
sensor-lag states, its noise and measurement noise ``R``) plus the friction of the plant
(:mod:`road_force_estimator.core.vehicle_model`): per spring ``f_i = -F_f tanh(dq_i / v_f)``
(N, > 0 pushing the body up and the axle down) added to the suspension force, i.e. the
generalised force ``D^T f`` (``q = D p``). The sample step is cut into ``substeps`` sub-steps,
exact for the linear part and the noise (Van Loan), the friction held over each.

Why not a particle filter on the whole state: the road's noise reaches the deflections only
two and three samples later, so a one-step proposal scatters 16 states blindly and the weights
collapse (tried: the effective sample size fell to 1 of 2000 within ten samples on the matched
drive). Instead only the rates are sampled: given the rates dq at every sub-step the model is
linear-Gaussian (the friction a known input), so each particle carries a Kalman mean of the
state conditioned on its sampled rates and the measurements, and all particles share one
covariance (it depends on neither). Per sub-step: draw dq ~ N(H m, H P H^T) per particle,
condition the mean on it (an exact pseudo-measurement), predict with the friction ``f(dq)``;
per sample: weigh by ``p(y | the particle's rates, y so far) = N(y; C m, S)``, update,
resample (systematic, when the effective sample size is below half the particles).

Look-ahead: a particle whose rates went wrong keeps them (its own covariance says it knows
them) and only the weights of later samples find it out; alone, such particles ran away
within a second (tried: loads of 1e20 N). So the weights carry a look-ahead (Lin, Chen & Liu
2013): the target at sample k is the posterior times ``p^(y_{k+1..k+A} | the particle)``, each
particle's mean rolled out A samples with its friction and the linear model's covariance,
and the weight's step is ``p(y_{k+1} | ...) p^_{k+1} / p^_k``.

Fixed lag L: the population at sample k has seen y up to k + A, so sample j is read out at
j + L - A: each particle's mean of (load, rate) at j, kept in a ring of slots augmenting the
Kalman state (their covariance shared too), moved by the linear smoother's step over the
look-ahead's residuals, and weighted by the target's weights: nothing after j + L is used.
(Reading out at j + L with the look-ahead divided out of the weights read past the lag: on
the linear drive with L = 0 its error was half the Kalman filter's.) Exact as N grows when
the model is linear; with friction, the last A samples enter through each particle's
rollout (its friction along its own mean path), so A = L is the most approximate and the
study compares A = L with a shorter one.

Without friction the model is linear-Gaussian and the estimate tends to the Kalman fixed-lag
smoother's (:class:`.SteadyStateKalman`; the particles start from its stationary posterior).
"""
from __future__ import annotations

from dataclasses import dataclass, field
import time

import numpy as np
from scipy import linalg

from bench.accuracy.peers import RollPlaneKalman
from road_force_estimator.core.friction import tanh_forces
from road_force_estimator.core.parameters import VehicleParameters
from road_force_estimator.estimation.observer.riccati import van_loan
from road_force_estimator.estimation.reconstruction import load_transfer_ratios


@dataclass
class ParticleResult:
    """Row j of every array is the estimate for sample j given y up to j + lag.

    Attributes
    ----------
    wheel_load_n : (n, 2) vertical wheel loads (N), [left, right].
    road_m : (n, 2) NaN (only the loads are estimated).
    ltr : (n,) load transfer ratio.
    dq_mps : (n, 2) suspension rates (m/s, > 0 extending).
    friction_n : (n, 2) the friction force on the body at each particle's rate, weighted (N,
        > 0 upward).
    ess : (n,) effective sample size after each sample's weighing (before any resampling).
    resampled : number of resamplings.
    cpu_s : CPU seconds of the run.
    latency_samples : the lag L.
    extra : settings.
    """

    wheel_load_n: np.ndarray
    road_m: np.ndarray
    ltr: np.ndarray
    dq_mps: np.ndarray
    friction_n: np.ndarray
    ess: np.ndarray
    resampled: int
    cpu_s: float
    latency_samples: int
    extra: dict = field(default_factory=dict)


class FrictionRollPlane:
    """The roll-plane model of :class:`RollPlaneKalman` with the plant's tanh leaf-spring
    friction (``vehicle.leaf_spring_friction`` N per spring, ``vehicle.leaf_spring_friction_
    velocity`` m/s) on sub-steps of ``dt_s / substeps`` (module notes).

    ``tuning``: :class:`RollPlaneKalman`'s keyword arguments (noise included).
    """

    def __init__(self, vehicle: VehicleParameters, dt_s: float, speed_mps: float, *,
                 substeps: int = 4, **tuning) -> None:
        lin = self.linear = RollPlaneKalman(vehicle, dt_s, speed_mps, **tuning)
        nx = self.nx = lin.nx
        self.substeps = int(substeps)
        self.friction_n = np.asarray(vehicle.leaf_spring_friction_n, dtype=float)
        self.v_f = float(vehicle.leaf_spring_friction_velocity_mps)
        d = lin.deflection_map
        # the friction's generalised force D^T f into the velocity rows, per unit force
        g_f = np.zeros((nx, 2))
        g_f[4:8] = d.T / lin.masses[:, None]
        #: dx/dt = a_continuous x + friction_input f (+ noise)
        self.friction_input = g_f
        h = dt_s / self.substeps
        big = np.zeros((nx + 2, nx + 2))
        big[:nx, :nx] = lin.a_continuous
        big[:nx, nx:] = g_f
        e = linalg.expm(big * h)
        #: one sub-step: x <- a_h x + b_h f + w, w ~ N(0, q_h)
        self.a_h, self.b_h = e[:nx, :nx], e[:nx, nx:]
        e = linalg.expm(big * dt_s)
        #: one sample, the friction held (the look-ahead's rollout)
        self.a_1, self.b_1 = e[:nx, :nx], e[:nx, nx:]
        self.q_h = van_loan(lin.a_continuous, lin.g_continuous, lin.q_continuous, h)[1]
        #: rates dq = rate_map x (m/s)
        self.rate_map = np.zeros((2, nx))
        self.rate_map[:, 4:8] = d
        self.c, self.r = lin.kf.c, lin.kf.r

    def lookahead_noise(self, steps: int) -> tuple[np.ndarray, np.ndarray]:
        """``O`` (3 steps, nx), the rows ``C A^j`` (j = 1..steps, one sample each), and the
        covariance (3 steps, 3 steps) of the process and measurement noise in those
        measurements."""
        a, q, c, nx = self.linear.kf.a, self.linear.kf.q, self.c, self.nx
        obs, acc, powers = [], [], [np.eye(nx)]
        v = np.zeros((nx, nx))
        for _ in range(steps):
            v = a @ v @ a.T + q                 # the noise accumulated by step j
            acc.append(v)
            powers.append(a @ powers[-1])
            obs.append(c @ powers[-1])
        cov = np.zeros((3 * steps, 3 * steps))
        for j in range(steps):
            for jj in range(j, steps):
                block = c @ acc[j] @ powers[jj - j].T @ c.T
                cov[3 * j:3 * j + 3, 3 * jj:3 * jj + 3] = block
                cov[3 * jj:3 * jj + 3, 3 * j:3 * j + 3] = block.T
            cov[3 * j:3 * j + 3, 3 * j:3 * j + 3] += self.r
        return np.vstack(obs), cov

    def friction(self, dq: np.ndarray) -> np.ndarray:
        """The friction forces on the body (N, > 0 upward) at rates dq (m/s), (..., 2)."""
        return tanh_forces(self.friction_n, dq, self.v_f)


def particle_fixed_lag(t_s, q_m, roll_rad, speed_mps, vehicle: VehicleParameters, *,
                       n_particles: int = 2000, lag_samples: int = 10, seed: int = 0,
                       substeps: int = 4, lookahead: int = 10, **tuning) -> ParticleResult:
    """The particle fixed-lag smoother (module notes) on the measurements (the peers'
    arguments, :mod:`bench.accuracy.peers`: uniform ``t_s`` (s), ``q_m`` (n, 2) m,
    ``roll_rad`` (n,), speed m/s), ``vehicle`` the truth's (friction included).

    ``lookahead`` (samples, at most ``lag_samples``): the look-ahead of the weights; sample j
    is read out at j + lag - lookahead (nothing after j + lag used).
    ``tuning``: :class:`RollPlaneKalman`'s keyword arguments (``noise_deflection_m``,
    ``noise_roll_rad``, ``force_psd``, ...); ``profile_cutoff_wavelength_m`` is ignored.
    """
    c0 = time.process_time()
    t_s = np.asarray(t_s, dtype=float)
    dt_s = float(np.median(np.diff(t_s)))
    speed = np.broadcast_to(np.asarray(speed_mps, dtype=float), t_s.shape)
    tuning = {k: v for k, v in tuning.items() if k != 'profile_cutoff_wavelength_m'}
    model = FrictionRollPlane(vehicle, dt_s, float(np.mean(np.abs(speed))), substeps=substeps,
                              **tuning)
    lin, kf = model.linear, model.linear.kf
    y = np.column_stack([q_m, roll_rad])
    n, big_n, lag = y.shape[0], int(n_particles), int(lag_samples)
    ahead = min(max(int(lookahead), 0), lag)
    behind = lag - ahead                      # sample j is read out at j + behind
    nx, slots = model.nx, behind + 1
    nz = nx + 4 * slots                       # the state and a ring of (load, rate) per sample
    rng = np.random.default_rng(seed)
    static = np.asarray(vehicle.static_load_n, dtype=float)
    h_slot = np.vstack([lin.h_force, model.rate_map])     # dF (N), dq (m/s) of the state
    hq = np.zeros((2, nz))
    hq[:, :nx] = model.rate_map
    cz = np.zeros((3, nz))
    cz[:, :nx] = model.c
    a_z = np.eye(nz)
    a_z[:nx, :nx] = model.a_h
    q_z = np.zeros((nz, nz))
    q_z[:nx, :nx] = model.q_h
    a_zt, a_ht, b_t = a_z.T, model.a_h.T, model.b_h.T
    fric = bool(np.any(model.friction_n > 0.0))
    obs, noise_y = model.lookahead_noise(max(ahead, 1))
    a1t, b1t, ct = model.a_1.T, model.b_1.T, model.c.T

    def slot(j: int) -> slice:
        return slice(nx + 4 * (j % slots), nx + 4 * (j % slots) + 4)

    def store(j: int) -> None:
        """Put the load and rate of sample j (linear in the state) in its ring slot."""
        s = slot(j)
        m[:, s] = m[:, :nx] @ h_slot.T
        p[s, :] = h_slot @ p[:nx, :]
        p[:, s] = p[s, :].T
        p[s, s] = h_slot @ p[:nx, :nx] @ h_slot.T

    def look(k: int):
        """log p^(y_{k+1..k+ahead} | the particle) (constants dropped), each mean rolled out
        with its friction and the linear model's covariance, and for the read-out the
        residuals whitened ``z`` and the covariance's Cholesky factor and rows ``O``."""
        steps = min(ahead, n - 1 - k)
        if steps <= 0:
            return np.zeros(big_n), None
        o = obs[:3 * steps]
        cov = o @ p[:nx, :nx] @ o.T + noise_y[:3 * steps, :3 * steps]
        root = np.linalg.cholesky(0.5 * (cov + cov.T))
        xr = m[:, :nx]
        res = np.empty((big_n, 3 * steps))
        for j in range(steps):
            xr = xr @ a1t
            if fric:
                xr += model.friction(xr @ model.rate_map.T) @ b1t
            res[:, 3 * j:3 * j + 3] = y[k + 1 + j] - xr @ ct
        z = linalg.solve_triangular(root, res.T, lower=True)
        return -0.5 * np.einsum('ij,ij->j', z, z), (z, root, o)

    def read_out(j: int, w: np.ndarray, ahead_fit) -> None:
        """Sample j from the ring, each particle's mean moved by the look-ahead's residuals
        (the linear smoother's step over them), weighted."""
        mean = m[:, slot(j)]
        if ahead_fit is not None:
            z, root, o = ahead_fit
            gain = p[slot(j), :nx] @ o.T                          # (4, 3 steps)
            mean = mean + (gain @ linalg.solve_triangular(root.T, z, lower=False)).T
        est[j, 0:2] = static + w @ mean[:, 0:2]
        est[j, 2:4] = w @ mean[:, 2:4]
        est[j, 4:6] = w @ model.friction(mean[:, 2:4])

    # start: the Kalman filter's stationary posterior given y_0, the same for every particle
    x0 = lin.prior(y[0])
    x0 = x0 + kf.k @ (y[0] - kf.c @ x0)
    m = np.zeros((big_n, nz))
    m[:, :nx] = x0
    p = np.zeros((nz, nz))
    p[:nx, :nx] = kf.p_post
    store(0)
    est = np.full((n, 6), np.nan)             # load (2), dq (2), friction (2)
    ess = np.empty(n)
    ess[0] = big_n
    resampled = 0
    ahead_ll, fit = look(0)
    logw = ahead_ll.copy()
    w = np.full(big_n, 1.0 / big_n)
    if behind == 0:
        read_out(0, w, fit)
    for k in range(n - 1):
        # the sub-steps from sample k to k + 1: draw the rates, condition on them, predict
        for _ in range(model.substeps):
            s_dq = hq @ p @ hq.T + 1e-18 * np.eye(2)
            s_dq = 0.5 * (s_dq + s_dq.T)
            root = np.linalg.cholesky(s_dq)
            gain = np.linalg.solve(s_dq, hq @ p).T                  # (nz, 2)
            eps = rng.standard_normal((big_n, 2))
            dq = m @ hq.T + eps @ root.T
            m += eps @ (gain @ root).T
            p = p - gain @ (hq @ p)
            m[:, :nx] = m[:, :nx] @ a_ht        # the ring stays
            if fric:
                m[:, :nx] += model.friction(dq) @ b_t
            p = a_z @ p @ a_zt + q_z
            p = 0.5 * (p + p.T)
        # the sample k + 1: weigh (this sample, the look-ahead's change), update, resample
        s_y = cz @ p @ cz.T + model.r
        innov = y[k + 1] - m @ cz.T
        z = np.linalg.solve(np.linalg.cholesky(s_y), innov.T)
        logw += -0.5 * np.einsum('ij,ij->j', z, z) - ahead_ll
        gain = np.linalg.solve(s_y, cz @ p).T                           # (nz, 3)
        m += innov @ gain.T
        p = p - gain @ (cz @ p)
        p = 0.5 * (p + p.T)
        store(k + 1)
        ahead_ll, fit = look(k + 1)
        logw += ahead_ll
        logw -= logw.max()
        w = np.exp(logw)
        w /= w.sum()
        ess[k + 1] = 1.0 / float(w @ w)
        if ess[k + 1] < 0.5 * big_n:
            idx = _systematic(w, rng)
            m, ahead_ll = m[idx], ahead_ll[idx]
            if fit is not None:
                fit = (fit[0][:, idx], fit[1], fit[2])
            logw = np.zeros(big_n)
            w = np.full(big_n, 1.0 / big_n)
            resampled += 1
        if k + 1 >= behind:
            read_out(k + 1 - behind, w, fit)
    for j in range(max(n - behind, 0), n):    # the record's end: what there is
        read_out(j, w, fit)
    load = est[:, 0:2]
    return ParticleResult(load, np.full((n, 2), np.nan),
                          load_transfer_ratios(load[:, 0], load[:, 1], 1.0), est[:, 2:4],
                          est[:, 4:6], ess, resampled, time.process_time() - c0, lag,
                          {'n_particles': big_n, 'substeps': model.substeps, 'seed': seed,
                           'lookahead': ahead})


def _systematic(w: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Systematic resampling: the indices of N draws from the weights ``w`` (sum 1)."""
    big_n = w.size
    u = (rng.random() + np.arange(big_n)) / big_n
    return np.minimum(np.searchsorted(np.cumsum(w), u), big_n - 1)
