"""Exact discretization and the Riccati solver (estimation/riccati.py): numerical quadrature,
scipy's ``solve_discrete_are``.
"""

import numpy as np
from scipy import integrate, linalg

from model_observer_data import SPEED, VEHICLE
from road_force_estimator.estimation.models.front_axle import FrontAxleModel
from road_force_estimator.estimation.observer.gains import design
from road_force_estimator.estimation.models.front_axle import continuous_model
from road_force_estimator.estimation.observer.riccati import van_loan


class TestRiccati:
    def test_van_loan_equals_quadrature(self):
        model = continuous_model(VEHICLE, SPEED, 256e-6)
        dt = 2e-3
        a_d, q_d = van_loan(model.a, model.g, model.q, dt)
        np.testing.assert_allclose(a_d, linalg.expm(model.a * dt), rtol=1e-12, atol=1e-14)
        gqg = model.g @ model.q @ model.g.T

        def integrand(t):
            e = linalg.expm(model.a * t)
            return e @ gqg @ e.T

        ref, _ = integrate.quad_vec(integrand, 0.0, dt, epsabs=0.0, epsrel=1e-10)
        scale = np.sqrt(np.outer(np.diag(ref), np.diag(ref))) + 1e-300
        assert np.max(np.abs(q_d - ref) / scale) < 1e-7


    def test_riccati_matches_scipy_where_scipy_solves_it(self):
        g = design(FrontAxleModel(VEHICLE), dt_s=1e-3, speed_mps=SPEED, noise_deflection_m=1e-5,
                      noise_roll_rad=1e-4, road_gd_m3=256e-6)
        ref = linalg.solve_discrete_are(g.a.T, g.model.c.T, g.q, g.r)
        np.testing.assert_allclose(g.p_prior, ref, rtol=1e-5,
                                   atol=1e-9 * np.max(np.abs(ref)))

