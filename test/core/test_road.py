"""Road profiles (MODEL.md "Road profiles"): ISO 8608 spectra and coherence checked with
scipy.signal, analytic enveloping, events. The files are test_road_files.py."""
import math

import numpy as np
import pytest
from scipy.signal import coherence, welch

from road_force_estimator.core.road import (
    ISO8608_GD0_M3, RoadProfile, add_event, coherence_model, flat_profile, iso8608_profile,
    iso8608_psd)



# ------------------------------------------------------------------------------------------
# ISO 8608
# ------------------------------------------------------------------------------------------

def test_class_levels_are_the_geometric_means_of_model_md():
    # MODEL.md: Gd(n0) = 16, 64, 256, 1024, 4096, 16384, 65536, 262144 x 1e-6 m^3 for A..H.
    expected = [16, 64, 256, 1024, 4096, 16384, 65536, 262144]
    assert [ISO8608_GD0_M3[c] / 1e-6 for c in 'ABCDEFGH'] == pytest.approx(expected)
    assert iso8608_psd('c', 0.1) == pytest.approx(256e-6)
    assert iso8608_psd('C', 1.0) == pytest.approx(256e-6 * 0.01)
    with pytest.raises(ValueError, match='road_class'):
        iso8608_psd('I', 0.1)


@pytest.fixture(scope='module')
def long_road():
    return iso8608_profile('C', 10000.0, seed=7)


@pytest.mark.parametrize('track', [0, 1])
def test_welch_psd_follows_gd(long_road, track):
    n, psd = welch(long_road.elevation_m[:, track], fs=1 / 0.05, nperseg=4096)
    # Octave bands from 0.02 to 5.12 cycles/m (50 m to 0.2 m wavelength).
    # Measured: within 4 % in every band (both tracks); tolerance 10 %.
    edges = 0.02 * 2.0 ** np.arange(9)
    for lo, hi in zip(edges[:-1], edges[1:]):
        band = (n >= lo) & (n < hi)
        gd = 256e-6 * (n[band] / 0.1) ** -2
        assert psd[band].mean() / gd.mean() == pytest.approx(1.0, abs=0.10), (lo, hi)


def test_variance_is_the_psd_integral():
    road = iso8608_profile('B', 2000.0, seed=3, dx_m=0.1)
    npts = len(road)
    dn = 1.0 / (npts * 0.1)
    k = np.arange(1, (npts + 1) // 2)
    n = k * dn
    n = n[(n >= 0.01) & (n <= 5.0)]
    # Each cosine carries Gd(n_k) dn; on a whole period they are orthogonal.
    riemann = np.sum(64e-6 * (n / 0.1) ** -2 * dn)
    assert np.mean(road.left_m ** 2) == pytest.approx(riemann, rel=1e-9)
    assert np.mean(road.left_m) == pytest.approx(0.0, abs=1e-12)
    # And close to the analytic integral Gd0 n0^2 (1/n_lo - 1/n_hi).
    assert riemann == pytest.approx(64e-6 * 0.01 * (1 / 0.01 - 1 / 5.0), rel=0.05)


def test_coherence_between_tracks_follows_the_model(long_road):
    n, coh = coherence(long_road.left_m, long_road.right_m, fs=1 / 0.05, nperseg=4096)
    edges = 0.01 * 2.0 ** np.arange(10)
    # Measured: within 0.02 of the model in every octave from 0.01 to 5 cycles/m (the
    # estimate is biased up by about 1/segments = 0.01 where coherence is low).
    for lo, hi in zip(edges[:-1], edges[1:]):
        band = (n >= lo) & (n < hi)
        assert coh[band].mean() == pytest.approx(coherence_model(n[band]).mean(), abs=0.05)


def test_coherence_model_matches_measured_roads():
    # MODEL.md: coherence ~0.6-0.7 at 50 m wavelength, below 0.2 under 2 m.
    assert 0.6 <= coherence_model(1 / 50) <= 0.7
    assert np.all(coherence_model(np.linspace(0.5, 10, 50)) < 0.2)
    assert np.all(np.diff(coherence_model(np.linspace(0, 10, 100))) < 0)


def test_coherence_options():
    same = iso8608_profile('D', 300.0, seed=2, coherence='identical')
    assert np.array_equal(same.left_m, same.right_m)
    free = iso8608_profile('D', 3000.0, seed=2, coherence=None)
    default = iso8608_profile('D', 3000.0, seed=2)
    # The left track depends on the seed only.
    assert np.array_equal(free.left_m, default.left_m)
    n, coh = coherence(free.left_m, free.right_m, fs=20, nperseg=2048)
    assert coh[(n > 0.02) & (n < 5)].mean() < 0.05
    const = iso8608_profile('D', 3000.0, seed=2, coherence=0.5)
    n, coh = coherence(const.left_m, const.right_m, fs=20, nperseg=2048)
    assert coh[(n > 0.02) & (n < 5)].mean() == pytest.approx(0.5, abs=0.05)
    with pytest.raises(ValueError, match='coherence'):
        iso8608_profile('D', 300.0, coherence='partial')
    with pytest.raises(ValueError, match='gamma'):
        iso8608_profile('D', 300.0, coherence=1.5)


def test_seeds_grid_and_levels():
    a = iso8608_profile('C', 200.0, seed=1)
    b = iso8608_profile('C', 200.0, seed=1)
    c = iso8608_profile('C', 200.0, seed=2)
    assert np.array_equal(a.elevation_m, b.elevation_m)
    assert not np.allclose(a.elevation_m, c.elevation_m)
    assert len(a) == 4001 and a.start_m == 0.0 and a.end_m == pytest.approx(200.0)
    # One class up is four times the PSD: twice the RMS, same seed and shape.
    d = iso8608_profile('D', 200.0, seed=1)
    np.testing.assert_allclose(d.elevation_m, 2 * a.elevation_m, rtol=1e-12, atol=1e-15)
    with pytest.raises(ValueError, match='length_m'):
        iso8608_profile('C', -1.0)
    with pytest.raises(ValueError, match='band'):
        iso8608_profile('C', 100.0, band_cpm=(20.0, 30.0))


# ------------------------------------------------------------------------------------------
# Profile object, enveloping, events
# ------------------------------------------------------------------------------------------

def test_profile_validation_and_interpolation():
    p = RoadProfile([0.0, 1.0, 3.0], [[0.0, 1.0], [1.0, 1.0], [3.0, -1.0]])
    np.testing.assert_allclose(p.elevation_at(0.5), [0.5, 1.0])
    np.testing.assert_allclose(p.elevation_at([2.0, 3.0]), [[2.0, 0.0], [3.0, -1.0]])
    np.testing.assert_allclose(p.slope_at([0.5, 1.0, 3.0]), [[1, 0], [1, -1], [1, -1]])
    assert (p.start_m, p.end_m, p.length_m) == (0.0, 3.0, 3.0)
    with pytest.raises(ValueError, match='outside'):
        p.elevation_at(3.01)
    with pytest.raises(ValueError, match='outside'):
        p.elevation_at(-1e-9)
    with pytest.raises(ValueError, match='strictly increasing'):
        RoadProfile([0.0, 1.0, 1.0], [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match='finite'):
        RoadProfile([0.0, 1.0], [0.0, float('nan')])
    with pytest.raises(ValueError, match='shape'):
        RoadProfile([0.0, 1.0], np.zeros((3, 2)))
    single = RoadProfile([0.0, 1.0], [0.1, 0.2])
    assert np.array_equal(single.left_m, single.right_m)
    assert single.elevation_m.flags.writeable is False


@pytest.mark.parametrize('wavelength', [0.5, 1.0, 3.0])
def test_envelope_of_a_sinusoid_is_the_sinc_attenuation(wavelength):
    # A fine grid: the envelope averages the linear interpolant, within (2 pi dx / lambda)^2
    # / 8 of the sinusoid.
    x = np.arange(0.0, 30.0, 0.002)
    p = RoadProfile(x, np.column_stack((np.sin(2 * np.pi * x / wavelength),
                                        np.cos(2 * np.pi * x / wavelength))))
    length = 0.25
    e = p.enveloped(length)
    # Moving average of length L: gain sin(pi L / lambda) / (pi L / lambda), no phase shift.
    a = np.pi * length / wavelength
    gain = math.sin(a) / a
    np.testing.assert_allclose(e.left_m, gain * np.sin(2 * np.pi * e.distance_m / wavelength),
                               atol=2e-4)
    np.testing.assert_allclose(e.right_m, gain * np.cos(2 * np.pi * e.distance_m / wavelength),
                               atol=2e-4)
    assert e.start_m == pytest.approx(0.125) and e.end_m == pytest.approx(x[-1] - 0.125)


def test_envelope_keeps_straight_lines_and_averages_a_step_exactly():
    x = np.array([0.0, 1.0, 2.0, 2.0001, 5.0])
    line = RoadProfile(x, 0.3 * x - 1.0)
    np.testing.assert_allclose(line.enveloped(0.5).left_m,
                               0.3 * line.enveloped(0.5).distance_m - 1.0, atol=1e-14)
    # A near-vertical 1 cm step at 2 m: the average over [x - 0.25, x + 0.25] ramps across it.
    step = RoadProfile(x, [0.0, 0.0, 0.0, 0.01, 0.01])
    e = step.enveloped(0.5)
    np.testing.assert_allclose(e.elevation_at(2.0)[0], 0.005, atol=1e-6)
    np.testing.assert_allclose(e.elevation_at(1.75)[0], 0.0, atol=1e-6)
    assert step.enveloped(0.0) is step
    with pytest.raises(ValueError, match='envelope'):
        step.enveloped(-0.1)
    with pytest.raises(ValueError, match='shorter'):
        RoadProfile([0.0, 0.2], [0.0, 0.0]).enveloped(0.25)


def test_events():
    road = flat_profile(20.0, dx_m=0.1)
    bump = add_event(road, 'bump', 'left', 5.0, 0.8, 0.05)
    assert bump.elevation_at(5.4)[0] == pytest.approx(0.05)
    assert bump.elevation_at(5.2)[0] == pytest.approx(0.025)    # (1 - cos(pi/2)) / 2
    assert np.all(bump.right_m == 0.0)
    assert bump.elevation_at(4.99)[0] == 0.0 and bump.elevation_at(5.81)[0] == 0.0
    assert np.max(np.diff(bump.distance_m[(bump.distance_m >= 5) & (bump.distance_m <= 5.8)])) \
        <= 0.005 + 1e-12
    hole = add_event(road, 'pothole', 'right', 10.0, 0.5, 0.08)
    assert hole.elevation_at(10.25)[1] == pytest.approx(-0.08)
    assert hole.elevation_at(10.011)[1] == pytest.approx(-0.08)
    assert hole.elevation_at(9.99)[1] == 0.0 and np.all(hole.left_m == 0.0)
    step = add_event(road, 'step', 'both', 3.0, 0.4, -0.02)
    np.testing.assert_allclose(step.elevation_at(3.2), [-0.01, -0.01])
    np.testing.assert_allclose(step.elevation_at(19.0), [-0.02, -0.02])
    both = add_event(add_event(road, 'bump', 'left', 2.0, 1.0, 0.01), 'bump', 'left', 2.0,
                     1.0, 0.01)
    assert both.elevation_at(2.5)[0] == pytest.approx(0.02)
    with pytest.raises(ValueError, match='outside'):
        add_event(road, 'bump', 'left', 19.8, 0.5, 0.05)
    with pytest.raises(ValueError, match='kind'):
        add_event(road, 'crack', 'left', 1.0, 0.5, 0.05)
    with pytest.raises(ValueError, match='side'):
        add_event(road, 'bump', 'middle', 1.0, 0.5, 0.05)
    with pytest.raises(ValueError, match='length_m'):
        add_event(road, 'bump', 'left', 1.0, 0.0, 0.05)
