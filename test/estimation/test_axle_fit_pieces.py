"""axle_fit.assess_pieces (the model fit per axle from samples read in pieces) against
assess_axles on the whole arrays: the same misfits, spreads and verdict, bit for bit, on a
drive with a stop and a wheel lifted (points the fit leaves out), in one piece, in many and
in pieces of one sample; and a drive too short for a verdict."""
import numpy as np
import pytest

from road_force_estimator.estimation.axle_fit import assess_axles, assess_pieces

POSITIONS = [0.0, 3.6, 9.1, 10.4, 11.7]
NAMES = ('front', 'drive1', 'trailer1', 'trailer2', 'trailer3')


def drive(seconds: float, seed: int = 5):
    """1 kHz stamps, a distance at ~20 m/s with a 1 s stop, 10 roads that are one road
    shifted by each axle's position plus noise (one axle's 3 % off), wheels grounded but
    for a lifted stretch."""
    rng = np.random.default_rng(seed)
    n = int(seconds * 1000)
    stamps = np.cumsum(rng.integers(990_000, 1_010_000, n)).astype(np.int64)
    v = np.full(n, 20.0)
    v[n // 2:n // 2 + 1000] = 0.0                             # a stop
    x = np.concatenate([[0.0], np.cumsum(v[1:] * np.diff(stamps) * 1e-9)])
    ground = np.cumsum(rng.normal(size=int(x[-1] / 0.01) + 2000)) * 1e-4
    road = np.empty((10, n))
    for j, xi in enumerate(POSITIONS):
        for s in (0, 1):
            at = np.interp(x - xi, np.arange(ground.size) * 0.01 - 20.0, ground)
            road[2 * j + s] = at * (1.03 if j == 2 else 1.0) + rng.normal(0, 2e-5, n)
    grounded = np.ones((10, n), bool)
    grounded[5, n // 4:n // 4 + 300] = False                  # a wheel lifted
    return stamps, x, road, grounded


@pytest.mark.parametrize('rows', [1 << 20, 4099, 1])
def test_in_pieces_is_the_whole_arrays(rows):
    stamps, x, road, grounded = drive(14.0 if rows > 1 else 9.0)
    want = assess_axles(stamps, x, road, None, None, POSITIONS, NAMES, grounded=grounded)
    got = assess_pieces(stamps.size, lambda lo, hi: stamps[lo:hi], lambda lo, hi: x[lo:hi],
                        lambda lo, hi, w: (road[w, lo:hi], grounded[w, lo:hi]), POSITIONS,
                        NAMES, rows=rows)
    assert want.measured and want.length_m > 100.0
    np.testing.assert_array_equal(got.misfit, want.misfit)
    np.testing.assert_array_equal(got.spread, want.spread)
    assert (got.axles, got.sensors, got.length_m, got.threshold) == \
        (want.axles, want.sensors, want.length_m, want.threshold)


def test_too_short_a_drive_has_no_verdict_either_way():
    stamps, x, road, grounded = drive(3.0)
    want = assess_axles(stamps, x, road, None, None, POSITIONS, NAMES, grounded=grounded)
    got = assess_pieces(stamps.size, lambda lo, hi: stamps[lo:hi], lambda lo, hi: x[lo:hi],
                        lambda lo, hi, w: (road[w, lo:hi], grounded[w, lo:hi]), POSITIONS,
                        NAMES, rows=700)
    assert not want.measured and not got.measured
    assert got.length_m == want.length_m
