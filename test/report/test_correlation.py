"""report.correlation: the IRI-filtered cross correlation of the estimated profile in the
summary, against the core function on the same window (analytically tested in
test/core/test_profile_correlation.py), and what an odometer scale error does to it."""
import numpy as np
import pytest

from report_case import VEHICLE, make_case
from road_force_estimator import report
from road_force_estimator.bagio import GroundTruth
from road_force_estimator.core.profile_correlation import cross_correlation
from road_force_estimator.report.markdown import write_markdown


def test_summary_rates_each_wheel_and_each_segment(tmp_path):
    """The right wheel's estimate is exact (1); the left carries a 0.2 mm, 5 m sine."""
    est, drive, _ = make_case()
    summary, seg, _ = report.summarize(est, drive, VEHICLE)
    acc = summary['accuracy']
    assert acc['profile_xcorr_distance'] == 'true'
    assert acc['profile_xcorr'][1] == pytest.approx(1.0, abs=1e-9)
    assert acc['profile_xcorr_lag_m'][1] == pytest.approx(0.0, abs=1e-9)
    x = est.distance_m
    start = x[np.argmax(est.converged)] + 30.0
    left = cross_correlation(x, est.road_m[:, 0], drive.truth.distance_m,
                             drive.truth.road_m[:, 0], start_m=start)
    assert acc['profile_xcorr'][0] == pytest.approx(left.rating, rel=1e-12)
    assert 0.99 < acc['profile_xcorr'][0] < 1.0 - 1e-6     # a small error: a little below 1
    segs = acc['profile_xcorr_segments']
    assert segs['start_m'] == list(seg['start_m'])      # the report's segments (the first
    assert segs['end_m'] == list(seg['end_m'])          # judged from the window's start on)
    np.testing.assert_allclose(segs['right'], 1.0, atol=1e-9)
    assert acc['profile_xcorr_segment_min'] == pytest.approx(min(segs['left']))
    write_markdown(tmp_path / 'report.md', summary, seg, [])
    text = (tmp_path / 'report.md').read_text()
    assert 'profile cross correlation, IRI-filtered' in text
    assert 'the truth at the distance truly travelled' in text


def test_an_odometer_reading_one_percent_long_collapses_the_rating():
    est, drive, _ = make_case()
    exact, _, _ = report.summarize(est, drive, VEHICLE)
    t = drive.truth
    drive.truth = GroundTruth(t.stamps_ns, t.wheel_load_n, t.road_m, t.distance_m.copy())
    est.distance_m[:] = 1.01 * est.distance_m
    long, _, _ = report.summarize(est, drive, VEHICLE)
    assert exact['accuracy']['profile_xcorr'][1] == pytest.approx(1.0, abs=1e-9)
    assert long['accuracy']['profile_xcorr'][1] < 0.5
    # the first segment is off by 0.3-1 m (inside the offset search): still mostly found;
    # the last, 5-6 m off, is not
    segs = long['accuracy']['profile_xcorr_segments']['right']
    assert segs[0] > 0.8 and segs[-1] < 0.5


def test_no_truth_no_correlation():
    est, drive, _ = make_case(with_truth=False)
    summary, _, _ = report.summarize(est, drive, VEHICLE)
    assert summary['accuracy'] is None
