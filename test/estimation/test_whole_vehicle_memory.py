"""estimate_whole_vehicle online in bounded pieces (estimation/whole_vehicle.py, issue 32
"memory stays bounded"): the samples turned into arrays a chunk at a time (no per-sample
object held for the drive). The reference is independent of that gathering: the estimator's
own samples stepped one by one (the node's numbers)."""
import numpy as np
import pytest

from road_force_estimator.core.parameters import ObserverParameters
from road_force_estimator.estimation.whole_vehicle import (
    WholeVehicleEstimator, estimate_whole_vehicle)


@pytest.fixture(scope='module')
def drive(articulated_c):
    """The conftest's 8 s of class C at 20 m/s, 1 kHz, with 0.2 s lost at 5 s (a gap)."""
    d, tr, stamps, y = articulated_c
    keep = (tr.t_s < 5.0) | (tr.t_s >= 5.2)
    return d.vehicle, stamps[keep], y[keep]


def test_online_in_chunks_is_the_estimator_sample_by_sample(drive):
    """Chunks of 700 samples (12 of them, one across the gap): every field the bits of the
    estimator's own samples, the fused points too."""
    vehicle, stamps, y = drive
    obs = ObserverParameters(latency_s=0.01)
    got = estimate_whole_vehicle(vehicle, stamps, y, 20.0, observer=obs, chunk_rows=700)
    est = WholeVehicleEstimator(vehicle, obs)
    samples = []
    for s, row in zip(stamps.tolist(), y):
        samples += est.step(s, row, 20.0)
    samples += est.finish()
    assert len(samples) == stamps.size == got.stamps_ns.size
    np.testing.assert_array_equal(got.stamps_ns, [s.stamp_ns for s in samples])
    np.testing.assert_array_equal(got.distance_m, [s.distance_m for s in samples])
    np.testing.assert_array_equal(got.converged, [s.converged for s in samples])
    np.testing.assert_array_equal(got.gaps, [s.gaps for s in samples])
    assert got.gap_count == 1
    for name in ('load_n', 'static_n', 'ltr', 'ltr_quasi_static', 'lateral_mps2', 'road_m',
                 'front_ltr', 'sensor_flags'):
        want = np.array([getattr(s, name) for s in samples]).T
        field = 'fault_flags' if name == 'sensor_flags' else name
        np.testing.assert_array_equal(getattr(got, field), want, err_msg=name)
        assert getattr(got, field).flags.c_contiguous, name
    np.testing.assert_array_equal(got.ltr_predicted,
                                  np.array([s.ltr_predicted for s in samples]).T)
    points = [p for s in samples for p in s.fused]
    assert len(points) > 100
    np.testing.assert_array_equal(got.fused.stamps_ns, [p[0] for p in points])
    np.testing.assert_array_equal(
        np.column_stack([got.fused.distance_m, got.fused.left_m, got.fused.right_m]),
        [p[1:] for p in points])
    fits = [(s.stamp_ns, s.axle_fit) for s in samples if s.axle_fit is not None]
    assert got.axle_fits == tuple(fits)         # none yet on 8 s: too little distance
    assert got.axle_fit == (fits[-1][1] if fits else None)
    assert got.innovations_gated == samples[-1].innovations_gated
    assert got.faults == est.faults.counts()
