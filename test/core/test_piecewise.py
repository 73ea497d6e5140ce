"""numpy's median and mean over pieces (core/piecewise.py) against numpy's whole-array
functions, bit for bit: odd and even counts, ties, signs, zeros, one piece and many uneven
ones (some empty), several series at once."""
import numpy as np
import pytest

from road_force_estimator.core.piecewise import medians, median, pairwise_mean, pairwise_sum


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
        got = median(lambda: (x[a:b] for a, b in cuts))
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

    got = medians(passes, len(xs))
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
    assert np.isnan(median(lambda: (x[:5], x[5:])))


@pytest.mark.parametrize('n', [1, 7, 8, 9, 127, 128, 129, 1000, 8193, 65539, 300001])
def test_pairwise_sum_and_mean_are_numpys(n):
    rng = np.random.default_rng(n)
    x = _series(n, 'mixed', rng)

    def read(a: int, b: int) -> np.ndarray:
        return x[a:b]

    for piece in (128, 1000, 65536, n):
        assert _bits(pairwise_sum(read, n, piece)) == _bits(np.add.reduce(x))
        assert _bits(pairwise_mean(read, n, piece)) == _bits(np.mean(x))


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
