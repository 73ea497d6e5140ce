"""Model-based observer: draft (being written)."""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np
from scipy import linalg

from road_force_estimator.parameters import VehicleParameters

ISO_N0 = 0.1

# State slots
Q1, Q2, PHI, DQ1, DQ2, DPHI, DZS, W1, W2, DU1, DU2, MR = range(12)
NX = 12
NY = 3

# Linear outputs (rows of H)
OUT_NAMES = ('q1', 'q2', 'phi', 'dq1', 'dq2', 'dphi', 'ddq1', 'ddq2', 'ddphi', 'dzs', 'ddzs',
             'dzu1', 'dzu2', 'ddzu1', 'ddzu2', 'w1', 'w2', 'df1', 'df2', 'fb1', 'fb2')
NO = len(OUT_NAMES)


def road_diffusion(gd_n0_m3: float) -> float:
    return 2.0 * math.pi ** 2 * gd_n0_m3 * ISO_N0 ** 2


def continuous_model(vehicle: VehicleParameters, speed_mps: float, road_gd_m3: float, *,
                     correlation_length_m: float, force_psd: float, roll_moment_psd: float):
    v = vehicle
    mass, ix, s = v.sprung_mass_kg, v.roll_inertia_kgm2, v.half_track_m
    m = v.unsprung_mass_kg
    k = v.suspension_stiffness_npm
    c = v.suspension_damping_nspm
    kt = v.tire_stiffness_npm
    ct = v.tire_damping_nspm
    speed = abs(speed_mps)
    w_v = 2.0 * math.pi * speed / correlation_length_m
    sig = (1.0, -1.0)

    def derivative(x):
        """d/dt of the state (columns of x), and the linear outputs."""
        q = (x[Q1], x[Q2])
        dq = (x[DQ1], x[DQ2])
        fb = [-(k[i] * q[i] + c[i] * dq[i]) for i in range(2)]
        ddzs = (fb[0] + fb[1]) / mass
        ddphi = (s * (fb[0] - fb[1]) + x[MR]) / ix
        dzu = [x[DZS] + sig[i] * s * x[DPHI] - dq[i] for i in range(2)]
        w = (x[W1], x[W2])
        du = (x[DU1], x[DU2])
        dw = [du[i] - dzu[i] for i in range(2)]
        df = [kt[i] * w[i] + ct[i] * dw[i] for i in range(2)]
        ddzu = [(df[i] - fb[i]) / m[i] for i in range(2)]
        ddq = [ddzs + sig[i] * s * ddphi - ddzu[i] for i in range(2)]
        dx = np.zeros_like(x)
        dx[Q1], dx[Q2], dx[PHI] = dq[0], dq[1], x[DPHI]
        dx[DQ1], dx[DQ2], dx[DPHI] = ddq[0], ddq[1], ddphi
        dx[DZS] = ddzs
        dx[W1], dx[W2] = dw[0], dw[1]
        dx[DU1] = -w_v * du[0]
        dx[DU2] = -w_v * du[1]
        out = np.array([q[0], q[1], x[PHI], dq[0], dq[1], x[DPHI], ddq[0], ddq[1], ddphi,
                        x[DZS], ddzs, dzu[0], dzu[1], ddzu[0], ddzu[1], w[0], w[1], df[0],
                        df[1], fb[0], fb[1]])
        return dx, out

    eye = np.eye(NX)
    a, h = derivative(eye)
    # process noise inputs: generalised forces (heave, roll, wheel 1, wheel 2), road, moment
    g = np.zeros((NX, 7))
    # heave force f_s: ddzs += f/M -> ddq_i += f/M, dzs' += f/M
    g[DZS, 0] = 1.0 / mass
    g[DQ1, 0] = g[DQ2, 0] = 1.0 / mass
    g[DPHI, 1] = 1.0 / ix
    g[DQ1, 1] = s / ix
    g[DQ2, 1] = -s / ix
    g[DQ1, 2] = -1.0 / m[0]
    g[DQ2, 3] = -1.0 / m[1]
    g[DU1, 4] = 1.0
    g[DU2, 5] = 1.0
    g[MR, 6] = 1.0
    diffusion = road_diffusion(road_gd_m3) * speed
    qc = np.diag([force_psd, force_psd * s * s, force_psd, force_psd,
                  diffusion * w_v ** 2, diffusion * w_v ** 2, roll_moment_psd])
    return a, g, qc, h


def van_loan(a_c, g_c, q_c, dt_s):
    nx = a_c.shape[0]
    big = np.zeros((2 * nx, 2 * nx))
    big[:nx, :nx] = -a_c
    big[:nx, nx:] = g_c @ q_c @ g_c.T
    big[nx:, nx:] = a_c.T
    e = linalg.expm(big * dt_s)
    a_d = e[nx:, nx:].T
    q_d = a_d @ e[:nx, nx:]
    return a_d, 0.5 * (q_d + q_d.T)


def solve_dare(a, c, q, r, *, rtol=1e-13, max_iter=200):
    """Stabilising P of P = A P A' - A P C'(C P C' + R)^-1 C P A' + Q (SDA doubling)."""
    nx = a.shape[0]
    lr = np.linalg.cholesky(r)
    cw = linalg.solve_triangular(lr, c, lower=True)
    ak = a.T.copy()
    gk = cw.T @ cw
    hk = 0.5 * (q + q.T)
    eye = np.eye(nx)
    for _ in range(max_iter):
        w = eye + gk @ hk
        aw = np.linalg.solve(w.T, ak.T).T
        a_next = aw @ ak
        g_next = gk + aw @ gk @ ak.T
        h_next = hk + ak.T @ hk @ np.linalg.solve(w, ak)
        g_next = 0.5 * (g_next + g_next.T)
        h_next = 0.5 * (h_next + h_next.T)
        done = np.max(np.abs(h_next - hk)) <= rtol * np.max(np.abs(h_next))
        ak, gk, hk = a_next, g_next, h_next
        if done:
            return hk
    raise ValueError('no convergence')
