"""The IRI-filtered cross correlation (Karamihas 2004, ProVAL): the analytic cases of its
definition (a copy, a scaled copy, a shifted copy, an inverted copy, an independent road), the
correlation coefficient against numpy's, and the signed IRI filter against the closed-form
steady-state response of the golden quarter-car."""
import numpy as np
import pytest

from road_force_estimator.core.iri import filtered_slope, rectified_slope
from road_force_estimator.core.profile_correlation import (cross_correlation, iri_filter,
                                                          segment_correlation)
from road_force_estimator.core.road import iso8608_profile

V = 80.0 / 3.6
K1, K2, C, MU = 653.0, 63.3, 6.0, 0.15


@pytest.fixture(scope='module')
def road():
    prof = iso8608_profile('C', 800.0, seed=7, dx_m=0.05)
    return prof.distance_m, prof.left_m


def test_identical_rates_one(road):
    x, z = road
    c = cross_correlation(x, z, x, z)
    assert c.rating == pytest.approx(1.0, abs=1e-12)
    assert c.lag_m == 0.0


@pytest.mark.parametrize('k', [0.5, 0.8, 1.25, 3.0])
def test_scaled_copy_rates_the_spread_ratio(road, k):
    """r = 1, penalised by sigma_small / sigma_large = min(k, 1/k)."""
    x, z = road
    c = cross_correlation(x, k * z, x, z)
    assert c.rating == pytest.approx(min(k, 1.0 / k), rel=1e-9)
    assert c.correlation == pytest.approx(1.0, abs=1e-9)
    assert c.spread_ratio == pytest.approx(k, rel=1e-9)


@pytest.mark.parametrize('shift_m', [-0.95, -0.4, 0.3, 0.85])
def test_copy_shifted_inside_the_window_rates_one(road, shift_m):
    """p(x + s) = q(x): the search finds the offset s (a multiple of the 0.05 m grid)."""
    x, z = road
    c = cross_correlation(x - shift_m, z, x, z)
    assert c.rating == pytest.approx(1.0, abs=1e-9)
    assert c.lag_m == pytest.approx(-shift_m, abs=1e-9)


def test_copy_shifted_beyond_the_window_rates_less(road):
    x, z = road
    assert cross_correlation(x - 3.0, z, x, z).rating < 0.5


def test_grade_and_offset_count_for_nothing(road):
    x, z = road
    c = cross_correlation(x, z + 0.02 * x + 0.3, x, z)
    assert c.rating == pytest.approx(1.0, abs=1e-6)


def test_inverted_copy_is_minus_one_at_zero_offset(road):
    x, z = road
    assert cross_correlation(x, -z, x, z, max_lag_m=0.0).rating == pytest.approx(-1.0,
                                                                                abs=1e-12)
    # with the +-1 m search the best offset is the best of the negated autocorrelation:
    # far below a match
    assert cross_correlation(x, -z, x, z).rating < 0.5


def test_independent_roads_rate_about_zero():
    a = iso8608_profile('C', 2000.0, seed=11, dx_m=0.05)
    b = iso8608_profile('C', 2000.0, seed=12, dx_m=0.05)
    c = cross_correlation(a.distance_m, a.left_m, b.distance_m, b.left_m)
    assert abs(c.rating) < 0.1


def test_rating_is_numpys_correlation_times_the_spread_penalty(road):
    """At one offset, rho = corrcoef(p, q) x min(sd) / max(sd), from the filtered signals."""
    x, z = road
    other = iso8608_profile('C', 800.0, seed=8, dx_m=0.05).left_m
    p = z + 0.7 * other
    # a window from one filtered interval's midpoint to another's: no interpolation
    c = cross_correlation(x, p, x, z, max_lag_m=0.0, start_m=50.025, end_m=700.025)
    xp, fp, _ = iri_filter(x, p)
    xq, fq, _ = iri_filter(x, z)
    sel = (xq >= 50.025 - 1e-6) & (xq <= 700.025 + 1e-6)
    r = np.corrcoef(fp[sel], fq[sel])[0, 1]
    sp, sq = np.std(fp[sel]), np.std(fq[sel])
    assert c.correlation == pytest.approx(r, rel=1e-9)
    assert c.rating == pytest.approx(r * min(sp, sq) / max(sp, sq), rel=1e-9)


def test_different_sample_intervals_are_compared_on_one_grid(road):
    """A profile recorded at 0.02 m against its 0.05 m source: the 250 mm base becomes 12
    samples of 0.02 m (0.24 m) instead of 5 of 0.05 m, which alone costs a little."""
    x, z = road
    xe = np.arange(x[0], x[-1], 0.02)
    c = cross_correlation(xe, np.interp(xe, x, z), x, z)
    assert 0.99 < c.rating < 1.0
    assert c.lag_m == pytest.approx(0.0, abs=0.02)


def test_segments_each_find_their_offset(road):
    x, z = road
    res = segment_correlation(x - 0.3, z, x, z, segment_length_m=100.0)
    edges, segs = res.edges_m, res.segments
    assert res.whole == cross_correlation(x - 0.3, z, x, z)
    assert np.all(np.diff(edges) > 0)
    assert len(segs) == edges.size - 1 >= 7
    for s in segs:
        assert s.rating == pytest.approx(1.0, abs=1e-9)
        assert s.lag_m == pytest.approx(-0.3, abs=1e-9)   # p(x - 0.3) = q(x)


def test_a_distance_scale_error_drops_the_rating(road):
    """An odometer reading 1 % long misplaces the profile by 1 m per 100 m: the whole-drive
    rating collapses; a short segment near the start (offset 0.1-0.4 m, inside the search)
    still rates high, one 5-6 m off (outside it) does not."""
    x, z = road
    whole = cross_correlation(1.01 * x, z, x, z)
    assert whole.rating < 0.5
    segs = segment_correlation(1.01 * x, z, x, z, edges_m=[10.0, 40.0, 500.0, 600.0]).segments
    assert segs[0].rating > 0.9
    assert segs[2].rating < 0.5


def test_no_overlap_is_refused(road):
    x, z = road
    with pytest.raises(ValueError, match='no overlap'):
        cross_correlation(x + 1000.0, z, x, z)


def _slope_gain(omega):
    """(z_s' - z_u') / (road slope), steady state at angular frequency omega (golden car)."""
    a = np.array([[0, 1, 0, 0], [-K2, -C, K2, C], [0, 0, 0, 1],
                  [K2 / MU, C / MU, -(K1 + K2) / MU, -C / MU]], dtype=float)
    b = np.array([0, 0, 0, K1 / MU], dtype=float)
    x = np.linalg.solve(1j * omega * np.eye(4) - a, b)
    return x[0] - x[2]


@pytest.mark.parametrize('wavelength_m', [1.5, 4.0, 15.0])
def test_signed_filter_is_the_closed_form_response(wavelength_m):
    """A sinusoid h = A sin(kx): slope over the base b = (2A/b) sin(kb/2) cos(k(x + b/2));
    the filter's steady state is Re(G(kV) * that phasor), amplitude and phase."""
    dx, amp = 0.005, 1e-3
    x = np.arange(0.0, 400.0, dx)
    kx = 2.0 * np.pi / wavelength_m
    out = filtered_slope(x, amp * np.sin(kx * x))
    b = out.base_samples * dx
    pos = out.position_m
    steady = pos > 200.0
    phasor = (2.0 * amp / b) * np.sin(kx * b / 2.0) * np.exp(1j * kx * (pos + b / 2.0))
    expected = np.real(_slope_gain(kx * V) * phasor)
    scale = np.max(np.abs(expected[steady]))
    assert np.max(np.abs(out.slope[steady] - expected[steady])) < 0.01 * scale
    assert np.array_equal(np.abs(out.slope), rectified_slope(x, amp * np.sin(kx * x)).slope)
