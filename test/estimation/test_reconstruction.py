"""MODEL.md steps 5-9 (estimation/reconstruction.py): per sample and over arrays the same
numbers; one lift-off threshold and one LTR floor."""
import math

import numpy as np
import pytest

from road_force_estimator.core.parameters import VehicleParameters
from road_force_estimator.estimation.outputs import Column, field_columns
from road_force_estimator.estimation.reconstruction import (
    load_transfer_ratio, load_transfer_ratios,
    LIFT_OFF_FRACTION, LTR_FLOOR_FRACTION, Reconstruction, distance_m, tire_decay,
    tire_deflections)

VEHICLE = VehicleParameters()


def _motions(rng, m):
    scale = {'q': 0.02, 'dq': 0.2, 'ddq': 5.0, 'phi': 0.02, 'dphi': 0.1, 'ddphi': 2.0,
             'zs': 0.01, 'dzs': 0.1, 'ddzs': 3.0, 'ddzu': 30.0, 'w': 0.01, 'df': 3e4,
             'fb': 2e4}
    return {k: rng.standard_normal((m, 2) if k in ('q', 'dq', 'ddq', 'ddzu', 'w', 'df', 'fb')
                                   else m) * s for k, s in scale.items()}


def _times(m):
    return np.cumsum(np.r_[0.0, np.full(m - 1, 1e-3)])


def _rows(rec, mo, conv):
    out = []
    steps = np.r_[0.0, np.diff(_times(mo['phi'].size))]
    rec.restart()
    for k in range(mo['phi'].size):
        g = {name: a[k].tolist() for name, a in mo.items()}
        out.append(rec.row(1.5, *g['q'], *g['dq'], *g['ddq'], g['phi'], g['dphi'], g['ddphi'],
                           g['zs'], g['dzs'], g['ddzs'], *g['ddzu'], *g['w'], *g['df'],
                           *g['fb'], conv, float(steps[k])))
    return np.array(out, dtype=float)


def _columns(rec, mo, heave):
    fields, cols = field_columns(mo['phi'].size)

    def pair(a):
        return a[:, 0], a[:, 1]
    rec.columns(cols, pair(mo['q']), pair(mo['dq']), pair(mo['ddq']), mo['phi'], mo['dphi'],
                mo['ddphi'], mo['ddzs'], pair(mo['ddzu']), pair(mo['w']), pair(mo['df']),
                pair(mo['fb']), (mo['zs'], mo['dzs']) if heave else None)
    if not heave:
        rec.add_heave(cols, mo['zs'], mo['dzs'])
    rec.add_quasi_static(cols, _times(mo['phi'].size))
    return np.column_stack([np.asarray(c, dtype=float) for c in cols])


def test_arrays_are_the_per_sample_rows():
    rec = Reconstruction(VEHICLE)
    mo = _motions(np.random.default_rng(1), 200)
    rows = _rows(rec, mo, True)
    table = _columns(rec, mo, heave=True)
    skip = [Column.DISTANCE, Column.CONVERGED]
    np.testing.assert_array_equal(np.delete(table, skip, axis=1), np.delete(rows, skip, axis=1))
    # the smoother's order (body heave added after the run): the same to rounding
    later = _columns(rec, mo, heave=False)
    np.testing.assert_allclose(np.delete(later, skip, axis=1), np.delete(rows, skip, axis=1),
                               rtol=1e-12, atol=1e-15)


def test_identities_of_the_row():
    rec = Reconstruction(VEHICLE)
    mo = _motions(np.random.default_rng(2), 50)
    rows = _rows(rec, mo, False)
    s = VEHICLE.half_track_m
    fc = np.array(VEHICLE.static_load_n)
    # F_n = max(0, F_c + dF): a tire cannot pull (issue 18)
    np.testing.assert_array_equal(rows[:, [Column.FN1, Column.FN2]],
                                  np.maximum(fc + mo['df'], 0.0))
    zu1 = mo['zs'] + s * np.sin(mo['phi']) - mo['q'][:, 0]
    np.testing.assert_allclose(rows[:, Column.ZU1], zu1, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(rows[:, Column.U1] - rows[:, Column.ZU1], mo['w'][:, 0],
                               rtol=1e-9, atol=1e-15)
    # step 9 with the gravity moment: r = I_x ddphi - s cos(phi) (F_b1 - F_b2) - M g h sin(phi)
    mgh = VEHICLE.sprung_mass_kg * 9.80665 * VEHICLE.cg_height_m
    res = (VEHICLE.roll_inertia_kgm2 * mo['ddphi']
           - s * np.cos(mo['phi']) * (mo['fb'][:, 0] - mo['fb'][:, 1]) - mgh * np.sin(mo['phi']))
    np.testing.assert_allclose(rows[:, Column.RESIDUAL], res, rtol=1e-12, atol=1e-9)


def test_one_lift_off_threshold_and_one_ltr_floor():
    rec = Reconstruction(VEHICLE)
    fc1, fc2 = VEHICLE.static_load_n
    assert rec.lift_off_n == (LIFT_OFF_FRACTION * fc1, LIFT_OFF_FRACTION * fc2)
    assert rec.ltr_floor_n == LTR_FLOOR_FRACTION * (fc1 + fc2)
    zero = (0.0,) * 2
    # left load 1 N below the threshold (lifts), right 1 N above it (does not)
    row = rec.row(0.0, *zero, *zero, *zero, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, *zero, *zero,
                  LIFT_OFF_FRACTION * fc1 - fc1 - 1.0, LIFT_OFF_FRACTION * fc2 - fc2 + 1.0,
                  *zero, True)
    assert row[Column.LIFT_OFF1] and not row[Column.LIFT_OFF2]
    # both wheels off: the floored denominator keeps the LTR finite (0)
    row = rec.row(0.0, *zero, *zero, *zero, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, *zero, *zero,
                  -2.0 * fc1, -2.0 * fc2, *zero, True)
    assert row[Column.LTR] == 0.0 and math.isfinite(row[Column.LTR])


def test_distance_is_the_trapezoidal_sum():
    steps = np.array([0.1, 0.2, 0.1])
    v = np.array([10.0, 12.0, 12.0, 8.0])
    np.testing.assert_allclose(distance_m(steps, v), [0.0, 1.1, 3.5, 4.5], rtol=1e-15)
    assert distance_m(np.zeros(0), np.array([3.0])).tolist() == [0.0]


def test_tire_lag_per_sample_and_over_arrays():
    rng = np.random.default_rng(4)
    kt = np.array(VEHICLE.tire_stiffness_npm)
    ct = np.array([1500.0, 0.0])
    for t in (np.arange(300) * 1e-3, np.cumsum(rng.uniform(0.5e-3, 1.5e-3, 300))):
        df = 1e4 * rng.standard_normal((300, 2))
        w = tire_deflections(df, t, kt, ct)
        ref = [df[0, 0] / kt[0]]
        for k in range(1, 300):
            e = tire_decay(t[k] - t[k - 1], kt[0], ct[0])
            ref.append(e * ref[-1] + (1.0 - e) * df[k, 0] / kt[0])
        np.testing.assert_allclose(w[:, 0], ref, rtol=1e-9, atol=1e-15)
        np.testing.assert_array_equal(w[:, 1], df[:, 1] / kt[1])   # no damping: dF / kt
    assert tire_decay(1e-3, 1e6, 0.0) == 0.0


def test_a_tire_cannot_pull():
    """An estimate below zero is published as 0 N (the unclipped value stays in dF), per
    sample and over arrays; the LTR of those samples is the rollover limit."""
    rec = Reconstruction(VEHICLE)
    fc1, fc2 = VEHICLE.static_load_n
    zero = (0.0,) * 2
    row = rec.row(0.0, *zero, *zero, *zero, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, *zero, *zero,
                  -fc1 - 4592.0, 1000.0, *zero, True)
    assert row[Column.FN1] == 0.0 and row[Column.FN2] == fc2 + 1000.0
    assert row[Column.DF1] == -fc1 - 4592.0 and row[Column.LTR] == 1.0
    assert row[Column.LIFT_OFF1] and not row[Column.LIFT_OFF2]
    df = np.array([[-fc1 - 4592.0, 1000.0], [-0.5 * fc1, -fc2 - 1.0], [0.0, 0.0]])
    out = [np.zeros(3) for _ in range(len(Column))]
    z3 = np.zeros(3)
    pair = (z3, z3)
    rec.columns(out, pair, pair, pair, z3, z3, z3, z3, pair, pair, (df[:, 0], df[:, 1]),
                pair, (z3, z3))
    np.testing.assert_array_equal(out[Column.FN1], [0.0, 0.5 * fc1, fc1])
    np.testing.assert_array_equal(out[Column.FN2], [fc2 + 1000.0, 0.0, fc2])
    np.testing.assert_array_equal(out[Column.LTR], [1.0, -1.0, (fc2 - fc1) / (fc1 + fc2)])


def test_quasi_static_ltr_is_the_low_passed_loads_ratio():
    # Step 8: the ratio of the loads (clipped at zero) through two first-order lags in
    # cascade, -3 dB at observer.rollover_cutoff_frequency (written here).
    rec = Reconstruction(VEHICLE, rollover_cutoff_hz=2.0)
    fc1, fc2 = VEHICLE.static_load_n
    t = np.arange(4000) * 1e-3
    rng = np.random.default_rng(4)
    fn1 = fc1 - 8000.0 * (t > 0.5) + 15000.0 * np.sin(2 * np.pi * 9.0 * t) + rng.normal(0, 2e3,
                                                                                      t.size)
    fn2 = fc2 + 8000.0 * (t > 0.5) - 15000.0 * np.sin(2 * np.pi * 9.0 * t)
    rec.restart()
    got = np.array([rec.quasi_static_ltr(a, b, d) for a, b, d in
                    zip(fn1, fn2, np.r_[0.0, np.diff(t)])])
    rate = 2 * np.pi * 2.0 / math.sqrt(math.sqrt(2) - 1)
    e = math.exp(-1e-3 * rate)
    ref = []
    st = None
    for a, b in zip(np.maximum(fn1, 0), np.maximum(fn2, 0)):
        if st is None:
            st = [a, a, b, b]
        else:
            st[0] = e * st[0] + (1 - e) * a
            st[1] = e * st[1] + (1 - e) * st[0]
            st[2] = e * st[2] + (1 - e) * b
            st[3] = e * st[3] + (1 - e) * st[2]
        ref.append((st[3] - st[1]) / (st[1] + st[3]))
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-12)
    # the 9 Hz wheel hop (LTR +-0.45 instantaneous) is damped ~9-fold (after the start's
    # transient); the step passes
    inst = (fn2 - fn1) / (fn1 + fn2)
    assert np.abs(inst).max() > 0.4
    assert np.abs(got[(t > 0.2) & (t < 0.5)]).max() < 0.07
    assert got[-1] == pytest.approx(16000.0 / (fc1 + fc2), abs=0.03)
    # -3 dB at the cutoff: the low-pass of a 2 Hz sine
    rec.restart()
    sine = 0.1 * np.sin(2 * np.pi * 2.0 * t)
    out = np.array([rec.quasi_static_ltr(fc1 * (1 - a), fc2 * (1 + a), 1e-3) for a in sine])
    assert np.abs(out[t > 2.0]).max() == pytest.approx(0.1 / math.sqrt(2), rel=0.01)


def test_batch_quasi_static_ltr_in_chunks_is_the_per_sample_one():
    """add_quasi_static runs the per-sample step in chunks: the same numbers across chunk
    edges, with uneven steps."""
    from road_force_estimator.estimation.reconstruction import QUASI_STATIC_CHUNK
    rng = np.random.default_rng(4)
    n = 2 * QUASI_STATIC_CHUNK + 17
    rec = Reconstruction(VehicleParameters(), 2.0)
    cols = field_columns(n)[1]
    cols[Column.FN1][:] = 2e4 + 3e3 * rng.standard_normal(n)
    cols[Column.FN2][:] = 2e4 + 3e3 * rng.standard_normal(n)
    t = np.cumsum(rng.uniform(0.9e-3, 1.1e-3, n))
    rec.add_quasi_static(cols, t)
    rec.restart()
    steps = np.concatenate([[0.0], np.diff(t)])
    per_sample = [rec.quasi_static_ltr(a, b, d) for a, b, d in
                  zip(cols[Column.FN1], cols[Column.FN2], steps)]
    np.testing.assert_array_equal(cols[Column.LTR_QUASI_STATIC], per_sample)


# Load transfer ratio: hand-computed values, the lift-off limits, scalar = array path.
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
