"""Load transfer ratio: hand-computed values, the lift-off limits, scalar = array path."""
import numpy as np
import pytest

from road_force_estimator.estimation.load_transfer import load_transfer_ratio, load_transfer_ratios

FLOOR = 578.6   # 1 % of the default static axle load (N)


@pytest.mark.parametrize('fn1, fn2, expected', [
    (30000.0, 30000.0, 0.0),
    (20000.0, 40000.0, 1.0 / 3.0),         # right heavier: positive
    (45000.0, 15000.0, -0.5),
    (0.0, 50000.0, 1.0),                   # left wheel lifted: the rollover limit
    (-3000.0, 50000.0, 1.0),               # an estimate below zero is a lifted wheel
    (50000.0, -10.0, -1.0),
    (-5.0, -7.0, 0.0),                     # airborne: finite, no transfer
    (100.0, 300.0, 200.0 / FLOOR),         # tiny loads: the floor keeps it finite
])
def test_values_by_hand(fn1, fn2, expected):
    assert load_transfer_ratio(fn1, fn2, FLOOR) == pytest.approx(expected)


def test_bounded_and_array_path_equal_to_scalar_path():
    rng = np.random.default_rng(7)
    f = rng.normal(20000.0, 30000.0, size=(1000, 2))
    arr = load_transfer_ratios(f[:, 0], f[:, 1], FLOOR)
    assert np.all(np.abs(arr) <= 1.0)
    assert arr.tolist() == [load_transfer_ratio(a, b, FLOOR) for a, b in f]
