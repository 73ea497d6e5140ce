"""The model observer offline (estimation/smoother.py): the RTS smoother against the textbook
one, the estimator's rejections and gaps, the blocked recursion.
"""
import math

import numpy as np
import pytest

from road_force_estimator.estimation.models.front_axle import FrontAxleModel
from road_force_estimator.core.parameters import ObserverParameters
from model_observer_data import FIXED, SPEED, VEHICLE, rts_reference, to_stamps
from road_force_estimator.estimation import estimate_batch, smooth
from road_force_estimator.estimation.observer.gains import design
from road_force_estimator.estimation.models.front_axle import OUTPUTS, rest_state, scheduled
from road_force_estimator.estimation.observer.schedule import SPEED_LEVEL_RATIO
from road_force_estimator.estimation.smoothing.lti import LTI_BLOCK, lti


class TestOffline:
    def test_smooth_is_the_rts_smoother(self, drive, noisy):
        q, phi = noisy
        n = 2000
        obs = ObserverParameters(**FIXED)
        est = smooth(to_stamps(drive.t_s[:n]), q[:n], phi[:n], SPEED, VEHICLE, obs)
        # the design the observer makes: the set noise and roughness (times the scheduled
        # factor), the speed on its 10 % grid, the step of the data
        force_psd, corr, factor, moment_psd = scheduled(1e-5, roll_moment=True)
        speed = SPEED_LEVEL_RATIO ** round(math.log(SPEED) / math.log(SPEED_LEVEL_RATIO))
        gains = design(FrontAxleModel(VEHICLE), dt_s=1e-3, speed_mps=speed,
                       noise_deflection_m=1e-5, noise_roll_rad=1e-4,
                       road_gd_m3=factor * 256e-6, correlation_length_m=corr,
                       force_psd=force_psd, roll_moment_psd=moment_psd)
        x0 = rest_state(VEHICLE, q[0, 0], q[0, 1], phi[0])
        xs = rts_reference(gains, np.column_stack([q[:n], phi[:n]]), x0)
        h_df = gains.model.h[[OUTPUTS.index('df1'), OUTPUTS.index('df2')]]
        # (two algorithms on an ill-conditioned covariance: agreement to ~1e-6 of the force)
        np.testing.assert_allclose(est.tire_force_dynamic_n, xs @ h_df.T, rtol=1e-5,
                                   atol=1e-2)

    def test_rejections_and_gaps_as_the_estimator(self, drive, noisy):
        q, phi = noisy
        n = 2000
        st = to_stamps(drive.t_s[:n])
        qq = q[:n].copy()
        qq[10] = np.inf
        st[1000:] += 500_000_000
        st[20] = st[19]
        off = smooth(st, qq, phi[:n], SPEED, VEHICLE, ObserverParameters())
        on = estimate_batch(st, qq, phi[:n], SPEED, VEHICLE, ObserverParameters())
        np.testing.assert_array_equal(off.valid, on.valid)
        for name in ('rejected_nonfinite', 'rejected_time', 'gaps', 'resets', 'accepted'):
            assert getattr(off.status, name) == getattr(on.status, name), name
        np.testing.assert_allclose(off.distance_m, on.distance_m, rtol=1e-12)
        assert np.all(np.isfinite(off.wheel_load_n))

    @pytest.mark.parametrize('m', [1, 7, 2 * LTI_BLOCK - 1, 3 * LTI_BLOCK,
                                   70 * LTI_BLOCK + 37])
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
        got = lti(f, drive, x0)
        span = np.max(np.abs(ref), axis=0)
        assert np.max(np.abs(got - ref) / span) < 1e-11


class TestWindows:
    """Long runs smoothed in overlapping windows (estimate_bag's bounded memory)."""

    FIELDS = ('wheel_load_n', 'road_m', 'tire_force_dynamic_n', 'body_heave_m', 'ltr',
              'ltr_quasi_static', 'wheel_heave_rate', 'ddroll')

    def test_overlap_covering_the_run_is_one_piece_bit_for_bit(self, drive, noisy):
        q, phi = noisy
        st = to_stamps(drive.t_s)
        one = smooth(st, q, phi, SPEED, VEHICLE, ObserverParameters())
        win = smooth(st, q, phi, SPEED, VEHICLE, ObserverParameters(),
                     window=(1500, q.shape[0]))
        for name in self.FIELDS + ('converged', 'lift_off', 'distance_m'):
            np.testing.assert_array_equal(getattr(win, name), getattr(one, name), name)
        assert win.status == one.status

    def test_window_edges_fade_within_the_overlap(self):
        # 60 s at 200 Hz: the smoother's slowest mode (~8.6 s) fades over the overlap
        from road_force_estimator.core.plant import simulate
        from road_force_estimator.core.road import iso8608_profile
        from road_force_estimator.core.sensors import SensorModel
        from road_force_estimator.estimation.smoothing.smoother import window_samples

        tr = simulate(VEHICLE, iso8608_profile('C', 1300.0, seed=2), speed_mps=SPEED,
                      rate_hz=200.0, duration_s=60.0, tire_envelope_m=0.25)
        q, phi = SensorModel(deflection_std_m=1e-5, roll_std_rad=1e-4, seed=3).measure(
            tr.q_m, tr.roll_rad)
        st = to_stamps(tr.t_s)
        obs = ObserverParameters()
        one = smooth(st, q, phi, SPEED, VEHICLE, obs, window=(10**9, 0))
        worst = []
        for taus in (1.0, 4.0):
            overlap = window_samples(5e-3, SPEED, obs.profile_cutoff_wavelength_m, 8.6, taus)[1]
            win = smooth(st, q, phi, SPEED, VEHICLE, obs, window=(2000, overlap))
            np.testing.assert_array_equal(win.converged, one.converged)
            worst.append(max(
                float(np.max(np.abs(getattr(win, f) - getattr(one, f))))
                / float(np.sqrt(np.mean(np.square(getattr(one, f))))) for f in self.FIELDS))
        # e^-1 of an edge's effect left with one time constant; e^-4 ~ 2 % of that with four
        assert worst[0] > 1e-4 and worst[1] < 1e-4 and worst[1] < 0.05 * worst[0]
