"""Exact discretization and the discrete algebraic Riccati equation (the model's gains).

:func:`van_loan` discretizes ``dx = A x dt + G dW`` exactly; :func:`solve_dare` solves the
filter Riccati equation by structured doubling, on scaled states (the vehicle model's
typical state magnitudes).
"""
from __future__ import annotations

import numpy as np
from scipy import linalg

__all__ = ['van_loan', 'solve_dare']


def van_loan(a_c: np.ndarray, g_c: np.ndarray, q_c: np.ndarray,
             dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact discretization ``(A_d, Q_d)`` of ``dx = A x dt + G dW`` at step dt (Van Loan 1978)."""
    nx = a_c.shape[0]
    big = np.zeros((2 * nx, 2 * nx))
    big[:nx, :nx] = -a_c
    big[:nx, nx:] = g_c @ q_c @ g_c.T
    big[nx:, nx:] = a_c.T
    e = linalg.expm(big * dt_s)
    a_d = e[nx:, nx:].T
    q_d = a_d @ e[:nx, nx:]
    return a_d, 0.5 * (q_d + q_d.T)


def solve_dare(a: np.ndarray, c: np.ndarray, q: np.ndarray, r: np.ndarray, *,
               scale: np.ndarray | None = None, rtol: float = 1e-13,
               max_iter: int = 200) -> np.ndarray:
    """Stabilising solution P of ``P = A P A^T - A P C^T (C P C^T + R)^-1 C P A^T + Q``.

    Structured doubling algorithm (SDA; Chu, Fan, Lin, Linear Algebra Appl. 396, 2005) on the
    states scaled by ``scale`` (comparable magnitudes): with ``A_0 = A^T``,
    ``G_0 = C^T R^-1 C``, ``H_0 = Q`` and ``W = I + G_k H_k``, ``A_{k+1} = A_k W^-1 A_k``,
    ``G_{k+1} = G_k + A_k W^-1 G_k A_k^T``, ``H_{k+1} = H_k + A_k^T H_k W^-1 A_k -> P``.
    Each iteration doubles the horizon, so slow modes converge in a few dozen iterations.

    Raises
    ------
    ValueError
        No convergence in ``max_iter`` doublings (the pair is not stabilisable/detectable).
    """
    nx = a.shape[0]
    sc = np.ones(nx) if scale is None else np.asarray(scale, dtype=float)
    si = 1.0 / sc
    a_s = a * si[:, None] * sc[None, :]
    c_s = c * sc[None, :]
    q_s = q * np.outer(si, si)
    lr = np.linalg.cholesky(r)
    cw = linalg.solve_triangular(lr, c_s, lower=True)
    ak = a_s.T.copy()
    gk = cw.T @ cw
    hk = 0.5 * (q_s + q_s.T)
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
            return hk * np.outer(sc, sc)
    raise ValueError(f'Riccati equation: no convergence in {max_iter} doubling steps')
