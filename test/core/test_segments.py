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
