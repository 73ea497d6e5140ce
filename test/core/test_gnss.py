"""GNSS route geometry against Vincenty's inverse geodesic (written here, independently)."""
import math

import numpy as np
import pytest

from road_force_estimator.core.gnss import positions_at, route


def vincenty_inverse(lat1, lon1, lat2, lon2):
    """Geodesic distance (m) and initial azimuth (deg) on WGS84 (Vincenty 1975)."""
    a, f = 6378137.0, 1 / 298.257223563
    b = a * (1 - f)
    u1 = math.atan((1 - f) * math.tan(math.radians(lat1)))
    u2 = math.atan((1 - f) * math.tan(math.radians(lat2)))
    lon_diff = math.radians(lon2 - lon1)
    lam = lon_diff
    for _ in range(200):
        sin_lam, cos_lam = math.sin(lam), math.cos(lam)
        sin_sigma = math.hypot(math.cos(u2) * sin_lam,
                               math.cos(u1) * math.sin(u2)
                               - math.sin(u1) * math.cos(u2) * cos_lam)
        cos_sigma = math.sin(u1) * math.sin(u2) + math.cos(u1) * math.cos(u2) * cos_lam
        sigma = math.atan2(sin_sigma, cos_sigma)
        sin_alpha = math.cos(u1) * math.cos(u2) * sin_lam / sin_sigma
        cos2_alpha = 1 - sin_alpha**2
        cos_2sm = cos_sigma - 2 * math.sin(u1) * math.sin(u2) / cos2_alpha if cos2_alpha else 0
        c = f / 16 * cos2_alpha * (4 + f * (4 - 3 * cos2_alpha))
        lam_prev = lam
        lam = lon_diff + (1 - c) * f * sin_alpha * (
            sigma + c * sin_sigma * (cos_2sm + c * cos_sigma * (-1 + 2 * cos_2sm**2)))
        if abs(lam - lam_prev) < 1e-13:
            break
    u_sq = cos2_alpha * (a**2 - b**2) / b**2
    big_a = 1 + u_sq / 16384 * (4096 + u_sq * (-768 + u_sq * (320 - 175 * u_sq)))
    big_b = u_sq / 1024 * (256 + u_sq * (-128 + u_sq * (74 - 47 * u_sq)))
    d_sigma = big_b * sin_sigma * (cos_2sm + big_b / 4 * (
        cos_sigma * (-1 + 2 * cos_2sm**2)
        - big_b / 6 * cos_2sm * (-3 + 4 * sin_sigma**2) * (-3 + 4 * cos_2sm**2)))
    dist = b * big_a * (sigma - d_sigma)
    az = math.degrees(math.atan2(math.cos(u2) * math.sin(lam),
                                 math.cos(u1) * math.sin(u2)
                                 - math.sin(u1) * math.cos(u2) * math.cos(lam)))
    return dist, az % 360.0


@pytest.mark.parametrize('heading', [0.0, 45.0, 90.0, 200.0])
def test_straight_route_matches_geodesic_distance_and_azimuth(heading):
    t = np.arange(0.0, 100.0 + 1e-9, 0.1)           # 100 s at 20 m/s = 2 km
    r = route(t, 20.0, start_latitude_deg=48.1486, start_longitude_deg=17.1077,
              heading_deg=heading)
    for k in (500, 1000):
        dist, az = vincenty_inverse(48.1486, 17.1077, r.latitude_deg[k], r.longitude_deg[k])
        assert dist == pytest.approx(20.0 * t[k], abs=0.05)
        # A rhumb line (constant heading) and the geodesic to its end point start apart by at
        # most (d / 2N) tan(lat) rad: 0.010 deg for 2 km east at 48 deg.
        assert (az - heading + 180.0) % 360.0 - 180.0 == pytest.approx(0.0, abs=0.012)


def test_lateral_acceleration_bends_the_route_left_on_a_circle():
    v, ay = 20.0, 2.0                               # radius v^2 / a_y = 200 m
    t = np.arange(0.0, 20.0 + 1e-9, 0.01)
    r = route(t, v, start_latitude_deg=48.0, start_longitude_deg=17.0, heading_deg=0.0,
              lateral_accel_mps2=ay)
    radius = v**2 / ay
    for k in (500, 1000, 2000):
        theta = v * t[k] / radius
        chord, _ = vincenty_inverse(48.0, 17.0, r.latitude_deg[k], r.longitude_deg[k])
        assert chord == pytest.approx(2 * radius * math.sin(theta / 2), abs=0.05)
    assert r.longitude_deg[1000] < 17.0             # heading north, a left turn goes west
    assert r.heading_deg[1000] == pytest.approx(360.0 - math.degrees(v * 10.0 / radius), abs=1e-6)


def test_positions_between_fixes_are_interpolated_and_never_extrapolated():
    stamps = np.array([0, 100_000_000, 200_000_000], dtype=np.int64)
    lat = np.array([48.0, 48.001, 48.003])
    lon = np.array([17.0, 17.0, 17.002])
    qlat, qlon = positions_at(stamps, lat, lon, np.array([50_000_000, 150_000_000,
                                                          250_000_000, -1]))
    assert qlat[:2] == pytest.approx([48.0005, 48.002])
    assert qlon[:2] == pytest.approx([17.0, 17.001])
    assert np.isnan(qlat[2:]).all() and np.isnan(qlon[2:]).all()
    nlat, _ = positions_at(stamps[:1], lat[:1], lon[:1], np.array([0]))
    assert np.isnan(nlat).all()


def test_fix_noise_per_fix_equals_batch_and_has_its_standard_deviation():
    from road_force_estimator.core.gnss import FixNoise, radii_of_curvature
    r = route(np.arange(0.0, 400.0, 0.1), 20.0, start_latitude_deg=48.1486,
              start_longitude_deg=17.1077, heading_deg=30.0)
    lat, lon = FixNoise(2.5, 7).apply(r.latitude_deg, r.longitude_deg)
    one = FixNoise(2.5, 7)                       # the node's path: one fix at a time
    for k in (0, 1, 2, 3):
        a, b = one.apply(r.latitude_deg[k], r.longitude_deg[k])
        assert (a[0], b[0]) == (lat[k], lon[k])
    m, n = radii_of_curvature(r.latitude_deg)
    north = np.radians(lat - r.latitude_deg) * m
    east = np.radians(lon - r.longitude_deg) * n * np.cos(np.radians(r.latitude_deg))
    for axis in (north, east):                   # 4000 fixes: the std within 5 %
        assert np.std(axis) == pytest.approx(2.5, rel=0.05)
        assert abs(np.mean(axis)) < 0.15
    assert abs(np.corrcoef(north, east)[0, 1]) < 0.05
    same = FixNoise(0.0, 7).apply(r.latitude_deg, r.longitude_deg)
    np.testing.assert_array_equal(same[0], r.latitude_deg)
    with pytest.raises(ValueError, match='GNSS noise'):
        FixNoise(-1.0, 1)


@pytest.mark.parametrize('lat0, heading', [(48.1486, 30.0), (65.0, 90.0), (-33.9, 200.0)])
def test_local_east_north_keeps_the_distances_along_a_track(lat0, heading):
    from road_force_estimator.core.gnss import local_east_north
    t = np.arange(0.0, 1000.0 + 1e-9, 1.0)       # 20 km, a fix every 20 m
    r = route(t, 20.0, start_latitude_deg=lat0, start_longitude_deg=17.1, heading_deg=heading,
              lateral_accel_mps2=np.where(t > 500.0, 0.2, 0.0))
    e, n = local_east_north(r.latitude_deg, r.longitude_deg)
    steps = np.hypot(np.diff(e), np.diff(n))
    geodesic = np.array([vincenty_inverse(r.latitude_deg[k], r.longitude_deg[k],
                                          r.latitude_deg[k + 1], r.longitude_deg[k + 1])[0]
                         for k in range(t.size - 1)])
    np.testing.assert_allclose(steps, geodesic, rtol=0.0, atol=1e-6)
    assert np.sum(steps) == pytest.approx(np.sum(geodesic), abs=1e-4)    # over 20 km
    assert np.sum(steps) == pytest.approx(20000.0, abs=0.2)   # the route's own chords
