"""report.fleet_map: segment polylines from the fixes inside each segment (made-up positions
along a meridian) and the GeoJSON of segments without coordinates."""
import json

import numpy as np
import pytest

from road_force_estimator.report import segment_lines, segments_geojson


def test_segment_lines_pick_the_fixes_inside_each_segment():
    # 10 m/s for 10 s, estimates at 100 Hz, fixes at 1 Hz along a meridian (made-up positions).
    stamps = np.arange(0, 1001) * 10_000_000
    x = 10.0 * stamps * 1e-9
    fix_ns = np.arange(0, 11) * 1_000_000_000
    lat = 50.0 + 0.001 * np.arange(11)
    lon = np.full(11, 8.0)
    edges = np.array([0.0, 25.0, 60.0, 100.0])
    start_lat = np.interp(edges[:-1], 10.0 * fix_ns * 1e-9, lat)
    end_lat = np.interp(edges[1:], 10.0 * fix_ns * 1e-9, lat)
    lines = segment_lines(edges[:-1], edges[1:], start_lat, np.full(3, 8.0), end_lat,
                          np.full(3, 8.0), stamps_ns=stamps, distance_m=x,
                          fix_stamps_ns=fix_ns, fix_latitude_deg=lat, fix_longitude_deg=lon)
    # Segment 0 (0-25 m = 0-2.5 s): start, fixes at 1 s and 2 s, end.
    assert [p[1] for p in lines[0]] == pytest.approx([50.0, 50.001, 50.002, 50.0025])
    assert [p[1] for p in lines[1]] == pytest.approx([50.0025, 50.003, 50.004, 50.005, 50.006])
    assert [p[1] for p in lines[2]] == pytest.approx([50.006, 50.007, 50.008, 50.009, 50.010])
    assert all(p[0] == 8.0 for line in lines for p in line)
    nan = np.full(3, np.nan)
    none = segment_lines(edges[:-1], edges[1:], nan, nan, nan, nan, stamps_ns=None,
                         distance_m=None, fix_stamps_ns=None, fix_latitude_deg=None,
                         fix_longitude_deg=None)
    assert none == [None, None, None]


def test_geojson_without_coordinates_has_null_geometry_and_null_nan():
    table = {'drive': ['a', 'a'], 'start_m': [0.0, 100.0], 'iri_left_m_per_km': [1.5, np.nan],
             'lift_offs': [np.int64(2), np.int64(0)]}
    doc = segments_geojson(table, [[[8.0, 50.0], [8.0, 50.001]], None])
    text = json.dumps(doc, allow_nan=False)
    back = json.loads(text)
    assert back['features'][0]['geometry'] == {'type': 'LineString',
                                               'coordinates': [[8.0, 50.0], [8.0, 50.001]]}
    assert back['features'][1]['geometry'] is None
    assert back['features'][1]['properties'] == {'drive': 'a', 'start_m': 100.0,
                                                 'iri_left_m_per_km': None, 'lift_offs': 0}


def test_the_map_labels_each_drive(tmp_path, monkeypatch):
    """plot_segments_map names each drive at its first segment (one label per drive)."""
    from road_force_estimator.report import fleet_map
    seen = []
    real = fleet_map._label_drives
    monkeypatch.setattr(fleet_map, '_label_drives',
                        lambda ax, drawn: seen.append([d[2] for d in drawn]) or real(ax, drawn))
    lines = [[[17.0, 48.0], [17.0, 48.001]], [[17.0, 48.001], [17.0, 48.002]],
             [[17.1, 48.0], [17.1, 48.001]]]
    assert fleet_map.plot_segments_map(tmp_path / 'm.png', lines, [1.0, 2.0, 3.0],
                                       labels=['a', 'a', 'b'], units='us')
    assert seen == [['a', 'a', 'b']]
    assert (tmp_path / 'm.png').read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


def test_drive_numbers_never_overlap_and_the_key_is_below_the_map(tmp_path, monkeypatch):
    """Issue 29: three drives from one start (the README's fleet example: two routes from
    the same place) were labelled with their names on top of each other and of the lines.
    Now a number per drive, moved apart where starts coincide, and the names in a key under
    the axes."""
    from matplotlib.text import Annotation, Text

    from road_force_estimator.report import fleet_map
    figures = []
    real = fleet_map._label_drives

    def spy(ax, drawn):
        real(ax, drawn)
        figures.append(ax)
    monkeypatch.setattr(fleet_map, '_label_drives', spy)
    start = [17.1077, 48.1486]
    lines = [[start, [17.1087, 48.1496]], [start, [17.1067, 48.1496]],
             [start, [17.1077, 48.1476]], [[17.1100, 48.1500], [17.1110, 48.1510]]]
    assert fleet_map.plot_segments_map(tmp_path / 'm.png', lines, [1.0, 2.0, 3.0, 4.0],
                                       labels=['truck1/monday', 'truck1/tuesday',
                                               'truck2/monday', 'truck3/monday'])
    ax, = figures
    fig = ax.figure
    renderer = fig.canvas.get_renderer()
    numbers = [t for t in ax.texts if isinstance(t, Annotation)]
    assert [t.get_text() for t in numbers] == ['1', '2', '3', '4']
    boxes = [Text.get_window_extent(t, renderer) for t in numbers]   # the digits, no leader
    for i in range(len(boxes)):
        for j in range(i + 1, len(boxes)):
            assert not boxes[i].overlaps(boxes[j]), (i, j)
    key, = [t for t in ax.texts if t.get_text().startswith('drives')]
    assert all(f'{n}: {name}' in key.get_text() for n, name in (
        (1, 'truck1/monday'), (2, 'truck1/tuesday'), (3, 'truck2/monday')))
    assert key.get_window_extent(renderer).y1 < ax.get_window_extent(renderer).y0
    assert key.get_window_extent(renderer).y0 >= 0.0             # inside the figure
