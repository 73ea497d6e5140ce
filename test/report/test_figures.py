"""report.figures: the min-max envelope of the whole-drive figure."""
import numpy as np

from road_force_estimator.report.figures import envelope


def test_envelope_is_min_and_max_per_pixel_column():
    x = np.arange(100_000) * 0.01
    y = np.sin(x)
    y[5000] = 7.0                                     # a spike survives the envelope
    xc, lo, hi = envelope(x, y, columns=100)
    assert xc.size == lo.size == hi.size == 100
    assert np.all(lo <= hi) and hi.max() == 7.0 and lo.min() == np.min(y)
    assert np.all(np.diff(xc) > 0)
    # Fewer points than two per column: the points themselves.
    xc, lo, hi = envelope(x[:150], y[:150], columns=100)
    assert np.array_equal(xc, x[:150]) and np.array_equal(lo, hi)


def test_envelope_of_sorted_samples_is_each_bins_min_and_max():
    # reference: every bin by its mask (bin j holds edges[j] <= x < edges[j + 1], the last
    # one closed), on sorted samples with stops (repeated x) and samples on the edges
    rng = np.random.default_rng(2)
    x = np.cumsum(rng.integers(0, 3, 20_000)).astype(float)
    y = rng.standard_normal(x.size)
    xc, lo, hi = envelope(x, y, columns=300)
    edges = np.linspace(x[0], x[-1], 301)
    for j in range(300):
        inside = (x >= edges[j]) & ((x < edges[j + 1]) if j < 299 else (x <= edges[j + 1]))
        if inside.any():
            assert lo[j] == y[inside].min() and hi[j] == y[inside].max(), j
        else:
            assert np.isnan(lo[j]) and np.isnan(hi[j]), j
