"""Per-segment figures of a drive, as road agencies use them (MODEL.md "Metrics").

A drive is cut by travelled distance into segments of ``segment_length_m`` (default 100 m,
the last one may be shorter; a remainder shorter than half a segment is merged into the one
before). Per segment and wheel: IRI (m/km) of the estimated profile and, when known, of the
true profile; the dynamic load coefficient DLC = std(F_n)/mean(F_n); the peak vertical load;
the largest |LTR|; the number of lift-off events (a wheel whose load reaches zero; one event
per contiguous run of lifted samples, counted in the segment where it starts); and, when the
drive has GNSS fixes, the coordinates of the segment's ends interpolated by stamp (an end up
to one fix period beyond the first or last fix is placed from that fix along the drive's
heading at the travelled distance).

A segment without data (no sample in it: a gap in the recording) has NaN in every column but
``lift_offs`` (0); a segment whose samples cover less than :data:`MIN_COVERAGE` of its length
(spacings above :func:`max_step` do not count) has NaN IRI: a gap is never measured as a
smooth road.

This module imports numpy only (core; :func:`coverage_pieces` and
:func:`coordinate_columns_pieces` :mod:`.pieces`).
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from road_force_estimator.core.gnss import positions_at

__all__ = ['SEGMENT_COLUMNS', 'MIN_COVERAGE', 'segment_bounds', 'segment_table',
           'segment_samples', 'max_step', 'blank_empty', 'coverage', 'coverage_pieces',
           'coordinate_columns', 'coordinate_columns_pieces',
           'sample_spacing', 'check_segment_length']

#: A segment's IRI needs samples over this fraction of its length.
MIN_COVERAGE = 0.9

#: Columns of the per-drive segment table, in order (INTERFACES.md, estimate_fleet; the
#: ``true_iri_*`` columns are extra and NaN when the drive has no ground truth).
SEGMENT_COLUMNS = (
    'start_m', 'end_m', 'iri_left_m_per_km', 'iri_right_m_per_km',
    'true_iri_left_m_per_km', 'true_iri_right_m_per_km',
    'dlc_left', 'dlc_right', 'peak_load_left_n', 'peak_load_right_n', 'max_abs_ltr',
    'lift_offs', 'start_lat', 'start_lon', 'end_lat', 'end_lon', 'static_load_left_n',
    'static_load_right_n', 'max_abs_ltr_quasi_static',
)


def sample_spacing(stamps_ns, speed_mps, max_speed_mps: float = np.inf) -> float:
    """The distance between two samples at the drive's top speed (m): the largest finite
    |speed| (m/s) up to ``max_speed_mps`` (faster ones are no speed a sample is estimated
    with) times the median step of the increasing stamps (ns); 0 when it cannot be told
    (fewer than two samples, no such speed)."""
    t = np.asarray(stamps_ns, dtype=np.int64)
    v = np.abs(np.asarray(speed_mps, dtype=float))
    steps = np.diff(t)
    steps = steps[steps > 0]
    v = v[np.isfinite(v) & (v <= max_speed_mps)]
    if steps.size == 0 or v.size == 0:
        return 0.0
    return float(v.max()) * float(np.median(steps)) * 1e-9


def check_segment_length(segment_length_m: float, spacing_m: float, what: str = 'drive'
                         ) -> None:
    """Raise ValueError when segments of ``segment_length_m`` (m) are shorter than the
    sample spacing ``spacing_m`` (m, :func:`sample_spacing`): such a segment holds at most one
    sample (no IRI, no load figures), and their number grows without bound as the length
    shrinks."""
    if not (segment_length_m > 0.0 and np.isfinite(segment_length_m)):
        raise ValueError(f'segment length {segment_length_m!r} m: must be finite and > 0')
    if segment_length_m < spacing_m:
        raise ValueError(f'segment length {segment_length_m:g} m is shorter than the '
                         f"{what}'s sample spacing ({spacing_m:.3g} m): a segment would hold "
                         f'at most one sample; give --segment-length >= {spacing_m:.3g} m')


def segment_bounds(start_m: float, end_m: float, segment_length_m: float) -> np.ndarray:
    """Segment edges (m) from ``start_m`` to ``end_m``: shape (k + 1,).

    Raises
    ------
    ValueError
        ``segment_length_m`` not positive, or an empty span.
    """
    if not segment_length_m > 0.0:
        raise ValueError(f'segment length = {segment_length_m!r} m: must be > 0')
    if not end_m > start_m:
        raise ValueError(f'no distance travelled ({start_m:g} m to {end_m:g} m)')
    edges = np.arange(start_m, end_m, segment_length_m, dtype=float)
    edges = np.append(edges, end_m)
    if edges.size > 2 and edges[-1] - edges[-2] < 0.5 * segment_length_m:
        edges = np.delete(edges, -2)
    return edges


def segment_table(distance_m: np.ndarray, wheel_load_n: np.ndarray, ltr: np.ndarray,
                  lift_off: np.ndarray, *, profile_m: np.ndarray | None = None,
                  true_profile_m: np.ndarray | None = None,
                  profile_distance_m: np.ndarray | None = None,
                  iri_segments: Callable[..., np.ndarray] | None = None,
                  stamps_ns: np.ndarray | None = None,
                  fix_stamps_ns: np.ndarray | None = None,
                  fix_latitude_deg: np.ndarray | None = None,
                  fix_longitude_deg: np.ndarray | None = None,
                  segment_length_m: float = 100.0,
                  ltr_quasi_static: np.ndarray | None = None,
                  static_load_n: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Per-segment table of one drive: ``{column: array (k,)}`` with :data:`SEGMENT_COLUMNS`.

    Parameters
    ----------
    distance_m : array (n,)
        Travelled distance of each estimate (m), non-decreasing.
    wheel_load_n : array (n, 2)
        Vertical loads [left, right] (N).
    ltr : array (n,)
        Load transfer ratio (F_n2 - F_n1) / (F_n1 + F_n2).
    lift_off : array (n, 2) of bool
        Wheel lifted off.
    profile_m, true_profile_m : array (n, 2), optional
        Estimated and true road profiles [left, right] (m) at ``profile_distance_m``
        (default ``distance_m``); IRI columns are NaN without them.
    iri_segments : callable, optional
        ``iri_segments(distance_m, elevation_m (n,), edges_m) -> (k,)`` IRI (m/km) per segment
        (``road_force_estimator.core.iri``); required with a profile.
    stamps_ns, fix_stamps_ns, fix_latitude_deg, fix_longitude_deg : arrays, optional
        Stamps of the estimates and the GNSS fixes; coordinates are NaN without fixes.
    segment_length_m : float
        Segment length (m), default 100.
    ltr_quasi_static : array (n,), optional
        The quasi-static LTR (MODEL.md step 8) for ``max_abs_ltr_quasi_static`` (NaN without).
    static_load_n : array (n, 2), optional
        The static wheel loads F_c,i [left, right] (N) for ``static_load_left_n`` /
        ``static_load_right_n``, their mean over each segment (NaN without).
    """
    x = np.asarray(distance_m, dtype=float)
    edges = segment_bounds(float(x[0]), float(x[-1]), segment_length_m)
    k = edges.size - 1
    # Sample i belongs to segment j when edges[j] <= x_i < edges[j+1] (last edge inclusive).
    seg = np.clip(np.searchsorted(edges, x, side='right') - 1, 0, k - 1)
    table: dict[str, np.ndarray] = {'start_m': edges[:-1].copy(), 'end_m': edges[1:].copy()}
    table.update(_load_columns(seg, k, wheel_load_n, ltr, lift_off))
    quasi = np.full(k, np.nan)
    if ltr_quasi_static is not None:
        np.fmax.at(quasi, seg, np.abs(np.asarray(ltr_quasi_static, dtype=float)))
    table['max_abs_ltr_quasi_static'] = quasi
    for side, name in enumerate(('static_load_left_n', 'static_load_right_n')):
        table[name] = np.full(k, np.nan)
        if static_load_n is not None:
            values = np.asarray(static_load_n, dtype=float)[:, side]
            sums = np.bincount(seg, weights=values, minlength=k)
            counts_s = np.bincount(seg, minlength=k)
            with np.errstate(invalid='ignore', divide='ignore'):
                table[name] = sums / counts_s
    px = x if profile_distance_m is None else np.asarray(profile_distance_m, dtype=float)
    table.update(_iri_columns(px, edges, profile_m, true_profile_m, iri_segments))
    counts = segment_samples(x, edges)
    blank_empty(table, coverage(px, edges) < MIN_COVERAGE, counts)
    table.update(coordinate_columns(x, edges, stamps_ns, fix_stamps_ns, fix_latitude_deg,
                                     fix_longitude_deg))
    return {name: table[name] for name in SEGMENT_COLUMNS}


def segment_samples(distance_m: np.ndarray, edges_m: np.ndarray) -> np.ndarray:
    """Samples in each segment (int, (k,)): ``edges[j] <= x < edges[j + 1]``, the last edge
    inclusive."""
    x = np.asarray(distance_m, dtype=float)
    k = len(edges_m) - 1
    inside = (x >= edges_m[0]) & (x <= edges_m[-1])
    seg = np.clip(np.searchsorted(edges_m, x[inside], side='right') - 1, 0, k - 1)
    return np.bincount(seg, minlength=k).astype(np.int64)


def max_step(distance_m: np.ndarray) -> float:
    """The largest spacing of samples (m) that still counts as continuous data: 10 x the median
    spacing, at least 0.5 m (a 5 s gap at 20 m/s, 100 m, is no data)."""
    dx = np.diff(np.asarray(distance_m, dtype=float))
    dx = dx[dx > 0]
    return max(0.5, 10.0 * float(np.median(dx))) if dx.size else 0.5


def blank_empty(table: dict, sparse: np.ndarray, counts: np.ndarray) -> None:
    """NaN, in place, where a segment cannot say: its IRI columns where the profile covers
    too little of it (``sparse``), its other figures where it has no sample (``counts``)."""
    for name in table:
        if name.endswith('_m_per_km'):
            table[name] = np.where(sparse, np.nan, table[name])
        elif name not in ('start_m', 'end_m', 'lift_offs'):
            table[name] = np.where(counts == 0, np.nan, table[name])


def coverage(x: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Fraction of each segment's length spanned by sample spacings up to :func:`max_step`."""
    dx = np.diff(x)
    good = (dx <= max_step(x)) & (dx > 0)
    cum = np.concatenate([[0.0], np.cumsum(np.where(good, dx, 0.0))])

    def covered_to(e: np.ndarray) -> np.ndarray:
        """Covered length from x[0] to each e (inside a gap it stays flat)."""
        i = np.clip(np.searchsorted(x, e, side='right') - 1, 0, max(x.size - 2, 0))
        part = np.where(good[i], np.clip(e - x[i], 0.0, dx[i]), 0.0) if dx.size else 0.0
        return cum[i] + part

    c = covered_to(np.asarray(edges, dtype=float))
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.diff(c) / np.diff(edges)


def coverage_pieces(n: int, read: Callable, edges: np.ndarray, rows: int | None = None
                    ) -> np.ndarray:
    """:func:`coverage` of distances ``x`` (n,) read ``read(lo, hi) -> x[lo:hi]`` ``rows`` at
    a time (default :data:`.pieces.PIECE_ROWS`), without ``x`` held whole (issue 32: the
    streamed report's spilled distances): its bits (:func:`max_step`'s median by counting,
    :func:`.pieces.median_positive_steps`; the covered length's running sum carried from
    piece to piece, as ``np.cumsum`` adds in order; each edge's bracketing step where it
    falls)."""
    from road_force_estimator.core import pieces

    rows = max(int(rows or pieces.PIECE_ROWS), 1)
    edges = np.asarray(edges, dtype=float)
    limit = max(0.5, 10.0 * pieces.median_positive_steps(n, read, rows))   # max_step
    at = np.zeros(edges.size, np.int64)                # samples at or before each edge
    for lo in range(0, n, rows):
        at += np.searchsorted(read(lo, min(lo + rows, n)), edges, side='right')
    i = np.clip(at - 1, 0, max(n - 2, 0))              # each edge's step
    c = np.zeros(edges.size)
    carry = 0.0
    for lo in range(0, n - 1, rows):                   # steps lo:hi
        hi = min(lo + rows, n - 1)
        x = np.asarray(read(lo, hi + 1), dtype=float)
        dx = np.diff(x)
        good = (dx <= limit) & (dx > 0)
        cum = np.cumsum(np.concatenate([[carry], np.where(good, dx, 0.0)]))
        carry = cum[-1]
        sel = (i >= lo) & (i < hi)
        j = i[sel] - lo
        c[sel] = cum[j] + np.where(good[j], np.clip(edges[sel] - x[j], 0.0, dx[j]), 0.0)
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.diff(c) / np.diff(edges)


def _load_columns(seg: np.ndarray, k: int, wheel_load_n, ltr, lift_off
                  ) -> dict[str, np.ndarray]:
    """DLC, peak load per wheel, max |LTR| and lift-off events of the ``k`` segments
    (``seg``: the segment of each sample)."""
    load = np.asarray(wheel_load_n, dtype=float)
    counts = np.bincount(seg, minlength=k)
    table: dict[str, np.ndarray] = {}
    for side, name in ((0, 'left'), (1, 'right')):
        f = load[:, side]
        total = np.bincount(seg, f, minlength=k)
        square = np.bincount(seg, f * f, minlength=k)
        with np.errstate(invalid='ignore', divide='ignore'):
            mean = total / counts
            std = np.sqrt(np.maximum(square / counts - mean * mean, 0.0))
            table[f'dlc_{name}'] = np.where(counts > 1, std / mean, np.nan)
        peak = np.full(k, np.nan)
        np.fmax.at(peak, seg, f)
        table[f'peak_load_{name}_n'] = peak
    max_ltr = np.full(k, np.nan)
    np.fmax.at(max_ltr, seg, np.abs(np.asarray(ltr, dtype=float)))
    table['max_abs_ltr'] = max_ltr

    lifted = np.asarray(lift_off, dtype=bool).reshape(len(seg), -1)
    starts = lifted & ~np.vstack([np.zeros((1, lifted.shape[1]), bool), lifted[:-1]])
    table['lift_offs'] = np.bincount(seg, starts.sum(axis=1), minlength=k).astype(np.int64)
    return table


def _iri_columns(px: np.ndarray, edges: np.ndarray, profile_m, true_profile_m,
                 iri_segments) -> dict[str, np.ndarray]:
    """IRI per segment and wheel of the estimated and the true profile (NaN without one)."""
    k = edges.size - 1
    table: dict[str, np.ndarray] = {}
    for prefix, prof in (('iri', profile_m), ('true_iri', true_profile_m)):
        for side, name in ((0, 'left'), (1, 'right')):
            column = f'{prefix}_{name}_m_per_km'
            if prof is None:
                table[column] = np.full(k, np.nan)
            else:
                if iri_segments is None:
                    raise ValueError('a profile needs iri_segments to compute IRI')
                table[column] = np.asarray(
                    iri_segments(px, np.asarray(prof, dtype=float)[:, side], edges), dtype=float)
    return table


def coordinate_columns(x: np.ndarray, edges: np.ndarray, stamps_ns, fix_stamps_ns,
                       fix_latitude_deg, fix_longitude_deg) -> dict[str, np.ndarray]:
    """Latitude and longitude (deg) of each segment's ends, NaN without fixes."""
    k = edges.size - 1
    have_fixes = (stamps_ns is not None and fix_stamps_ns is not None
                  and len(fix_stamps_ns) >= 2)
    if have_fixes:
        stamps = np.asarray(stamps_ns, dtype=np.int64)
        # Stamp at each edge: interpolate time over distance (distance is non-decreasing).
        rel = (stamps - stamps[0]).astype(float)
        edge_ns = stamps[0] + np.round(np.interp(edges, x, rel)).astype(np.int64)
        lat, lon = positions_at(fix_stamps_ns, fix_latitude_deg, fix_longitude_deg, edge_ns)

        def fix_x() -> dict[int, float]:
            f = np.asarray(fix_stamps_ns, dtype=np.int64)
            fx = np.interp((f - stamps[0]).astype(float), rel, x)     # distance at each fix
            return {i: fx[i] for i in _END_FIXES}

        _beyond_fixes(lat, lon, edges, edge_ns, fix_x, fix_stamps_ns, fix_latitude_deg,
                      fix_longitude_deg)
    else:
        lat = lon = np.full(k + 1, np.nan)
    return _coordinates(lat, lon)


def coordinate_columns_pieces(n: int, read: Callable, edges: np.ndarray, fix_stamps_ns,
                              fix_latitude_deg, fix_longitude_deg, rows: int | None = None
                              ) -> dict[str, np.ndarray]:
    """:func:`coordinate_columns` of distances ``x`` (n,) and stamps (n,) read ``read(lo,
    hi) -> (x[lo:hi] (m), stamps_ns[lo:hi])`` ``rows`` at a time (default
    :data:`.pieces.PIECE_ROWS`), without them held whole (issue 32: the streamed report's
    spilled columns): its bits (each edge's stamp and the end fixes' distances by
    :class:`.pieces.Interp`, one query at a time: ``np.interp``'s bracketing samples and
    formula; held: about two pieces)."""
    from road_force_estimator.core import pieces

    edges = np.asarray(edges, dtype=float)
    if fix_stamps_ns is None or len(fix_stamps_ns) < 2:
        return coordinate_columns(np.zeros(0), edges, None, None, None, None)
    rows = max(int(rows or pieces.PIECE_ROWS), 1)
    t0 = np.asarray(read(0, 1)[1], dtype=np.int64)[0]

    def rel(stamps) -> np.ndarray:
        return (np.asarray(stamps, dtype=np.int64) - t0).astype(float)

    def x_rel(lo: int, hi: int) -> tuple[np.ndarray, np.ndarray]:
        x, stamps = read(lo, hi)
        return np.asarray(x, dtype=float), rel(stamps)[None]

    at = pieces.Interp(n, x_rel, rows)
    edge_rel = np.array([at(edges[j:j + 1])[0, 0] for j in range(edges.size)])
    edge_ns = t0 + np.round(edge_rel).astype(np.int64)
    lat, lon = positions_at(fix_stamps_ns, fix_latitude_deg, fix_longitude_deg, edge_ns)

    def fix_x() -> dict[int, float]:
        def rel_x(lo: int, hi: int) -> tuple[np.ndarray, np.ndarray]:
            x, stamps = read(lo, hi)
            return rel(stamps), np.asarray(x, dtype=float)[None]

        f = np.asarray(fix_stamps_ns, dtype=np.int64)
        q = (f[list(_END_FIXES)] - t0).astype(float)
        by = pieces.Interp(n, rel_x, rows)
        order = np.argsort(q, kind='stable')                  # forward: one pass
        out = np.empty(q.size)
        for j in order:
            out[j] = by(q[j:j + 1])[0, 0]
        return dict(zip(_END_FIXES, out))

    _beyond_fixes(lat, lon, edges, edge_ns, fix_x, fix_stamps_ns, fix_latitude_deg,
                  fix_longitude_deg)
    return _coordinates(lat, lon)


def _coordinates(lat: np.ndarray, lon: np.ndarray) -> dict[str, np.ndarray]:
    """The coordinate columns of the ends' latitudes and longitudes (deg, (k + 1,))."""
    return {'start_lat': lat[:-1].copy(), 'start_lon': lon[:-1].copy(),
            'end_lat': lat[1:].copy(), 'end_lon': lon[1:].copy()}


#: The fixes an end beyond the fixes is placed from (:func:`_beyond_fixes`).
_END_FIXES = (0, 1, -2, -1)


def _beyond_fixes(lat: np.ndarray, lon: np.ndarray, edges: np.ndarray, edge_ns: np.ndarray,
                  fix_x: Callable[[], dict], fix_stamps_ns, fix_lat, fix_lon) -> None:
    """Place (in place) the ends up to one fix period before the first or after the last fix:
    from that fix, along the heading of the two nearest fixes, at the travelled distance
    (``fix_x()``: the distance (m) at the fixes :data:`_END_FIXES`, by index; called once,
    when an end is there)."""
    f = np.asarray(fix_stamps_ns, dtype=np.int64)
    flat, flon = np.asarray(fix_lat, dtype=float), np.asarray(fix_lon, dtype=float)
    period = float(np.median(np.diff(f)))
    fx = None
    for near, far, side in ((-1, -2, 1), (0, 1, -1)):
        gap = (edge_ns - f[near]) * side
        sel = ~np.isfinite(lat) & (gap > 0) & (gap <= period)
        if not sel.any():
            continue
        fx = fix_x() if fx is None else fx
        span = fx[near] - fx[far]
        if span == 0.0:
            continue
        along = (edges[sel] - fx[near]) / span
        lat[sel] = flat[near] + along * (flat[near] - flat[far])
        lon[sel] = flon[near] + along * (flon[near] - flon[far])
