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
