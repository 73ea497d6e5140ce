"""Gaps in a whole-vehicle drive (estimation/whole_vehicle.py, estimation/articulated.py):
0.2 s of lost samples restart the estimate (counted), online and offline, and its error
against the plant's truth is back to the gapless drive's within 0.3 s of the gap; the
samples before the gap keep theirs (with a latency or offline, the gap taken as one long
step would smear it over them)."""
import numpy as np
import pytest

from road_force_estimator.core.parameters import ObserverParameters
from road_force_estimator.estimation.acceptance import StepGaps, gap_samples
from road_force_estimator.estimation.whole_vehicle import (
    WholeVehicleEstimator, estimate_whole_vehicle)

DURATION_S = 8.0
GAP_S = (4.0, 4.2)           # the samples lost
BACK_S = 0.3                 # the estimate is judged again from this long after the gap


@pytest.fixture(scope='module')
def drive(articulated_c):
    """8 s of class C at 20 m/s, 1 kHz, 10 um of deflection noise (conftest); ``keep`` drops
    0.2 s."""
    d, tr, stamps, y = articulated_c
    keep = (tr.t_s < GAP_S[0]) | (tr.t_s >= GAP_S[1])
    return d.vehicle, tr, stamps, y, keep


def worst_error(est, true: np.ndarray, t: np.ndarray, lo: float, hi: float) -> float:
    """The worst wheel's RMS load error over lo <= t < hi, % of its true dynamic load's RMS."""
    sel = (t >= lo) & (t < hi)
    e = est.load_n.T[sel] - true[sel]
    dyn = true[sel] - true[sel].mean(axis=0)
    return float(np.max(np.sqrt(np.mean(e ** 2, axis=0) / np.mean(dyn ** 2, axis=0)))) * 100


@pytest.mark.parametrize('mode', ['causal', 'latency', 'offline'])
def test_a_gap_restarts_the_estimate_and_it_is_back_within_0_3_s(drive, mode):
    """Within 1.1 x the gapless drive's worst-wheel error from 2 s to 50 ms before the gap
    (offline, the run's end has no future there: its last 50 ms 20.8 % against 16.1) and
    from 0.3 s after it to the end (offline the first 0.1 s after it: 85 % against 5.7,
    then 6.36 against 6.36)."""
    vehicle, tr, stamps, y, keep = drive
    obs = ObserverParameters(latency_s=0.01 if mode == 'latency' else 0.0)
    offline = mode == 'offline'
    full = estimate_whole_vehicle(vehicle, stamps, y, 20.0, observer=obs, offline=offline)
    gap = estimate_whole_vehicle(vehicle, stamps[keep], y[keep], 20.0, observer=obs,
                                 offline=offline)
    assert full.gap_count == 0 and gap.gap_count == 1
    t = tr.t_s[keep]
    after = np.flatnonzero(t >= GAP_S[1])[0]
    np.testing.assert_array_equal(gap.gaps, (np.arange(t.size) >= after).astype(int))
    for lo, hi in ((2.0, GAP_S[0] - 0.05), (GAP_S[1] + BACK_S, DURATION_S)):
        ref = worst_error(full, tr.wheel_load_n, tr.t_s, lo, hi)
        got = worst_error(gap, tr.wheel_load_n[keep], t, lo, hi)
        assert got <= 1.1 * ref, (lo, hi, got, ref)
    # the distance goes on over the gap: |v| times the step
    np.testing.assert_allclose(gap.distance_m[after] - gap.distance_m[after - 1],
                               20.0 * (t[after] - t[after - 1]), rtol=1e-9)


def test_the_gap_taken_as_one_step_smears_the_fixed_lag(drive):
    """The reason for the restart: with 10 ms of latency and the gap taken as one long step
    (a threshold above it), the fixed lag smears the step over the samples before it (their
    worst wheel's error > 50 %)."""
    vehicle, tr, stamps, y, keep = drive
    obs = ObserverParameters(latency_s=0.01)
    one = estimate_whole_vehicle(vehicle, stamps[keep], y[keep], 20.0, observer=obs,
                                 gap_threshold_s=10.0)
    assert one.gap_count == 0
    t = tr.t_s[keep]
    assert worst_error(one, tr.wheel_load_n[keep], t, GAP_S[0] - 0.01, GAP_S[0]) > 50.0


def test_per_sample_gives_the_drive_bits_over_a_gap(drive):
    """The node's path (one sample at a time) and the drive's give the same bits and counts
    over the gap, zero-load readings (the static tracker over the gap) and a latency."""
    vehicle, _, stamps, y, keep = drive
    m = np.flatnonzero(keep)[4500]
    sel = np.flatnonzero(keep[:m])
    obs = ObserverParameters(latency_s=0.01)
    batch = estimate_whole_vehicle(vehicle, stamps[sel], y[sel], 20.0, observer=obs)
    est = WholeVehicleEstimator(vehicle, obs)
    samples = []
    for s, yi in zip(stamps[sel].tolist(), y[sel].tolist()):
        samples += est.step(s, yi, 20.0)
    samples += est.finish()
    assert [s.stamp_ns for s in samples] == stamps[sel].tolist()
    np.testing.assert_array_equal(np.array([s.load_n for s in samples]).T, batch.load_n)
    assert [s.gaps for s in samples] == batch.gaps.tolist()
    assert samples[-1].gaps == 1 and est.online.gaps == 1


def test_the_per_sample_rule_finds_the_drive_rule_s_gaps():
    """:class:`StepGaps` one step at a time and :func:`gap_samples` over the steps agree on
    steps of 1 ms with jitter, lost stretches of 0.05 to 2 s and a rate that drops to 20 Hz."""
    rng = np.random.default_rng(3)
    dts = np.full(20000, 1e-3) * (1.0 + 0.05 * rng.standard_normal(20000))
    dts[rng.choice(20000, 30, replace=False)] = rng.uniform(0.05, 2.0, 30)
    dts[15000:] = 0.05
    rule = StepGaps(0.1)
    per_sample = [i for i, dt in enumerate(dts.tolist()) if rule.take(dt)]
    assert per_sample == gap_samples(dts, 0.1).tolist()
    assert 10 < len(per_sample) < 31 and 15000 not in per_sample
