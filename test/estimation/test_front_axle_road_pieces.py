"""The front axle's offline road in pieces (``OfflineRows.road_pieces``: the profile pass's
columns in a file, the body heave's zero-phase integral and cubic over pieces) against the
whole run's road (``OfflineRows.road``, the one-block path) bit for bit, and
``body_heave.zero_phase_pieces`` against ``scipy.signal.sosfilt`` over the whole series;
the traced peak of the road in pieces against the drive's length."""
import numpy as np
import pytest
from scipy import signal

from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
from road_force_estimator.core.spill import SpillColumn
from road_force_estimator.estimation import body_heave
from road_force_estimator.estimation.models.front_axle import FrontAxleModel
from road_force_estimator.estimation.outputs import Column

DT = 1e-3


def _rows():
    return FrontAxleModel(VehicleParameters()).offline_rows(ObserverParameters())


def _columns(m: int, seed: int = 1) -> np.ndarray:
    """(m, 3): u_1, u_2 (m) and dd z_s (m/s^2) of a run, smooth random series."""
    rng = np.random.default_rng(seed)
    x = np.cumsum(rng.standard_normal((m, 3)), axis=0) * 1e-3
    x[:, 2] = 0.5 * np.sin(np.arange(m) * 2.0 * np.pi * DT * 1.3) + rng.standard_normal(m)
    return x


def _speeds(m: int, kind: str) -> np.ndarray:
    v = np.full(m, 20.0)
    if kind == 'standing':           # steady (the 5th percentile at speed), a short stand
        v[m // 3:m // 3 + m // 50] = 0.0
        v[m // 2] = 0.0              # one sample at 0: no standing step
    elif kind == 'unsteady':         # speeding up without a stop: zero_phase, no cubic
        v = np.linspace(4.0, 24.0, m)
    elif kind == 'stop':             # a stop: the integral in distance (read whole)
        v[m // 3:m // 3 + m // 5] = 0.0
    return v


def _in_file(x: np.ndarray, folder) -> SpillColumn:
    f = SpillColumn(float, x.shape[1], folder)
    f.append(x)
    return f


def _road_whole(rows, x: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``OfflineRows.road`` on the columns in memory (the run in one block)."""
    cols = {j: x[:, k].copy() for k, j in enumerate(rows.profile_columns)}
    speed = float(np.median(np.abs(v)))
    return np.column_stack(rows.road(cols, DT, speed, None, True, None, v))


@pytest.mark.parametrize('kind', ['steady', 'standing', 'unsteady', 'stop'])
@pytest.mark.parametrize('piece', [1, 777, None])
def test_road_pieces_is_the_whole_runs_road(kind, piece, tmp_path):
    """Every kind of run (steady, with standing steps, speeding up, with a stop), read 1 and
    777 rows at a time and by default (body_heave.CHUNK: two chunks of the cubic's sums):
    the same bits as the road of the whole run's columns."""
    m = 70_001 if piece != 1 else 3_001
    rows = _rows()
    assert tuple(rows.profile_columns) == (Column.U1, Column.U2, Column.DDZS)
    x, v = _columns(m), _speeds(m, kind)
    if kind == 'stop':
        assert body_heave.offline_profile_way(v, 20.0, 100.0, 100.0) is None
    kept = _in_file(x, tmp_path)
    roads = rows.road_pieces(kept, m, DT, float(np.median(np.abs(v))), tmp_path, piece, v=v)
    try:
        got = roads.array()
    finally:
        roads.close()
        kept.close()
    want = _road_whole(rows, x, v)
    assert got.shape == (m, 2)
    np.testing.assert_array_equal(got, want)
    if kind == 'standing':                  # held where the model stands
        assert np.all(np.diff(got[m // 3:m // 3 + m // 50], axis=0) == 0.0)


@pytest.mark.parametrize('m', [1, 5, 8])
def test_road_pieces_of_short_runs(m, tmp_path):
    """Under 8 samples no integral (the road the deflections), at 8 the integral: the whole
    run's bits, in pieces of 3."""
    rows = _rows()
    x, v = _columns(m), np.full(m, 20.0)
    kept = _in_file(x, tmp_path)
    roads = rows.road_pieces(kept, m, DT, 20.0, tmp_path, 3, v=v)
    got = roads.array()
    roads.close()
    kept.close()
    np.testing.assert_array_equal(got, _road_whole(rows, x, v))


@pytest.mark.parametrize('piece', [1, 500, 65536])
def test_zero_phase_pieces_is_sosfilt_forward_and_backward(piece, tmp_path):
    """Two series filtered forward then backward over pieces: scipy's sosfilt over the
    whole series (each pass started in its steady state for its first value), bit for bit,
    and body_heave.zero_phase."""
    m = 4_001 if piece == 1 else 70_000
    a = _columns(m)[:, 1:]
    w = 2.0 * np.pi * 20.0 / 1e4
    fwd, back = body_heave.zero_phase_sections(DT, w)
    want = np.empty_like(a)
    for k in range(2):
        f = signal.sosfilt(fwd, a[:, k], zi=signal.sosfilt_zi(fwd) * a[0, k])[0]
        want[:, k] = signal.sosfilt(back, f[::-1], zi=signal.sosfilt_zi(back) * f[-1])[0][::-1]
    out = body_heave.zero_phase_pieces(m, lambda i, j: a[i:j], 2, DT, w, tmp_path, piece)
    try:
        got = out.array()
    finally:
        out.close()
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(got[:, 0], body_heave.zero_phase(a[:, 0], DT, w))


def test_polynomial_fit_over_a_file_is_the_arrays(tmp_path):
    """The cubic's coefficients from a series read from a file a chunk at a time: the bits
    of the array's fit (the same chunks), and within 1e-13 of z's RMS of np.polyfit's
    values."""
    m = 150_001
    z = _columns(m)[:, 0]
    f = _in_file(z[:, None], tmp_path)
    got = body_heave.polynomial_fit_pieces(m, lambda i, j: f.read(i, j)[:, 0], 3)
    f.close()
    np.testing.assert_array_equal(got, body_heave.polynomial_fit(z, 3))
    tt = np.linspace(-1.0, 1.0, m)
    ref = np.polyval(np.polyfit(tt, z, 3), tt)
    err = np.max(np.abs(body_heave.polynomial_values(got, m) - ref))
    assert err < 1e-13 * np.sqrt(np.mean(z ** 2))


def test_road_pieces_does_not_hold_the_run(tmp_path):
    """The road in pieces (default pieces) holds no whole-run column: its traced peak grows
    with the run by < 4 bytes a sample (measured 0.005: the pieces' buffers, a constant,
    outweigh the speeds' steady and standing tests' moments here), the whole run's road by
    > 20 (measured 24: the heave and the two roads). Traced on 200 000 and 400 000 samples
    after a first run (the modules' one-time caches); the run's columns and speeds are the
    caller's, not counted."""
    import tracemalloc

    rows = _rows()
    peaks: dict = {'pieces': [], 'whole': []}
    sizes = (200_000, 200_000, 400_000)
    for m in sizes:
        x, v = _columns(m), _speeds(m, 'steady')
        kept = _in_file(x, tmp_path)
        cols = {j: x[:, k].copy() for k, j in enumerate(rows.profile_columns)}
        del x
        try:
            tracemalloc.start()
            roads = rows.road_pieces(kept, m, DT, 20.0, tmp_path, v=v)
            peaks['pieces'].append(tracemalloc.get_traced_memory()[1])
            tracemalloc.stop()
            roads.close()
            tracemalloc.start()
            road = rows.road(cols, DT, 20.0, None, True, None, v)
            peaks['whole'].append(tracemalloc.get_traced_memory()[1])
            tracemalloc.stop()
            del road
        finally:
            tracemalloc.stop()
            kept.close()
    growth = {k: (p[2] - p[1]) / (sizes[2] - sizes[1]) for k, p in peaks.items()}
    assert growth['pieces'] < 4.0, growth
    assert growth['whole'] > 20.0, growth
