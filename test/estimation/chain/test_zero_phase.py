"""Offline (non-causal) estimation: building blocks against analytic references, the whole
chain against the plant's ground truth, robustness as the estimator's.

References: closed-form responses of the zero-phase filters to sines and polynomials, the
statistics of seeded white noise, the plant's ground truth (road_force_estimator.core.plant, RK4 of
the roll-plane model, written apart from this module) and the identities of MODEL.md.

Stated bounds (ISO 8608 class C, 20 m/s, 1 kHz, 8 s, seeded; measured values in parentheses):

- noise-free: wheel-load RMS error <= 2 % of the true dynamic-load RMS (0.4 %), band-passed
  profile error <= 3 % (1.0 %);
- 10 um deflection and 0.1 mrad roll noise: the offline error is at most HALF the online
  estimator's, for the loads (measured ~2.6 % against ~29 %, a factor ~11) and for the
  band-passed profile (~1.3 % against ~12 %).
"""
import math

import numpy as np
import pytest
from scipy import signal

from road_force_estimator.estimation import body_heave
from road_force_estimator.estimation.chain import zero_phase as offline
from road_force_estimator.estimation import estimate_batch
from road_force_estimator.estimation.chain.zero_phase import (
    OfflineEstimateArrays, auto_cutoff_hz, edge_time_s, estimate_offline, noise_std,
    zero_phase_body_heave, zero_phase_derivatives)
from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
from road_force_estimator.core.plant import simulate
from road_force_estimator.core.road import iso8608_profile
from road_force_estimator.core.sensors import SensorModel

VEHICLE = VehicleParameters()
RATE = 1000.0
SPEED = 20.0


def _stamps(t_s):
    return np.round(np.asarray(t_s) * 1e9).astype(np.int64)


@pytest.fixture(scope='module')
def drive():
    """8 s on ISO 8608 class C at 20 m/s, 1 kHz, tire envelope 0.25 m (the plant)."""
    road = iso8608_profile('C', SPEED * 8.0 + 10.0, seed=7)
    return simulate(VEHICLE, road, speed_mps=SPEED, rate_hz=RATE, duration_s=8.0,
                    tire_envelope_m=0.25)


def _errors(est, tr, skip_s=0.5):
    """(load error % of the true dynamic RMS, band-passed profile error % of its RMS), both
    wheels pooled, computed here with numpy/scipy (not with road_force_estimator.core.metrics)."""
    k0 = int(skip_s * RATE)
    fc = np.asarray(VEHICLE.static_load_n)
    err = est.wheel_load_n[k0:] - tr.wheel_load_n[k0:]
    dyn = tr.wheel_load_n[k0:] - fc
    load_pct = 100.0 * math.sqrt(np.mean(err ** 2)) / math.sqrt(np.mean(dyn ** 2))
    dx = SPEED / RATE
    sos = signal.butter(2, [1.0 / 30.0, 1.0 / 0.5], btype='bandpass', fs=1.0 / dx, output='sos')
    bp_e = signal.sosfiltfilt(sos, est.road_m, axis=0)
    bp_t = signal.sosfiltfilt(sos, tr.road_m, axis=0)
    x = tr.distance_m
    m = (x >= x[k0] + 30.0) & (x <= x[-1] - 30.0)
    prof_pct = 100.0 * math.sqrt(np.mean((bp_e[m] - bp_t[m]) ** 2)) / math.sqrt(
        np.mean(bp_t[m] ** 2))
    return load_pct, prof_pct


class TestBuildingBlocks:
    def test_noise_std_of_white_noise_on_a_smooth_signal(self):
        rng = np.random.default_rng(3)
        t = np.arange(20000) / RATE
        x = 0.02 * np.sin(2 * np.pi * 1.7 * t) + 3e-5 * rng.standard_normal(t.size)
        assert noise_std(x) == pytest.approx(3e-5, rel=0.03)
        assert noise_std(0.02 * np.sin(2 * np.pi * 1.7 * t)) < 1e-9
        assert noise_std([1.0, 2.0]) == 0.0

    def test_derivatives_of_a_sine_within_the_pass_band(self):
        # A 5 Hz sine through a 60 Hz zero-phase low-pass: no phase, gain 1 to within the
        # Butterworth's |H|^2 = 1 / (1 + (5/60)^16) ~ 1; central differences: sin(w dt)/(w dt).
        dt = 1e-3
        t = np.arange(4000) * dt
        w = 2 * np.pi * 5.0
        y, dy, ddy = zero_phase_derivatives(np.sin(w * t), dt, 60.0)
        mid = slice(500, -500)
        np.testing.assert_allclose(y[mid], np.sin(w * t[mid]), atol=1e-6)
        np.testing.assert_allclose(dy[mid], w * np.cos(w * t[mid]), rtol=0, atol=2e-4 * w)
        np.testing.assert_allclose(ddy[mid], -w * w * np.sin(w * t[mid]), atol=2e-4 * w * w)

    def test_no_filter_above_the_limit_is_exact_on_quadratics(self):
        dt = 2e-3
        t = np.arange(200) * dt
        f = 3.0 - 2.0 * t + 4.5 * t * t
        y, dy, ddy = zero_phase_derivatives(np.column_stack([f, -f]), dt, math.inf)
        np.testing.assert_allclose(y[:, 0], f, rtol=0, atol=1e-12)
        np.testing.assert_allclose(dy[:, 0], -2.0 + 9.0 * t, rtol=0, atol=1e-9)
        np.testing.assert_allclose(ddy[:, 1], -9.0, rtol=0, atol=1e-6)

    def test_body_heave_is_the_double_integral_with_butterworth_squared_gain(self):
        # a = -A w^2 sin(w t) -> z = A |H(jw)|^2 sin(w t), |H|^2 = r^2n / (1 + r^2n), r = w/wc
        # (Butterworth of order n), and no phase (to the bilinear transform's frequency
        # warping, ~(w dt)^2 / 12).
        n = body_heave.ZERO_PHASE_ORDER
        dt = 1e-3
        t = np.arange(120000) * dt
        wc = 2 * np.pi * 20.0 / 100.0
        for wave_m in (30.0, 10.0):
            w = 2 * np.pi * 20.0 / wave_m
            z = zero_phase_body_heave(-0.01 * w * w * np.sin(w * t), dt, wc)
            r2n = (w / wc) ** (2 * n)
            # (edges: the start transients decay as exp(-sin(pi / 2n) wc t): 40 s)
            mid = slice(40000, -40000)
            np.testing.assert_allclose(z[mid], 0.01 * r2n / (1 + r2n) * np.sin(w * t[mid]),
                                       rtol=0, atol=1e-4 * 0.01)

    def test_body_heave_removes_an_acceleration_bias(self):
        # A constant bias b: the forward filter settles at b / wc^2, the backward high-pass
        # takes it out: nothing drifts.
        dt = 1e-3
        z = zero_phase_body_heave(np.full(30000, 0.05), dt, 2 * np.pi * 0.2)
        assert np.max(np.abs(z)) < 1e-9

    def test_auto_cutoff(self):
        rng = np.random.default_rng(11)
        n = 30000
        # Signal confined below ~10 Hz (large), plus white noise: the cut-off lies where the
        # signal's spectrum meets the noise, above 10 Hz and well below Nyquist.
        sos = signal.butter(8, 10.0, fs=RATE, output='sos')
        sig = signal.sosfilt(sos, rng.standard_normal(n))
        sig *= 0.01 / np.std(sig)
        noisy = sig + 1e-5 * rng.standard_normal(n)
        cut = auto_cutoff_hz(noisy, RATE)
        assert 10.0 < cut < 60.0
        assert auto_cutoff_hz(1e-5 * rng.standard_normal(n), RATE) == offline.MIN_CUTOFF_HZ
        assert auto_cutoff_hz(sig, RATE, sigma=0.0) == math.inf
        assert auto_cutoff_hz(noisy[:100], RATE) == math.inf

    def test_edge_time(self):
        assert edge_time_s((50.0, math.inf, 20.0), 1e-3) == pytest.approx(0.2)
        assert edge_time_s((math.inf,) * 3, 1e-3) == 0.05
        assert edge_time_s((math.inf,) * 3, 0.01) == pytest.approx(0.2)


class TestAccuracy:
    def test_noise_free_against_the_plant(self, drive):
        tr = drive
        est = estimate_offline(_stamps(tr.t_s), tr.q_m, tr.roll_rad, SPEED, VEHICLE)
        assert isinstance(est, OfflineEstimateArrays)
        load_pct, prof_pct = _errors(est, tr)
        assert load_pct <= 2.0, load_pct
        assert prof_pct <= 3.0, prof_pct
        # Identity of MODEL.md on the outputs: total load = static + inertial forces.
        total = est.wheel_load_n.sum(axis=1)
        rhs = (sum(VEHICLE.static_load_n) + VEHICLE.sprung_mass_kg * est.body_accel_mps2
               + est.wheel_accel_mps2 @ np.asarray(VEHICLE.unsprung_mass_kg))
        np.testing.assert_allclose(total, rhs, rtol=1e-12)
        # Kinematics: z_u1 = z_s + s sin(phi) - q_1.
        s = VEHICLE.half_track_m
        np.testing.assert_allclose(est.wheel_heave_m[:, 0], est.body_heave_m
                                   + s * np.sin(est.roll_rad) - est.q_m[:, 0], atol=1e-15)
        # Distance is the integral of the speed.
        np.testing.assert_allclose(est.distance_m, SPEED * tr.t_s, rtol=1e-12, atol=1e-9)
        assert est.valid.all() and est.status.accepted == len(tr.t_s)

    def test_offline_beats_online_on_a_noisy_drive(self, drive):
        # The acceptance of issue 6: measurably more accurate, here by a factor of at least 2.
        tr = drive
        q, phi = SensorModel(deflection_std_m=1e-5, roll_std_rad=1e-4, seed=5).measure(
            tr.q_m, tr.roll_rad)
        stamps = _stamps(tr.t_s)
        on = estimate_batch(stamps, q, phi, SPEED, VEHICLE, ObserverParameters())
        off = estimate_offline(stamps, q, phi, SPEED, VEHICLE, ObserverParameters())
        load_on, prof_on = _errors(on, tr)
        load_off, prof_off = _errors(off, tr)
        assert load_off <= 0.5 * load_on, (load_off, load_on)
        assert prof_off <= 0.5 * prof_on, (prof_off, prof_on)
        # The noise it estimated is the noise that was added.
        np.testing.assert_allclose(off.noise_std, (1e-5, 1e-5, 1e-4), rtol=0.1)
        assert all(5.0 < c < 200.0 for c in off.cutoff_hz)

    def test_tire_damping_relation_holds(self, drive):
        tr = drive
        from dataclasses import replace
        veh = replace(VEHICLE, tire_damping_nspm=(800.0, 1200.0))
        est = estimate_offline(_stamps(tr.t_s), tr.q_m, tr.roll_rad, SPEED, veh)
        # kt w + ct dw/dt = dF with w = u - z_u, discretised exactly with dF held: check the
        # one-step recursion independently.
        w = est.road_m - est.wheel_heave_m
        kt = np.asarray(veh.tire_stiffness_npm)
        ct = np.asarray(veh.tire_damping_nspm)
        e = np.exp(-1e-3 * kt / ct)
        pred = e * w[:-1] + (1 - e) * est.tire_force_dynamic_n[1:] / kt
        np.testing.assert_allclose(w[1:], pred, rtol=1e-9, atol=1e-15)


class TestRobustness:
    def test_rejections_and_gaps_as_the_estimator(self):
        rng = np.random.default_rng(2)
        n = 3000
        t = np.arange(n) / 500.0
        t[1500:] += 0.5                      # a gap of 0.5 s
        stamps = _stamps(t)
        q = 0.01 * np.column_stack([np.sin(3 * t), np.cos(2 * t)]) + 1e-6 * rng.standard_normal(
            (n, 2))
        phi = 0.002 * np.sin(t)
        stamps[100] = stamps[99]            # duplicate
        stamps[200] = stamps[198]           # backwards
        q[300, 0] = np.nan                  # non-finite
        phi[400] = 2.0                      # impossible roll
        v = np.full(n, 15.0)
        off = estimate_offline(stamps, q, phi, v, VEHICLE)
        on = estimate_batch(stamps, q, phi, v, VEHICLE)
        np.testing.assert_array_equal(off.valid, on.valid)
        for name in ('accepted', 'rejected_nonfinite', 'rejected_range', 'rejected_time',
                     'gaps', 'resets'):
            assert getattr(off.status, name) == getattr(on.status, name), name
        # 4 bad samples, and the first after the gap (held: the next one confirms the jump)
        assert off.status.gaps == 1 and off.status.rejected == 5
        assert len(off.runs) == 2
        # Distance continues across the gap exactly as the estimator integrates it.
        np.testing.assert_allclose(off.distance_m, on.distance_m, rtol=1e-12)
        # Rejected rows hold the previous estimate.
        for k in (100, 200, 300, 400):
            np.testing.assert_array_equal(off.wheel_load_n[k], off.wheel_load_n[k - 1])
        assert not off.converged[1500] and off.converged[1500 + 200]
        assert np.all(np.isfinite(off.wheel_load_n))

    def test_uneven_steps_are_resampled(self, drive):
        tr = drive
        rng = np.random.default_rng(9)
        stamps = _stamps(tr.t_s) + rng.integers(-100_000, 100_000, len(tr.t_s))  # +-0.1 ms
        stamps[0] = _stamps(tr.t_s)[0]
        true_t = (stamps - stamps[0]) * 1e-9
        # The plant's outputs at the jittered instants (interpolated: smooth at 1 kHz).
        q = np.column_stack([np.interp(true_t, tr.t_s, tr.q_m[:, i]) for i in (0, 1)])
        phi = np.interp(true_t, tr.t_s, tr.roll_rad)
        est = estimate_offline(stamps, q, phi, SPEED, VEHICLE)
        assert est.runs[0].resampled
        even = estimate_offline(_stamps(tr.t_s), tr.q_m, tr.roll_rad, SPEED, VEHICLE)
        mid = slice(1000, -1000)
        err = est.wheel_load_n[mid] - np.column_stack(
            [np.interp(true_t[mid], tr.t_s, even.wheel_load_n[:, i]) for i in (0, 1)])
        dyn = even.wheel_load_n[mid] - np.asarray(VEHICLE.static_load_n)
        assert math.sqrt(np.mean(err ** 2)) < 0.1 * math.sqrt(np.mean(dyn ** 2))

    def test_short_and_empty_inputs(self):
        est = estimate_offline(np.array([5, 10, 15], dtype=np.int64), np.zeros((3, 2)),
                               np.zeros(3), 10.0, VEHICLE)
        assert est.status.accepted == 3 and np.all(est.wheel_load_n == VEHICLE.static_load_n)
        empty = estimate_offline(np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros(0), 10.0)
        assert len(empty) == 0 and empty.status.accepted == 0
        nan = estimate_offline(np.arange(4), np.full((4, 2), np.nan), np.zeros(4), 10.0)
        assert not nan.valid.any() and np.all(nan.wheel_load_n == 0.0)

    def test_bad_arguments(self):
        with pytest.raises(ValueError, match='expected'):
            estimate_offline(np.arange(3), np.zeros((3, 3)), np.zeros(3), 1.0)
        with pytest.raises(ValueError, match='cutoff_hz'):
            estimate_offline(np.arange(3), np.zeros((3, 2)), np.zeros(3), 1.0, cutoff_hz=-1.0)
        with pytest.raises(ValueError, match='gap_threshold_s'):
            estimate_offline(np.arange(3), np.zeros((3, 2)), np.zeros(3), 1.0,
                             gap_threshold_s=0.0)

    def test_given_cutoffs_are_used(self, drive):
        tr = drive
        est = estimate_offline(_stamps(tr.t_s), tr.q_m, tr.roll_rad, SPEED, VEHICLE,
                               cutoff_hz=(50.0, 60.0, 20.0))
        assert est.cutoff_hz == (50.0, 60.0, 20.0)
        assert est.runs[0].cutoff_hz == (50.0, 60.0, 20.0)
