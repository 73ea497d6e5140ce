"""IRI per segment a chunk at a time (core.iri_chunks) against core.iri in one piece."""
import numpy as np
import pytest

from road_force_estimator.core import iri, iri_chunks
from road_force_estimator.core.road import iso8608_profile
from road_force_estimator.core.segments import segment_bounds


@pytest.mark.parametrize('chunk', [7, 1000, 1 << 18])
def test_chunks_equal_one_piece(monkeypatch, chunk):
    monkeypatch.setattr(iri_chunks, 'CHUNK', chunk)
    road = iso8608_profile('C', 400.0, seed=2)
    x = np.asarray(road.distance_m, dtype=float)[::4] + 3.0
    z = np.asarray(road.elevation_m, dtype=float)[::4, 0]
    edges = segment_bounds(x[0], x[-1], 37.0)
    values, counts = iri_chunks.segment_iri(x, z, edges)
    np.testing.assert_array_equal(values, iri.iri_segments(x, z, edges))
    np.testing.assert_array_equal(counts, iri.interval_counts(x, edges))
    assert np.isfinite(values).all() and values.min() > 0.5


def test_uneven_and_short_profiles_as_core_iri():
    rng = np.random.default_rng(1)
    x = np.cumsum(rng.uniform(0.01, 0.05, 20000))
    z = 1e-3 * rng.standard_normal(x.size)
    edges = segment_bounds(x[0], x[-1], 100.0)
    values, counts = iri_chunks.segment_iri(x, z, edges)
    np.testing.assert_array_equal(values, iri.iri_segments(x, z, edges))
    np.testing.assert_array_equal(counts, iri.interval_counts(x, edges))
    with pytest.raises(ValueError):
        iri_chunks.segment_iri(x[:100], z[:100], segment_bounds(x[0], x[99], 1.0))
