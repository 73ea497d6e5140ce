"""Metrics: band-pass against pure tones, error figures against hand-computed values."""
import math

import numpy as np
import pytest

from road_force_estimator.core.metrics import (
    convergence_time, dlc, error_stats, load_errors, ltr_stats, profile_bandpass,
    profile_errors)

DX = 0.02   # m: 20 m/s at 1 kHz


def _tone(x, wavelength, amp=1.0, phase=0.0):
    return amp * np.sin(2.0 * np.pi * x / wavelength + phase)


class TestBandpass:
    x = np.arange(0.0, 2000.0, DX)
    core = (x > 300.0) & (x < 1700.0)

    def test_keeps_the_band_and_removes_the_rest_without_phase(self):
        inside = _tone(self.x, 5.0, 1e-3, 0.4)
        out = profile_bandpass(self.x, inside + _tone(self.x, 0.1, 1e-3) +
                               _tone(self.x, 400.0, 5e-2) + 0.3)
        # Mid-band: unit gain (within 1 %) and no shift (zero phase).
        assert np.abs(out - inside)[self.core].max() <= 0.01e-3 + 5e-2 * 0.01

    @pytest.mark.parametrize('wavelength', [0.2, 1.0, 10.0, 30.0, 100.0, 1000.0])
    def test_gain_follows_the_butterworth_prototype(self, wavelength):
        # Analog Butterworth band-pass of order N between f1 = 1/30 and f2 = 2 cycles/m:
        # |H|^2 = 1 / (1 + W^(2N)), W = (f^2 - f1 f2) / (f (f2 - f1)); run twice (zero phase),
        # the gain is |H|^2 (-6 dB at each edge). The digital design differs a little near
        # Nyquist (bilinear warping), hence the tolerance.
        f, f1, f2 = 1.0 / wavelength, 1.0 / 30.0, 2.0
        w = (f * f - f1 * f2) / (f * (f2 - f1))
        expected = 1.0 / (1.0 + w ** 4)
        out = profile_bandpass(self.x, _tone(self.x, wavelength))
        gain = np.abs(out[self.core]).max()
        assert gain == pytest.approx(expected, rel=0.2, abs=0.005)

    def test_columns_and_uneven_spacing(self):
        rng = np.random.default_rng(0)
        z = np.column_stack([_tone(self.x, 7.0), _tone(self.x, 13.0, 2.0)])
        both = profile_bandpass(self.x, z)
        np.testing.assert_allclose(both[:, 1], profile_bandpass(self.x, z[:, 1]), atol=1e-12)
        xs = np.sort(rng.choice(self.x, self.x.size // 2, replace=False))
        zs = np.column_stack([_tone(xs, 7.0), _tone(xs, 13.0, 2.0)])
        uneven = profile_bandpass(xs, zs)
        keep = (xs > 300.0) & (xs < 1700.0)
        np.testing.assert_allclose(uneven[keep], np.interp(xs, self.x, both[:, 0])[keep, None]
                                   * [1, 0] + np.interp(xs, self.x, both[:, 1])[keep, None]
                                   * [0, 1], atol=0.02)

    def test_bad_input(self):
        with pytest.raises(ValueError, match='non-decreasing'):   # a standstill is allowed
            profile_bandpass([0.0, 1.0, 0.5, 2.0], np.zeros(4))
        with pytest.raises(ValueError, match='short_m'):
            profile_bandpass(np.arange(100.0), np.zeros(100))   # 1 m grid: 0.5 m unresolved
        with pytest.raises(ValueError, match='finite'):
            profile_bandpass(self.x[:10], np.full(10, math.nan))


class TestErrors:
    def test_error_stats_by_hand(self):
        est = np.array([1.0, 2.0, 3.0, 4.0])
        tru = np.array([1.0, 1.0, 1.0, 6.0])
        s = error_stats(est, tru)
        # errors 0, 1, 2, -2: RMS = sqrt(9/4) = 1.5; truth RMS = sqrt(39/4)
        assert s.rms == pytest.approx(1.5) and s.peak == pytest.approx(2.0)
        assert s.rms_pct == pytest.approx(100 * 1.5 / math.sqrt(39 / 4))
        assert s.samples == 4
        masked = error_stats(est, tru, mask=[False, True, True, False])
        assert masked.rms == pytest.approx(math.sqrt(2.5)) and masked.samples == 2
        with pytest.raises(ValueError, match='shape'):
            error_stats(est, tru[:3])
        with pytest.raises(ValueError, match='no sample'):
            error_stats(est, tru, mask=np.zeros(4, bool))

    def test_load_errors_use_the_dynamic_load_and_the_static_load(self):
        fc = np.array([30e3, 20e3])
        dyn = np.array([[1e3, -2e3], [-1e3, 2e3], [1e3, -2e3], [-1e3, 2e3]])
        truth = fc + dyn
        est = truth + np.array([100.0, -50.0])
        s = load_errors(est, truth, fc)
        np.testing.assert_allclose(s.rms, [100.0, 50.0])
        np.testing.assert_allclose(s.rms_pct, [10.0, 2.5])        # of 1 kN and 2 kN
        np.testing.assert_allclose(s.rms_pct_static, [100 / 300, 0.25])

    def test_profile_errors_ignore_what_lies_outside_the_band(self):
        x = np.arange(0.0, 1500.0, DX)
        truth = np.column_stack([_tone(x, 6.0, 1e-3), _tone(x, 11.0, 1e-3)])
        drift = _tone(x, 700.0, 0.2)[:, None] + 0.05 + 1e-5 * _tone(x, 0.08)[:, None]
        core = (x > 300) & (x < 1200)
        s = profile_errors(x, truth + drift, truth, mask=core)
        assert np.all(s.rms_pct < 1.0)
        bad = profile_errors(x, 1.1 * truth, truth, mask=core)
        np.testing.assert_allclose(bad.rms_pct, 10.0, rtol=0.02)
        # Truth on its own grid is interpolated onto the estimate's distances.
        xt = np.arange(0.0, 1500.0, 0.05)
        tt = np.column_stack([_tone(xt, 6.0, 1e-3), _tone(xt, 11.0, 1e-3)])
        s2 = profile_errors(x, truth, tt, mask=core, truth_distance_m=xt)
        assert np.all(s2.rms_pct < 1.0)

    def test_ltr_stats_and_dlc(self):
        s = ltr_stats([0.1, -0.4, 0.2], [0.1, -0.2, 0.2])
        assert s['max_abs'] == pytest.approx(0.4)
        assert s['peak_error'] == pytest.approx(0.2)
        assert s['rms_error'] == pytest.approx(math.sqrt(0.04 / 3))
        assert dlc(np.array([[1.0, 10.0], [3.0, 10.0]])) == pytest.approx([0.5, 0.0])


class TestConvergenceTime:
    def test_by_hand(self):
        t = np.arange(6.0)
        assert convergence_time(t, [5, 3, 0.5, 2, 0.1, 0.0], 1.0) == 4.0
        assert convergence_time(t, [0, 0, 0, 0, 0, 0], 1.0) == 0.0
        assert convergence_time(t, [0, 0, 0, 0, 0, 3], 1.0) == math.inf
        two = np.column_stack([[5, 0, 0, 0, 0, 0], [0, 0, 3, 0, 0, 0]])
        assert convergence_time(t, two, [1.0, 1.0]) == 3.0
        assert convergence_time(t, two, [1.0, 4.0]) == 1.0
        with pytest.raises(ValueError, match='match'):
            convergence_time(t, np.zeros(5), 1.0)

    def test_a_stated_window_on_a_constructed_error_signal(self):
        """MODEL.md: the first time after which the error stays inside its tolerance for a
        stated window - not the last spike of a long drive."""
        t = np.arange(0.0, 30.0, 0.01)                      # 30 s at 100 Hz
        err = np.where(t < 0.48, 10.0, 0.1)                  # converges at 0.48 s ...
        err[(t >= 2.0) & (t < 2.05)] = 5.0                   # ... a spike at 2 s
        err[(t >= 29.38) & (t < 29.40)] = 5.0                # ... and one near the end
        assert convergence_time(t, err, 1.0) == pytest.approx(29.40)    # no window: the last
        assert convergence_time(t, err, 1.0, window_s=1.0) == pytest.approx(0.48)
        assert convergence_time(t, err, 1.0, window_s=1.6) == pytest.approx(2.05)
        # The window must fit in the record, and a signal that never settles gives inf.
        assert convergence_time(t, err, 1.0, window_s=40.0) == math.inf
        assert convergence_time(t, np.full(t.size, 2.0), 1.0, window_s=1.0) == math.inf
        assert convergence_time(t, np.zeros(t.size), 1.0, window_s=1.0) == 0.0


def test_band_pass_through_a_standstill_reads_standing_samples_at_their_distance():
    """A stop repeats a distance: the band-pass of the moving samples, read back at each
    sample's distance (the same numbers as the moving samples alone)."""
    x_moving = np.arange(0.0, 300.0, 0.02)
    z_moving = 0.003 * np.sin(2 * np.pi * x_moving / 7.0)
    stop = 5000                                       # 2000 samples standing at x[5000]
    x = np.concatenate([x_moving[:stop + 1], np.full(2000, x_moving[stop]),
                        x_moving[stop + 1:]])
    z = np.concatenate([z_moving[:stop + 1], np.full(2000, z_moving[stop]),
                        z_moving[stop + 1:]])
    alone = profile_bandpass(x_moving, z_moving)
    got = profile_bandpass(x, z)
    np.testing.assert_array_equal(got[:stop + 1], alone[:stop + 1])
    np.testing.assert_array_equal(got[stop + 1:stop + 2001], alone[stop])
    np.testing.assert_array_equal(got[stop + 2001:], alone[stop + 1:])
    with pytest.raises(ValueError, match='non-decreasing'):
        profile_bandpass(x[::-1], z)
