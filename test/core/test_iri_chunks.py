"""The IRI of a profile read in pieces, a chunk at a time (core.iri_chunks), against
core.iri on the whole arrays."""
import numpy as np
import pytest

from road_force_estimator.core import iri, iri_chunks
from road_force_estimator.core.road import iso8608_profile
from road_force_estimator.core.segments import segment_bounds


def _drive_profile(n, seed):
    """Distances of an uneven drive with stops (repeated distances) and two tracks."""
    rng = np.random.default_rng(seed)
    step = rng.uniform(0.015, 0.025, n)
    step[rng.random(n) < 0.02] = 0.0
    step[n // 3:n // 3 + 50] = 0.0                     # a stop
    x = 5.0 + np.cumsum(step)
    z = 1e-4 * np.cumsum(rng.standard_normal((n, 2)), axis=0)
    return x, z


def _in_pieces(x, z, rows):
    return iri_chunks.profile_iri(x.size, lambda lo, hi: (x[lo:hi], z[lo:hi]), rows)


@pytest.mark.parametrize('chunk', [7, 1 << 18])
@pytest.mark.parametrize('rows', [1, 3, 997, 4000, 4001, 10_000])
def test_profile_iri_in_pieces_is_core_iri(monkeypatch, chunk, rows):
    """The whole profile's IRI read ``rows`` points at a time (one point, fewer than a
    stop's repeats, one piece: 4000 and more) against core.iri.iri on the arrays: the same
    bits; an uneven profile with stops (resampled) and an even one (kept as it is)."""
    monkeypatch.setattr(iri_chunks, 'CHUNK', chunk)
    x, z = _drive_profile(4000, 5)
    want = iri.iri(x, z)
    assert np.isfinite(want).all() and want.min() > 0.0
    assert _in_pieces(x, z, rows).tobytes() == want.tobytes()
    even = 2.0 + 0.02 * np.arange(4000)
    assert iri.evenly_spaced(even, z)[0] is not None and \
        np.array_equal(iri.evenly_spaced(even, z)[0], even)        # not resampled
    assert _in_pieces(even, z, rows).tobytes() == iri.iri(even, z).tobytes()


@pytest.mark.parametrize('case', ['one point', 'no distance', 'short', 'decreasing',
                                  'not finite', 'too fine'])
def test_profile_iri_refuses_what_core_iri_refuses(case):
    """The profiles core.iri.iri raises on (ValueError): the same in pieces."""
    x, z = _drive_profile(2000, 6)
    if case == 'one point':
        x, z = x[:1], z[:1]
    elif case == 'no distance':
        x = np.full(x.size, 3.0)
    elif case == 'short':
        x, z = x[:400], z[:400]                          # ~8 m, under the 11 m start
    elif case == 'decreasing':
        x = x.copy()
        x[1500] = x[1499] - 0.01
    elif case == 'not finite':
        z = z.copy()
        z[1200, 1] = np.nan
    else:                                                # a jump: a grid too fine
        x = np.concatenate([[0.0], 1e9 + 1e-3 * np.arange(1999)])
    with pytest.raises(ValueError):
        iri.iri(x, z)
    for rows in (1, 7, 5000):
        with pytest.raises(ValueError):
            _in_pieces(x, z, rows)


def _segments_in_pieces(x, z, edges, rows):
    return iri_chunks.profile_segment_iri(x.size, lambda lo, hi: (x[lo:hi], z[lo:hi]), edges,
                                          rows)


@pytest.mark.parametrize('chunk', [7, 1 << 18])
@pytest.mark.parametrize('rows', [1, 997, 4001])
def test_profile_segment_iri_in_pieces_is_core_iri_segments(monkeypatch, chunk, rows):
    """The IRI per segment and the intervals per segment read ``rows`` points at a time
    against core.iri.iri_segments (per track) and core.iri.interval_counts on the arrays:
    the same bits; an uneven profile with stops (resampled) and an even one."""
    monkeypatch.setattr(iri_chunks, 'CHUNK', chunk)
    for x, z in (_drive_profile(4000, 5), (2.0 + 0.02 * np.arange(4000),
                                           _drive_profile(4000, 5)[1])):
        edges = segment_bounds(x[0], x[-1], 13.0)
        values, counts = _segments_in_pieces(x, z, edges, rows)
        want = np.column_stack([iri.iri_segments(x, z[:, j], edges) for j in (0, 1)])
        assert np.isfinite(want).all() and want.min() > 0.0 and want.shape[0] > 4
        assert values.tobytes() == want.tobytes()
        assert counts.tobytes() == iri.interval_counts(x, edges).tobytes()


@pytest.mark.parametrize('case', ['short', 'not finite', 'NaN distance', 'too fine'])
def test_profile_segment_iri_refuses_what_iri_segments_refuses(case):
    x, z = _drive_profile(2000, 6)
    if case == 'short':
        x, z = x[:400], z[:400]
    elif case == 'not finite':
        z = z.copy()
        z[1200, 1] = np.nan
    elif case == 'NaN distance':
        x = x.copy()
        x[700] = np.nan
    else:
        x = np.concatenate([[0.0], 1e9 + 1e-3 * np.arange(1999)])
    edges = segment_bounds(x[0], x[-1], 3.0) if case != 'too fine' else np.array([0.0, 2e9])
    with pytest.raises(ValueError):
        iri.iri_segments(x, z, edges)
    with pytest.raises(ValueError):
        _segments_in_pieces(x, z, edges, 7)


@pytest.mark.parametrize('chunk', [7, 1000, 1 << 18])
@pytest.mark.parametrize('rows', [5, 4096, 1 << 20])
def test_profile_segment_iri_of_an_iso_road_is_iri_segments(monkeypatch, chunk, rows):
    """An even ISO 8608 class C road (one track, 400 m at 4 cm, not from 0 m), 37 m
    segments (the last shorter), filtered in chunks of 7, 1000 and 2^18 intervals and read
    5, 4096 and all points at a time: core.iri.iri_segments and interval_counts' bits."""
    monkeypatch.setattr(iri_chunks, 'CHUNK', chunk)
    road = iso8608_profile('C', 400.0, seed=2)
    x = np.asarray(road.distance_m, dtype=float)[::4] + 3.0
    z = np.asarray(road.elevation_m, dtype=float)[::4, :1]
    edges = segment_bounds(x[0], x[-1], 37.0)
    values, counts = _segments_in_pieces(x, z, edges, rows)
    want = iri.iri_segments(x, z[:, 0], edges)
    assert np.isfinite(want).all() and want.min() > 0.5 and want.size > 9
    assert values.shape == (want.size, 1)
    assert values[:, 0].tobytes() == want.tobytes()
    assert counts.tobytes() == iri.interval_counts(x, edges).tobytes()


@pytest.mark.parametrize('rows', [3, 1000, 20000])
def test_profile_segment_iri_resampled_and_empty_segments_as_iri_segments(rows):
    """An unevenly spaced profile (steps 1-5 cm: resampled on the median step) and edges
    that reach past both of its ends (segments without an interval: NaN, no count): the
    same bits as core.iri.iri_segments and interval_counts."""
    rng = np.random.default_rng(1)
    x = np.cumsum(rng.uniform(0.01, 0.05, 20000))
    z = 1e-3 * rng.standard_normal((x.size, 1))
    assert not np.array_equal(iri.evenly_spaced(x, z[:, 0])[0], x)       # resampled
    edges = np.concatenate([[x[0] - 250.0, x[0] - 120.0],
                            segment_bounds(x[0], x[-1], 100.0), [x[-1] + 80.0]])
    values, counts = _segments_in_pieces(x, z, edges, rows)
    want = iri.iri_segments(x, z[:, 0], edges)
    assert np.isnan(want[[0, 1, -1]]).all() and np.isfinite(want[2:-1]).all()
    assert values[:, 0].tobytes() == want.tobytes()
    want_counts = iri.interval_counts(x, edges)
    assert want_counts[[0, 1, -1]].tolist() == [0, 0, 0]
    assert counts.tobytes() == want_counts.tobytes()
