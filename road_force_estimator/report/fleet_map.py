"""Segments on a map: their polylines from GNSS fixes, a GeoJSON file and a PNG picture.

A drive's segment ``[start_m, end_m)`` runs between two stamps (the stamps at which the
estimate's travelled distance reaches the segment's ends, interpolated linearly); its polyline
is the segment's start position, every fix stamped strictly between those stamps, and its end
position, as ``[longitude, latitude]`` pairs (GeoJSON order, RFC 7946 section 3.1.1). A
segment with fewer than two known positions has no polyline (``None``).

The GeoJSON is one FeatureCollection of every segment of every drive: a LineString per segment
with the row's columns as properties (NaN written as ``null``); a segment without a polyline
(no ``/fix`` in its drive, or outside the span of the fixes) keeps its feature with a ``null``
geometry, which RFC 7946 (section 3.2) allows, so that the file has the same rows as the
tables. The PNG draws the polylines on plain longitude / latitude axes (aspect corrected by
the cosine of the mean latitude, no map tiles), coloured by the mean of the left and right IRI.

This module imports numpy, json and matplotlib (without pyplot: no global state) only.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from road_force_estimator.core.units import IN_PER_MI_PER_M_PER_KM

# IN_PER_MI_PER_M_PER_KM (1 m/km = 63.36 in/mi) is core.units', offered here as before.
__all__ = ['IN_PER_MI_PER_M_PER_KM', 'COORDINATE_DECIMALS', 'segment_lines',
           'segments_geojson', 'write_geojson', 'plot_segments_map']

#: Decimals kept in GeoJSON coordinates: 1e-8 deg is about 1 mm.
COORDINATE_DECIMALS = 8


def segment_lines(start_m: np.ndarray, end_m: np.ndarray, start_lat: np.ndarray,
                  start_lon: np.ndarray, end_lat: np.ndarray, end_lon: np.ndarray, *,
                  stamps_ns: np.ndarray | None, distance_m: np.ndarray | None,
                  fix_stamps_ns: np.ndarray | None, fix_latitude_deg: np.ndarray | None,
                  fix_longitude_deg: np.ndarray | None) -> list[list[list[float]] | None]:
    """Polyline of each segment of one drive, ``[[lon, lat], ...]`` (deg) or ``None``.

    Parameters
    ----------
    start_m, end_m : array (k,)
        Segment ends (m of travelled distance).
    start_lat, start_lon, end_lat, end_lon : array (k,)
        Positions of the segment ends (deg, NaN when unknown).
    stamps_ns, distance_m : array (n,), optional
        Stamps (ns) and travelled distance (m, non-decreasing) of the estimates: they map a
        distance to a stamp.
    fix_stamps_ns, fix_latitude_deg, fix_longitude_deg : array (f,), optional
        The drive's GNSS fixes (increasing stamps).

    Returns
    -------
    list
        One entry per segment: the start position (when known), the fixes strictly inside the
        segment's stamp span, the end position (when known); ``None`` with fewer than two.
    """
    start_m = np.asarray(start_m, dtype=float)
    k = start_m.size
    ends = [np.asarray(a, dtype=float) for a in (start_lat, start_lon, end_lat, end_lon)]
    inner: list[np.ndarray] = [np.zeros((0, 2))] * k
    have_fixes = (stamps_ns is not None and distance_m is not None and fix_stamps_ns is not None
                  and len(fix_stamps_ns) > 0 and len(stamps_ns) > 1)
    if have_fixes:
        stamps = np.asarray(stamps_ns, dtype=np.int64)
        x = np.asarray(distance_m, dtype=float)
        rel = (stamps - stamps[0]).astype(float)
        edges = np.concatenate([start_m, np.asarray(end_m, dtype=float)[-1:]])
        edge_ns = stamps[0] + np.round(np.interp(edges, x, rel)).astype(np.int64)
        fs = np.asarray(fix_stamps_ns, dtype=np.int64)
        pos = np.column_stack([np.asarray(fix_longitude_deg, dtype=float),
                               np.asarray(fix_latitude_deg, dtype=float)])
        lo = np.searchsorted(fs, edge_ns[:-1], side='right')
        hi = np.searchsorted(fs, edge_ns[1:], side='left')
        inner = [pos[a:b] for a, b in zip(lo.tolist(), hi.tolist())]
    lines: list[list[list[float]] | None] = []
    for j in range(k):
        points = []
        if math.isfinite(ends[0][j]) and math.isfinite(ends[1][j]):
            points.append([float(ends[1][j]), float(ends[0][j])])
        points.extend([float(lon), float(lat)] for lon, lat in inner[j].tolist()
                      if math.isfinite(lon) and math.isfinite(lat))
        if math.isfinite(ends[2][j]) and math.isfinite(ends[3][j]):
            points.append([float(ends[3][j]), float(ends[2][j])])
        lines.append(points if len(points) >= 2 else None)
    return lines


def _json_value(value):
    if isinstance(value, (np.integer, int)) and not isinstance(value, bool):
        return int(value)
    if isinstance(value, (np.floating, float)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.bool_):
        return bool(value)
    return value


def segments_geojson(table: Mapping[str, Sequence], lines: Sequence[list | None],
                     columns: Sequence[str] | None = None) -> dict:
    """A GeoJSON FeatureCollection (dict): one LineString Feature per row of ``table``.

    Parameters
    ----------
    table : mapping
        ``column -> sequence`` (all of the same length k); the properties of each feature.
    lines : sequence of k polylines
        ``[[lon, lat], ...]`` or ``None`` (the feature's geometry is then ``null``).
    columns : sequence of str, optional
        Property order (default: the table's).
    """
    columns = list(table) if columns is None else list(columns)
    k = len(lines)
    features = []
    for j in range(k):
        line = lines[j]
        geometry = None if line is None else {
            'type': 'LineString',
            'coordinates': [[round(lon, COORDINATE_DECIMALS), round(lat, COORDINATE_DECIMALS)]
                            for lon, lat in line]}
        features.append({'type': 'Feature', 'geometry': geometry,
                         'properties': {c: _json_value(table[c][j]) for c in columns}})
    return {'type': 'FeatureCollection', 'features': features}


def write_geojson(path: str | Path, table: Mapping[str, Sequence],
                  lines: Sequence[list | None], columns: Sequence[str] | None = None) -> None:
    """Write :func:`segments_geojson` to ``path`` (UTF-8, strict JSON: no NaN)."""
    doc = segments_geojson(table, lines, columns)
    Path(path).write_text(json.dumps(doc, allow_nan=False, separators=(',', ':')) + '\n',
                          encoding='utf-8')


def plot_segments_map(path: str | Path, lines: Sequence[list | None],
                      iri_m_per_km: Sequence[float], *, title: str = '',
                      labels: Sequence[str] | None = None, units: str = 'si') -> bool:
    """Draw the segments' polylines coloured by IRI into a PNG.

    Parameters
    ----------
    path : str or Path
        PNG file to write.
    lines : sequence of polylines (``[[lon, lat], ...]``) or ``None``
    iri_m_per_km : sequence of float
        Colour value of each segment (m/km); NaN is drawn grey.
    title : str
        Figure title.
    labels : sequence of str, optional
        The drive of each segment: each drive is labelled at its first segment drawn.
    units : 'si' or 'us'
        Colour scale in m/km or in/mi.

    Returns
    -------
    bool
        False (and nothing written) when no segment has a polyline.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.collections import LineCollection
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure

    from road_force_estimator.core.units import units as unit_system

    u = unit_system(units)
    names = list(labels) if labels is not None else [''] * len(lines)
    drawn = [(np.asarray(line, dtype=float), u.iri(v), name)
             for line, v, name in zip(lines, iri_m_per_km, names) if line is not None]
    if not drawn:
        return False
    segs = [line for line, _, _ in drawn]
    values = np.array([v for _, v, _ in drawn])
    finite = np.isfinite(values)
    fig = Figure(figsize=(8.0, 7.0), dpi=110)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    if finite.any():
        hi = float(np.nanmax(values))
        norm = Normalize(vmin=0.0, vmax=hi if hi > 0.0 else 1.0)
        coll = LineCollection([s for s, f in zip(segs, finite) if f], cmap='turbo', norm=norm,
                              linewidths=3.0)
        coll.set_array(values[finite])
        ax.add_collection(coll)
        bar = fig.colorbar(coll, ax=ax, shrink=0.8)
        bar.set_label(f'IRI, mean of left and right ({u.iri_unit})')
    if (~finite).any():
        ax.add_collection(LineCollection([s for s, f in zip(segs, finite) if not f],
                                         colors='0.6', linewidths=2.0))
    allpts = np.vstack(segs)
    lat_mid = float(np.mean(allpts[:, 1]))
    ax.set_aspect(1.0 / max(math.cos(math.radians(lat_mid)), 1e-6))
    ax.autoscale_view()
    ax.margins(0.05)
    _label_drives(ax, drawn)
    ax.set_xlabel('longitude (deg, WGS84)')
    ax.set_ylabel('latitude (deg, WGS84)')
    ax.ticklabel_format(useOffset=False, style='plain')
    ax.grid(True, linewidth=0.3)
    if title:
        ax.set_title(title)
    fig.tight_layout()
    fig.savefig(str(path))
    return True


#: A drive's number on the map keeps this far (points) from every other number.
LABEL_SPACING_PT = 12.0


def _label_drives(ax, drawn) -> None:
    """Each drive's number beside the start of its first segment (a hollow dot there), moved
    apart where starts coincide, and the key (number: drive) under the map: no name over
    the lines, none over another."""
    seen: dict[str, int] = {}
    placed: list[np.ndarray] = []            # the numbers' positions (points, display)
    fig = ax.figure
    to_pt = 72.0 / fig.dpi
    for line, _, name in drawn:
        if not name or name in seen or line.size == 0:
            continue
        seen[name] = len(seen) + 1
        ax.plot(line[0, 0], line[0, 1], 'o', mfc='none', mec='k', ms=5, zorder=4)
        at = ax.transData.transform((line[0, 0], line[0, 1])) * to_pt
        offset = np.array([6.0, 6.0])
        while any(np.hypot(*(at + offset - q)) < LABEL_SPACING_PT for q in placed):
            offset[1] += LABEL_SPACING_PT
        placed.append(at + offset)
        ax.annotate(str(seen[name]), (line[0, 0], line[0, 1]), xytext=tuple(offset),
                    textcoords='offset points', fontsize=8, fontweight='bold', zorder=5,
                    arrowprops={'arrowstyle': '-', 'lw': 0.5, 'color': '0.3'}
                    if offset[1] > 6.0 else None)
    if seen:
        key = '   '.join(f'{n}: {name}' for name, n in seen.items())
        ax.text(0.0, -0.1, f'drives (number at the start): {key}', transform=ax.transAxes,
                va='top', ha='left', fontsize=8, wrap=True)
