"""The calibration's interval covariance against independent references: the direct double
sum of its definition, and the exact covariance of least squares under AR(1) noise."""
import types

import numpy as np
import pytest
from scipy import linalg, signal

from road_force_estimator.calibration.covariance import (
    covariance, sandwich_middle, window_lags)

N, P = 3000, 4


def _design():
    """Smooth regressors (as a fit's Jacobian: body modes), one (n, 3, p) block per channel."""
    t = np.arange(N) / 200.0
    x = np.stack([np.sin(2 * np.pi * f * t + ph)
                  for f, ph in ((0.7, 0.0), (1.3, 1.0), (3.1, 2.0), (0.2, 0.5))], axis=1)
    return x[:, None, :] * np.array([1.0, 0.5, -0.3])[None, :, None]


def test_middle_is_the_double_sum_of_its_definition():
    jac = _design()[:400]
    res = np.random.default_rng(3).standard_normal((400, 3))
    lags = 7
    x = res - res.mean(axis=0)
    want = np.zeros((P, P))
    n = x.shape[0]
    for a in range(3):
        for b in range(3):
            for k in range(-lags, lags + 1):
                lo, hi = max(0, -k), min(n, n - k)          # t with t + k inside
                c = x[lo:hi, a] @ x[lo + k:hi + k, b] / n
                cross = jac[lo:hi, a].T @ jac[lo + k:hi + k, b]
                want += (1.0 - abs(k) / (lags + 1.0)) * c * cross
    assert np.allclose(sandwich_middle(jac, res, lags), want, rtol=1e-12, atol=1e-12)


def test_white_residuals_get_a_short_window():
    res = np.random.default_rng(4).standard_normal((5000, 3))
    assert window_lags(res, 500) <= 10
    ar = signal.lfilter([1.0], [1.0, -0.9], res, axis=0)
    assert 30 <= window_lags(ar, 500) <= 200                # 0.9^k under 0.03: k ~ 35


@pytest.mark.parametrize('rho, tol', [(0.0, 0.05), (0.9, 0.15)])
def test_standard_errors_match_the_exact_ones_under_ar1_noise(rho, tol):
    """Least squares of independent AR(1) noise on the regressors: the exact covariance is
    (J'J)^-1 J' R J (J'J)^-1 with R_ij = rho^|i-j| / (1 - rho^2) per channel."""
    block = _design()
    jac = block.reshape(-1, P)
    toeplitz = linalg.toeplitz(rho ** np.arange(N)) / (1.0 - rho ** 2)
    inv = np.linalg.inv(jac.T @ jac)
    exact = inv @ sum(block[:, c].T @ toeplitz @ block[:, c] for c in range(3)) @ inv
    rng = np.random.default_rng(5)
    ratios = []
    for _ in range(20):
        e = signal.lfilter([1.0], [1.0, -rho], rng.standard_normal((N, 3)), axis=0).ravel()
        beta, *_ = np.linalg.lstsq(jac, e, rcond=None)
        cov, deficient, _ = covariance(types.SimpleNamespace(jac=jac, fun=e - jac @ beta), 400)
        assert not deficient.any()
        ratios.append(np.sqrt(np.diag(cov) / np.diag(exact)))
    # The Bartlett window trades a little bias (measured 0.91-0.98 at rho 0.9) for variance.
    assert np.mean(ratios, axis=0) == pytest.approx(np.ones(P), abs=tol)


def test_rank_deficient_column_is_flagged():
    jac = _design().reshape(-1, P)
    jac = np.column_stack([jac, jac[:, 0] * 2.0])
    fun = np.random.default_rng(6).standard_normal(jac.shape[0])
    cov, deficient, _ = covariance(types.SimpleNamespace(jac=jac, fun=fun), 10)
    assert deficient.sum() == 1 and np.isnan(cov[deficient]).all()
    assert np.isfinite(cov[np.ix_(~deficient, ~deficient)]).all()
