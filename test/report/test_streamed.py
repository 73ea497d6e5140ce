"""The streamed report's whole-drive numbers (report.streamed.StreamedSummary: the IRI per
segment, the coverage that blanks it, the whole drive's IRI) from a drive fed in pieces and
read back a piece at a time, against core.iri and core.segments on the whole arrays (the
one-piece report's functions): the same bits; and its traced peak does not grow with the
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


def _fed(x, v, z, piece: int, spill=None, rows: int | None = None) -> StreamedSummary:
    """A StreamedSummary (50 m segments) fed the drive ``piece`` samples at a time, every
    sample accepted and converged; ``rows``: the samples it reads back at a time."""
    acc = StreamedSummary(50.0, capacity=x.size, spill=spill)
    if rows is not None:
        acc.piece_rows = rows
    for lo in range(0, x.size, piece):
        k = min(piece, x.size - lo)
        ones = np.ones(k, bool)
        load = np.full((k, 2), 3e4) + np.arange(k)[:, None]
        acc.add(SimpleNamespace(
            stamp_ns=np.arange(lo, lo + k, dtype=np.int64) * 1_000_000, valid=ones,
            converged=ones, distance_m=x[lo:lo + k], road_m=z[lo:lo + k], wheel_load_n=load,
            ltr=np.zeros(k), ltr_quasi_static=np.zeros(k), lift_off=np.zeros((k, 2), bool),
            load_clipped=np.zeros((k, 2), bool), static_load_n=np.full((k, 2), 3e4),
            speed_contradicted=np.zeros(k, bool)), v[lo:lo + k])
    return acc


def _close(acc: StreamedSummary) -> None:
    for col in (acc.x_up, acc.road_up, acc.stamps, acc.speed):
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


def test_the_whole_drives_numbers_do_not_hold_the_columns(tmp_path):
    """The traced peak of segment_table and whole_iri on a spilled drive at 20 m/s (1 kHz) of
    600 000 and 1 200 000 samples (the IRI filter's chunks full at both): it does not grow
    with the drive (under 2 bytes a sample; measured 0.0) where the distance and road read
    whole grew by 24 (before this: bench.probes.streamed_report_memory). A first run for the
    one-time caches."""
    peaks = []
    for n in (200_000, 600_000, 1_200_000):
        x, v, z = _drive(n, 5, uneven=False, gap=False)
        acc = _fed(x, v, z, 65536, tmp_path)
        del x, v, z
        try:
            gc.collect()
            tracemalloc.start()
            try:
                table = acc.segment_table()
                whole = acc.whole_iri(table)
                peaks.append(tracemalloc.get_traced_memory()[1])
            finally:
                tracemalloc.stop()
        finally:
            _close(acc)
        assert whole is not None and np.isfinite(whole).all()
    growth = (peaks[2] - peaks[1]) / 600_000
    assert growth < 2.0, (growth, peaks)
