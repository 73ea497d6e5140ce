"""Per-segment table: hand-computed figures on small drives."""
import numpy as np
import pytest

from road_force_estimator.core.segments import SEGMENT_COLUMNS, segment_bounds, segment_table


def test_bounds_merge_a_short_remainder():
    assert segment_bounds(0.0, 250.0, 100.0).tolist() == [0.0, 100.0, 200.0, 250.0]
    assert segment_bounds(0.0, 230.0, 100.0).tolist() == [0.0, 100.0, 230.0]
    assert segment_bounds(10.0, 60.0, 100.0).tolist() == [10.0, 60.0]
    with pytest.raises(ValueError, match='segment length = 0'):
        segment_bounds(0.0, 10.0, 0.0)
    with pytest.raises(ValueError, match='no distance travelled'):
        segment_bounds(5.0, 5.0, 100.0)


def test_dlc_peak_ltr_and_lift_offs_by_hand():
    x = np.arange(0.0, 200.0, 1.0)                   # 200 samples, 1 m apart: 2 segments
    load = np.empty((200, 2))
    load[:, 0] = np.where(np.arange(200) % 2 == 0, 9000.0, 11000.0)   # mean 1e4, std 1e3
    load[:, 1] = 20000.0
    load[150, 1] = 35000.0
    ltr = (load[:, 1] - load[:, 0]) / load.sum(axis=1)
    lifted = np.zeros((200, 2), bool)
    lifted[10:13, 0] = True                           # one event in segment 0
    lifted[120, 1] = lifted[140:142, 1] = True        # two events in segment 1
    table = segment_table(x, load, ltr, lifted, segment_length_m=100.0)
    assert list(table) == list(SEGMENT_COLUMNS)
    assert table['start_m'].tolist() == [0.0, 100.0]
    assert table['end_m'].tolist() == [100.0, 199.0]
    assert table['dlc_left'] == pytest.approx([0.1, 0.1])
    assert table['dlc_right'][0] == pytest.approx(0.0, abs=1e-12)
    assert table['peak_load_right_n'].tolist() == [20000.0, 35000.0]
    assert table['peak_load_left_n'].tolist() == [11000.0, 11000.0]
    assert table['max_abs_ltr'][1] == pytest.approx((35000 - 9000) / 44000)  # left: 9 kN
    assert table['lift_offs'].tolist() == [1, 2]
    assert np.isnan(table['iri_left_m_per_km']).all() and np.isnan(table['start_lat']).all()


def test_coordinates_interpolated_at_segment_edges_and_iri_hook_called_per_side():
    x = np.linspace(0.0, 300.0, 301)
    stamps = (x / 20.0 * 1e9).astype(np.int64)       # 20 m/s
    fix_ns = np.arange(0, 16_000_000_000, 100_000_000, dtype=np.int64)
    fix_lat = 48.0 + fix_ns * 1e-12                  # a made-up linear track
    fix_lon = 17.0 + fix_ns * 2e-12
    profile = np.column_stack([np.zeros(301), np.ones(301)])
    calls = []

    def fake_iri(d, z, edges):
        calls.append(float(z[0]))
        return np.full(len(edges) - 1, 1.0 + z[0])
    table = segment_table(x, np.full((301, 2), 1e4), np.zeros(301), np.zeros((301, 2), bool),
                          profile_m=profile, iri_segments=fake_iri, stamps_ns=stamps,
                          fix_stamps_ns=fix_ns, fix_latitude_deg=fix_lat,
                          fix_longitude_deg=fix_lon)
    assert calls == [0.0, 1.0]
    assert table['iri_left_m_per_km'].tolist() == [1.0, 1.0, 1.0]
    assert table['iri_right_m_per_km'].tolist() == [2.0, 2.0, 2.0]
    assert np.isnan(table['true_iri_left_m_per_km']).all()
    # Edge at 100 m is reached at 5 s: lat 48 + 5e9 * 1e-12.
    assert table['end_lat'][0] == pytest.approx(48.005)
    assert table['start_lon'][1] == pytest.approx(17.010)
    assert table['end_lat'][2] == pytest.approx(48.015)


def test_a_gap_leaves_segments_without_data_never_zero():
    """A 5 s gap at 20 m/s (100 m without a sample): those segments have no data (NaN), the
    segments the gap cuts into have no IRI, the others are as without the gap."""
    x = np.concatenate([np.arange(0.0, 100.0, 0.02), np.arange(200.0, 400.0, 0.02)])
    n = x.size
    load = np.full((n, 2), 1e4)
    calls = []

    def fake_iri(d, z, edges):
        calls.append(len(edges))
        return np.full(len(edges) - 1, 3.0)
    table = segment_table(x, load, np.zeros(n), np.zeros((n, 2), bool),
                          profile_m=np.zeros((n, 2)), true_profile_m=np.zeros((n, 2)),
                          iri_segments=fake_iri, segment_length_m=50.0)
    assert table['start_m'].tolist() == [0.0, 50.0, 100.0, 150.0, 200.0, 250.0, 300.0, 350.0]
    empty = [2, 3]                                   # 100-200 m: no sample
    for j in empty:
        for name in SEGMENT_COLUMNS:
            if name not in ('start_m', 'end_m', 'lift_offs'):
                assert np.isnan(table[name][j]), (name, j)
        assert table['lift_offs'][j] == 0
    full = [0, 4, 5, 6, 7]
    assert table['iri_left_m_per_km'][full].tolist() == [3.0] * 5
    assert table['true_iri_right_m_per_km'][full].tolist() == [3.0] * 5
    assert table['peak_load_left_n'][full].tolist() == [1e4] * 5
    # 50-100 m holds samples up to 99.98 m: covered, so its IRI stands.
    assert table['iri_left_m_per_km'][1] == 3.0


def test_a_segment_half_in_a_gap_has_no_iri():
    x = np.concatenate([np.arange(0.0, 120.0, 0.02), np.arange(180.0, 300.0, 0.02)])
    n = x.size
    table = segment_table(x, np.full((n, 2), 1e4), np.zeros(n), np.zeros((n, 2), bool),
                          profile_m=np.zeros((n, 2)),
                          iri_segments=lambda d, z, e: np.full(len(e) - 1, 2.0),
                          segment_length_m=100.0)
    assert table['start_m'].tolist() == [0.0, 100.0, 200.0]
    assert table['iri_left_m_per_km'][0] == 2.0 and table['iri_left_m_per_km'][2] == 2.0
    assert np.isnan(table['iri_left_m_per_km'][1])          # 100-200 m: 40 % covered
    assert table['peak_load_left_n'][1] == 1e4               # but it has load samples


def test_last_segment_end_after_the_last_fix_is_placed_from_it():
    """Fixes every 0.1 s stop 50 ms before the drive's end: the last edge lies less than one
    fix period after the last fix and gets its position from that fix along the track, at the
    travelled distance (no NaN)."""
    x = np.linspace(0.0, 300.0, 3001)
    stamps = (x / 20.0 * 1e9).astype(np.int64)        # 20 m/s: 15 s
    fix_ns = np.arange(0, 14_960_000_000, 100_000_000, dtype=np.int64)   # last at 14.9 s
    fix_lat = 48.0 + fix_ns * 1e-12
    fix_lon = 17.0 + fix_ns * 2e-12
    table = segment_table(x, np.full((3001, 2), 1e4), np.zeros(3001),
                          np.zeros((3001, 2), bool), stamps_ns=stamps, fix_stamps_ns=fix_ns,
                          fix_latitude_deg=fix_lat, fix_longitude_deg=fix_lon)
    assert table['end_m'][-1] == 300.0                  # reached at 15 s, 0.1 s after 14.9 s
    assert table['end_lat'][-1] == pytest.approx(48.015, abs=1e-9)
    assert table['end_lon'][-1] == pytest.approx(17.030, abs=1e-9)
    assert table['start_lat'][0] == pytest.approx(48.0)
    # More than one period beyond the fixes: still unknown, never guessed.
    fix_ns = fix_ns[fix_ns <= 14_000_000_000]
    table = segment_table(x, np.full((3001, 2), 1e4), np.zeros(3001),
                          np.zeros((3001, 2), bool), stamps_ns=stamps, fix_stamps_ns=fix_ns,
                          fix_latitude_deg=48.0 + fix_ns * 1e-12,
                          fix_longitude_deg=17.0 + fix_ns * 2e-12)
    assert np.isnan(table['end_lat'][-1])


def test_max_abs_quasi_static_ltr_per_segment():
    # INTERFACES.md: max |quasi-static LTR| per segment (NaN when the estimate has none)
    x = np.linspace(0.0, 300.0, 3001)
    quasi = np.where(x < 100.0, -0.3, 0.1) * np.sin(x)
    args = (x, np.full((3001, 2), 1e4), np.zeros(3001), np.zeros((3001, 2), bool))
    table = segment_table(*args, ltr_quasi_static=quasi)
    assert 'max_abs_ltr_quasi_static' in SEGMENT_COLUMNS
    for j in range(3):
        inside = (x >= 100.0 * j) & ((x < 100.0 * (j + 1)) if j < 2 else (x <= 300.0))
        assert table['max_abs_ltr_quasi_static'][j] == np.abs(quasi[inside]).max()
    assert np.isnan(segment_table(*args)['max_abs_ltr_quasi_static']).all()


@pytest.mark.parametrize('rows', [1, 2, 7, 1000, 5000])
def test_coverage_in_pieces_is_coverage(rows):
    """coverage_pieces (the distances read ``rows`` at a time) against coverage on the whole
    array: the same bits; an uneven drive with stops, a gap (no data over 40 m) and edges
    before the first and past the last sample."""
    from road_force_estimator.core.segments import coverage, coverage_pieces

    rng = np.random.default_rng(7)
    step = rng.uniform(0.015, 0.025, 4000)
    step[rng.random(step.size) < 0.02] = 0.0
    step[2500] = 40.0                                  # a gap
    x = 3.0 + np.cumsum(step)
    for edges in (segment_bounds(x[0], x[-1], 7.0), np.array([0.0, 5.0, 50.0, 90.0, 200.0])):
        want = coverage(x, edges)
        assert np.nanmin(want) < 0.5 < np.nanmax(want)      # the gap and covered ones
        got = coverage_pieces(x.size, lambda lo, hi: x[lo:hi], edges, rows)
        assert got.tobytes() == want.tobytes()
    for short in (x[:1], x[:2]):
        edges = np.array([0.0, 3.01, 4.0])
        got = coverage_pieces(short.size, lambda lo, hi: short[lo:hi], edges, rows)
        assert got.tobytes() == coverage(short, edges).tobytes()


def _fixed_drive(seed):
    """An uneven drive (1-2.5 cm steps, ~1 kHz with jittered stamps, ~4 s) and a curved
    track of fixes every ~0.1 s from 60 ms after its first stamp to 70 ms before its last."""
    rng = np.random.default_rng(seed)
    x = 3.0 + np.cumsum(rng.uniform(0.01, 0.025, 4000))
    stamps = 5_000_000_000 + np.cumsum(rng.integers(900_000, 1_100_000, x.size))
    a, b = stamps[0] + 60_000_000, stamps[-1] - 70_000_000
    fix_ns = np.round(np.linspace(a, b, round((b - a) / 1e8) + 1)).astype(np.int64)
    t = (fix_ns - fix_ns[0]) * 1e-9
    return x, stamps, fix_ns, 48.0 + 1e-5 * t + 1e-6 * np.sin(t), 11.0 + 2e-5 * t


@pytest.mark.parametrize('rows', [1, 2, 7, 1000, 5000])
def test_coordinates_in_pieces_are_coordinate_columns(rows):
    """coordinate_columns_pieces (distances and stamps read ``rows`` at a time) against
    coordinate_columns on the whole arrays: the same bits; the first and last ends placed
    beyond the fixes, an end more than a period past them (NaN), edges outside the drive,
    fewer than two fixes (NaN)."""
    from road_force_estimator.core.segments import coordinate_columns, coordinate_columns_pieces

    x, stamps, fix_ns, lat, lon = _fixed_drive(3)

    def read(lo, hi):
        return x[lo:hi], stamps[lo:hi]

    bounds = segment_bounds(x[0], x[-1], 7.0)
    cases = [(bounds, fix_ns, lat, lon),
             (np.array([0.0, 5.0, 30.0, 90.0, 200.0]), fix_ns, lat, lon),
             (bounds, fix_ns[:-3], lat[:-3], lon[:-3]),           # the end 0.37 s past them
             (bounds, fix_ns[:1], lat[:1], lon[:1]), (bounds, None, None, None)]
    for j, (edges, f, la, lo_) in enumerate(cases):
        want = coordinate_columns(x, edges, stamps, f, la, lo_)
        got = coordinate_columns_pieces(x.size, read, edges, f, la, lo_, rows)
        assert sorted(got) == sorted(want)
        for name in want:
            assert got[name].tobytes() == want[name].tobytes(), (j, name)
        if j == 0:                     # both ends beyond the fixes, placed from them
            assert np.isfinite(want['start_lat']).all() and np.isfinite(want['end_lon']).all()
        elif j == 2:
            assert np.isnan(want['end_lat'][-1]) and np.isfinite(want['end_lat'][:-1]).all()
        elif j > 2:
            assert np.isnan(want['start_lat']).all()
