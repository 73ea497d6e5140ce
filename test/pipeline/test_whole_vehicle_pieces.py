"""The whole vehicle's sinks read in pieces (pipeline.whole_vehicle.SpilledEstimate, the
``rows`` of add_diagnostics, report.whole_vehicle's summary and segment table) against the
same sinks on the whole arrays in one piece: the same statuses, numbers and columns, on a
synthetic drive with sensor flags rising and falling, the IMU's pairing codes, gaps, a NaN
load and a truth to compare with. The one-piece forms are checked against the drive's own
numbers by test_whole_vehicle_status.py and test/report/test_whole_vehicle_estimate.py."""
from types import SimpleNamespace

import numpy as np
import pytest

from road_force_estimator.estimation.whole_vehicle import WholeVehicleArrays, take_rows
from road_force_estimator.interfaces import wheel_joints
from road_force_estimator.pipeline.whole_vehicle import SpilledEstimate, add_diagnostics
from road_force_estimator.report.whole_vehicle import segment_table, summarize_estimate

AXLES = ('front', 'drive1', 'drive2', 'trailer1', 'trailer2')
M = 5000                                  # samples at 1 kHz


@pytest.fixture(scope='module')
def wv():
    rng = np.random.default_rng(3)
    t = 1_700_000_000 * 10**9 + np.arange(M, dtype=np.int64) * 1_000_000
    t[3000:] += 400_000_000               # a gap
    w = 2 * len(AXLES)
    load = 4e4 + 3e3 * rng.standard_normal((w, M))
    load[3, 1234] = np.nan
    static = 4e4 + 10.0 * np.cumsum(rng.standard_normal((w, M)), axis=1) * 1e-2
    qs = 0.3 * np.sin(np.arange(M) / 400.0)[None, :] * np.array([[1.0], [1.2], [0.9]])
    flags = np.zeros((12, M), np.int8)
    flags[2, 700:1500] = 1
    flags[2, 2100:2300] = 2
    flags[7, 1999:4100] = 1
    flags[7, 4500:] = 2
    gaps = (np.arange(M) >= 3000).astype(np.int64)
    codes = rng.choice(3, M, p=[0.9, 0.07, 0.03]).astype(np.int8)
    return WholeVehicleArrays(
        t, np.cumsum(np.full(M, 0.02)) - 0.02, np.arange(M) > 300, wheel_joints(AXLES),
        AXLES, ('tractor',) * 3 + ('trailer',) * 2, load, static,
        qs + 0.05 * rng.standard_normal((3, M)), qs, np.zeros(M),
        1e-3 * rng.standard_normal((w, M)), (0,) * 12, tuple(f'c{i}' for i in range(12)),
        np.vstack([qs[0], qs[0]]), gaps, fault_flags=flags, imu_codes=codes,
        rejected={'/vehicle/twist': {'nonfinite': 2}})


def spilled(wv, tmp_path, piece: int) -> SpilledEstimate:
    """``wv`` spilled in pieces of ``piece`` samples (its IMU codes beside them)."""
    out = SpilledEstimate(tmp_path)
    for lo in range(0, M, piece):
        part = take_rows(wv, lo, lo + piece)
        out.add(part)
        out.add_codes(part.imu_codes)
    out.meta = take_rows(wv, 0, 0)
    return out


def test_the_statuses_are_one_pieces(wv, tmp_path):
    second = 1_000_000_000
    stamps = list(range(int(wv.stamps_ns[0]) - second // 2, int(wv.stamps_ns[-1]) + second,
                        second // 3))
    diagnostics = [(s, [{'name': 'front'}]) for s in stamps]
    one = add_diagnostics(diagnostics, wv)
    assert one[0][1] == [{'name': 'front'}]               # before the first sample: none
    values = one[-1][1][1]['values']
    assert values['total.gaps'] == '1'
    assert values['total.stuck.c7'] == '1' and values['total.drift.c7'] == '1'
    assert values['total.stuck.c2'] == '1' and values['total.drift.c2'] == '1'
    assert int(values['total.imu.stale']) == int(np.count_nonzero(wv.imu_codes == 1))
    assert values['total.rejected_by_reader'] == '2'
    for rows in (1, 7, 613):
        assert add_diagnostics(diagnostics, wv, rows) == one, rows
    source = spilled(wv, tmp_path, 333)
    assert add_diagnostics(diagnostics, source, 250) == one
    source.close()


def test_the_report_sums_are_one_pieces(wv, tmp_path):
    truth = SimpleNamespace(stamps_ns=wv.stamps_ns[::2], wheel_names=wheel_joints(AXLES),
                            wheel_load_n=(wv.load_n[:, ::2] + 500.0).T,
                            static_load_n=np.r_[np.full(9, 4e4), np.nan],
                            unit_ltr=np.tile(wv.ltr_quasi_static[1, ::2, None], (1, 4)) + 0.01)
    one = summarize_estimate(wv, truth)
    assert one['converged'] == M - 301
    assert one['tractor_imu']['missing'] == int(np.count_nonzero(wv.imu_codes == 2))
    use = wv.converged
    f = wv.load_n[0, use]
    assert one['wheels'][0]['mean_load_n'] == pytest.approx(np.mean(f), rel=1e-12)
    assert one['wheels'][0]['dlc'] == pytest.approx(np.std(f) / np.mean(f), rel=1e-9)
    assert np.isnan(one['wheels'][3]['max_load_n'])        # the NaN load
    assert one['accuracy']['ltr_trailer_quasi_static_rms_error'] == pytest.approx(0.01)
    source = spilled(wv, tmp_path, 401)
    for rows in (1, 9, 1000):
        got = summarize_estimate(source, truth, rows)
        assert repr(got) == repr(one), rows               # NaN-safe and bit for bit
    start = np.arange(0.0, 95.0, 7.5)
    end = np.r_[start[1:], 99.98]
    table = segment_table(wv, start, end)
    for rows in (1, 9, 1000):
        got = segment_table(source, start, end, rows)
        assert list(got) == list(table)
        for name in table:
            np.testing.assert_array_equal(got[name], table[name], err_msg=name)
    seg = (wv.distance_m >= 15.0) & (wv.distance_m < 22.5)
    np.testing.assert_allclose(table['gross_weight_n'][2], wv.static_n[:, seg].sum(axis=0)
                               .mean(), rtol=1e-12)
    source.close()
