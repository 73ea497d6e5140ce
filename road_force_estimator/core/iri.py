"""International Roughness Index (IRI) of a longitudinal road profile (ASTM E1926).

The IRI is the accumulated suspension stroke of the *golden quarter-car* driven over the
profile at 80 km/h, divided by the distance travelled: m/km (equivalently mm/m). The car is
the normalised two-mass model of Sayers (1995) and ASTM E1926, every coefficient divided by
the sprung mass:

    z_s'' = -K2 (z_s - z_u) - C (z_s' - z_u')
    mu z_u'' = K2 (z_s - z_u) + C (z_s' - z_u') - K1 (z_u - h)

with K1 = 653 s^-2 (tire), K2 = 63.3 s^-2 (suspension), C = 6.0 s^-1 (damper), mu = 0.15
(unsprung / sprung mass) and h the profile elevation under the tire. Following Sayers' GETPI
routine the model is driven by the profile *slope* (so its states are slopes, and a constant
grade costs nothing): the slope is taken over a 250 mm base (the moving average of ASTM E1926),
held constant over each sample interval and propagated with the exact state-transition matrix
``expm(A dt)``, dt = dx / (80 km/h). The initial state is the average slope over the first
11 m for both masses, at rest. The rectified slope ``|z_s' - z_u'| / V`` of every interval,
averaged and multiplied by 1000, is the IRI in m/km.

This module imports numpy and scipy only (core).

References
----------
ASTM E1926-08, Standard Practice for Computing International Roughness Index of Roads from
Longitudinal Profile Measurements. M. W. Sayers, "On the calculation of International
Roughness Index from longitudinal road profile", Transportation Research Record 1501 (1995).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.linalg import expm

from road_force_estimator.core.scipy_signal import signal as _signal
from road_force_estimator.core.segments import segment_bounds

__all__ = [
    'GOLDEN_K1', 'GOLDEN_K2', 'GOLDEN_C', 'GOLDEN_MU', 'IRI_SPEED_MPS', 'BASE_LENGTH_M',
    'INIT_LENGTH_M', 'RectifiedSlope', 'golden_car_matrices', 'rectified_slope',
    'filtered_slope', 'iri', 'iri_segments', 'interval_counts', 'iri_table', 'evenly_spaced',
    'even_spacing_tolerance',
]

#: Golden quarter-car, normalised by the sprung mass (ASTM E1926).
GOLDEN_K1 = 653.0    # tire stiffness, s^-2
GOLDEN_K2 = 63.3     # suspension stiffness, s^-2
GOLDEN_C = 6.0       # suspension damping, s^-1
GOLDEN_MU = 0.15     # unsprung / sprung mass ratio
#: Simulated speed, 80 km/h (m/s).
IRI_SPEED_MPS = 80.0 / 3.6
#: Base length of the slope moving average (m).
BASE_LENGTH_M = 0.25
#: Length over which the initial slope is taken (m).
INIT_LENGTH_M = 11.0
#: Relative tolerance on the sample spacing for a profile to count as evenly spaced (of the
#: mean step), plus the distances' own rounding: :data:`EVEN_SPACING_ULPS` units in the last
#: place of the largest |distance| (:func:`even_spacing_tolerance`).
EVEN_SPACING_RTOL = 1e-6
EVEN_SPACING_ULPS = 64


def golden_car_matrices() -> tuple[np.ndarray, np.ndarray]:
    """State matrix A (4, 4) and input vector B (4,) of the golden quarter-car.

    States ``[z_s, z_s', z_u, z_u']`` (sprung and unsprung displacement and rate); input the
    road elevation h (or, as used here, its slope, which makes every state a slope).
    """
    k1, k2, c, mu = GOLDEN_K1, GOLDEN_K2, GOLDEN_C, GOLDEN_MU
    a = np.array([
        [0.0, 1.0, 0.0, 0.0],
        [-k2, -c, k2, c],
        [0.0, 0.0, 0.0, 1.0],
        [k2 / mu, c / mu, -(k1 + k2) / mu, -c / mu],
    ])
    b = np.array([0.0, 0.0, 0.0, k1 / mu])
    return a, b


def transition(dx_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation over one sample interval: (ST, PR)."""
    a, b = golden_car_matrices()
    st = expm(a * (dx_m / IRI_SPEED_MPS))
    pr = np.linalg.solve(a, (st - np.eye(4)) @ b)
    return st, pr


@dataclass(frozen=True)
class RectifiedSlope:
    """Output of the quarter-car over one profile track.

    Attributes
    ----------
    position_m : ndarray (m,)
        Distance of each slope interval's midpoint (m).
    slope : ndarray (m,)
        Rectified slope ``|z_s' - z_u'| / V`` of each interval (m/m; times 1000 = m/km).
    dx_m : float
        Sample spacing used (m), after resampling if the input was unevenly spaced.
    base_samples : int
        Samples in the 250 mm slope base.
    """

    position_m: np.ndarray
    slope: np.ndarray
    dx_m: float
    base_samples: int


#: A resampled profile is refused when it would have more points than this many times the
#: samples given (and more than :data:`MIN_RESAMPLE_BOUND`): a jump in the distance (a corrupt
#: stamp or odometer reading) would otherwise allocate without bound.
MAX_RESAMPLE_FACTOR = 100
MIN_RESAMPLE_BOUND = 10_000_000


def even_spacing_tolerance(mean_step_m: float, largest_abs_m: float) -> float:
    """How far (m) a step may lie from the mean step ``mean_step_m`` for a profile to count as
    evenly spaced: :data:`EVEN_SPACING_RTOL` of it plus :data:`EVEN_SPACING_ULPS` units in the
    last place of the largest |distance| ``largest_abs_m`` (a double's steps at 40 km are exact
    to ~7e-12 m). Not relative to the distance itself: at 40 km that allowed 4 cm, and a 1 kHz
    drive at 15 and 25 m/s (steps 1.5 and 2.5 cm) passed as even, its 100 m segments' IRI off by
    up to 19 % (test_iri.py)."""
    return EVEN_SPACING_RTOL * mean_step_m + EVEN_SPACING_ULPS * float(
        np.spacing(abs(largest_abs_m)))


def _evenly_spaced(distance_m: np.ndarray, elevation_m: np.ndarray,
                   dx_m: float | None) -> tuple[np.ndarray, np.ndarray, float]:
    """Profile on an even grid: unchanged when it already is, else linearly resampled."""
    x = np.asarray(distance_m, dtype=float)
    z = np.asarray(elevation_m, dtype=float)
    if x.ndim != 1 or z.shape[0] != x.size:
        raise ValueError(f'distance_m shape {x.shape} and elevation_m shape {z.shape}: '
                         'need (n,) and (n,) or (n, 2)')
    if x.size < 2:
        raise ValueError(f'profile has {x.size} sample(s): need at least 2')
    bad = int(np.count_nonzero(~np.isfinite(x)) + np.count_nonzero(~np.isfinite(z)))
    if bad:
        raise ValueError(f'profile has {bad} non-finite value(s): remove them first')
    steps = np.diff(x)
    if np.any(steps < 0.0):
        raise ValueError('distance_m decreases: it must be non-decreasing')
    keep = np.concatenate([[True], steps > 0.0])       # a standstill repeats a distance
    x, z = x[keep], z[keep]
    if x.size < 2:
        raise ValueError('profile covers no distance')
    steps = np.diff(x)
    span = x[-1] - x[0]
    mean_step = span / (x.size - 1)
    uniform = np.all(np.abs(steps - mean_step)
                     <= even_spacing_tolerance(mean_step, max(abs(x[0]), abs(x[-1]))))
    if dx_m is None and uniform:
        return x, z, float(mean_step)
    if dx_m is None:
        dx_m = float(min(np.median(steps), BASE_LENGTH_M))
    if not (dx_m > 0.0 and np.isfinite(dx_m)):
        raise ValueError(f'dx_m = {dx_m!r} m: must be > 0')
    n = int(np.floor(span / dx_m + 1e-9)) + 1
    if n > max(MAX_RESAMPLE_FACTOR * x.size, MIN_RESAMPLE_BOUND):
        i = int(np.argmax(steps))
        raise ValueError(f'profile of {x.size} samples would need {n} points on a {dx_m:g} m '
                         f'grid: its largest distance step is {steps[i]:.6g} m (samples {i} to '
                         f'{i + 1}, from {x[i]:.6g} m); a corrupt distance or stamp?')
    grid = x[0] + dx_m * np.arange(n)
    if z.ndim == 1:
        return grid, np.interp(grid, x, z), float(dx_m)
    return grid, np.column_stack([np.interp(grid, x, z[:, j]) for j in range(z.shape[1])]), \
        float(dx_m)


def evenly_spaced(distance_m: np.ndarray, elevation_m: np.ndarray,
                  dx_m: float | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """The profile on the even grid the IRI runs on: ``(grid (m,), elevation, dx)``.

    Unchanged when already evenly spaced and ``dx_m`` is None; else linearly resampled at
    ``dx_m`` (default min(median spacing, 0.25 m)) from the first sample; a standstill's
    repeated distances keep their first sample (see :func:`rectified_slope`).
    """
    return _evenly_spaced(distance_m, elevation_m, dx_m)


def rectified_slope(distance_m: np.ndarray, elevation_m: np.ndarray, *,
                    dx_m: float | None = None) -> RectifiedSlope:
    """Rectified slope of the golden quarter-car over one profile track.

    Parameters
    ----------
    distance_m : array_like (n,)
        Distance along the road (m), non-decreasing; repeated distances (a standstill) keep
        their first sample. An unevenly spaced profile is resampled linearly at ``dx_m``.
    elevation_m : array_like (n,)
        Elevation (m), any datum (a grade does not change the result).
    dx_m : float, optional
        Spacing to resample at (m). Default: keep an evenly spaced profile as it is, and
        resample an uneven one at min(median spacing, 0.25 m).

    Returns
    -------
    RectifiedSlope

    Raises
    ------
    ValueError
        Shapes, non-finite values, decreasing distance, or a profile shorter than the 11 m
        initialisation plus one slope base.

    Notes
    -----
    ASTM E1926: slope over a base of ``k = max(1, round(0.25 / dx))`` samples,
    ``s_i = (h[i + k] - h[i]) / (k dx)``; ``Z_{i+1} = ST Z_i + PR s_i`` with ST = expm(A dt),
    PR = A^-1 (ST - I) B, dt = dx / V; ``Z_0 = [s0, 0, s0, 0]``, s0 the slope from the first
    sample to the one 11 m further; output ``|Z1 - Z3|`` after each interval. The linear
    recursion runs on the decoupled modes of ST (first-order filters), which keeps its
    accuracy when dx is small and ST is close to the identity.
    """
    out = filtered_slope(distance_m, elevation_m, dx_m=dx_m)
    return replace(out, slope=np.abs(out.slope))


def filtered_slope(distance_m: np.ndarray, elevation_m: np.ndarray, *,
                   dx_m: float | None = None) -> RectifiedSlope:
    """The IRI filter's signed output: the golden quarter-car's ``(z_s' - z_u') / V``.

    What :func:`rectified_slope` rectifies (same arguments, same intervals, same
    initialisation): the slope of each interval with its sign (m/m, positive when the sprung
    mass rises faster than the axle). The IRI filter of profile comparisons (the cross
    correlation of :mod:`road_force_estimator.core.profile_correlation`) is this signal.
    """
    z = np.asarray(elevation_m, dtype=float)
    if z.ndim != 1:
        raise ValueError(f'elevation_m shape {z.shape}: one track (n,) expected')
    x, h, dx = _evenly_spaced(distance_m, z, dx_m)
    k = max(1, int(round(BASE_LENGTH_M / dx)))
    i11 = int(round(INIT_LENGTH_M / dx))
    if x.size <= max(i11, k):
        raise ValueError(f'profile length {x[-1] - x[0]:.3g} m: IRI needs at least '
                         f'{INIT_LENGTH_M:g} m (the initialisation length)')
    slope = (h[k:] - h[:-k]) / (k * dx)
    s0 = (h[i11] - h[0]) / INIT_LENGTH_M
    st, pr = transition(dx)
    # Modal form: ST = V diag(lam) V^-1; eta = V^-1 Z; eta_{i+1} = lam eta_i + beta s_i.
    lam, vec = np.linalg.eig(st)
    inv = np.linalg.inv(vec)
    beta = inv @ pr
    eta0 = inv @ np.array([s0, 0.0, s0, 0.0])
    out = np.array([1.0, 0.0, -1.0, 0.0]) @ vec      # Z1 - Z3 in modal coordinates
    rel = np.zeros(slope.size)
    lfilter = _signal().lfilter
    for j in range(4):
        # a real input gives conjugate modes conjugate responses (LAPACK returns exact
        # conjugate pairs): one of each pair, twice its real part
        if lam[j].imag < 0.0:
            continue
        eta, _ = lfilter([beta[j]], [1.0, -lam[j]], slope, zi=[lam[j] * eta0[j]])
        rel += (2.0 if lam[j].imag > 0.0 else 1.0) * (out[j] * eta).real
    position = x[0] + dx * (np.arange(slope.size) + 0.5)
    return RectifiedSlope(position_m=position, slope=rel.real, dx_m=dx, base_samples=k)


def iri(distance_m: np.ndarray, elevation_m: np.ndarray, *,
        dx_m: float | None = None) -> float | np.ndarray:
    """IRI (m/km) of a whole profile.

    Parameters
    ----------
    distance_m : array_like (n,)
        Distance along the road (m), non-decreasing.
    elevation_m : array_like (n,) or (n, 2)
        One track, or ``[left, right]`` tracks (m).
    dx_m : float, optional
        Resampling spacing (m), see :func:`rectified_slope`.

    Returns
    -------
    float, or ndarray (2,) for two tracks
        Mean rectified slope times 1000 (m/km).

    Examples
    --------
    >>> import numpy as np
    >>> x = np.arange(0.0, 200.0, 0.25)
    >>> round(float(iri(x, 0.01 * x)), 12)    # a constant grade is perfectly smooth
    0.0
    """
    z = np.asarray(elevation_m, dtype=float)
    if z.ndim == 2:
        return np.array([iri(distance_m, z[:, j], dx_m=dx_m) for j in range(z.shape[1])])
    return 1000.0 * float(np.mean(rectified_slope(distance_m, z, dx_m=dx_m).slope))


def iri_segments(distance_m: np.ndarray, elevation_m: np.ndarray,
                 edges_m: np.ndarray | float | None = None, *,
                 segment_length_m: float = 100.0, dx_m: float | None = None) -> np.ndarray:
    """IRI (m/km) per segment of a profile.

    The quarter-car runs once over the whole profile (initialised on its first 11 m); a
    segment's IRI is the mean rectified slope of the intervals whose midpoints lie in
    ``[start, end)`` (the last segment includes its end). NaN for a segment with no interval.

    Parameters
    ----------
    distance_m : array_like (n,)
        Distance along the road (m), non-decreasing.
    elevation_m : array_like (n,) or (n, 2)
        One track or ``[left, right]`` (m).
    edges_m : array_like (k + 1,) or float, optional
        Segment edges (m), increasing. A number is taken as the segment length. Default:
        :func:`road_force_estimator.core.segments.segment_bounds` over the profile with
        ``segment_length_m``.
    segment_length_m : float
        Segment length (m) when no edges are given; default 100 m.
    dx_m : float, optional
        Resampling spacing (m), see :func:`rectified_slope`.

    Returns
    -------
    ndarray (k,) or (k, 2)
    """
    x = np.asarray(distance_m, dtype=float)
    z = np.asarray(elevation_m, dtype=float)
    if edges_m is not None and np.ndim(edges_m) == 0:
        segment_length_m, edges_m = float(edges_m), None
    if edges_m is None:
        if x.size == 0:
            raise ValueError('profile has no sample')
        edges = segment_bounds(float(x[0]), float(x[-1]), segment_length_m)
    else:
        edges = np.asarray(edges_m, dtype=float)
        if edges.ndim != 1 or edges.size < 2 or np.any(np.diff(edges) <= 0.0):
            raise ValueError(f'edges_m = {edges!r}: need at least 2 increasing values')
    if z.ndim == 2:
        return np.column_stack([iri_segments(x, z[:, j], edges, dx_m=dx_m)
                                for j in range(z.shape[1])])
    out = rectified_slope(x, z, dx_m=dx_m)
    k = edges.size - 1
    seg = np.searchsorted(edges, out.position_m, side='right') - 1
    seg[out.position_m == edges[-1]] = k - 1
    inside = (seg >= 0) & (seg < k)
    total = np.bincount(seg[inside], out.slope[inside], minlength=k)
    count = np.bincount(seg[inside], minlength=k)
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.where(count > 0, 1000.0 * total / count, np.nan)


def interval_counts(distance_m: np.ndarray, edges_m: np.ndarray, *,
                    dx_m: float | None = None) -> np.ndarray:
    """How many of :func:`rectified_slope`'s intervals (by their midpoints) fall in each
    segment ``[edges[j], edges[j+1])`` (the last includes its end), as :func:`iri_segments`
    counts them; (k,) int. With these, the IRI of the whole profile is the count-weighted mean
    of the segment IRIs (when the segments cover it), without running the quarter-car again.
    """
    x = np.asarray(distance_m, dtype=float)
    edges = np.asarray(edges_m, dtype=float)
    grid, _, dx = _evenly_spaced(x, np.zeros(x.size), dx_m)
    k_base = max(1, int(round(BASE_LENGTH_M / dx)))
    position = grid[0] + dx * (np.arange(max(grid.size - k_base, 0)) + 0.5)
    k = edges.size - 1
    seg = np.searchsorted(edges, position, side='right') - 1
    seg[position == edges[-1]] = k - 1
    inside = (seg >= 0) & (seg < k)
    return np.bincount(seg[inside], minlength=k)


def iri_table(distance_m: np.ndarray, elevation_m: np.ndarray, *,
              segment_length_m: float = 100.0,
              dx_m: float | None = None) -> dict[str, np.ndarray]:
    """Per-segment IRI table: ``start_m, end_m, iri_left_m_per_km, iri_right_m_per_km``.

    One track (n,) is used for both wheel paths. Segments as in
    :func:`road_force_estimator.core.segments.segment_bounds` (a remainder shorter than half a
    segment joins the one before).
    """
    x = np.asarray(distance_m, dtype=float)
    z = np.asarray(elevation_m, dtype=float)
    if z.ndim == 1:
        z = np.column_stack([z, z])
    if x.size == 0:
        raise ValueError('profile has no sample')
    edges = segment_bounds(float(x[0]), float(x[-1]), segment_length_m)
    values = iri_segments(x, z, edges, dx_m=dx_m)
    return {
        'start_m': edges[:-1].copy(),
        'end_m': edges[1:].copy(),
        'iri_left_m_per_km': values[:, 0],
        'iri_right_m_per_km': values[:, 1],
    }
