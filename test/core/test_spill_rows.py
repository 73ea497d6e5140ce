"""SpillRows (core/spill.py): rows of a file indexed as the array of them is."""
import numpy as np
import pytest

from road_force_estimator.core.spill import SpillColumn, SpillRows


def test_spill_rows_index_as_the_array(tmp_path):
    a = np.random.default_rng(2).standard_normal((1001, 12))
    file = SpillColumn(float, 12, tmp_path)
    for k in range(0, a.shape[0], 97):
        file.append(a[k:k + 97])
    rows = SpillRows(file)
    assert rows.shape == a.shape and len(rows) == a.shape[0]
    for sl in (slice(0, 1001), slice(5, 17), slice(990, 2000), slice(-11, None),
               slice(30, 20), slice(None, 3)):
        np.testing.assert_array_equal(rows[sl], a[sl])
    for k in (0, 500, 1000, -1, -1001):
        np.testing.assert_array_equal(rows[k], a[k])
    sub = rows.sub(100, 300)
    assert sub.shape == (200, 12)
    np.testing.assert_array_equal(sub[10:250], a[100:300][10:250])
    np.testing.assert_array_equal(sub[-1], a[299])
    for bad in (1001, -1002):
        with pytest.raises(IndexError):
            rows[bad]
    with pytest.raises(IndexError):
        rows[::2]
    file.close()
