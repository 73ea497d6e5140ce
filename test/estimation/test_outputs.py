"""Named output slots (estimation/outputs.py): every slot named once, rows and arrays agree."""
import numpy as np

from road_force_estimator.estimation.outputs import (
    FIELD_COLUMNS, FLAG_FIELDS, N_COLUMNS, PAIR_FIELDS, SCALAR_FIELDS, Column, Estimate,
    EstimateArrays, arrays_from_table, estimate_from_row, field_columns, hold_rejected)


def test_every_slot_belongs_to_one_field():
    slots = [c for cols in FIELD_COLUMNS.values() for c in cols]
    assert sorted(slots) == list(range(N_COLUMNS)) == [int(c) for c in Column]
    assert set(FIELD_COLUMNS) == set(PAIR_FIELDS) | set(SCALAR_FIELDS)
    assert list(FIELD_COLUMNS) == list(Estimate._fields[1:])
    assert all(len(FIELD_COLUMNS[name]) == 2 for name in PAIR_FIELDS)
    assert set(FLAG_FIELDS) <= set(FIELD_COLUMNS)


def test_row_estimate_and_arrays_agree():
    rng = np.random.default_rng(3)
    rows = rng.standard_normal((5, N_COLUMNS))
    rows[:, [Column.LIFT_OFF1, Column.LIFT_OFF2, Column.CONVERGED]] = [1.0, 0.0, 1.0]
    est = estimate_from_row(7, tuple(rows[2]))
    assert est.stamp_ns == 7
    assert est.wheel_load_n == (rows[2, Column.FN1], rows[2, Column.FN2])
    assert est.ltr == rows[2, Column.LTR]
    arrays = arrays_from_table(rows, np.arange(5), np.ones(5, bool), None)
    assert isinstance(arrays, EstimateArrays)
    for name, cols in FIELD_COLUMNS.items():
        got = getattr(arrays, name)
        want = rows[:, list(cols)] if len(cols) == 2 else rows[:, cols[0]]
        np.testing.assert_array_equal(got, want != 0.0 if name in FLAG_FIELDS else want)
    fields, columns = field_columns(5)
    for j in Column:
        columns[j][:] = rows[:, j]
    for name in FIELD_COLUMNS:
        np.testing.assert_array_equal(fields[name], getattr(arrays, name))


def test_rejected_rows_take_the_last_accepted_one():
    valid = np.array([False, True, False, False, True, False])
    rows, sources = hold_rejected(valid)
    assert rows.tolist() == [1, 2, 3, 4, 5] and sources.tolist() == [1, 1, 1, 4, 4]
