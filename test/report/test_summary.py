"""report.summary: numbers against closed-form answers on synthetic estimates.

References: estimates built from a known truth plus known errors (a constant load offset, a
sine on the profile, an LTR offset; test/report_case.py), DLC and peaks computed here per
segment with numpy, and a reference profile shifted by a known distance.
"""
import math

import numpy as np
import pytest

from report_case import VEHICLE, make_case
from road_force_estimator import report
from road_force_estimator.core.road import RoadProfile


class TestNumbers:
    def test_accuracy_has_the_closed_form_values(self):
        est, drive, _ = make_case()
        summary, _, _ = report.summarize(est, drive, VEHICLE, mode='online')
        acc = summary['accuracy']
        fc = np.asarray(VEHICLE.static_load_n)
        # Constant offsets: RMS = |offset|; dynamic RMS of a sine = amplitude / sqrt(2).
        np.testing.assert_allclose(acc['load_rms_n'], [100.0, 200.0], rtol=1e-9)
        np.testing.assert_allclose(acc['load_rms_pct_static'], 100.0 * np.array([100, 200]) / fc,
                                   rtol=1e-9)
        np.testing.assert_allclose(acc['load_rms_pct_dynamic'],
                                   [100 * 100 / (3000 / math.sqrt(2)),
                                    100 * 200 / (4000 / math.sqrt(2))], rtol=2e-3)
        # The 5 m sine passes the 0.5-30 m band-pass at ~unit gain: RMS 0.2 mm / sqrt(2).
        assert acc['profile_rms_m'][0] == pytest.approx(2e-4 / math.sqrt(2), rel=0.02)
        assert acc['profile_rms_m'][1] == pytest.approx(0.0, abs=1e-12)
        assert acc['profile_against'] == 'ground truth'
        assert acc['samples_judged'] == int(np.count_nonzero(est.converged))
        assert summary['rejected_total'] == 3 and summary['lift_off_samples'] == 13
        assert summary['segments'] == 6 and summary['distance_m'] == pytest.approx(599.96)

    def test_segments_against_numpy(self):
        est, drive, _ = make_case(fixes=True)
        _, seg, _ = report.summarize(est, drive, VEHICLE, segment_length_m=100.0)
        x = est.distance_m
        np.testing.assert_allclose(seg['start_m'], [0, 100, 200, 300, 400, 500])
        for j in range(6):
            last = j == 5
            m = (x >= 100 * j) & ((x <= x[-1]) if last else (x < 100 * (j + 1)))
            f = est.wheel_load_n[m]
            np.testing.assert_allclose([seg['dlc_left'][j], seg['dlc_right'][j]],
                                       f.std(axis=0) / f.mean(axis=0), rtol=1e-9)
            assert seg['peak_load_right_n'][j] == pytest.approx(f[:, 1].max())
            assert seg['max_abs_ltr'][j] == pytest.approx(np.abs(est.ltr[m]).max())
        np.testing.assert_array_equal(seg['lift_offs'], [1, 0, 0, 1, 0, 0])
        # IRI of the truth equals that of the estimate's right track (no error there).
        np.testing.assert_allclose(seg['iri_right_m_per_km'], seg['true_iri_right_m_per_km'])
        assert np.all(seg['true_iri_left_m_per_km'] > 0.5)
        # Coordinates from the fixes: latitude 48 + 1e-5 x.
        np.testing.assert_allclose(seg['start_lat'], 48.0 + 1e-5 * seg['start_m'], atol=1e-9)

    def test_no_truth_no_accuracy(self):
        est, drive, _ = make_case(with_truth=False)
        summary, seg, _ = report.summarize(est, drive, VEHICLE)
        assert summary['accuracy'] is None and not summary['has_ground_truth']
        assert np.all(np.isnan(seg['true_iri_left_m_per_km']))
        assert np.all(np.isnan(seg['start_lat']))

    def test_reference_profile_is_aligned_by_correlation(self):
        est, drive, road = make_case(with_truth=False, road_start_m=3.3)
        # The drive starts 3.3 m into the reference (whose distances start at -10 m).
        shifted = RoadProfile(road.distance_m - 10.0, road.elevation_m, name='lpa')
        summary, _, al = report.summarize(est, drive, VEHICLE, reference=shifted)
        assert summary['reference_offset_m'] == pytest.approx(3.3, abs=0.005)
        assert summary['accuracy']['profile_against'] == 'lpa'
        assert summary['accuracy']['profile_rms_m'][0] == pytest.approx(2e-4 / math.sqrt(2),
                                                                        rel=0.05)
        given, _, _ = report.summarize(est, drive, VEHICLE, reference=shifted,
                                       reference_offset_m=3.3)
        assert given['reference_offset_m'] == 3.3

    def test_rejected_rows_and_a_standstill_are_skipped(self):
        est, drive, _ = make_case()
        est.valid[5000:5100] = False
        est.distance_m[7000:7050] = est.distance_m[7000]        # standing still
        summary, seg, al = report.summarize(est, drive, VEHICLE)
        assert al.rows.size == est.valid.sum()
        assert summary['accuracy']['profile_rms_m'][0] == pytest.approx(
            2e-4 / math.sqrt(2), rel=0.05)
        assert len(seg['start_m']) == 6


class TestWhatTheReportSays:
    def test_one_convergence_figure_on_a_constructed_load_error(self):
        """The 100 ms moving RMS of a load error of 3 kN up to 0.48 s, then 50 N, with a 20 ms
        spike at 29.38 s: t_0 is when the moving RMS falls below the tolerance for good over
        the 1 s hold, not the last spike."""
        from road_force_estimator.report import summary as summary_mod
        t = np.arange(0.0, 30.0, 0.001)
        err = np.where(t < 0.48, 3000.0, 50.0)
        err[(t >= 29.38) & (t < 29.40)] = 3000.0
        two = np.column_stack([err, err])
        # Moving RMS over [t - 0.1, t]: below 500 N once the 3 kN share a of the window has
        # a 3000^2 + (1 - a) 50^2 < 500^2, i.e. a < 0.02750; t > 0.48 + 0.1 (1 - a).
        a = (500.0**2 - 50.0**2) / (3000.0**2 - 50.0**2)
        expected = 0.48 + 0.1 * (1.0 - a)
        assert summary_mod.convergence(t, two, 500.0) == pytest.approx(expected, abs=2e-3)
        assert summary_mod.convergence(t, two, 10.0) == math.inf

    def test_summary_says_what_was_run_and_counts_negative_loads(self):
        est, drive, _ = make_case()
        est.wheel_load_n[2000:2039, 1] = -4592.0          # 39 samples below zero
        summary, _, _ = report.summarize(
            est, drive, VEHICLE, mode='online', units='us',
            run_info={'command': 'estimate_bag in -o out', 'params_file': 'p.yaml',
                      'overrides': ['observer.latency:=0.01']})
        assert summary['negative_load_samples'] == 39
        run = summary['run']
        assert run['command'] == 'estimate_bag in -o out' and run['params_file'] == 'p.yaml'
        assert run['overrides'] == ['observer.latency:=0.01']
        assert run['package_version'] and run['mode'] == 'online' and run['latency_s'] == 0.0
        assert run['static_load_n'] == pytest.approx(list(VEHICLE.static_load_n))
        conv = summary['convergence']
        assert conv['source'] == 'measured' and conv['hold_s'] == 1.0
        assert conv['time_s'] == summary['accuracy']['convergence_s']
        assert summary['units'] == 'us'

    def test_the_true_iri_is_taken_on_the_truths_own_samples(self):
        """Online and offline estimates of the same drive accept different samples; the true
        IRI comes from the truth's samples, so both reports show the same one."""
        est, drive, _ = make_case()
        s1, seg1, _ = report.summarize(est, drive, VEHICLE)
        est.valid[7000:7400] = False                     # another mode drops other samples
        s2, seg2, _ = report.summarize(est, drive, VEHICLE)
        assert s1['iri_m_per_km']['true'] == s2['iri_m_per_km']['true']
        assert s1['iri_m_per_km']['reference'] == 'enveloped'
        np.testing.assert_array_equal(seg1['true_iri_left_m_per_km'],
                                      seg2['true_iri_left_m_per_km'])


class TestFindings:
    def test_speed_contradicted_and_negative_loads_reported(self, tmp_path):
        """The drive's contradicted-speed spans (s from the first stamp) and the count of
        load estimates below zero, in the summary and as report lines (issues 16, 18)."""
        from road_force_estimator.report.markdown import write_markdown

        est, drive, _ = make_case()
        est.speed_contradicted[2500:3000] = True        # 5.0 - 5.998 s at 500 Hz
        est.speed_contradicted[5000:5010] = True
        est.wheel_load_n[100:107, 0] = 0.0               # 7 samples clipped at 0 N
        summary, seg, _ = report.summarize(est, drive, VEHICLE, mode='online')
        assert summary['speed_contradicted'] == {'samples': 510,
                                                 'spans_s': [[5.0, 5.998], [10.0, 10.018]]}
        assert summary['negative_load_samples'] == 7
        write_markdown(tmp_path / 'report.md', summary, seg, [])
        text = (tmp_path / 'report.md').read_text()
        assert '510; 5.000-5.998, 10.000-10.018' in text and 'WARNING: speed reads' in text
        assert 'samples where a load estimate went below zero (plotted as 0) | 7' in text

    def test_no_findings_no_lines(self):
        est, drive, _ = make_case()
        summary, _, _ = report.summarize(est, drive, VEHICLE, mode='online')
        assert 'speed_contradicted' not in summary and summary['negative_load_samples'] == 0
