"""The roll-plane model of the observer (estimation/model.py): its equations against the plant
helper's linearised model (``VehicleModel.linearised``)."""

import math

import numpy as np
import pytest

from road_force_estimator.core.vehicle_model import VehicleModel
from model_observer_data import ASYM, SPEED, VEHICLE
from road_force_estimator.estimation.models.front_axle import OUTPUTS, continuous_model


class TestModel:
    @pytest.mark.parametrize('vehicle', [VEHICLE, ASYM])
    def test_equations_match_the_linearised_plant_model(self, vehicle):
        # Map random plant states (z_s, phi, z_u, rates) and road (u, du) to the observer's
        # coordinates; the observer's A must give the accelerations of VehicleModel's
        # linearised matrices (written by another helper from MODEL.md).
        lin = VehicleModel(vehicle).linearised()
        a_p, b_p = lin.state_matrices()
        model = continuous_model(vehicle, SPEED, 256e-6)
        s = vehicle.half_track_m
        rng = np.random.default_rng(3)
        for _ in range(5):
            xp = rng.normal(0.0, [0.01, 0.01, 0.01, 0.01, 0.1, 0.1, 0.1, 0.1])
            u = rng.normal(0.0, 0.01, 2)
            du = rng.normal(0.0, 0.1, 2)
            ay = rng.normal(0.0, 1.0)
            dxp = a_p @ xp + b_p @ np.concatenate([u, du, [ay]])
            zs, ph, zu1, zu2, dzs, dph, dzu1, dzu2 = xp
            x = np.zeros(12)
            x[:3] = zs + s * ph - zu1, zs - s * ph - zu2, ph
            x[3:6] = dzs + s * dph - dzu1, dzs - s * dph - dzu2, dph
            x[6] = dzs
            x[7:9] = u[0] - zu1, u[1] - zu2
            x[9:11] = du
            x[11] = vehicle.sprung_mass_kg * vehicle.cg_height_m * ay
            dx = model.a @ x
            acc = dxp[4:]
            np.testing.assert_allclose(dx[3], acc[0] + s * acc[1] - acc[2], rtol=1e-9,
                                       atol=1e-9)
            np.testing.assert_allclose(dx[4], acc[0] - s * acc[1] - acc[3], rtol=1e-9,
                                       atol=1e-9)
            np.testing.assert_allclose(dx[5], acc[1], rtol=1e-9, atol=1e-12)
            np.testing.assert_allclose(dx[6], acc[0], rtol=1e-9, atol=1e-12)
            np.testing.assert_allclose(dx[7:9], du - [dzu1, dzu2], rtol=1e-12, atol=1e-15)
            # tire force output: kt (u - z_u) + ct (du - dz_u)
            out = model.h @ x
            df = (np.array(vehicle.tire_stiffness_npm) * (u - [zu1, zu2])
                  + np.array(vehicle.tire_damping_nspm) * (du - [dzu1, dzu2]))
            np.testing.assert_allclose(out[[OUTPUTS.index('df1'), OUTPUTS.index('df2')]],
                                       df, rtol=1e-12)



def test_offline_roll_moment_density_from_the_residual():
    # a random walk of known density (plus white noise, which block means average out) is
    # read back; a straight drive's residual (noise only) gives the floor, a lateral step the
    # load tuning's fast roll moment (the offline profile smoother's, issue 21)
    from road_force_estimator.estimation.models import front_axle as mdl

    rng = np.random.default_rng(3)
    dt, n = 1e-3, 200_000
    q = 1e5
    walk = np.cumsum(rng.normal(0.0, math.sqrt(q * dt), n))
    got = mdl.offline_roll_moment_psd(walk + rng.normal(0.0, 50.0, n), dt)
    assert got == pytest.approx(q, rel=0.25)
    assert mdl.offline_roll_moment_psd(rng.normal(0.0, 50.0, n), dt) == (
        mdl.PROFILE_OFFLINE_ROLL_MOMENT_MIN_PSD)
    step = np.where(np.arange(n) > n // 2, 2e4, 0.0)          # M h a_y of a 3 m/s^2 step
    assert mdl.offline_roll_moment_psd(step, dt) == mdl.PROFILE_OFFLINE_ROLL_MOMENT_PSD
    assert mdl.offline_roll_moment_psd(walk[:3000], dt) == mdl.PROFILE_OFFLINE_ROLL_MOMENT_PSD
