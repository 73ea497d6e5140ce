"""GNSS route of a simulated drive and position look-up by stamp (WGS84 degrees).

The route starts at a given latitude/longitude with a heading (degrees clockwise from north)
and runs straight unless a lateral acceleration bends it: with a_y positive to the LEFT
(REP-103) the vehicle turns left, so the clockwise heading changes at ``-a_y / v`` rad/s.
Positions are integrated on the WGS84 ellipsoid with the local meridian and prime-vertical
radii of curvature, so a constant heading follows a rhumb line; over the few kilometres of a
drive this is exact to well below a centimetre per kilometre.

The simulated receiver's error (:class:`FixNoise`) is white Gaussian noise in metres, north and
east, of one standard deviation (``simulator.gnss.noise``), drawn two per fix in fix order from
its own generator, so the batch path and the per-fix path (the plant_simulator node) give the
same numbers. :func:`local_east_north` maps a track of positions to metres on a plane, step by
step (for the odometer fusion).

This module imports numpy only (core).
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

__all__ = ['WGS84_A_M', 'WGS84_E2', 'GnssRoute', 'route', 'positions_at', 'radii_of_curvature',
           'FixNoise', 'local_east_north', 'NOISE_SEED_OFFSET']

#: The fix noise's generator is seeded with (simulator.seed, this): a stream of its own, apart
#: from the sensor noise's.
NOISE_SEED_OFFSET = 8608

WGS84_A_M = 6378137.0
WGS84_F = 1.0 / 298.257223563
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)


def radii_of_curvature(lat_deg: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """Meridian radius M and prime-vertical radius N (m) of WGS84 at ``lat_deg``."""
    s2 = np.sin(np.radians(lat_deg)) ** 2
    w = np.sqrt(1.0 - WGS84_E2 * s2)
    return WGS84_A_M * (1.0 - WGS84_E2) / w**3, WGS84_A_M / w


@dataclass(frozen=True)
class GnssRoute:
    """Positions of a drive at the samples of ``time_s``.

    Attributes: ``time_s`` (n,), ``latitude_deg`` (n,), ``longitude_deg`` (n,),
    ``heading_deg`` (n,), clockwise from north.
    """

    time_s: np.ndarray
    latitude_deg: np.ndarray
    longitude_deg: np.ndarray
    heading_deg: np.ndarray


def route(time_s: np.ndarray, speed_mps: np.ndarray | float, *, start_latitude_deg: float,
          start_longitude_deg: float, heading_deg: float,
          lateral_accel_mps2: np.ndarray | float = 0.0) -> GnssRoute:
    """Integrate the route over the samples ``time_s`` (s, increasing).

    Parameters
    ----------
    time_s : array (n,)
        Sample times (s).
    speed_mps : array (n,) or float
        Vehicle speed (m/s), >= 0 (a stop: the position holds).
    start_latitude_deg, start_longitude_deg : float
        WGS84 position at ``time_s[0]``.
    heading_deg : float
        Initial heading, degrees clockwise from north.
    lateral_accel_mps2 : array (n,) or float
        Lateral acceleration, positive to the left (m/s^2).

    Notes
    -----
    Heading and position are integrated with the trapezoidal rule between samples.
    """
    t = np.asarray(time_s, dtype=float)
    n = t.size
    v = np.broadcast_to(np.asarray(speed_mps, dtype=float), (n,))
    ay = np.broadcast_to(np.asarray(lateral_accel_mps2, dtype=float), (n,))
    dt = np.diff(t)
    yaw_rate = -ay / np.maximum(v, 1e-3)            # rad/s, clockwise positive
    psi = np.radians(heading_deg) + np.concatenate(
        ([0.0], np.cumsum(0.5 * (yaw_rate[1:] + yaw_rate[:-1]) * dt)))
    north_rate = v * np.cos(psi)
    east_rate = v * np.sin(psi)
    lat = np.empty(n)
    lon = np.empty(n)
    lat[0], lon[0] = start_latitude_deg, start_longitude_deg
    # Step by step so that the radii follow the latitude (a midpoint evaluation per step).
    for k in range(n - 1):
        dn = 0.5 * (north_rate[k] + north_rate[k + 1]) * dt[k]
        de = 0.5 * (east_rate[k] + east_rate[k + 1]) * dt[k]
        m, _ = radii_of_curvature(lat[k] + np.degrees(0.5 * dn / WGS84_A_M))
        lat_mid = lat[k] + np.degrees(0.5 * dn / m)
        _, n_mid = radii_of_curvature(lat_mid)
        lat[k + 1] = lat[k] + np.degrees(dn / m)
        lon[k + 1] = lon[k] + np.degrees(de / (n_mid * np.cos(np.radians(lat_mid))))
    return GnssRoute(t, lat, lon, np.degrees(psi) % 360.0)


def positions_at(fix_stamps_ns: np.ndarray, latitude_deg: np.ndarray,
                 longitude_deg: np.ndarray, query_stamps_ns: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Latitude and longitude at ``query_stamps_ns``, linearly interpolated between fixes.

    Stamps outside the span of the fixes (or with fewer than two fixes) give NaN: a position is
    never extrapolated.
    """
    q = np.asarray(query_stamps_ns, dtype=np.int64)
    if len(fix_stamps_ns) < 2:
        nan = np.full(q.shape, np.nan)
        return nan, nan.copy()
    f = np.asarray(fix_stamps_ns, dtype=np.int64)
    t0 = f[0]
    x = (f - t0).astype(float)
    xq = (q - t0).astype(float)
    lat = np.interp(xq, x, latitude_deg)
    lon = np.interp(xq, x, longitude_deg)
    outside = (xq < x[0]) | (xq > x[-1])
    lat[outside] = np.nan
    lon[outside] = np.nan
    return lat, lon


def local_east_north(lat_deg, lon_deg) -> tuple[np.ndarray, np.ndarray]:
    """East and north (m, (k,)) of a track of positions, built step by step from the first:
    each step's north and east with the WGS84 radii of curvature at its midpoint, so that the
    distance between consecutive positions is exact to ~(step / 6400 km)^2 relative however
    long the track (a tangent plane at one point would stretch distances by ~1e-5 per 2 km
    away from it). The frame turns slowly with the meridians' convergence (``dlon sin(lat)``:
    under 2 mrad per 10 km east at 48 deg), a bend of the track, not a change of its length."""
    lat = np.asarray(lat_deg, dtype=float)
    lon = np.asarray(lon_deg, dtype=float)
    mid = 0.5 * (lat[1:] + lat[:-1])
    m, n = radii_of_curvature(mid)
    dn = np.radians(np.diff(lat)) * m
    de = np.radians(np.diff(lon)) * n * np.cos(np.radians(mid))
    zero = np.zeros(1)
    return np.concatenate([zero, np.cumsum(de)]), np.concatenate([zero, np.cumsum(dn)])


class FixNoise:
    """White position noise of a simulated receiver: ``std_m`` (m) north and east per fix.

    Parameters
    ----------
    std_m : float
        Standard deviation per horizontal axis (m), >= 0 (0: no noise, nothing drawn).
    seed : int
        ``simulator.seed``; the generator is ``default_rng((seed, NOISE_SEED_OFFSET))``.
    """

    def __init__(self, std_m: float, seed: int) -> None:
        if not (math.isfinite(std_m) and std_m >= 0.0):
            raise ValueError(f'GNSS noise = {std_m!r} m: must be a finite number >= 0')
        self.std_m = float(std_m)
        self._rng = np.random.default_rng((int(seed), NOISE_SEED_OFFSET))

    def apply(self, latitude_deg, longitude_deg) -> tuple[np.ndarray, np.ndarray]:
        """The positions (deg, (k,)) with the next k fixes' noise added: two standard normals
        per fix (north, east), in order; unchanged (same values) when ``std_m`` is 0."""
        lat = np.array(latitude_deg, dtype=float, ndmin=1)
        lon = np.array(longitude_deg, dtype=float, ndmin=1)
        if self.std_m == 0.0:
            return lat, lon
        z = self._rng.standard_normal((lat.size, 2)) * self.std_m
        m, n = radii_of_curvature(lat)
        return (lat + np.degrees(z[:, 0] / m),
                lon + np.degrees(z[:, 1] / (n * np.cos(np.radians(lat)))))
