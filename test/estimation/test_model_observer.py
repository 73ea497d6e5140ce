"""Model observer (``observer.discretization = 'model'``): model, gains, latency, offline.

Independent references: the plant helper's linearised model (``VehicleModel.linearised``) for
the observer's equations and as a data generator (scipy ``lsim``); the Riccati equation itself
and scipy's ``solve_discrete_are``; numerical quadrature for the exact discretization; a
Rauch-Tung-Striebel smoother written here in its textbook (covariance) form for the fixed-lag
and offline estimates; the plant's ground truth end to end. Stated bounds (measured values in
parentheses, ISO 8608 class C at 20 m/s, 1 kHz, 8 s drives): without noise, zero latency
load error <= 2 % of the true dynamic-load RMS (0.8 %), 10 ms latency <= 0.5 % (0.07 %),
offline <= 0.5 % (0.07 %); with 10 um / 0.1 mrad noise: zero latency <= 22 % (17.5 %),
10 ms <= 5 % (3.1 %), offline <= 4 % (2.4 %), offline band-passed profile <= 3 % (1.1 %).
"""
import math

import numpy as np
import pytest
from scipy import integrate, linalg, signal

from road_force_estimator.core import metrics
from road_force_estimator.estimation import model_observer as mo
from road_force_estimator.estimation.estimator import (PAIR_FIELDS, SCALAR_FIELDS, Estimator,
                                            estimate_batch)
from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
from road_force_estimator.core.plant import simulate
from road_force_estimator.core.road import iso8608_profile
from road_force_estimator.core.sensors import SensorModel
from road_force_estimator.core.vehicle_model import VehicleModel

VEHICLE = VehicleParameters()
# Asymmetric, with tire damping, so that index and sign slips show.
ASYM = VehicleParameters(
    sprung_mass_kg=5200.0, roll_inertia_kgm2=2800.0, track_width_m=2.1, cg_height_m=0.7,
    unsprung_mass_kg=(430.0, 470.0), suspension_stiffness_npm=(380e3, 420e3),
    suspension_damping_nspm=(14e3, 16e3), tire_stiffness_npm=(950e3, 1050e3),
    tire_damping_nspm=(1500.0, 2500.0))
SPEED = 20.0
# Known noise and roughness: constant gains (for the exactness checks).
FIXED = dict(noise_deflection_m=1e-5, noise_roll_rad=1e-4, road_roughness_m3=256e-6,
             sliding_mode_gain=0.0)


def _stamps(t_s):
    return np.round(np.asarray(t_s) * 1e9).astype(np.int64)


@pytest.fixture(scope='module')
def drive():
    """8 s of ISO 8608 class C at 20 m/s, 1 kHz, tire envelope 0.25 m."""
    road = iso8608_profile('C', 220.0, seed=5)
    return simulate(VEHICLE, road, speed_mps=SPEED, rate_hz=1000.0, duration_s=8.0,
                    tire_envelope_m=0.25)


@pytest.fixture(scope='module')
def noisy(drive):
    q, phi = SensorModel(deflection_std_m=1e-5, roll_std_rad=1e-4, seed=7).measure(
        drive.q_m, drive.roll_rad)
    return q, phi


def _load_pct(est_load, truth, mask):
    err = metrics.load_errors(est_load, truth.wheel_load_n, VEHICLE.static_load_n, mask=mask)
    return float(np.sqrt(np.mean(err.rms ** 2)) / np.sqrt(np.mean(err.reference_rms ** 2))
                 * 100.0)


class TestModel:
    @pytest.mark.parametrize('vehicle', [VEHICLE, ASYM])
    def test_equations_match_the_linearised_plant_model(self, vehicle):
        # Map random plant states (z_s, phi, z_u, rates) and road (u, du) to the observer's
        # coordinates; the observer's A must give the accelerations of VehicleModel's
        # linearised matrices (written by another helper from MODEL.md).
        lin = VehicleModel(vehicle).linearised()
        a_p, b_p = lin.state_matrices()
        model = mo.continuous_model(vehicle, SPEED, 256e-6)
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
            np.testing.assert_allclose(out[[mo.OUTPUTS.index('df1'), mo.OUTPUTS.index('df2')]],
                                       df, rtol=1e-12)

    def test_van_loan_equals_quadrature(self):
        model = mo.continuous_model(VEHICLE, SPEED, 256e-6)
        dt = 2e-3
        a_d, q_d = mo.van_loan(model.a, model.g, model.q, dt)
        np.testing.assert_allclose(a_d, linalg.expm(model.a * dt), rtol=1e-12, atol=1e-14)
        gqg = model.g @ model.q @ model.g.T

        def integrand(t):
            e = linalg.expm(model.a * t)
            return e @ gqg @ e.T

        ref, _ = integrate.quad_vec(integrand, 0.0, dt, epsabs=0.0, epsrel=1e-10)
        scale = np.sqrt(np.outer(np.diag(ref), np.diag(ref))) + 1e-300
        assert np.max(np.abs(q_d - ref) / scale) < 1e-7

    @pytest.mark.parametrize('noise', [1e-5, 1e-7])
    def test_gains_satisfy_the_riccati_equation(self, noise):
        g = mo.design(VEHICLE, dt_s=1e-3, speed_mps=SPEED, noise_deflection_m=noise,
                      noise_roll_rad=10.0 * noise, road_gd_m3=256e-6)
        a, c, q, r, p = g.a, g.model.c, g.q, g.r, g.p_prior
        rhs = a @ p @ a.T - a @ p @ c.T @ np.linalg.solve(c @ p @ c.T + r, c @ p @ a.T) + q
        assert np.max(np.abs(rhs - p)) <= 1e-8 * np.max(np.abs(p))
        np.testing.assert_allclose(g.k, p @ c.T @ np.linalg.inv(c @ p @ c.T + r), rtol=1e-6,
                                   atol=1e-12 * np.max(np.abs(g.k)))
        assert np.max(np.abs(np.linalg.eigvals((np.eye(12) - g.k @ c) @ a))) < 1.0

    def test_riccati_matches_scipy_where_scipy_solves_it(self):
        g = mo.design(VEHICLE, dt_s=1e-3, speed_mps=SPEED, noise_deflection_m=1e-5,
                      noise_roll_rad=1e-4, road_gd_m3=256e-6)
        ref = linalg.solve_discrete_are(g.a.T, g.model.c.T, g.q, g.r)
        np.testing.assert_allclose(g.p_prior, ref, rtol=1e-5,
                                   atol=1e-9 * np.max(np.abs(ref)))


class TestNoiseEstimate:
    @pytest.mark.parametrize('sigma', [1e-6, 1e-5, 5e-5])
    def test_recovers_a_known_noise_std(self, sigma):
        rng = np.random.default_rng(11)
        t = np.arange(4000) * 1e-3
        smooth = 5e-3 * np.sin(2 * math.pi * 1.7 * t) + 1e-3 * np.sin(2 * math.pi * 9.0 * t)
        x = smooth + rng.normal(0.0, sigma, t.size)
        assert mo.noise_std(x) == pytest.approx(sigma, rel=0.05)
        # uneven sampling: the divided differences
        tu = np.cumsum(rng.uniform(0.5e-3, 1.5e-3, 4000))
        xu = 5e-3 * np.sin(2 * math.pi * 1.7 * tu) + rng.normal(0.0, sigma, tu.size)
        assert mo.noise_std(xu, tu) == pytest.approx(sigma, rel=0.05)

    def test_online_estimates_on_the_plant(self, drive, noisy):
        q, phi = noisy
        est = estimate_batch(_stamps(drive.t_s), q, phi, SPEED, VEHICLE, ObserverParameters())
        st = est.status
        assert st.noise_deflection_m == pytest.approx(1e-5, rel=0.1)
        assert st.noise_roll_rad == pytest.approx(1e-4, rel=0.1)
        # ISO class C: Gd(n0) = 256e-6 m^3 (geometric mean of the class)
        assert 256e-6 / 1.5 <= st.road_roughness_m3 <= 256e-6 * 1.5
        assert st.gain_designs <= 10


class TestOnLinearModelData:
    def test_converges_to_the_truth_without_noise(self):
        # Data generated by the linearised plant model itself (scipy lsim, first-order hold on
        # a smooth road input); the observer's tire forces converge to kt (u - z_u) + ct (...).
        vehicle = ASYM
        a_p, b_p = VehicleModel(vehicle).linearised().state_matrices()
        t = np.arange(0.0, 4.0, 1e-4)
        rng = np.random.default_rng(5)
        freq = rng.uniform(0.5, 15.0, (2, 12))
        amp = 3e-3 / freq
        phase = rng.uniform(0.0, 2 * math.pi, (2, 12))
        arg = 2 * math.pi * freq[:, :, None] * t + phase[:, :, None]
        u = np.sum(amp[:, :, None] * np.sin(arg), axis=1).T
        du = np.sum((amp * 2 * math.pi * freq)[:, :, None] * np.cos(arg), axis=1).T
        inputs = np.column_stack([u, du, np.zeros(t.size)])
        sys_ = signal.StateSpace(a_p, b_p, np.eye(8), np.zeros((8, 5)))
        x0 = np.concatenate([[0.5 * (u[0, 0] + u[0, 1]), (u[0, 0] - u[0, 1]) / (2 * 1.05)],
                             u[0], np.zeros(4)])
        _, _, xs = signal.lsim(sys_, inputs, t, X0=x0)
        keep = slice(None, None, 10)                       # 1 kHz samples
        xs, u, du, tk = xs[keep], u[keep], du[keep], t[keep]
        s = vehicle.half_track_m
        q = np.column_stack([xs[:, 0] + s * xs[:, 1] - xs[:, 2],
                             xs[:, 0] - s * xs[:, 1] - xs[:, 3]])
        df = (np.array(vehicle.tire_stiffness_npm) * (u - xs[:, 2:4])
              + np.array(vehicle.tire_damping_nspm) * (du - xs[:, 6:8]))
        est = estimate_batch(_stamps(tk), q, xs[:, 1], 1.0, vehicle, ObserverParameters())
        late = tk >= 1.0
        err = np.sqrt(np.mean((est.tire_force_dynamic_n - df)[late] ** 2, axis=0))
        ref = np.sqrt(np.mean(df[late] ** 2, axis=0))
        assert np.all(err <= 0.02 * ref), err / ref
        assert est.converged[late].all()
        np.testing.assert_allclose(est.q_m[late], q[late], atol=1e-8)


def _rts_reference(gains, y, x0):
    """Textbook Kalman filter (constant gain, steady-state covariances as the prior) and
    Rauch-Tung-Striebel smoother: x_k|n = x_k|k + G (x_k+1|n - A x_k|k), G = P+ A^T P-^-1."""
    a, c, k = gains.a, gains.model.c, gains.k
    p_post = gains.p_post
    p_prior = a @ p_post @ a.T + gains.q
    g = p_post @ a.T @ np.linalg.inv(p_prior)
    xf = np.empty((len(y), 12))
    xf[0] = x0
    for i in range(1, len(y)):
        xp = a @ xf[i - 1]
        xf[i] = xp + k @ (y[i] - c @ xp)
    xs = xf.copy()
    for i in range(len(y) - 2, -1, -1):
        xs[i] = xf[i] + g @ (xs[i + 1] - a @ xf[i])
    return xs


class TestLatency:
    def test_fixed_lag_equals_rts_over_the_window(self, drive, noisy):
        q, phi = noisy
        n = 1500
        lag = 10
        obs = ObserverParameters(latency_s=lag * 1e-3, **FIXED)
        est = Estimator(VEHICLE, obs)
        outs = [est.update(int(t), q[k], phi[k], SPEED)
                for k, t in enumerate(_stamps(drive.t_s[:n]))]
        assert all(o is None for o in outs[:lag]) and all(o is not None for o in outs[lag:])
        outs = [o for o in outs if o is not None] + est.flush()
        assert len(outs) == n
        assert [o.stamp_ns for o in outs] == _stamps(drive.t_s[:n]).tolist()
        gains = est._model.gains
        y = np.column_stack([q[:n], phi[:n]])
        core = mo.ModelCore(VEHICLE, obs)     # the restart state of the first sample
        core.restart(0, *y[0], (0.0, 0.0, SPEED, False))
        x0 = core._x0
        h_df = gains.model.h[[mo.OUTPUTS.index('df1'), mo.OUTPUTS.index('df2')]]
        for t_end in (300, 701, n - 1):
            xs = _rts_reference(gains, y[:t_end + 1], x0)
            for t in (t_end - lag, t_end - 3) if t_end == n - 1 else (t_end - lag,):
                ref = h_df @ xs[t]
                np.testing.assert_allclose(outs[t].tire_force_dynamic_n, ref, rtol=1e-7,
                                           atol=1e-6)

    def test_per_sample_and_batch_are_identical_with_latency(self, drive, noisy):
        q, phi = noisy
        n = 3000
        rng = np.random.default_rng(4)
        stamps = _stamps(drive.t_s[:n]) + rng.integers(-100_000, 100_000, n)
        stamps[1500:] += 400_000_000          # a gap
        qq = q[:n].copy()
        pp = phi[:n].copy()
        qq[100] = np.nan
        stamps[300] = stamps[299]             # duplicate
        obs = ObserverParameters(latency_s=0.01)
        batch = estimate_batch(stamps, qq, pp, SPEED, VEHICLE, obs)
        est = Estimator(VEHICLE, obs)
        outs = [est.update(int(stamps[k]), qq[k], pp[k], SPEED) for k in range(n)]
        good = [o for o in outs if o is not None] + est.flush()
        assert len(good) == int(batch.valid.sum()) == n - 2
        assert est.status == batch.status
        assert batch.status.gaps == 1 and batch.status.latency_samples == 10
        np.testing.assert_array_equal([o.stamp_ns for o in good], batch.stamp_ns[batch.valid])
        for name in PAIR_FIELDS + SCALAR_FIELDS:
            per_sample = np.array([getattr(o, name) for o in good])
            np.testing.assert_array_equal(per_sample, getattr(batch, name)[batch.valid], name)

    def test_chain_latency_only_delays(self, drive):
        n = 500
        st = _stamps(drive.t_s[:n])
        base = estimate_batch(st, drive.q_m[:n], drive.roll_rad[:n], SPEED, VEHICLE,
                              ObserverParameters(discretization='implicit'))
        est = Estimator(VEHICLE, ObserverParameters(discretization='implicit', latency_s=0.005))
        outs = [est.update(int(st[k]), drive.q_m[k], drive.roll_rad[k], SPEED)
                for k in range(n)]
        assert outs[:5] == [None] * 5
        good = [o for o in outs if o is not None] + est.flush()
        np.testing.assert_array_equal([o.wheel_load_n for o in good], base.wheel_load_n)


class TestOffline:
    def test_smooth_is_the_rts_smoother(self, drive, noisy):
        q, phi = noisy
        n = 2000
        obs = ObserverParameters(**FIXED)
        est = mo.smooth(_stamps(drive.t_s[:n]), q[:n], phi[:n], SPEED, VEHICLE, obs)
        core = mo.ModelCore(VEHICLE, obs)
        core.restart(0, q[0, 0], q[0, 1], phi[0], (0.0, 0.0, SPEED, False))
        # the design the observer makes: the set noise and roughness (times the scheduled
        # factor), the speed on its 10 % grid, the step of the data
        force_psd, corr, factor, moment_psd = mo.scheduled(1e-5, roll_moment=True)
        speed = mo.SPEED_LEVEL_RATIO ** round(math.log(SPEED) / math.log(mo.SPEED_LEVEL_RATIO))
        gains = mo.design(VEHICLE, dt_s=1e-3, speed_mps=speed, noise_deflection_m=1e-5,
                          noise_roll_rad=1e-4, road_gd_m3=factor * 256e-6,
                          correlation_length_m=corr, force_psd=force_psd,
                          roll_moment_psd=moment_psd)
        xs = _rts_reference(gains, np.column_stack([q[:n], phi[:n]]), core._x0)
        h_df = gains.model.h[[mo.OUTPUTS.index('df1'), mo.OUTPUTS.index('df2')]]
        # (two algorithms on an ill-conditioned covariance: agreement to ~1e-6 of the force)
        np.testing.assert_allclose(est.tire_force_dynamic_n, xs @ h_df.T, rtol=1e-5,
                                   atol=1e-2)

    def test_rejections_and_gaps_as_the_estimator(self, drive, noisy):
        q, phi = noisy
        n = 2000
        st = _stamps(drive.t_s[:n])
        qq = q[:n].copy()
        qq[10] = np.inf
        st[1000:] += 500_000_000
        st[20] = st[19]
        off = mo.smooth(st, qq, phi[:n], SPEED, VEHICLE, ObserverParameters())
        on = estimate_batch(st, qq, phi[:n], SPEED, VEHICLE, ObserverParameters())
        np.testing.assert_array_equal(off.valid, on.valid)
        for name in ('rejected_nonfinite', 'rejected_time', 'gaps', 'resets', 'accepted'):
            assert getattr(off.status, name) == getattr(on.status, name), name
        np.testing.assert_allclose(off.distance_m, on.distance_m, rtol=1e-12)
        assert np.all(np.isfinite(off.wheel_load_n))

    @pytest.mark.parametrize('m', [1, 7, 2 * mo._LTI_BLOCK - 1, 3 * mo._LTI_BLOCK,
                                   70 * mo._LTI_BLOCK + 37])
    def test_blocked_recursion_is_the_sample_loop(self, m):
        # x_k = F x_(k-1) + d_k, in long double one sample at a time, on a stable F whose
        # states differ in scale by 1e6 (the observer's is as ill-conditioned)
        rng = np.random.default_rng(m)
        nx = 9
        a = rng.standard_normal((nx, nx))
        a *= 0.9995 / np.max(np.abs(np.linalg.eigvals(a)))
        scale = np.logspace(-3, 3, nx)
        f = (a * scale[:, None]) / scale[None, :]
        drive = rng.standard_normal((m, nx)) * scale
        x0 = rng.standard_normal(nx) * scale
        ref = np.empty((m, nx))
        x = x0.astype(np.longdouble)
        for k in range(m):
            x = f.astype(np.longdouble) @ x + drive[k]
            ref[k] = x
        got = mo._lti(f, drive, x0)
        span = np.max(np.abs(ref), axis=0)
        assert np.max(np.abs(got - ref) / span) < 1e-11

    def test_acceptance_rules_are_the_estimators_on_irregular_steps(self):
        # many steps around the gap threshold and ten typical steps: the offline rules must
        # accept, reject and restart exactly where the per-sample estimator does
        rng = np.random.default_rng(5)
        n = 3000
        dt = np.where(rng.random(n) < 0.03, rng.uniform(0.05, 1.5, n),
                      rng.uniform(0.002, 0.03, n))
        st = np.cumsum(np.round(dt * 1e9).astype(np.int64)) + 1_700_000_000 * 10**9
        st[[50, 51, 900]] = st[[49, 49, 800]]                  # duplicates, backwards
        q = 1e-3 * rng.standard_normal((n, 2))
        phi = 1e-3 * rng.standard_normal(n)
        q[70, 1] = np.nan
        phi[71] = 3.0
        v = np.full(n, 12.0)
        valid, restart, _, counts = mo._acceptance(st, q, phi, v, 0.1)
        est = Estimator(VEHICLE, ObserverParameters(discretization='implicit'))
        accepted, restarts = [], []
        for k in range(n):
            before = (est.status.accepted, est.status.resets)
            est.update(int(st[k]), q[k], float(phi[k]), float(v[k]))
            accepted.append(est.status.accepted > before[0])
            restarts.append(est.status.resets > before[1])
        np.testing.assert_array_equal(valid, accepted)
        restarts[int(np.flatnonzero(valid)[0])] = True          # the first sample starts
        np.testing.assert_array_equal(restart, restarts)
        for name, value in counts.items():
            assert getattr(est.status, name) == value, name
        assert counts['gaps'] > 20 and counts['rejected_time'] == 3


class TestEndToEnd:
    def test_without_noise(self, drive):
        st = _stamps(drive.t_s)
        late = drive.t_s >= 2.0
        for latency, bound in ((0.0, 2.0), (0.01, 0.5)):
            est = estimate_batch(st, drive.q_m, drive.roll_rad, SPEED, VEHICLE,
                                 ObserverParameters(latency_s=latency))
            assert _load_pct(est.wheel_load_n, drive, late) <= bound, latency
        off = mo.smooth(st, drive.q_m, drive.roll_rad, SPEED, VEHICLE, ObserverParameters())
        assert _load_pct(off.wheel_load_n, drive, late) <= 0.5

    def test_with_noise(self, drive, noisy):
        q, phi = noisy
        st = _stamps(drive.t_s)
        late = drive.t_s >= 2.0
        for latency, bound in ((0.0, 22.0), (0.01, 5.0)):
            est = estimate_batch(st, q, phi, SPEED, VEHICLE, ObserverParameters(latency_s=latency))
            assert _load_pct(est.wheel_load_n, drive, late) <= bound, latency
        off = mo.smooth(st, q, phi, SPEED, VEHICLE, ObserverParameters())
        assert _load_pct(off.wheel_load_n, drive, late) <= 4.0
        x = off.distance_m
        judged = late & (x >= x[0] + 70.0) & (x <= x[-1] - 30.0)
        prof = metrics.profile_errors(x, off.road_m, drive.road_m, mask=judged)
        assert np.all(prof.rms_pct <= 3.0), prof.rms_pct

    def test_first_sample_is_the_state_at_rest(self):
        est = Estimator(VEHICLE, ObserverParameters())
        out = est.update(0, (0.01, -0.02), 0.003, 15.0)
        assert out.q_m == (0.01, -0.02) and out.roll_rad == 0.003
        assert out.dq == (0.0, 0.0) and out.ddq == (0.0, 0.0) and out.droll == 0.0
        assert out.ddroll == pytest.approx(0.0, abs=1e-12)
        assert not out.converged

    def test_sliding_mode_ablation_changes_nothing_on_noisy_data_by_much(self, drive, noisy):
        # The sliding-mode weight falls with the noise: at 10 um it is ~1e-4 (see the module
        # notes); the two estimates agree to a small fraction of the error.
        q, phi = noisy
        st = _stamps(drive.t_s[:3000])
        on = estimate_batch(st, q[:3000], phi[:3000], SPEED, VEHICLE, ObserverParameters())
        off = estimate_batch(st, q[:3000], phi[:3000], SPEED, VEHICLE,
                             ObserverParameters(sliding_mode_gain=0.0))
        diff = np.sqrt(np.mean((on.wheel_load_n - off.wheel_load_n)[1000:] ** 2))
        assert diff <= 0.01 * np.sqrt(np.mean(drive.tire_force_dynamic_n[:3000] ** 2))
