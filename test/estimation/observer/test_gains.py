"""The gains (estimation/gains.py): the Riccati equation itself, the Kalman gain, stability.
"""

import numpy as np
import pytest

from model_observer_data import SPEED, VEHICLE
from road_force_estimator.estimation.models.front_axle import FrontAxleModel
from road_force_estimator.estimation.observer.gains import design


class TestGains:
    @pytest.mark.parametrize('noise', [1e-5, 1e-7])
    def test_gains_satisfy_the_riccati_equation(self, noise):
        g = design(FrontAxleModel(VEHICLE), dt_s=1e-3, speed_mps=SPEED, noise_deflection_m=noise,
                      noise_roll_rad=10.0 * noise, road_gd_m3=256e-6)
        a, c, q, r, p = g.a, g.model.c, g.q, g.r, g.p_prior
        rhs = a @ p @ a.T - a @ p @ c.T @ np.linalg.solve(c @ p @ c.T + r, c @ p @ a.T) + q
        assert np.max(np.abs(rhs - p)) <= 1e-8 * np.max(np.abs(p))
        np.testing.assert_allclose(g.k, p @ c.T @ np.linalg.inv(c @ p @ c.T + r), rtol=1e-6,
                                   atol=1e-12 * np.max(np.abs(g.k)))
        assert np.max(np.abs(np.linalg.eigvals((np.eye(12) - g.k @ c) @ a))) < 1.0

