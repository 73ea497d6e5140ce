"""The whole vehicle offline over blocks (estimation/whole_vehicle.py,
WholeVehicleOfflineStream): fed in blocks and handed out in pieces, with a gap; without
windows the one-block estimate's numbers (the articulated smoother over each run,
estimation/articulated.py's estimate_articulated, and each unit's LTR by the core's
recursion over those loads, stepped by the stamps); in small windows within 1e-3 of each
field's RMS of them."""
import pathlib

import numpy as np
import pytest

from road_force_estimator.core.articulated_setup import ArticulatedDrive
from road_force_estimator.core.parameters import load_params_file
from road_force_estimator.core.unit_loads import UnitLoadTransfer
from road_force_estimator.estimation.articulated import estimate_articulated
from road_force_estimator.estimation.whole_vehicle import (
    WholeVehicleEstimator, WholeVehicleOfflineStream, concatenate_arrays)

CONFIG = pathlib.Path(__file__).resolve().parents[2] / 'config' / 'tractor_semitrailer.yaml'
FIELDS = ('load_n', 'static_n', 'ltr', 'ltr_quasi_static', 'lateral_mps2', 'road_m',
          'front_ltr', 'distance_m')


def _vehicle(values: dict):
    base = load_params_file(CONFIG)
    base.update(values)
    return ArticulatedDrive.from_values(base).vehicle


@pytest.fixture(scope='module')
def drive(articulated_c):
    """8 s of class C at 20 m/s, 1 kHz, 10 um (conftest), with 0.2 s lost at 5 s."""
    d, tr, stamps, y = articulated_c
    keep = (tr.t_s < 5.0) | (tr.t_s >= 5.2)
    stamps = stamps[keep]
    return d.vehicle, stamps, y[keep]


def streamed(vehicle, stamps, y, block: int = 777, **kwargs) -> list:
    stream = WholeVehicleOfflineStream(vehicle, **kwargs)
    for a in range(0, stamps.size, block):
        assert stream.feed(stamps[a:a + block], y[a:a + block], 20.0) == []
    assert stream.fed == stamps.size
    return list(stream.finish())


@pytest.mark.parametrize('block', [777, 1000])     # 1000: a block starts at the gap
def test_blocks_without_windows_are_the_one_block_estimate(drive, block):
    vehicle, stamps, y = drive
    pieces = streamed(vehicle, stamps, y, block, window=(10 ** 9, 0), piece_rows=1000)
    assert len(pieces) >= 8 and max(len(p.stamps_ns) for p in pieces) <= 1000
    got = concatenate_arrays(pieces)
    one = estimate_articulated(vehicle, stamps, y, 20.0, offline=True)
    np.testing.assert_array_equal(got.stamps_ns, stamps)
    for name in ('load_n', 'lateral_mps2', 'road_m', 'converged', 'distance_m'):
        np.testing.assert_array_equal(getattr(got, name), getattr(one, name), err_msg=name)
    assert got.innovations_gated == one.innovations_gated and one.gaps == 1
    assert got.gap_count == 1 and got.gaps[0] == 0
    static = WholeVehicleEstimator(vehicle).static_n
    np.testing.assert_array_equal(got.static_n, np.repeat(np.array(static)[:, None],
                                                          stamps.size, axis=1))
    rec = UnitLoadTransfer([a.body for a in vehicle.axles], np.reshape(static, (-1, 2)), 1e-3)
    steps = np.concatenate([[0.0], np.diff(stamps) * 1e-9])     # the gap's step as it is
    true = np.array([rec.update(f, dt) for f, dt in zip(one.load_n.T.tolist(),
                                                         steps.tolist())])
    np.testing.assert_array_equal(got.ltr, true[:, 0::2].T)
    np.testing.assert_array_equal(got.ltr_quasi_static, true[:, 1::2].T)


def test_zero_load_static_loads_over_blocks_are_the_per_sample_tracker(drive):
    """Zero-load readings: the static-load tracker run block by block (a gap in them) gives
    the per-sample path's static loads bit for bit."""
    _, stamps, y = drive
    vehicle = _vehicle({'vehicle.deflection_reference': 'zero_load'})
    got = concatenate_arrays(streamed(vehicle, stamps, y, block=1001, window=(10 ** 9, 0)))
    est = WholeVehicleEstimator(vehicle)
    statics = []
    for s, yi in zip(stamps.tolist(), y.tolist()):
        statics += [x.static_n for x in est.step(s, yi, 20.0)]
    np.testing.assert_array_equal(got.static_n, np.array(statics).T)
    assert got.gap_count == est.online.gaps == 1


def test_small_windows_are_within_1e_3_of_each_field_s_rms(drive):
    """Windows of 2 s with 1 s of overlap (the stream's own: 131 s and 10 s): each field
    within 1e-3 of its RMS of the one-block estimate (measured 3.8e-4, the loads), the road
    the same bits (its profile pass is over the whole run)."""
    vehicle, stamps, y = drive
    one = concatenate_arrays(streamed(vehicle, stamps, y, block=stamps.size, eager=False))
    got = concatenate_arrays(streamed(vehicle, stamps, y, window=(2000, 1000),
                                      piece_rows=999))
    np.testing.assert_array_equal(got.road_m, one.road_m)
    for name in FIELDS:
        a, b = np.asarray(getattr(got, name), float), np.asarray(getattr(one, name), float)
        rms = np.sqrt(np.mean((b - b.mean(axis=-1, keepdims=True)) ** 2, axis=-1,
                              keepdims=True))
        assert np.all(np.abs(a - b) <= 1e-3 * np.maximum(rms, 1e-12)), name
    assert not np.array_equal(got.load_n, one.load_n)      # (the windows are there)
    np.testing.assert_array_equal(got.gaps, one.gaps)


def test_estimate_whole_vehicle_with_windows_is_the_eager_stream(drive, monkeypatch):
    """``estimate_whole_vehicle(..., offline=True, windows=True)`` (what estimate_bag runs
    offline on an articulated drive, pipeline/plan.py's ``whole_vehicle_windows``): the
    stream's own windows (made 2 s and 1 s here) over the drive, each field within 1e-3 of its
    RMS of the one-block estimate, the road the same bits; the sensor flags the same."""
    from road_force_estimator.estimation import whole_vehicle
    vehicle, stamps, y = drive
    one = whole_vehicle.estimate_whole_vehicle(vehicle, stamps, y, 20.0, offline=True)
    monkeypatch.setattr(whole_vehicle, 'STREAM_WINDOW_SAMPLES', 2000)
    monkeypatch.setattr(whole_vehicle, 'STREAM_OVERLAP_S', 1.0)
    got = whole_vehicle.estimate_whole_vehicle(vehicle, stamps, y, 20.0, offline=True,
                                               windows=True)
    np.testing.assert_array_equal(got.road_m, one.road_m)
    np.testing.assert_array_equal(got.fault_flags, one.fault_flags)
    for name in FIELDS:
        a, b = np.asarray(getattr(got, name), float), np.asarray(getattr(one, name), float)
        rms = np.sqrt(np.mean((b - b.mean(axis=-1, keepdims=True)) ** 2, axis=-1,
                              keepdims=True))
        assert np.all(np.abs(a - b) <= 1e-3 * np.maximum(rms, 1e-12)), name
    assert not np.array_equal(got.load_n, one.load_n)      # (the windows are there)


@pytest.mark.parametrize('chunk, piece', [(None, None), (1000, 777)])
def test_spilled_the_windows_are_the_same_bits(drive, tmp_path, monkeypatch, chunk, piece):
    """With ``spill`` (estimate_bag offline in pieces) the readings (the run's statistics
    taken from them in pieces), the sensor flags, the static loads, a windowed run's profile
    pass columns and its road (built over them in pieces: the double integral's forward pass
    in order, its backward pass over the pieces reversed) go to temporary files there
    (core.spill): every field the same bits as without, in 2 s windows with 1 s of overlap
    and zero-load readings; every file closed after. ``chunk``: the smoother's chunks (its
    profile pass's written from the end) and the statistics' pieces, ``piece``: the road's
    pieces (None: the module's, one piece here)."""
    from road_force_estimator.core import spill as spill_module
    from road_force_estimator.estimation.models import articulated_rows
    from road_force_estimator.estimation.observer import schedule
    from road_force_estimator.estimation.smoothing import smoother

    if chunk is not None:
        monkeypatch.setattr(smoother, '_SMOOTH_CHUNK', chunk)
        monkeypatch.setattr(schedule, 'PIECE_ROWS', chunk)
        monkeypatch.setattr(articulated_rows, 'ROAD_PIECE_ROWS', piece)

    opened = []
    init = spill_module.SpillColumn.__init__

    def counted(self, *args, **kwargs):
        init(self, *args, **kwargs)
        opened.append(self)

    _, stamps, y = drive
    vehicle = _vehicle({'vehicle.deflection_reference': 'zero_load'})
    one = concatenate_arrays(streamed(vehicle, stamps, y, window=(2000, 1000)))
    monkeypatch.setattr(spill_module.SpillColumn, '__init__', counted)
    got = concatenate_arrays(streamed(vehicle, stamps, y, window=(2000, 1000),
                                      spill=tmp_path))
    # the readings, sensor flags, static loads; the first run's profile pass columns, its
    # integral's forward pass and its roads (the run after the gap, 2.8 s, is one window)
    assert len(opened) == 6 and all(c._file.closed for c in opened)
    for name in FIELDS + ('converged', 'gaps', 'fault_flags'):
        np.testing.assert_array_equal(getattr(got, name), getattr(one, name), err_msg=name)
