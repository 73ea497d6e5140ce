"""core.pieces against the whole-array numpy / scipy calls it reproduces (np.interp,
np.arange, np.median, np.add.reduce, np.mean, np.gradient, scipy.signal.sosfiltfilt), bit
for bit, on awkward sizes: one piece for the whole series, many, pieces of one sample,
uneven ones (some empty), a series just longer than the filter's pad; distances with stops
(repeated values) and queries past both ends; medians of odd and even counts, ties, signs,
zeros, several series at once."""
import numpy as np
import pytest
from scipy import signal

from road_force_estimator.core import pieces


def reader(*arrays):
    """read(lo, hi) of the arrays (the last axis the samples')."""
    def read(lo, hi):
        out = tuple(a[..., lo:hi] for a in arrays)
        return out if len(out) > 1 else out[0]
    return read


def stops(n: int, seed: int = 3) -> np.ndarray:
    """A non-decreasing distance (m) with stops (steps of zero) and uneven steps."""
    rng = np.random.default_rng(seed)
    step = rng.uniform(0.0, 0.05, n)
    step[rng.random(n) < 0.2] = 0.0
    step[n // 3:n // 3 + n // 10] = 0.0                  # a long stop
    return np.cumsum(step)


@pytest.mark.parametrize('rows', [1, 2, 7, 997, 5000])
def test_interp_is_numpys(rows):
    x = stops(3000)
    f = np.random.default_rng(1).normal(size=(3, x.size))
    f[1, 100:200] = np.nan
    q = np.sort(np.concatenate([x[::3], x[::7] + 0.003, [x[0] - 1.0, x[-1] + 1.0],
                                np.full(5, x[x.size // 3])]))
    at = pieces.Interp(x.size, reader(x, f), rows)
    got = np.concatenate([at(q[lo:lo + 50]) for lo in range(0, q.size, 50)], axis=1)
    want = np.array([np.interp(q, x, r) for r in f])
    np.testing.assert_array_equal(got, want)
    again = at(q[:10])                                  # back to the start: read again
    np.testing.assert_array_equal(again, want[:, :10])


@pytest.mark.parametrize('start, stop, step', [(0.0, 10.0, 0.05), (3.217, 845.1, 0.05),
                                               (-2.5, 7.123, 0.0213), (1.0, 1.04, 0.05)])
def test_arange_is_numpys(start, stop, step):
    want = np.arange(start, stop, step)
    n = pieces.arange_size(start, stop, step)
    assert n == want.size
    for k in (1, 3, n or 1):
        got = np.concatenate([pieces.arange_piece(start, step, lo, min(lo + k, n))
                              for lo in range(0, n, k)] or [np.empty(0)])
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize('n, rows', [(3000, 1), (3000, 997), (3001, 5000), (2, 1), (5, 2)])
def test_median_of_positive_steps_is_numpys(n, rows):
    x = stops(n, seed=n)
    s = np.diff(x)
    want = float(np.median(s[s > 0])) if np.any(s > 0) else 0.0
    assert pieces.median_positive_steps(n, reader(x), rows) == want


def test_median_of_positive_steps_even_odd_and_none():
    for x in ([0.0, 1.0, 3.0, 3.0, 3.5], [0.0, 0.25, 0.25, 1.0], [2.0, 2.0, 2.0]):
        x = np.array(x)
        s = np.diff(x)
        want = float(np.median(s[s > 0])) if np.any(s > 0) else 0.0
        assert pieces.median_positive_steps(x.size, reader(x), 1) == want


@pytest.mark.parametrize('kind', ['lowpass', 'bandpass'])
@pytest.mark.parametrize('n, rows', [(5000, 1), (5000, 613), (5000, 5000), (None, 1),
                                     (None, 4)])
def test_sosfiltfilt_is_scipys(tmp_path, kind, n, rows):
    band = 0.1 if kind == 'lowpass' else (0.05, 0.2)
    sos = signal.butter(2, band, btype=kind, output='sos')
    pad = 3 * (2 * len(sos) + 1 - min((sos[:, 2] == 0).sum(), (sos[:, 5] == 0).sum()))
    n = pad + 1 if n is None else n                    # just past the pad
    x = np.random.default_rng(2).normal(size=(3, n)).cumsum(axis=1)
    out = pieces.sosfiltfilt(sos, n, reader(x), 3, tmp_path, rows)
    try:
        np.testing.assert_array_equal(out.array().T, signal.sosfiltfilt(sos, x, axis=-1))
    finally:
        out.close()
    with pytest.raises(ValueError):
        pieces.sosfiltfilt(sos, pad, reader(x[:, :pad]), 3, tmp_path, rows)


@pytest.mark.parametrize('n, rows', [(6000, 6000), (6000, 977), (6000, 1), (900, 64)])
def test_fuse_path_in_pieces_is_fuse_path(tmp_path, n, rows):
    """The fused road of one wheel path in pieces against fuse_path on the arrays: a drive
    with stops and a lifted wheel, long enough for the low pass (6000 samples, ~115 m) and
    too short for it (900)."""
    from road_force_estimator.estimation.articulated import fuse_path, fuse_path_pieces

    rng = np.random.default_rng(n)
    x = stops(n, seed=7)
    xi = [0.0, 3.6, 9.1, 10.4, 11.7]
    road = rng.normal(size=(5, n)).cumsum(axis=1) * 1e-3
    grounded = rng.random((5, n)) > 0.02
    grounded[2, n // 2:n // 2 + 200] = False
    want = fuse_path(x, road, grounded, xi)
    m, got = fuse_path_pieces(n, reader(x), lambda lo, hi, j: (road[j, lo:hi],
                                                             grounded[j, lo:hi]),
                              xi, tmp_path, rows)
    try:
        assert m == want.size > 0
        np.testing.assert_array_equal(got.array(), want)
    finally:
        got.close()


@pytest.mark.parametrize('even', [True, False])
@pytest.mark.parametrize('n, rows', [(1000, 1), (1000, 333), (1000, 1000), (2, 1), (3, 2)])
def test_gradient_is_numpys(even, n, rows):
    t = np.arange(n) * 0.5 if even else np.cumsum(
        np.random.default_rng(n).uniform(5e-4, 2e-3, n))
    f = stops(n, seed=n + 1)
    step = pieces.uniform_step(n, reader(t), rows)
    assert (step is not None) == (even or n == 2)        # one step: even
    got = np.concatenate([pieces.gradient_piece(reader(f), reader(t), n, lo,
                                                min(lo + rows, n), step)
                          for lo in range(0, n, rows)])
    np.testing.assert_array_equal(got, np.gradient(f, t))


@pytest.mark.parametrize('n, rows', [(n, r) for n in (0, 1, 7, 128, 129, 1000)
                                     for r in (1, 13, None)]
                         + [(100_003, 13), (100_003, 4096), (100_003, None)])
def test_pairwise_sum_is_numpys(n, rows):
    """numpy's own sum (and mean: that sum over n) of a float64 array, given in pieces of
    ``rows`` (None: one piece), to the bit; sizes across numpy's 128-point blocks, the
    ranges summed at once numpy's blocks (``hold`` 128) or the default's."""
    a = np.abs(np.random.default_rng(n).standard_normal(n)) * 1e-3
    step = rows or max(n, 1)
    for hold in (pieces.PAIRWISE_BLOCK, pieces.PIECE_ROWS):
        total = pieces.pairwise_sum(n, (a[lo:lo + step] for lo in range(0, n, step)), hold)
        assert total.hex() == np.add.reduce(a).hex()
        if n:
            assert float(total / n) == float(np.mean(a))


def _bits(x) -> bytes:
    return np.float64(x).tobytes()


def _cuts(n: int, rng, k: int) -> list:
    """k uneven cuts of range(n) (empty pieces among them)."""
    inner = np.sort(rng.integers(0, n + 1, size=max(k - 1, 0)))
    return list(zip([0, *inner.tolist()], [*inner.tolist(), n]))


def _series(n: int, kind: str, rng) -> np.ndarray:
    x = rng.standard_normal(n) * 10.0 ** rng.uniform(-6, 3, n)
    if kind == 'ties':
        x = np.round(rng.standard_normal(n), 1)       # few distinct values, many equal
    elif kind == 'positive':
        x = np.abs(x)
    elif kind == 'zeros':
        x[rng.random(n) < 0.5] = 0.0
        x[rng.random(n) < 0.2] = -0.0
    elif kind == 'constant':
        x = np.full(n, 2.5e-5)
    return x


@pytest.mark.parametrize('n', [1, 2, 3, 4, 7, 8, 129, 1000, 1001, 65537])
@pytest.mark.parametrize('kind', ['mixed', 'ties', 'positive', 'zeros', 'constant'])
def test_median_is_numpys(n, kind):
    rng = np.random.default_rng(n * 7 + len(kind))
    x = _series(n, kind, rng)
    ref = np.median(x)
    for cuts in ([(0, n)], _cuts(n, rng, 2), _cuts(n, rng, 13)):
        got = pieces.median(lambda: (x[a:b] for a, b in cuts))
        assert got == ref and (_bits(got) == _bits(ref) or got == 0.0), (cuts, got, ref)


def test_medians_of_several_series_at_once():
    """Series of different lengths (odd, even, one empty) in the same pieces, as the
    statistics take each channel's differences."""
    rng = np.random.default_rng(4)
    xs = [_series(n, k, rng) for n, k in ((5000, 'mixed'), (4999, 'ties'), (1, 'positive'),
                                           (0, 'mixed'), (3000, 'zeros'))]
    cuts = [_cuts(x.size, rng, 9) for x in xs]

    def passes():
        for i in range(9):
            yield [x[c[i][0]:c[i][1]] for x, c in zip(xs, cuts)]

    got = pieces.medians(passes, len(xs))
    for x, g in zip(xs, got):
        if x.size:
            assert g == np.median(x)
        else:
            assert np.isnan(g)


def test_median_of_a_series_with_nan_is_nan():
    x = np.arange(11.0)
    x[7] = np.nan
    with np.errstate(invalid='ignore'):
        assert np.isnan(np.median(x))
    assert np.isnan(pieces.median(lambda: (x[:5], x[5:])))


@pytest.mark.parametrize('n', [1, 7, 8, 9, 127, 128, 129, 1000, 8193, 65539, 300001])
def test_pairwise_sum_and_mean_in_ranges_are_numpys(n):
    rng = np.random.default_rng(n)
    x = _series(n, 'mixed', rng)

    for piece in (128, 1000, 65536, n):
        cut = range(0, n, piece)
        total = pieces.pairwise_sum(n, (x[a:a + piece] for a in cut), piece)
        assert _bits(total) == _bits(np.add.reduce(x))
        mean = pieces.pairwise_mean(n, (x[a:a + piece] for a in cut), piece)
        assert _bits(mean) == _bits(np.mean(x))
    uneven = _cuts(n, rng, 13)                          # pieces of any size, some empty
    total = pieces.pairwise_sum(n, (x[a:b] for a, b in uneven), 1000)
    assert _bits(total) == _bits(np.add.reduce(x))


def test_the_sum_tests_tell_orders_of_summation_apart():
    """The values above are such that another order of summation gives other bits (the
    comparison is not vacuous): the sequential sum and a sum of 1000-value pieces differ
    from numpy's on the 300001 values."""
    rng = np.random.default_rng(300001)
    x = _series(300001, 'mixed', rng)
    sequential = 0.0
    for v in x.tolist():
        sequential += v
    pieces = sum(float(np.add.reduce(x[a:a + 1000])) for a in range(0, x.size, 1000))
    assert sequential != np.add.reduce(x) and pieces != np.add.reduce(x)
