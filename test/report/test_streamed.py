"""The streamed report's whole-drive numbers (report.streamed.StreamedSummary: the IRI per
segment, the coverage that blanks it, the segments' coordinates, the whole drive's IRI, the
speed's statistics, the model fit's medians) from a drive fed in pieces and read back a
piece at a time, against core.iri and core.segments on the whole arrays (the one-piece
report's functions) and numpy: the same bits; and its traced peak does not grow with the
drive."""
import gc
from types import SimpleNamespace
import tracemalloc

import numpy as np
import pytest

from road_force_estimator.core import iri
from road_force_estimator.core.segments import MIN_COVERAGE, coverage
from road_force_estimator.report.streamed import StreamedSummary
from road_force_estimator.report.summary import whole_from_segments


def _drive(n: int, seed: int, uneven: bool = True, gap: bool = True):
    """Distances (m; an uneven drive with stops and, with ``gap``, 40 m without data), the
    speeds (m/s, 1 kHz) and a two-track random-walk road (m)."""
    rng = np.random.default_rng(seed)
    step = rng.uniform(0.015, 0.025, n) if uneven else np.full(n, 0.02)
    if uneven:
        step[rng.random(n) < 0.02] = 0.0                 # stops: distances repeated
    if gap:
        step[n // 2] = 40.0
    x = 2.0 + np.cumsum(step)
    z = 1e-4 * np.cumsum(rng.standard_normal((n, 2)), axis=0)
    return x, step * 1000.0, z


def _fed(x, v, z, piece: int, spill=None, rows: int | None = None,
         with_stamps: bool = False, stamps=None) -> StreamedSummary:
    """A StreamedSummary (50 m segments) fed the drive ``piece`` samples at a time (its
    ``stamps``, ns; default 1 ms apart), every sample accepted and converged; ``rows``: the
    samples it reads back at a time; ``with_stamps``: the stamps kept (for the coordinates)."""
    acc = StreamedSummary(50.0, with_stamps=with_stamps, capacity=x.size, spill=spill)
    if stamps is None:
        stamps = np.arange(x.size, dtype=np.int64) * 1_000_000
    if rows is not None:
        acc.piece_rows = rows
    for lo in range(0, x.size, piece):
        k = min(piece, x.size - lo)
        ones = np.ones(k, bool)
        load = np.full((k, 2), 3e4) + np.arange(k)[:, None]
        acc.add(SimpleNamespace(
            stamp_ns=stamps[lo:lo + k], valid=ones,
            converged=ones, distance_m=x[lo:lo + k], road_m=z[lo:lo + k], wheel_load_n=load,
            ltr=np.zeros(k), ltr_quasi_static=np.zeros(k), lift_off=np.zeros((k, 2), bool),
            load_clipped=np.zeros((k, 2), bool), static_load_n=np.full((k, 2), 3e4),
            speed_contradicted=np.zeros(k, bool)), v[lo:lo + k])
    return acc


def _close(acc: StreamedSummary) -> None:
    for col in (acc.x_up, acc.road_up, acc.stamps, acc.speed, acc.stamps_up, acc.x_valid):
        if hasattr(col, 'close'):
            col.close()


@pytest.mark.parametrize('rows', [7, 1000, None])
@pytest.mark.parametrize('spilled', [False, True])
@pytest.mark.parametrize('uneven', [True, False])
def test_pieces_equal_the_whole_arrays(tmp_path, rows, spilled, uneven):
    """The IRI columns, their blanking (coverage) and the whole IRI of a drive fed in pieces
    of 4096 and read back ``rows`` at a time (None: the default), its columns in memory or
    spilled, against iri_segments, coverage and whole_from_segments on the whole arrays of
    the samples that advance; an uneven drive (resampled) and an even one."""
    x, v, z = _drive(30_000, 3, uneven)
    acc = _fed(x, v, z, 4096, tmp_path if spilled else None, rows)
    try:
        table = acc.segment_table()
        whole = acc.whole_iri(table)
    finally:
        _close(acc)
    up = np.concatenate([[True], np.diff(x) > 0])        # the samples that advance
    xu, zu = x[up], z[up]
    edges = np.concatenate([table['start_m'], table['end_m'][-1:]])
    sparse = coverage(xu, edges) < MIN_COVERAGE
    assert sparse.any() and not sparse.all()             # the gap blanks a segment or two
    want = {}
    for side, name in ((0, 'left'), (1, 'right')):
        want[f'iri_{name}_m_per_km'] = np.where(
            sparse, np.nan, iri.iri_segments(xu, zu[:, side], edges))
        assert table[f'iri_{name}_m_per_km'].tobytes() == want[f'iri_{name}_m_per_km'].tobytes()
    assert np.isfinite(want['iri_left_m_per_km'][~sparse]).all()
    segments = {'start_m': table['start_m'], 'end_m': table['end_m'], **want}
    reference = whole_from_segments(xu, zu, segments, 'iri')
    assert whole is not None and whole == reference


def test_a_track_not_finite(tmp_path):
    """A NaN in the right track's road: the left track's IRI as on the arrays, the right's
    NaN, no whole IRI (as whole_from_segments gives)."""
    x, v, z = _drive(20_000, 4, gap=False)
    z[5000, 1] = np.nan
    acc = _fed(x, v, z, 3000, tmp_path, 999)
    try:
        table = acc.segment_table()
        whole = acc.whole_iri(table)
    finally:
        _close(acc)
    up = np.concatenate([[True], np.diff(x) > 0])
    edges = np.concatenate([table['start_m'], table['end_m'][-1:]])
    left = iri.iri_segments(x[up], z[up, 0], edges)
    assert np.isfinite(left).all()
    assert table['iri_left_m_per_km'].tobytes() == left.tobytes()
    assert np.isnan(table['iri_right_m_per_km']).all()
    assert whole is None and whole_from_segments(x[up], z[up], table, 'iri') is None


def _fixes(x, stamps):
    """Fixes every ~0.1 s from 50 ms after the first stamp to 70 ms before the last (the
    first and last segment ends placed beyond them) on a straight road 30 deg east of north,
    at the travelled distance ``x`` (m) at ``stamps`` (ns)."""
    a, b = stamps[0] + 50_000_000, stamps[-1] - 70_000_000
    t = np.round(np.linspace(a, b, round((b - a) / 1e8) + 1))
    along = np.interp(t, stamps, x)
    lat = 48.0 + along * np.cos(np.radians(30.0)) / 111_195.0
    lon = 11.0 + along * np.sin(np.radians(30.0)) / (111_195.0 * np.cos(np.radians(48.0)))
    return SimpleNamespace(stamps_ns=t.astype(np.int64), latitude_deg=lat, longitude_deg=lon)


@pytest.mark.parametrize('rows', [7, 1000, None])
@pytest.mark.parametrize('spilled', [False, True])
def test_coordinates_and_speed_in_pieces_equal_the_whole_arrays(tmp_path, rows, spilled):
    """The segments' coordinates (GNSS fixes, the stamps kept) and the speed's statistics
    (NaN speeds among them) of a drive fed in pieces of 4096 and read back ``rows`` at a
    time, in memory or spilled, against coordinate_columns on the whole arrays of the samples
    that advance and np.mean/min/max of the finite speeds: the same bits."""
    from road_force_estimator.core.segments import coordinate_columns

    x, v, z = _drive(30_000, 6)
    v = v + np.random.default_rng(6).uniform(0.0, 1e-3, v.size)    # not in 8-bit steps
    v[[10, 20_000, 29_999]] = np.nan
    stamps = np.arange(x.size, dtype=np.int64) * 1_000_000
    fixes = _fixes(x, stamps)
    acc = _fed(x, v, z, 4096, tmp_path if spilled else None, rows, with_stamps=True)
    try:
        table = acc.segment_table(fixes)
        speed = acc.speed_stats()
    finally:
        _close(acc)
    up = np.concatenate([[True], np.diff(x) > 0])        # the samples that advance
    edges = np.concatenate([table['start_m'], table['end_m'][-1:]])
    want = coordinate_columns(x[up], edges, stamps[up], fixes.stamps_ns, fixes.latitude_deg,
                              fixes.longitude_deg)
    assert np.isfinite(want['start_lat']).all() and np.isfinite(want['end_lon']).all()
    for name, column in want.items():
        assert table[name].tobytes() == column.tobytes(), name
    finite = v[np.isfinite(v)]
    assert speed == {'mean': float(np.mean(finite)), 'min': float(np.min(finite)),
                     'max': float(np.max(finite))}


@pytest.mark.parametrize('rows', [7, 1000, None])
@pytest.mark.parametrize('n', [30_000, 30_001])
def test_the_fits_medians_in_pieces_are_np_median(tmp_path, rows, n):
    """The model fit's median moving speed and median stamp step (fit_speed_and_step) of a
    spilled drive fed in pieces of 4096 (speeds of either sign, some under 1 m/s, NaN; stamps
    jittered; an even and an odd count) against np.median on the arrays, as
    estimation.fit_check.assess takes them; no speed over 1 m/s: 1.0."""
    rng = np.random.default_rng(n)
    x, _, z = _drive(n, 7, gap=False)
    v = rng.uniform(-30.0, 30.0, n)
    v[rng.random(n) < 0.1] = 0.5
    v[[3, n // 2]] = np.nan
    stamps = 7_000_000_000 + np.cumsum(rng.integers(990_000, 1_010_000, n))
    t = stamps * 1e-9
    moving = np.abs(v)[np.abs(v) >= 1.0]
    want = (float(np.median(moving)), float(np.median(np.diff(t))))
    for speeds, expected in ((v, want), (np.full(n, 0.5), (1.0, want[1]))):
        acc = _fed(x, speeds, z, 4096, tmp_path, rows, stamps=stamps)
        try:
            got = acc.fit_speed_and_step()
        finally:
            _close(acc)
        assert np.array(got).tobytes() == np.array(expected).tobytes()


def test_the_whole_drives_numbers_do_not_hold_the_columns(tmp_path):
    """The traced peak of segment_table (with GNSS fixes: the coordinates too), whole_iri,
    speed_stats and fit_speed_and_step on a spilled drive at 20 m/s (1 kHz) of 600 000 and
    1 200 000 samples (the IRI filter's chunks full at both): it does not grow with the
    drive (under 2 bytes a sample; measured 0.06) where the distance, road, stamps and speeds
    read whole grew by 24 without fixes and 40 with them, the fit's medians by 32 (before
    these: bench.probes.streamed_report_memory; the medians: docs/articulated.md). A first
    run for the one-time caches."""
    peaks = []
    for n in (200_000, 600_000, 1_200_000):
        x, v, z = _drive(n, 5, uneven=False, gap=False)
        fixes = _fixes(x, np.arange(n, dtype=np.int64) * 1_000_000)
        acc = _fed(x, v, z, 65536, tmp_path, with_stamps=True)
        del x, v, z
        try:
            gc.collect()
            tracemalloc.start()
            try:
                table = acc.segment_table(fixes)
                whole = acc.whole_iri(table)
                speed = acc.speed_stats()
                fit = acc.fit_speed_and_step()
                peaks.append(tracemalloc.get_traced_memory()[1])
            finally:
                tracemalloc.stop()
        finally:
            _close(acc)
        assert whole is not None and np.isfinite(whole).all()
        assert np.isfinite(table['end_lat']).all() and speed['mean'] == 20.0
        assert fit[0] == 20.0 and abs(fit[1] - 1e-3) < 1e-12
    growth = (peaks[2] - peaks[1]) / 600_000
    assert growth < 2.0, (growth, peaks)
