"""Light correctness tests of the benchmark's peers (bench/accuracy/peers.py).

References are independent of the code under test: analytic discretizations, the package's
vehicle model (another module) for the physics, a Kalman filter's own error covariance for its
statistical consistency, a state-augmented filter for the fixed-lag smoother, polynomials for
the differentiators, and the plant's ground truth for the reconstruction.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import linalg

from bench.accuracy import peers
from road_force_estimator.core.parameters import VehicleParameters

DT = 1e-3
SPEED = 20.0


def _simulate_own_model(model: peers.RollPlaneKalman, n: int, seed: int,
                        measurement_noise: bool = True):
    """Sample the filter's own discrete model: x_{k+1} = A x_k + w_k, y_k = C x_k + v_k."""
    kf = model.kf
    rng = np.random.default_rng(seed)
    nx = kf.a.shape[0]
    lq = np.linalg.cholesky(kf.q + 1e-30 * np.eye(nx))
    x = np.zeros((n, nx))
    for k in range(1, n):
        x[k] = kf.a @ x[k - 1] + lq @ rng.standard_normal(nx)
    y = x @ kf.c.T
    if measurement_noise:
        y = y + rng.standard_normal(y.shape) * np.sqrt(np.diag(kf.r))
    return x, y


class TestVanLoan:
    def test_double_integrator_matches_the_analytic_covariance(self):
        # x = (p, v), dv = w dt, E[w w] = q: Q_d = q [[dt^3/3, dt^2/2], [dt^2/2, dt]]
        q, dt = 2.5, 0.01
        a = np.array([[0.0, 1.0], [0.0, 0.0]])
        a_d, q_d = peers.van_loan(a, np.array([[0.0], [1.0]]), np.array([[q]]), dt)
        np.testing.assert_allclose(a_d, [[1.0, dt], [0.0, 1.0]], rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(q_d, q * np.array([[dt ** 3 / 3, dt ** 2 / 2],
                                                      [dt ** 2 / 2, dt]]), rtol=1e-9)

    def test_ornstein_uhlenbeck_variance(self):
        # dx = -a x dt + dW (density q): Var step = q (1 - exp(-2 a dt)) / (2 a)
        a, q, dt = 3.0, 0.7, 0.05
        a_d, q_d = peers.van_loan(np.array([[-a]]), np.eye(1), np.array([[q]]), dt)
        assert a_d[0, 0] == pytest.approx(math.exp(-a * dt), rel=1e-12)
        assert q_d[0, 0] == pytest.approx(q * (1 - math.exp(-2 * a * dt)) / (2 * a), rel=1e-9)


class TestRollPlaneModel:
    def test_mechanics_match_the_package_vehicle_model(self):
        """The filter's physics block equals expm of vehicle_model's linearised matrices."""
        from road_force_estimator.core.vehicle_model import VehicleModel

        vehicle = VehicleParameters(tire_damping_nspm=(0.0, 0.0))
        model = peers.RollPlaneKalman(vehicle, DT, SPEED, road_model='position',
                                      noise_deflection_m=1e-5, leak_wavelength_m=1e5)
        a_ref, b_ref = VehicleModel(vehicle).linearised().state_matrices()
        big = np.zeros((10, 10))
        big[:8, :8] = a_ref
        big[:8, 8:10] = b_ref[:, 0:2]              # road elevations, held (random walk mean)
        # the road's leak (1e5 m wavelength) changes its block by ~1e-6 per step
        np.testing.assert_allclose(model.kf.a[:10, :10], linalg.expm(big * DT),
                                   rtol=1e-5, atol=1e-5)

    def test_measurement_and_load_rows(self):
        vehicle = VehicleParameters()
        model = peers.RollPlaneKalman(vehicle, DT, SPEED)
        s = vehicle.half_track_m
        x = np.arange(1.0, model.nx + 1.0) * 1e-3
        zs, phi, zu1, zu2 = x[0:4]
        np.testing.assert_allclose(model.kf.c @ x, [zs + s * phi - zu1, zs - s * phi - zu2, phi])
        kt = vehicle.tire_stiffness_npm
        np.testing.assert_allclose(model.h_force @ x, [kt[0] * (x[8] - zu1),
                                                       kt[1] * (x[9] - zu2)])


    def test_sensor_lag_states(self):
        # a file that states a sensor lag: one first-order state per lagged channel
        # (tau dl/dt = y - l), measured in place of the channel; it feeds nothing back, so the
        # discrete transition is block triangular: the truck's block unchanged, the lag's
        # diagonal exp(-dt / tau)
        from dataclasses import replace
        tau = (0.003, 0.002)
        vehicle = replace(VehicleParameters(), sensor_time_constant_s=tau)
        plain = peers.RollPlaneKalman(VehicleParameters(), DT, SPEED)
        model = peers.RollPlaneKalman(vehicle, DT, SPEED)
        n = plain.nx
        assert model.nx == n + 3
        a = model.kf.a
        np.testing.assert_allclose(np.diag(a)[n:], np.exp(-DT / np.array([tau[0], tau[0],
                                                                          tau[1]])),
                                   rtol=1e-12)
        np.testing.assert_allclose(a[:n, :n], plain.kf.a, rtol=1e-12, atol=1e-15)
        assert not a[:n, n:].any()                   # the sensors do not move the truck
        c = model.kf.c
        np.testing.assert_array_equal(c[:, n:], np.eye(3))
        assert not c[:, :n].any()
        x0 = model.prior(np.array([0.01, -0.02, 0.003]))
        np.testing.assert_allclose(x0[n:], [0.01, -0.02, 0.003])


class TestKalmanOnItsOwnModel:
    @pytest.fixture(scope='class')
    @staticmethod
    def run():
        vehicle = VehicleParameters()
        model = peers.RollPlaneKalman(vehicle, DT, SPEED, road_gd_m3=256e-6, force_psd=1e2,
                                      noise_deflection_m=1e-5, noise_roll_rad=1e-4,
                                      noise_floor_m=0.0, leak_wavelength_m=200.0)
        x, y = _simulate_own_model(model, 12000, seed=3)
        xf = model.kf.filter(y, np.zeros(model.nx))
        return model, x, y, xf

    def test_filter_error_matches_its_own_covariance(self, run):
        """An exact Kalman filter's empirical error covariance equals its computed P_f."""
        model, x, _, xf = run
        skip = 2000
        err = (xf - x)[skip:] @ model.h_force.T
        predicted = np.sqrt(np.diag(model.h_force @ model.kf.p_post @ model.h_force.T))
        empirical = np.sqrt(np.mean(err ** 2, axis=0))
        np.testing.assert_allclose(empirical, predicted, rtol=0.1)

    def test_smoothers_are_never_worse_than_the_filter(self, run):
        model, x, _, xf = run
        skip = 2000

        def load_rms(est):
            return float(np.sqrt(np.mean(((est - x)[skip:-20] @ model.h_force.T) ** 2)))

        e_filter = load_rms(xf)
        e_lag5 = load_rms(model.kf.fixed_lag(xf, 5))
        e_lag10 = load_rms(model.kf.fixed_lag(xf, 10))
        e_rts = load_rms(model.kf.rts(xf))
        assert e_rts <= e_lag10 * 1.01
        assert e_lag10 <= e_lag5 * 1.01
        assert e_lag5 < e_filter
        assert e_rts < 0.5 * e_filter

    def test_noise_free_data_recovers_loads_with_a_short_lag(self):
        """On noise-free data from the model (smooth road: velocity model), the loads are known
        a few samples later. (With a Brownian road, 'position' model, the road at the sample
        instant keeps a Brownian-bridge uncertainty of about kt sqrt(D v dt / 12).)"""
        vehicle = VehicleParameters()
        model = peers.RollPlaneKalman(vehicle, DT, SPEED, road_model='velocity',
                                      road_gd_m3=256e-6, force_psd=1e-6,
                                      noise_deflection_m=0.0, noise_roll_rad=0.0,
                                      noise_floor_m=1e-9, leak_wavelength_m=200.0)
        x, y = _simulate_own_model(model, 6000, seed=5, measurement_noise=False)
        xf = model.kf.filter(y, np.zeros(model.nx))
        true_rms = np.sqrt(np.mean((x @ model.h_force.T)[1000:] ** 2))

        def rel_err(est):
            return np.sqrt(np.mean((((est - x) @ model.h_force.T)[1000:-10]) ** 2)) / true_rms

        assert rel_err(model.kf.fixed_lag(xf, 4)) < 0.01
        assert rel_err(xf) > 0.015


class TestFixedLagIsExact:
    def test_matches_a_state_augmented_filter(self):
        """The RTS-window fixed-lag smoother equals the filter of the lag-augmented state."""
        lag = 3
        a, q = peers._irw_model(3, 1e4, DT)
        c = np.array([[1.0, 0.0, 0.0]])
        r = np.array([[1e-8]])
        scale = np.array([1e-4, 1e-1, 1e2])
        base = peers.SteadyStateKalman(a, c, q, r, scale)
        # augmented state (x_k, x_{k-1}, ..., x_{k-lag}), independent construction
        nx = 3
        na = nx * (lag + 1)
        aa = np.zeros((na, na))
        aa[:nx, :nx] = a
        aa[nx:, :-nx] = np.eye(nx * lag)
        qa = np.zeros((na, na))
        qa[:nx, :nx] = q
        ca = np.zeros((1, na))
        ca[:, :nx] = c
        aug = peers.SteadyStateKalman(aa, ca, qa + 1e-30 * np.eye(na), r,
                                      np.tile(scale, lag + 1))
        rng = np.random.default_rng(11)
        n = 3000
        x = np.zeros((n, nx))
        lq = np.linalg.cholesky(q)
        for k in range(1, n):
            x[k] = a @ x[k - 1] + lq @ rng.standard_normal(nx)
        y = x @ c.T + 1e-4 * rng.standard_normal((n, 1))
        xf = base.filter(y, np.zeros(nx))
        lagged = base.fixed_lag(xf, lag)          # row j = x_{j | j + lag}
        xa = aug.filter(y, np.zeros(na))           # row k block m = x_{k - m | k}
        ref = xa[lag:, nx * lag:]                  # = x_{k - lag | k}, for j = k - lag
        got = lagged[:n - lag]
        skip = 500
        scale_err = np.std(x[skip:], axis=0)
        np.testing.assert_allclose((got - ref)[skip:] / scale_err, 0.0, atol=1e-6)


class TestDifferences:
    t = np.arange(4000) * DT

    @pytest.mark.parametrize('scheme', ['backward', 'backward2'])
    @pytest.mark.parametrize('order', [1, 2, 4])
    def test_lowpass_ramp_slope_is_exact_after_the_transient(self, scheme, order):
        x = (0.3 + 0.02 * self.t)[:, None]
        d = peers.lowpass_differences(x, DT, order, 25.0, scheme)
        np.testing.assert_allclose(d[2000:, 1, 0], 0.02, rtol=1e-9)
        np.testing.assert_allclose(d[2000:, 2, 0], 0.0, atol=1e-6)

    @pytest.mark.parametrize('scheme', ['backward', 'backward2'])
    def test_lowpass_quadratic_curvature_is_exact_after_the_transient(self, scheme):
        c = 1.5
        x = np.column_stack([0.1 + 0.2 * self.t + c * self.t ** 2, -c * self.t ** 2])
        d = peers.lowpass_differences(x, DT, 3, 40.0, scheme)
        np.testing.assert_allclose(d[2000:, 2, 0], 2 * c, rtol=1e-6)
        np.testing.assert_allclose(d[2000:, 2, 1], -2 * c, rtol=1e-6)
        # the slope is the true one at the filter's DC group delay: constant lag
        lag = (0.2 + 2 * c * self.t[2000:] - d[2000:, 1, 0]) / (2 * c)
        np.testing.assert_allclose(lag, lag[0], atol=1e-7)
        assert 0.0 < lag[0] < 0.05

    def test_zero_phase_quadratic_is_exact_in_the_interior(self):
        c = 1.5
        x = (0.1 + 0.2 * self.t + c * self.t ** 2)[:, None]
        d = peers.zero_phase_differences(x, DT, 2, 30.0)
        inner = slice(1000, 3000)
        np.testing.assert_allclose(d[inner, 1, 0], 0.2 + 2 * c * self.t[inner], rtol=1e-6)
        np.testing.assert_allclose(d[inner, 2, 0], 2 * c, rtol=1e-5)

    def test_bad_scheme_is_refused(self):
        with pytest.raises(ValueError, match='differences'):
            peers.lowpass_differences(np.zeros((10, 1)), DT, 2, 30.0, 'forward')


class TestReconstruction:
    def test_exact_derivatives_give_the_plant_loads(self):
        """Steps 1-3 with the plant's exact states reproduce the plant's true wheel loads."""
        from road_force_estimator.core.plant import simulate
        from road_force_estimator.core.road import iso8608_profile

        vehicle = VehicleParameters()
        road = iso8608_profile('C', 80.0, seed=4)
        tr = simulate(vehicle, road, speed_mps=SPEED, rate_hz=1000.0, duration_s=3.0,
                      lateral_acceleration=2.0)
        s = vehicle.half_track_m
        phi, dphi, ddphi = tr.roll_rad, tr.roll_rate_radps, tr.roll_accel_radps2
        roll = s * (np.cos(phi) * ddphi - np.sin(phi) * dphi ** 2)
        ddq = np.column_stack([tr.body_accel_mps2 + roll - tr.wheel_accel_mps2[:, 0],
                               tr.body_accel_mps2 - roll - tr.wheel_accel_mps2[:, 1]])
        res = peers.reconstruct(tr.t_s, tr.q_m, tr.dq_mps, ddq, phi, dphi, ddphi, SPEED,
                                vehicle)
        np.testing.assert_allclose(res.wheel_load_n, tr.wheel_load_n, rtol=0, atol=1e-6)
        ltr = (tr.wheel_load_n[:, 1] - tr.wheel_load_n[:, 0]) / tr.wheel_load_n.sum(axis=1)
        np.testing.assert_allclose(res.ltr, ltr, atol=1e-12)
        # roll residual = M h a_y cos(phi) (MODEL.md step 9)
        np.testing.assert_allclose(res.extra['residual_nm'],
                                   vehicle.sprung_mass_kg * vehicle.cg_height_m * 2.0
                                   * np.cos(phi), rtol=1e-6)

    def test_total_load_identity(self):
        rng = np.random.default_rng(2)
        vehicle = VehicleParameters()
        n = 50
        q, dq, ddq = (rng.normal(0, 0.01, (n, 2)) for _ in range(3))
        phi, dphi, ddphi = (rng.normal(0, 0.02, n) for _ in range(3))
        t = np.arange(n) * DT
        res = peers.reconstruct(t, q, dq, ddq, phi, dphi, ddphi, SPEED, vehicle)
        m = np.asarray(vehicle.unsprung_mass_kg)
        total = (sum(vehicle.static_load_n) + vehicle.sprung_mass_kg
                 * res.extra['body_accel_mps2'] + res.extra['wheel_accel_mps2'] @ m)
        np.testing.assert_allclose(res.wheel_load_n.sum(axis=1), total, rtol=1e-12)


class TestCallPeer:
    def test_unknown_peer_is_refused(self):
        with pytest.raises(ValueError, match='unknown'):
            peers.call_peer('nope', np.arange(5.0), np.zeros((5, 2)), np.zeros(5), 20.0,
                            VehicleParameters())

    def test_uneven_stamps_are_refused(self):
        t = np.array([0.0, 0.001, 0.003, 0.004, 0.005])
        with pytest.raises(ValueError, match='uniformly'):
            peers.lowpass_fd(t, np.zeros((5, 2)), np.zeros(5), 20.0, VehicleParameters())


class TestTunedSettings:
    def test_settings_follow_the_noise_level(self):
        from bench.accuracy import tune

        doc = {'peers': {'lowpass-fd': {
            '0': {'settings': {'cutoff_hz': 400.0}},
            '1e-05': {'settings': {'cutoff_hz': 40.0}},
            '5e-05': {'settings': {'cutoff_hz': 25.0}}}}}
        assert tune.settings_for(doc, 'lowpass-fd', 0.0) == {'cutoff_hz': 400.0}
        assert tune.settings_for(doc, 'lowpass-fd', 1e-5) == {'cutoff_hz': 40.0}
        assert tune.settings_for(doc, 'lowpass-fd', 3e-5) == {'cutoff_hz': 25.0}
        assert tune.settings_for(doc, 'lowpass-fd', 2e-6) == {'cutoff_hz': 40.0}
        assert tune.settings_for(doc, 'kf-model', 1e-5) == peers.DEFAULT_TUNING['kf-model']


class TestRollChannelKnobs:
    """The roll channel's own knob changes what depends on roll and nothing else."""

    @pytest.fixture(scope='class')
    @staticmethod
    def signals():
        rng = np.random.default_rng(7)
        n = 3000
        t = np.arange(n) * DT
        q = np.column_stack([1e-3 * np.sin(2 * np.pi * 1.3 * t), 1e-3 * np.cos(2 * np.pi * t)])
        q += rng.normal(0.0, 1e-5, q.shape)
        phi = 2e-3 * np.sin(2 * np.pi * 0.7 * t) + rng.normal(0.0, 1e-4, n)
        return t, q, phi

    @pytest.mark.parametrize('peer, knob, value', [
        ('lowpass-fd', 'roll_cutoff_hz', 5.0),
        ('zero-phase-offline', 'roll_cutoff_hz', 5.0),
        ('kf-jerk', 'roll_jerk_psd', 1e-2),
    ])
    def test_body_acceleration_depends_on_the_deflections_only(self, signals, peer, knob,
                                                               value):
        t, q, phi = signals
        base = dict(peers.DEFAULT_TUNING[peer])
        a = peers.call_peer(peer, t, q, phi, SPEED, VehicleParameters(), base,
                            noise_deflection_m=1e-5, noise_roll_rad=1e-4)
        b = peers.call_peer(peer, t, q, phi, SPEED, VehicleParameters(), {**base, knob: value},
                            noise_deflection_m=1e-5, noise_roll_rad=1e-4)
        # dd z_s = (F_b1 + F_b2) / M uses q and dq only (MODEL.md step 1)
        np.testing.assert_array_equal(a.extra['body_accel_mps2'], b.extra['body_accel_mps2'])
        # the wheel loads use ddphi: a much smoother roll estimate changes them
        assert np.max(np.abs(a.wheel_load_n - b.wheel_load_n)) > 1.0

    def test_kf_jerk_default_roll_density_is_the_deflections_over_s_squared(self, signals):
        t, q, phi = signals
        vehicle = VehicleParameters(track_width_m=2.5)      # s^2 = 1.5625, not 1
        base = dict(peers.DEFAULT_TUNING['kf-jerk'])
        a = peers.call_peer('kf-jerk', t, q, phi, SPEED, vehicle, base,
                            noise_deflection_m=1e-5, noise_roll_rad=1e-4)
        b = peers.call_peer('kf-jerk', t, q, phi, SPEED, vehicle,
                            {**base, 'roll_jerk_psd': base['jerk_psd']
                             / vehicle.half_track_m ** 2},
                            noise_deflection_m=1e-5, noise_roll_rad=1e-4)
        np.testing.assert_allclose(a.wheel_load_n, b.wheel_load_n, rtol=0, atol=1e-9)
