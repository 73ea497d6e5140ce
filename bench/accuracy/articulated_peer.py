"""A Kalman peer of the articulated observer (issue 32): the full linear tractor and
semi-trailer in absolute coordinates with every wheel path's road as a state, tuned on the
truth; causal, exact fixed lag and Rauch-Tung-Striebel smoother.

State ``[x (6 + 2N), dx (6 + 2N), u (2N), a_y,t, a_y,r]``: the coordinates of
:meth:`road_force_estimator.core.articulated_model.ArticulatedModel.dof_names` from static
equilibrium, their rates, the road under every tire (a random walk with a leak at 500 m of
wavelength, as :class:`bench.accuracy.peers.RollPlaneKalman`'s, so that the vehicle and road rising
together decay) and each unit's a_y (a random walk). ``M ddx + C dx + K x = K_u u + l a_y``
(:meth:`~road_force_estimator.core.articulated_model.ArticulatedModel.linearised`; tire
damping 0, so the road rate does not enter), white noise on the road's rate (density
``factor x D v``, D from the drive's true ISO class) and a generalised force noise on every
equation (density ``force_psd``). Measured: the springs' extensions of the instrumented axles
and the rolls, with the true noise. The steady-state gains from the first sample (the exact
filter and smoothers for a stationary prior). Loads: ``dF_j,i = kt (u_j,i - z_w,j,i)``.

``lag_s``: each measured channel's first-order lag (s; 0 = none), as the plant's sensors
apply it (:func:`road_force_estimator.core.sensors.lag_step`, exact for a reading linear over
the step): a lag state per lagged channel, ``m_k = a m_(k-1) + (b - c) y_(k-1) + c y_k`` with
``y = C x`` the true reading, so that the state ``[x, m]`` is exact for the plant's discrete
lag and the measurement is ``m`` (the peer knows the lag as well as the truth).

:func:`tuned` picks ``factor`` and ``force_psd`` per drive and mode from a grid on the truth
(the best a user with the truth could tune: a bound for the package's defaults).
"""
from __future__ import annotations

import math

import numpy as np

from road_force_estimator.core.articulated_model import ArticulatedModel
from road_force_estimator.estimation.observer.riccati import solve_dare, van_loan

__all__ = ['ArticulatedKalmanPeer', 'tuned', 'GRID']

LEAK_WAVELENGTH_M = 500.0
#: The tuning grid: (road-density factor, force-noise density N^2 s).
GRID = tuple((f, p) for f in (0.0625, 0.25, 1.0, 4.0, 16.0) for p in (1e-2, 1.0, 1e2, 1e4))


class ArticulatedKalmanPeer:
    """The peer at one speed, step, noise and road (module notes)."""

    def __init__(self, vehicle, *, speed_mps: float, dt_s: float, noise_m: float,
                 noise_rad: float, road_gd_m3: float, factor: float = 1.0,
                 force_psd: float = 1.0, ay_psd: float = 1e-3,
                 lag_s: tuple[float, ...] = ()) -> None:
        core = ArticulatedModel(vehicle)
        lin = core.linearised()
        springs, wheels, _, _ = core.kinematics()
        n, nw = core.n_dof, 2 * core.n_axles
        nx = 2 * n + nw + 2
        minv = np.linalg.inv(lin.mass)
        lateral = np.zeros((n, 2))
        for b in (0, 1):
            lateral[3 * b + 2, b] = lin.lateral[3 * b + 2]
        for j, a in enumerate(core.axles):
            lateral[6 + 2 * j + 1, core.body_index(a)] = lin.lateral[6 + 2 * j + 1]
        a = np.zeros((nx, nx))
        a[:n, n:2 * n] = np.eye(n)
        a[n:2 * n, :n] = -minv @ lin.stiffness
        a[n:2 * n, n:2 * n] = -minv @ lin.damping
        a[n:2 * n, 2 * n:2 * n + nw] = minv @ lin.road_stiffness
        a[n:2 * n, 2 * n + nw:] = minv @ lateral
        speed = max(abs(speed_mps), 0.5)
        a[2 * n:2 * n + nw, 2 * n:2 * n + nw] = -2.0 * math.pi * speed / LEAK_WAVELENGTH_M * \
            np.eye(nw)
        g = np.zeros((nx, n + nw + 2))
        g[n:2 * n, :n] = minv
        g[2 * n:, n:] = np.eye(nw + 2)
        diffusion = 2.0 * math.pi ** 2 * road_gd_m3 * 0.01 * speed
        qc = np.diag([force_psd] * n + [factor * diffusion] * nw + [ay_psd] * 2)
        ad, qd = van_loan(a, g, qc, dt_s)
        instrumented = [2 * j + s for j, ax in enumerate(core.axles) if ax.instrumented
                        for s in (0, 1)]
        rows = [np.concatenate([springs.reshape(nw, n)[k], np.zeros(nx - n)])
                for k in instrumented]
        for b in ((0, 1) if vehicle.trailer_roll_sensor else (0,)):
            e = np.zeros(nx)
            e[3 * b + 2] = 1.0
            rows.append(e)
        c = np.array(rows)
        r = np.diag([noise_m ** 2] * len(instrumented) + [noise_rad ** 2] * (len(rows) -
                                                                               len(instrumented)))
        scale = np.concatenate([np.full(n, 1e-2), np.full(n, 1e-1), np.full(nw, 1e-2),
                                [1.0, 1.0]])
        h = np.hstack([-wheels.reshape(nw, n), np.zeros((nw, n)), np.eye(nw), np.zeros((nw, 2))])
        if any(t > 0.0 for t in lag_s):
            ad, qd, c, scale, h = _with_lag(ad, qd, c, scale, h, lag_s, dt_s)
            nx = ad.shape[0]
        p = solve_dare(ad, c, qd, r, scale=scale)
        s = c @ p @ c.T + r
        k = np.linalg.solve(s, c @ p).T
        pf = (np.eye(nx) - k @ c) @ p
        self.a, self.c, self.k = ad, c, k
        self.j = np.linalg.solve(p, ad @ pf).T              # RTS: P+ A^T P^-1
        kt = np.array([t for ax in core.axles for t in ax.tire_stiffness_npm])
        self.h = kt[:, None] * h

    def dynamic_loads(self, y: np.ndarray, lag: int | None = 0) -> np.ndarray:
        """Every wheel's dynamic load (nw, m) from the readings y (m, ny): causal (lag 0),
        the exact fixed lag of ``lag`` samples, or the RTS smoother (None)."""
        m = y.shape[0]
        nx = self.a.shape[0]
        xf = np.zeros((m, nx))
        x = np.zeros(nx)
        ikc_a = (np.eye(nx) - self.k @ self.c) @ self.a
        ky = y @ self.k.T
        k0 = self.k @ y[0]
        x = k0
        xf[0] = x
        for i in range(1, m):
            x = ikc_a @ x + ky[i]
            xf[i] = x
        if lag == 0:
            return self.h @ xf.T
        d = xf[1:] - xf[:-1] @ self.a.T               # x+_k - A x+_(k-1) = K nu_k
        if lag is None:                               # RTS, backwards
            xs = xf.copy()
            for i in range(m - 2, -1, -1):
                xs[i] = xf[i] + self.j @ (xs[i + 1] - self.a @ xf[i])
            return self.h @ xs.T
        out = self.h @ xf.T
        hj = self.h
        for i in range(1, lag + 1):                   # x_(t|t+N) = x+_t + sum J^i d_(t+i)
            hj = hj @ self.j
            out[:, :m - i] += hj @ d[i - 1:].T
        return out


def _with_lag(ad, qd, c, scale, h, lag_s, dt_s):
    """The model with a lag state per lagged channel (module notes): ``(A, Q, C, scale, H)``
    of the state ``[x, m]``."""
    from road_force_estimator.core.sensors import lag_coefficients

    lagged = [i for i, t in enumerate(lag_s) if t > 0.0]
    nx, nm = ad.shape[0], len(lagged)
    coef = [lag_coefficients(lag_s[i], dt_s) for i in lagged]
    a_m = np.diag([co[0] for co in coef])
    cl = c[lagged]
    gain_c = np.diag([co[2] for co in coef]) @ cl                 # c C
    a = np.zeros((nx + nm, nx + nm))
    a[:nx, :nx] = ad
    a[nx:, :nx] = np.diag([co[1] - co[2] for co in coef]) @ cl + gain_c @ ad
    a[nx:, nx:] = a_m
    q = np.zeros_like(a)                         # the noise enters x and, through c C, m
    q[:nx, :nx] = qd
    q[:nx, nx:] = qd @ gain_c.T
    q[nx:, :nx] = gain_c @ qd
    q[nx:, nx:] = gain_c @ qd @ gain_c.T
    c_new = np.hstack([c, np.zeros((c.shape[0], nm))])
    for r, i in enumerate(lagged):
        c_new[i] = 0.0
        c_new[i, nx + r] = 1.0
    scale = np.concatenate([scale, np.full(nm, 1e-2)])
    return a, q, c_new, scale, np.hstack([h, np.zeros((h.shape[0], nm))])


def tuned(vehicle, y, true_dyn, judged, lag, **design) -> tuple[np.ndarray, tuple]:
    """The peer's estimate at the grid point (:data:`GRID`) with the least dynamic-load RMS
    error over every wheel on the judged samples (the truth); ``(dynamic loads, (factor,
    force_psd))``."""
    best = None
    for factor, psd in GRID:
        try:
            peer = ArticulatedKalmanPeer(vehicle, factor=factor, force_psd=psd, **design)
        except (ValueError, np.linalg.LinAlgError):
            continue
        est = peer.dynamic_loads(y, lag)
        err = float(np.mean((est[:, judged] - true_dyn[:, judged]) ** 2))
        if math.isfinite(err) and (best is None or err < best[0]):
            best = (err, est, (factor, psd))
    return best[1], best[2]
