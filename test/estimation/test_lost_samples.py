"""A stream that lost samples at random (issue 28): the model observer stays bounded, as good
as with every sample but for the samples it lacks.

When an observer falls behind, the samples it takes have steps of 1 to 25 sample periods.
After its first block of statistics the model observer filters that block again with the
newly estimated noise; it did so with the gains of one step length for steps of every length,
which is unstable: on this drive four of six random thirds drove the profile to between 5 m
and 5e17 m and the loads to 1e11 N. Each step now uses the gains of its own length. The
reference is the plant's own load (core.plant) and the estimate of the drive with every
sample.
"""
import numpy as np
import pytest

from road_force_estimator.estimation import estimate_batch
from model_observer_data import SPEED, load_pct, to_stamps


@pytest.fixture(scope='module')
def full(drive, noisy):
    q, phi = noisy                             # 10 um, 0.1 mrad of noise
    est = estimate_batch(to_stamps(drive.t_s), q, phi, SPEED)
    return est, load_pct(est.wheel_load_n, drive, drive.t_s >= 2.0)


@pytest.mark.parametrize('seed', range(6))
def test_a_third_of_the_samples_kept_at_random(drive, noisy, full, seed):
    q, phi = noisy
    stamps = to_stamps(drive.t_s)
    keep = np.random.default_rng(seed).random(stamps.size) < 1 / 3
    steps = np.diff(stamps[keep]) // 1_000_000
    assert steps.max() >= 15 and (steps == 1).mean() > 0.2           # random, not regular
    est = estimate_batch(stamps[keep], q[keep], phi[keep], SPEED)
    assert est.status.resets == 0 and est.valid.all()
    everything, error_all = full
    # bounded: the profile as with every sample (its start-up included), the loads near the
    # plant's
    assert np.abs(est.road_m).max() < 1.5 * np.abs(everything.road_m).max()
    assert np.abs(est.wheel_load_n).max() < 1.5 * np.abs(drive.wheel_load_n).max()

    class Kept:
        wheel_load_n = drive.wheel_load_n[keep]
    # the load error after 2 s: 20-21 % of the dynamic-load RMS against 16 % with every sample
    assert load_pct(est.wheel_load_n, Kept, drive.t_s[keep] >= 2.0) < 1.5 * error_all
