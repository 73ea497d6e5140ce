"""Road profiles: elevation of the left and right wheel paths against distance.

Sources: ISO 8608 synthetic roads (classes A-H, seeded, with a left/right coherence model) and
discrete events (bump, pothole, step); measured profiles from files are read by
:mod:`.road_files` (CSV, UMTRI ERD, text columns), LPA bags by :mod:`road_force_estimator.bagio`.
A :class:`RoadProfile` is linearly interpolated in distance and never extrapolated;
:meth:`RoadProfile.enveloped` gives the road a tire of finite contact length follows.

Conventions (``../shared/design/MODEL.md``): SI units, elevation in metres (z up), distance
along the road in metres (x forward), column 0 = left wheel path, column 1 = right.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import Callable

import numpy as np

__all__ = [
    'RoadProfile', 'ISO8608_GD0_M3', 'ISO8608_N0_CPM', 'iso8608_psd', 'coherence_model',
    'iso8608_profile', 'flat_profile', 'add_event', 'DEFAULT_SYNTHETIC_LENGTH_M',
    'synthetic_profile',
]

#: Reference spatial frequency n0 of ISO 8608 (cycles/m).
ISO8608_N0_CPM = 0.1

#: Gd(n0) of each ISO 8608 class (m^3): the GEOMETRIC MEAN of the class's band, as MODEL.md
#: prescribes. Public generators disagree here: some take the class's upper limit (twice these
#: values) or the arithmetic midpoint of the band (1.25 times these values); the geometric mean
#: is what ISO 8608 tabulates as the class's typical value.
ISO8608_GD0_M3 = {
    c: 16e-6 * 4.0 ** i for i, c in enumerate('ABCDEFGH')
}

#: Default band of synthesized profiles (cycles/m): 100 m to 0.1 m wavelength (and never above
#: the Nyquist frequency of the grid, nor below the profile's own fundamental).
DEFAULT_BAND_CPM = (0.01, 10.0)

#: Default left/right coherence model: gamma^2(n) = 1 / (1 + n / n_c), n_c in cycles/m.
#: n_c = 0.0372 cycles/m gives gamma^2 = 0.65 at 50 m wavelength, 0.27 at 10 m and 0.07 at 2 m
#: (measured roads: 0.6-0.7 at 50 m, below 0.2 under 2 m).
DEFAULT_COHERENCE_CORNER_CPM = 0.0372

#: Points of an enveloped profile closer than this are merged (m).
_MERGE_M = 1e-9


@dataclass(frozen=True, eq=False)
class RoadProfile:
    """Elevation of the two wheel paths against distance, linearly interpolated.

    Parameters
    ----------
    distance_m : ndarray, shape (n,)
        Distance along the road (m), strictly increasing, n >= 2.
    elevation_m : ndarray, shape (n, 2) or (n,)
        Elevation (m, z up) of the [left, right] wheel paths; a 1-D array is used for both.
    name : str
        Where the profile came from (for reports).
    notes : tuple of str
        What was found and dropped on reading (non-finite or out-of-order rows...).

    Notes
    -----
    The arrays are copied, made read-only and validated once; a bad array raises
    :class:`ValueError` naming the problem.
    """

    distance_m: np.ndarray
    elevation_m: np.ndarray
    name: str = ''
    notes: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        x = np.array(self.distance_m, dtype=np.float64)
        z = np.array(self.elevation_m, dtype=np.float64)
        if x.ndim != 1 or x.size < 2:
            raise ValueError(f'distance_m must be 1-D with at least 2 points, got shape '
                             f'{x.shape}')
        if z.ndim == 1:
            z = np.column_stack((z, z))
        if z.shape != (x.size, 2):
            raise ValueError(f'elevation_m must have shape ({x.size}, 2) or ({x.size},), got '
                             f'{z.shape}')
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(z))):
            raise ValueError('distance_m and elevation_m must be finite')
        steps = np.diff(x)
        if np.any(steps <= 0.0):
            i = int(np.argmax(steps <= 0.0))
            raise ValueError(f'distance_m must be strictly increasing: {x[i + 1]!r} m at index '
                             f'{i + 1} follows {x[i]!r} m')
        x.setflags(write=False)
        z.setflags(write=False)
        object.__setattr__(self, 'distance_m', x)
        object.__setattr__(self, 'elevation_m', z)
        object.__setattr__(self, 'notes', tuple(self.notes))

    def __len__(self) -> int:
        return int(self.distance_m.size)

    @property
    def start_m(self) -> float:
        """First distance (m)."""
        return float(self.distance_m[0])

    @property
    def end_m(self) -> float:
        """Last distance (m)."""
        return float(self.distance_m[-1])

    @property
    def length_m(self) -> float:
        """end_m - start_m (m)."""
        return self.end_m - self.start_m

    @property
    def left_m(self) -> np.ndarray:
        """Elevation of the left wheel path (m), shape (n,)."""
        return self.elevation_m[:, 0]

    @property
    def right_m(self) -> np.ndarray:
        """Elevation of the right wheel path (m), shape (n,)."""
        return self.elevation_m[:, 1]

    def elevation_at(self, x_m) -> np.ndarray:
        """Elevation of both wheel paths at distance(s) ``x_m``, linearly interpolated.

        Parameters
        ----------
        x_m : float or array_like
            Distance(s) along the road (m), inside [start_m, end_m].

        Returns
        -------
        ndarray, shape (..., 2)
            [left, right] elevation (m).

        Raises
        ------
        ValueError
            A distance outside the profile (the road is never extrapolated) or not finite.
        """
        x = np.asarray(x_m, dtype=np.float64)
        self._check_inside(x)
        left = np.interp(x, self.distance_m, self.elevation_m[:, 0])
        right = np.interp(x, self.distance_m, self.elevation_m[:, 1])
        return np.stack((left, right), axis=-1)

    def slope_at(self, x_m) -> np.ndarray:
        """Slope du/dx of both paths at ``x_m`` (dimensionless), shape (..., 2).

        The interpolated road is piecewise linear: the slope is that of the segment
        ``[x_j, x_j+1)`` holding ``x`` (right-continuous at the knots; the last segment at the
        end point).
        """
        x = np.asarray(x_m, dtype=np.float64)
        self._check_inside(x)
        slopes = self.segment_slopes()
        j = np.clip(np.searchsorted(self.distance_m, x, side='right') - 1, 0, len(self) - 2)
        return slopes[j]

    def segment_slopes(self) -> np.ndarray:
        """Slope of each segment between knots, shape (n - 1, 2)."""
        return np.diff(self.elevation_m, axis=0) / np.diff(self.distance_m)[:, None]

    def _check_inside(self, x: np.ndarray) -> None:
        if x.size == 0:
            return
        lo, hi = float(np.min(x)), float(np.max(x))
        if not (math.isfinite(lo) and math.isfinite(hi)):
            raise ValueError('x_m must be finite')
        if lo < self.start_m or hi > self.end_m:
            raise ValueError(f'x_m = [{lo:g}, {hi:g}] m is outside the profile '
                             f'[{self.start_m:g}, {self.end_m:g}] m (never extrapolated)')

    def enveloped(self, length_m: float) -> RoadProfile:
        """The road a tire of contact length ``length_m`` follows: a centred moving average.

        Parameters
        ----------
        length_m : float
            Averaging length (m), >= 0; 0 returns the profile itself (point contact).

        Returns
        -------
        RoadProfile
            ``(1/L) * integral of u over [x - L/2, x + L/2]`` of the linearly interpolated
            profile, computed exactly (the integral of a piecewise-linear function), at the
            original knots and at the knots shifted by +-L/2 (the breakpoints of the averaged,
            piecewise-quadratic profile) inside ``[start + L/2, end - L/2]``, and at those two
            ends. The profile loses ``L/2`` at each end: it is never extrapolated.

        Notes
        -----
        A tire does not follow wavelengths shorter than its contact patch (MODEL.md "Road
        profiles"); the moving average is the simplest enveloping model (as in the IRI's
        250 mm average).
        """
        length_m = float(length_m)
        if not math.isfinite(length_m) or length_m < 0.0:
            raise ValueError(f'envelope length_m = {length_m!r} must be >= 0 m')
        if length_m == 0.0:
            return self
        half = 0.5 * length_m
        if self.length_m <= length_m:
            raise ValueError(f'envelope length_m = {length_m:g} m must be shorter than the '
                             f'profile ({self.length_m:g} m)')
        x = self.distance_m
        lo, hi = self.start_m + half, self.end_m - half
        # The average of a piecewise-linear profile is piecewise quadratic with breakpoints at
        # the knots shifted by +-L/2: evaluate it there (and at the knots), merging points
        # closer than 1 nm.
        cand = np.concatenate((x, x - half, x + half))
        cand = np.unique(cand[(cand > lo) & (cand < hi)])
        if cand.size:
            keep = np.concatenate(([True], np.diff(cand) > _MERGE_M))
            cand = cand[keep]
            cand = cand[(cand - lo > _MERGE_M) & (hi - cand > _MERGE_M)]
        xe = np.concatenate(([lo], cand, [hi]))
        z = self.elevation_m
        # Cumulative integral of the piecewise-linear profile at the knots (exact trapezoids).
        cum = np.zeros_like(z)
        cum[1:] = np.cumsum(0.5 * (z[1:] + z[:-1]) * np.diff(x)[:, None], axis=0)
        slopes = self.segment_slopes()

        def integral(xq: np.ndarray) -> np.ndarray:
            j = np.clip(np.searchsorted(x, xq, side='right') - 1, 0, len(x) - 2)
            d = (xq - x[j])[:, None]
            return cum[j] + z[j] * d + 0.5 * slopes[j] * d * d

        ze = (integral(xe + half) - integral(xe - half)) / length_m
        return RoadProfile(xe, ze, name=_join_name(self.name, f'enveloped {length_m:g} m'),
                           notes=self.notes)

    def segment(self, start_m: float, end_m: float) -> RoadProfile:
        """The part of the profile in [start_m, end_m] (interpolated at the two ends)."""
        start_m, end_m = float(start_m), float(end_m)
        if not start_m < end_m:
            raise ValueError(f'segment start_m = {start_m:g} must be < end_m = {end_m:g}')
        self._check_inside(np.array([start_m, end_m]))
        x = self.distance_m
        inner = x[(x > start_m) & (x < end_m)]
        xs = np.concatenate(([start_m], inner, [end_m]))
        return RoadProfile(xs, self.elevation_at(xs), name=self.name, notes=self.notes)


def _join_name(name: str, what: str) -> str:
    return f'{name}, {what}' if name else what


# --------------------------------------------------------------------------------------------
# ISO 8608 synthesis
# --------------------------------------------------------------------------------------------

def iso8608_psd(road_class: str, n_cpm) -> np.ndarray:
    """ISO 8608 displacement PSD Gd(n) = Gd(n0) (n / n0)^-2 (m^3, one-sided).

    Parameters
    ----------
    road_class : str
        'A' .. 'H' (case-insensitive); Gd(n0) is the class's geometric mean
        (:data:`ISO8608_GD0_M3`).
    n_cpm : float or array_like
        Spatial frequency (cycles/m), > 0.
    """
    gd0 = _gd0(road_class)
    n = np.asarray(n_cpm, dtype=np.float64)
    return gd0 * (n / ISO8608_N0_CPM) ** -2.0


def _gd0(road_class: str) -> float:
    key = str(road_class).strip().upper()
    if key not in ISO8608_GD0_M3:
        raise ValueError(f'road_class = {road_class!r}: must be one of A, B, C, D, E, F, G, H')
    return ISO8608_GD0_M3[key]


def coherence_model(n_cpm, corner_cpm: float = DEFAULT_COHERENCE_CORNER_CPM) -> np.ndarray:
    """Default left/right magnitude-squared coherence gamma^2(n) = 1 / (1 + n / n_c).

    Parameters
    ----------
    n_cpm : float or array_like
        Spatial frequency (cycles/m), >= 0.
    corner_cpm : float
        n_c (cycles/m) where gamma^2 = 0.5; the default gives 0.65 at 50 m wavelength and
        0.07 at 2 m, as measured on real roads (MODEL.md "Road profiles").

    Returns
    -------
    ndarray
        gamma^2(n), what :func:`scipy.signal.coherence` estimates between the two tracks.
    """
    n = np.asarray(n_cpm, dtype=np.float64)
    return 1.0 / (1.0 + n / corner_cpm)


def iso8608_profile(road_class: str, length_m: float, *, seed: int = 1, dx_m: float = 0.05,
                    coherence: str | float | Callable | None = 'default',
                    band_cpm: tuple[float, float] = DEFAULT_BAND_CPM,
                    start_m: float = 0.0) -> RoadProfile:
    """Synthesize an ISO 8608 road: a sum of cosines with random phases, seeded.

    Parameters
    ----------
    road_class : str
        'A' .. 'H'; Gd(n0) = 16e-6 * 4^i m^3 (geometric means, MODEL.md).
    length_m : float
        Length of the profile (m), > 0.
    seed : int
        Seed of :func:`numpy.random.default_rng`; the left track depends only on the seed,
        the class, the grid and the band (not on ``coherence``).
    dx_m : float
        Grid spacing (m), > 0.
    coherence : 'default', 'identical', None, float or callable
        Left/right coherence gamma^2(n): 'default' = :func:`coherence_model`; None or
        'independent' = independent tracks; 'identical' = the same track on both sides; a float
        in [0, 1] = constant gamma^2; a callable ``n_cpm (ndarray) -> gamma^2 (ndarray)``.
    band_cpm : (float, float)
        Spatial-frequency band (cycles/m) that gets energy; clipped to the grid's resolvable
        range (above 1 / period and below the Nyquist frequency 1 / (2 dx)).
    start_m : float
        Distance of the first point (m).

    Returns
    -------
    RoadProfile
        ``ceil(length / dx) + 1`` points from ``start_m``.

    Notes
    -----
    Component k (n_k = k / P, P = N dx the period, dn = 1 / P) has amplitude
    ``A_k = sqrt(2 Gd(n_k) dn)`` (so each cosine carries the PSD's power in its bin) and a
    random phase; the sum over the grid is evaluated exactly by an inverse real FFT. The right
    track is ``gamma_k * (left component) + sqrt(1 - gamma_k^2) * (independent component of
    the same amplitude)``: its expected PSD is Gd(n) and its expected magnitude-squared
    coherence with the left track is gamma_k^2.
    """
    gd0 = _gd0(road_class)
    length_m, dx_m, start_m = float(length_m), float(dx_m), float(start_m)
    if not (math.isfinite(length_m) and length_m > 0.0):
        raise ValueError(f'length_m = {length_m!r} must be > 0 m')
    if not (math.isfinite(dx_m) and 0.0 < dx_m <= length_m):
        raise ValueError(f'dx_m = {dx_m!r} must be in (0, length_m] m')
    n_lo, n_hi = (float(b) for b in band_cpm)
    if not 0.0 < n_lo < n_hi:
        raise ValueError(f'band_cpm = {band_cpm!r}: must be 0 < low < high (cycles/m)')
    if not math.isfinite(start_m):
        raise ValueError(f'start_m = {start_m!r} must be finite')
    npts = int(math.ceil(length_m / dx_m - 1e-9)) + 1
    period = npts * dx_m
    dn = 1.0 / period
    k = np.arange(npts // 2 + 1)
    n = k * dn
    use = (k >= 1) & (k < npts / 2.0) & (n >= n_lo) & (n <= n_hi)
    if not np.any(use):
        raise ValueError(f'band_cpm = {band_cpm!r} holds no frequency of a {length_m:g} m '
                         f'profile on a {dx_m:g} m grid')
    amp = np.zeros(n.size)
    amp[use] = np.sqrt(2.0 * gd0 * (n[use] / ISO8608_N0_CPM) ** -2.0 * dn)
    rng = np.random.default_rng(seed)
    phase_left = rng.uniform(0.0, 2.0 * np.pi, n.size)
    phase_free = rng.uniform(0.0, 2.0 * np.pi, n.size)
    gamma2 = _coherence_values(coherence, n)
    gamma = np.sqrt(gamma2)
    left_c = amp * np.exp(1j * phase_left)
    right_c = gamma * left_c + np.sqrt(1.0 - gamma2) * amp * np.exp(1j * phase_free)
    # irfft(X)[j] = (1/N) (X_0 + 2 Re sum_k X_k e^{2 pi i k j / N}) for k < N/2:
    # X_k = N/2 A_k e^{i theta_k} gives sum_k A_k cos(2 pi n_k x_j + theta_k).
    scale = 0.5 * npts
    left = np.fft.irfft(scale * left_c, npts)
    right = np.fft.irfft(scale * right_c, npts)
    x = start_m + dx_m * np.arange(npts)
    label = coherence if isinstance(coherence, str) or coherence is None else 'custom'
    return RoadProfile(x, np.column_stack((left, right)),
                       name=f'iso8608:{road_class.upper()}:seed={seed} (coherence {label})')


def _coherence_values(coherence, n: np.ndarray) -> np.ndarray:
    if coherence is None or coherence in ('independent', 'none'):
        return np.zeros_like(n)
    if coherence == 'default':
        return coherence_model(n)
    if coherence == 'identical':
        return np.ones_like(n)
    if isinstance(coherence, str):
        raise ValueError(f'coherence = {coherence!r}: must be "default", "identical", '
                         f'"independent"/None, a number in [0, 1] or a callable')
    if callable(coherence):
        values = np.broadcast_to(np.asarray(coherence(n), dtype=np.float64), n.shape)
    else:
        values = np.full_like(n, float(coherence))
    if not np.all((values >= 0.0) & (values <= 1.0)):
        raise ValueError(f'coherence = {coherence!r}: gamma^2 must lie in [0, 1]')
    return np.array(values)


def flat_profile(length_m: float, *, dx_m: float = 0.05, start_m: float = 0.0) -> RoadProfile:
    """A flat road (zero elevation) of ``length_m`` metres, e.g. to place events on."""
    length_m, dx_m = float(length_m), float(dx_m)
    if not (math.isfinite(length_m) and length_m > 0.0):
        raise ValueError(f'length_m = {length_m!r} must be > 0 m')
    if not (math.isfinite(dx_m) and 0.0 < dx_m <= length_m):
        raise ValueError(f'dx_m = {dx_m!r} must be in (0, length_m] m')
    npts = int(math.ceil(length_m / dx_m - 1e-9)) + 1
    x = float(start_m) + dx_m * np.arange(npts)
    return RoadProfile(x, np.zeros((npts, 2)), name='flat')


# --------------------------------------------------------------------------------------------
# Discrete events
# --------------------------------------------------------------------------------------------

_EVENT_KINDS = ('bump', 'pothole', 'step')
_SIDES = {'left': (True, False), 'right': (False, True), 'both': (True, True)}


def add_event(profile: RoadProfile, kind: str, side: str, start_m: float, length_m: float,
              height_m: float) -> RoadProfile:
    """Add a discrete event to one or both wheel paths.

    Parameters
    ----------
    profile : RoadProfile
        The road; the event must lie inside it.
    kind : {'bump', 'pothole', 'step'}
        'bump': raised cosine ``h (1 - cos(2 pi (x - x0) / L)) / 2`` over [x0, x0 + L];
        'pothole': a flat-bottomed hole of depth ``h`` (a positive ``height_m`` digs DOWN) with
        near-vertical walls (each min(1 cm, L/10) long) over [x0, x0 + L];
        'step': a half-cosine ramp from 0 to ``h`` over [x0, x0 + L], then ``h`` to the end.
    side : {'left', 'right', 'both'}
    start_m : float
        x0 (m).
    length_m : float
        L (m), > 0.
    height_m : float
        h (m); a bump or step with a negative height goes down.

    Returns
    -------
    RoadProfile
        A new profile on the union of the old grid and a fine grid over the event (spacing
        <= min(L / 50, 5 mm)), so the event is resolved whatever the road's own spacing.
    """
    if kind not in _EVENT_KINDS:
        raise ValueError(f'kind = {kind!r}: must be one of {", ".join(_EVENT_KINDS)}')
    if side not in _SIDES:
        raise ValueError(f'side = {side!r}: must be one of left, right, both')
    x0, length, h = float(start_m), float(length_m), float(height_m)
    if not (math.isfinite(length) and length > 0.0):
        raise ValueError(f'length_m = {length_m!r} must be > 0 m')
    if not math.isfinite(h):
        raise ValueError(f'height_m = {height_m!r} must be finite')
    x1 = x0 + length
    if not (math.isfinite(x0) and profile.start_m <= x0 and x1 <= profile.end_m):
        raise ValueError(f'event [{x0:g}, {x1:g}] m lies outside the profile '
                         f'[{profile.start_m:g}, {profile.end_m:g}] m')
    step = min(length / 50.0, 0.005)
    fine = np.linspace(x0, x1, int(math.ceil(length / step)) + 1)
    if kind == 'pothole':
        wall = min(0.01, 0.1 * length)
        fine = np.union1d(fine, [x0 + wall, x1 - wall])
    x = np.union1d(profile.distance_m, fine)
    z = profile.elevation_at(x)
    shape = np.zeros_like(x)
    inside = (x >= x0) & (x <= x1)
    xi = x[inside] - x0
    if kind == 'bump':
        shape[inside] = 0.5 * (1.0 - np.cos(2.0 * np.pi * xi / length))
    elif kind == 'step':
        shape[inside] = 0.5 * (1.0 - np.cos(np.pi * xi / length))
        shape[x > x1] = 1.0
    else:
        shape[inside] = -np.interp(xi, [0.0, wall, length - wall, length], [0.0, 1.0, 1.0, 0.0])
    on_left, on_right = _SIDES[side]
    z = z.copy()
    if on_left:
        z[:, 0] += h * shape
    if on_right:
        z[:, 1] += h * shape
    what = f'{kind} {h:g} m on {side} at {x0:g} m'
    return RoadProfile(x, z, name=_join_name(profile.name, what), notes=profile.notes)



# --------------------------------------------------------------------------------------------
# Synthetic sources
# --------------------------------------------------------------------------------------------

DEFAULT_SYNTHETIC_LENGTH_M = 1000.0


def synthetic_profile(text: str, length_m: float | None = None) -> RoadProfile:
    """A synthetic road from its source string: ``iso8608:<A-H>[:option=value...]`` (options
    ``seed``, ``length`` (m), ``dx`` (m), ``coherence``, ``start`` (m)) or
    ``flat[:length=..][:dx=..][:start=..]``; ``length_m`` when the string gives no length
    (default :data:`DEFAULT_SYNTHETIC_LENGTH_M`). Raises ValueError on a bad string."""
    parts = text.split(':')
    kind = parts[0].lower()
    road_class = None
    rest = parts[1:]
    if kind == 'iso8608':
        if not rest or '=' in rest[0]:
            raise ValueError(f'road source {text!r}: expected "iso8608:<A-H>[:seed=N]"')
        road_class = rest[0].strip().upper()
        _gd0(road_class)
        rest = rest[1:]
    options: dict[str, str] = {}
    for part in rest:
        if '=' not in part:
            raise ValueError(f'road source {text!r}: option {part!r} is not name=value')
        name, value = (s.strip() for s in part.split('=', 1))
        options[name.lower()] = value
    allowed = {'seed', 'length', 'dx', 'coherence', 'start'} if kind == 'iso8608' else {
        'length', 'dx', 'start'}
    unknown = set(options) - allowed
    if unknown:
        raise ValueError(f'road source {text!r}: unknown option(s) {", ".join(sorted(unknown))}'
                         f' (allowed: {", ".join(sorted(allowed))})')

    def number(name: str, default: float) -> float:
        if name not in options:
            return default
        try:
            return float(options[name])
        except ValueError:
            raise ValueError(f'road source {text!r}: {name} = {options[name]!r} is not a '
                             f'number') from None

    length = number('length', DEFAULT_SYNTHETIC_LENGTH_M if length_m is None else length_m)
    dx = number('dx', 0.05)
    start = number('start', 0.0)
    if kind == 'flat':
        return flat_profile(length, dx_m=dx, start_m=start)
    seed_text = options.get('seed', '1')
    try:
        seed = int(seed_text)
    except ValueError:
        raise ValueError(f'road source {text!r}: seed = {seed_text!r} is not an integer') \
            from None
    if seed < 0:
        raise ValueError(f'road source {text!r}: seed = {seed} must be >= 0')
    coherence: str | float | None = options.get('coherence', 'default')
    if coherence not in ('default', 'identical', 'independent', 'none'):
        coherence = number('coherence', 0.0)
    return iso8608_profile(road_class, length, seed=seed, dx_m=dx, coherence=coherence,
                           start_m=start)
