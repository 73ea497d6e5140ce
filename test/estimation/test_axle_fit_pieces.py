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


@pytest.mark.parametrize('window_m, rows', [(60.0, 4099), (100.0, 1 << 20), (90.0, 997)])
def test_in_windows_pieces_are_the_whole_arrays_and_name_the_axle(window_m, rows):
    """A drive judged over more than ``window_m`` (here 208 m over 3-4 windows, the last
    one short; the stop and the lifted wheel inside them) in windows: assess_pieces ==
    assess_axles bit for bit; the axle 3 % off (trailer1) named, as judged in one piece,
    its misfit within 0.1 % of the one-piece one; the same drive without that axle's error
    names nothing."""
    stamps, x, road, grounded = drive(14.0)

    def both(roads):
        want = assess_axles(stamps, x, roads, None, None, POSITIONS, NAMES, grounded=grounded,
                            window_m=window_m)
        got = assess_pieces(stamps.size, lambda lo, hi: stamps[lo:hi],
                            lambda lo, hi: x[lo:hi],
                            lambda lo, hi, w: (roads[w, lo:hi], grounded[w, lo:hi]),
                            POSITIONS, NAMES, rows=rows, window_m=window_m)
        np.testing.assert_array_equal(got.misfit, want.misfit)
        np.testing.assert_array_equal(got.spread, want.spread)
        assert (got.axles, got.sensors, got.length_m) == \
            (want.axles, want.sensors, want.length_m)
        return want

    one = assess_axles(stamps, x, road, None, None, POSITIONS, NAMES, grounded=grounded)
    assert one.length_m > 2 * window_m and one.culprits == ('trailer1',)
    fit = both(road)
    assert fit.culprits == ('trailer1',), fit.axle_misfit
    np.testing.assert_allclose(fit.misfit, one.misfit, atol=0.001)     # measured 6e-5
    clean = road.copy()
    clean[4:6] /= 1.03                       # trailer1's roads back on the others'
    fit = both(clean)
    assert fit.measured and fit.culprits == (), fit.axle_misfit


def test_in_windows_the_grid_is_not_held_whole():
    """assess_pieces' traced peak (tracemalloc; samples read 4099 at a time) on 20 s and
    80 s drives (~380 m and ~1560 m judged) after a first run (the one-time caches): in
    windows of 60 m it grows by under 8 bytes a sample (measured 3: a window's grid arrays
    held, not the drive's), in one piece by over 40 (measured 53: the whole grid's)."""
    import gc
    import tracemalloc

    drives = {s: drive(s) for s in (20.0, 80.0)}
    growth = {}
    for window_m in (60.0, 1e9):
        peaks = []
        for seconds in (20.0, 20.0, 80.0):
            stamps, x, road, grounded = drives[seconds]
            gc.collect()
            tracemalloc.start()
            try:
                fit = assess_pieces(stamps.size, lambda lo, hi: stamps[lo:hi],
                                    lambda lo, hi: x[lo:hi],
                                    lambda lo, hi, w: (road[w, lo:hi], grounded[w, lo:hi]),
                                    POSITIONS, NAMES, rows=4099, window_m=window_m)
                peaks.append(tracemalloc.get_traced_memory()[1])
            finally:
                tracemalloc.stop()
            assert fit.culprits == ('trailer1',)
        growth[window_m] = (peaks[2] - peaks[1]) / (drives[80.0][0].size - drives[20.0][0].size)
    assert growth[60.0] < 8.0, growth
    assert growth[1e9] > 40.0, growth
