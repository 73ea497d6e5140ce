"""report: numbers against closed-form answers on synthetic estimates, files and figures.

References: estimates built here from a known truth plus known errors (a constant load offset,
a sine on the profile, an LTR offset), DLC and peaks computed here per segment with numpy, a
reference profile shifted by a known distance, and the PNG format's own header.
"""
import csv
import json
import math
import struct
from types import SimpleNamespace

import numpy as np
import pytest

from road_force_estimator.report import report
from road_force_estimator.bagio.bag_io import Fixes, GroundTruth
from road_force_estimator.estimation import EstimateArrays, EstimatorStatus
from road_force_estimator.core.parameters import VehicleParameters
from road_force_estimator.core.road import RoadProfile, iso8608_profile
from road_force_estimator.core.segments import SEGMENT_COLUMNS

VEHICLE = VehicleParameters()
RATE = 500.0
SPEED = 20.0


def make_case(n=15000, load_offset=(100.0, -200.0), with_truth=True, fixes=False,
              road_start_m=0.0):
    """A drive of n samples at 500 Hz and 20 m/s (600 m for n = 15000): the truth is an ISO
    class C road and sinusoidal loads; the estimate = truth + known errors."""
    t = np.arange(n) / RATE
    x = SPEED * t
    road = iso8608_profile('C', x[-1] + road_start_m + 1.0, seed=4, dx_m=0.04)
    true_road = road.elevation_at(road_start_m + x)
    fc = np.asarray(VEHICLE.static_load_n)
    dyn = np.column_stack([3000.0 * np.sin(2 * np.pi * 2.0 * t),
                           4000.0 * np.cos(2 * np.pi * 3.0 * t)])
    true_load = fc + dyn
    est_load = true_load + np.asarray(load_offset)
    # Profile error: a 5 m sine of 0.2 mm on the left only (inside the 0.5-30 m band).
    est_road = true_road + np.column_stack([2e-4 * np.sin(2 * np.pi * x / 5.0), np.zeros(n)])
    ltr = (est_load[:, 1] - est_load[:, 0]) / est_load.sum(axis=1)
    zeros, pair = np.zeros(n), np.zeros((n, 2))
    lift = np.zeros((n, 2), bool)
    lift[1000:1010, 0] = True          # one lift-off event of 10 samples in the first segment
    lift[8000:8003, 1] = True          # and one in the fifth
    stamps = 10**18 + np.round(t * 1e9).astype(np.int64)
    conv = t >= 0.2
    est = EstimateArrays(
        stamp_ns=stamps, valid=np.ones(n, bool), distance_m=x, q_m=pair, dq=pair, ddq=pair,
        roll_rad=zeros, droll=zeros, ddroll=zeros, body_heave_m=zeros, body_heave_rate=zeros,
        body_accel_mps2=zeros, wheel_heave_m=pair, wheel_heave_rate=pair,
        wheel_accel_mps2=pair, road_m=est_road, tire_force_dynamic_n=est_load - fc,
        wheel_load_n=est_load, ltr=ltr, residual_nm=zeros, lift_off=lift, converged=conv,
        status=EstimatorStatus(accepted=n, settling_time_s=0.2))
    truth = GroundTruth(stamps, true_load, true_road, x) if with_truth else None
    fx = None
    if fixes:
        k = np.arange(0, n, 50)
        fx = Fixes(stamps[k], 48.0 + 1e-5 * x[k], np.full(k.size, 17.0), np.zeros(k.size))
    drive = SimpleNamespace(
        truth=truth, fixes=fx, q_m=pair, roll_rad=zeros,
        messages={'/suspension/deflections': n + 3},
        rejected={'/suspension/deflections': {'nonfinite': 2, 'duplicate_stamp': 1}},
        issues=('bag_0.mcap: the file ends inside a chunk',))
    return est, drive, road


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


def png_size(path):
    data = path.read_bytes()
    assert data[:8] == b'\x89PNG\r\n\x1a\n'
    return struct.unpack('>II', data[16:24])


class TestFiles:
    def test_report_folder(self, tmp_path):
        est, drive, _ = make_case(fixes=True)
        summary = report.write_report(tmp_path / 'r', est, drive, VEHICLE, mode='offline',
                                      input_name='drive_a')
        folder = tmp_path / 'r'
        assert summary['figures'] == list(report.FIGURES)
        for name in report.FIGURES:
            w, h = png_size(folder / name)
            assert w >= 1000 and h >= 600 and (folder / name).stat().st_size > 20_000
        with (folder / 'segments.csv').open() as f:
            rows = list(csv.reader(f))
        assert tuple(rows[0]) == SEGMENT_COLUMNS and len(rows) == 7
        assert float(rows[1][rows[0].index('start_lat')]) == pytest.approx(48.0)
        md = (folder / 'report.md').read_text()
        for text in ('# Estimate report: drive_a', 'Mode **offline**', '## Accuracy',
                     '| `/suspension/deflections` | nonfinite | 2 |',
                     'Breaks found while reading', '## Segments (100 m)', '![states](states.png)'):
            assert text in md, text
        data = json.loads((folder / 'report.json').read_text())
        assert data['accuracy']['load_rms_n'] == pytest.approx([100.0, 200.0])
        assert data['mode'] == 'offline' and data['input'] == 'drive_a'

    def test_without_figures_and_never_converged(self, tmp_path):
        est, drive, _ = make_case(n=3000)
        est.converged[:] = False        # never converged: judged from the settling time (0.2 s)
        summary = report.write_report(tmp_path / 'r', est, drive, VEHICLE, figures=False)
        assert summary['figures'] == [] and summary['judged_from'] == 'settling time'
        assert summary['accuracy']['samples_judged'] == 3000 - 100
        np.testing.assert_allclose(summary['accuracy']['load_rms_n'], [100.0, 200.0])
        assert not list((tmp_path / 'r').glob('*.png'))
        data = json.loads((tmp_path / 'r' / 'report.json').read_text())
        assert data['first_converged_s'] is None        # inf -> null in JSON
        assert 'never reported convergence' in (tmp_path / 'r' / 'report.md').read_text()

    def test_a_drive_without_distance(self, tmp_path):
        est, drive, _ = make_case(n=400)
        est.distance_m[:] = 0.0
        summary = report.write_report(tmp_path / 'r', est, drive, VEHICLE)
        assert summary['segments'] == 0
        assert 'No segment' in (tmp_path / 'r' / 'report.md').read_text()
