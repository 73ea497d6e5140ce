"""The rejection and gap rules (estimation/acceptance.py): one sample at a time, and over
arrays exactly as per sample."""
import math

import numpy as np

from road_force_estimator.core.parameters import ObserverParameters
from road_force_estimator.estimation import Estimator, EstimatorStatus
from model_observer_data import VEHICLE
from road_force_estimator.estimation.acceptance import (
    BEHIND_SAMPLES, SampleGate, accept_arrays)


class TestAcceptance:
    def test_acceptance_rules_are_the_estimators_on_irregular_steps(self):
        # many steps around the gap threshold and ten typical steps: the offline rules must
        # accept, reject and restart exactly where the per-sample estimator does
        rng = np.random.default_rng(5)
        n = 3000
        dt = np.where(rng.random(n) < 0.03, rng.uniform(0.05, 1.5, n),
                      rng.uniform(0.002, 0.03, n))
        st = np.cumsum(np.round(dt * 1e9).astype(np.int64)) + 1_700_000_000 * 10**9
        st[[50, 51, 900]] = st[[49, 49, 800]]                  # duplicates, backwards
        q = 1e-3 * rng.standard_normal((n, 2))
        phi = 1e-3 * rng.standard_normal(n)
        q[70, 1] = np.nan
        phi[71] = 3.0
        v = np.full(n, 12.0)
        valid, restart, _, counts = accept_arrays(st, q, phi, v, 0.1)
        est = Estimator(VEHICLE, ObserverParameters(discretization='implicit'))
        accepted, restarts = [], []
        for k in range(n):
            before = (est.status.accepted, est.status.resets)
            est.update(int(st[k]), q[k], float(phi[k]), float(v[k]))
            accepted.append(est.status.accepted > before[0])
            restarts.append(est.status.resets > before[1])
        np.testing.assert_array_equal(valid, accepted)
        restarts[int(np.flatnonzero(valid)[0])] = True          # the first sample starts
        np.testing.assert_array_equal(restart, restarts)
        for name, value in counts.items():
            assert getattr(est.status, name) == value, name
        # 3 duplicates / backwards, and the sample after a jump (held: the next decides)
        assert counts['gaps'] > 20 and counts['rejected_time'] > counts['gaps']



class TestSampleGate:
    def test_rules_one_sample_at_a_time(self):
        status = EstimatorStatus()
        gate = SampleGate(0.1, status)
        assert gate.check_pair((1.0, 2.0, 3.0)) is None and status.rejected_nonfinite == 1
        assert gate.check(0, 0.0, 0.0, 0.0, 10.0) == (0, 0.0, 0.0, 0.0, 10.0, 0.0, True, 0.0)
        gate.commit(0, 0.0)
        sample = gate.check(1_000_000, 0.0, 0.0, 0.0, 10.0)
        assert sample[5:] == (1e-3, False, 1e-3)           # the first step taken as it is
        gate.commit(1_000_000, sample[7])
        assert gate.check(2_000_000, 0.0, 0.0, 0.0, 10.0)[7] == 1e-3
        assert gate.check(1_000_000, 0.0, 0.0, 0.0, 10.0) is None     # not later
        assert gate.check(2_000_000, 1.5, 0.0, 0.0, 10.0) is None     # |q| > 1 m
        assert gate.check(2_000_000, math.nan, 0.0, 0.0, 10.0) is None
        counts = (status.rejected_time, status.rejected_range, status.rejected_nonfinite)
        assert counts == (1, 1, 2)
        # a step of 0.2 s > max(0.1 s, 10 x 1 ms): a jump, held (the next sample decides)...
        assert gate.check(201_000_000, 0.0, 0.0, 0.0, 10.0) is None
        assert status.rejected_time == 2 and gate.held == 201_000_000
        # ... it continues from there: a gap, the typical step restarts
        assert gate.check(202_000_000, 0.0, 0.0, 0.0, 10.0)[5:] == (0.201, True, 0.0)
        assert status.gaps == status.resets == 1 and gate.held is None


def _per_sample(st, q, phi, v):
    """The accepted mask and the estimates of the per-sample estimator."""
    est = Estimator(VEHICLE, ObserverParameters(discretization='implicit'))
    accepted, out = [], []
    for k in range(st.size):
        n = est.status.accepted
        e = est.update(int(st[k]), q[k], float(phi[k]), float(v[k]))
        accepted.append(est.status.accepted > n)
        if e is not None:
            out.append(e.wheel_load_n)
    return np.array(accepted), np.array(out), est.status


class TestOutlierStamps:
    """Issue 28: a few outlier stamps (some in the future, some in the past) lost most of a
    drive: the rest was rejected as backwards. Any number of them costs those samples only."""

    def drive(self, n=4000, seed=2):
        rng = np.random.default_rng(seed)
        st = 1_700_000_000 * 10**9 + np.arange(n, dtype=np.int64) * 1_000_000      # 1 kHz
        q = 1e-3 * rng.standard_normal((n, 2))
        phi = 1e-3 * rng.standard_normal(n)
        return st, q, phi, np.full(n, 15.0)

    def test_any_number_of_lone_outliers_cost_those_samples_only(self):
        st, q, phi, v = self.drive()
        bad = st.copy()
        outliers = np.array([300, 301 + 9, 777, 1200, 1900, 2500, 2501 + 40, 3333, 3600])
        offsets = np.array([30, 5, 3600 * 24 * 365, -2, 59, -7200, 0.5, 61, -1e-3]) * 1e9
        bad[outliers] = st[outliers] + offsets.astype(np.int64)
        accepted, loads, status = _per_sample(bad, q, phi, v)
        expect = np.ones(st.size, bool)
        expect[outliers] = False
        np.testing.assert_array_equal(accepted, expect)
        assert status.gaps == status.resets == 0 and status.rejected_time == outliers.size
        # the very estimates of the drive without those samples
        _, clean, _ = _per_sample(st[expect], q[expect], phi[expect], v[expect])
        np.testing.assert_array_equal(loads, clean)
        valid, restart, _, counts = accept_arrays(bad, q, phi, v, 0.1)
        np.testing.assert_array_equal(valid, expect)
        assert counts['rejected_time'] == outliers.size and counts['gaps'] == 0

    def test_a_real_jump_is_a_gap_that_costs_one_sample(self):
        st, q, phi, v = self.drive()
        st[2000:] += 5 * 10**9                          # 5 s of no data
        accepted, _, status = _per_sample(st, q, phi, v)
        assert np.flatnonzero(~accepted).tolist() == [2000]      # held, then confirmed
        assert status.gaps == status.resets == 1
        valid, restart, _, counts = accept_arrays(st, q, phi, v, 0.1)
        np.testing.assert_array_equal(valid, accepted)
        assert np.flatnonzero(restart).tolist() == [0, 2001]

    def test_a_first_sample_stamped_in_the_future(self):
        st, q, phi, v = self.drive()
        st[0] += 3600 * 10**9
        accepted, _, status = _per_sample(st, q, phi, v)
        # the run behind it is taken once BEHIND_SAMPLES in a row continue each other
        assert np.flatnonzero(~accepted).tolist() == list(range(1, BEHIND_SAMPLES))
        assert status.gaps == status.resets == 1
        valid, restart, _, _ = accept_arrays(st, q, phi, v, 0.1)
        np.testing.assert_array_equal(valid, accepted)
        assert np.flatnonzero(restart).tolist() == [0, BEHIND_SAMPLES]

    def test_a_stream_whose_rate_drops_goes_on_at_the_new_rate(self):
        """A stream at 15 kHz that goes on at 1 kHz: the first slow step is a jump (held),
        the next continues from it at the same step: taken, and the rest with it."""
        st = 1_700_000_000 * 10**9 + np.concatenate([
            np.arange(3000) * 66_667, 3000 * 66_667 + np.arange(1, 2001) * 1_000_000])
        n = st.size
        rng = np.random.default_rng(8)
        q = 1e-3 * rng.standard_normal((n, 2))
        phi = 1e-3 * rng.standard_normal(n)
        v = np.full(n, 15.0)
        accepted, _, status = _per_sample(st, q, phi, v)
        assert np.flatnonzero(~accepted).tolist() == [3000]
        assert status.gaps == 0
        valid, _, _, _ = accept_arrays(st, q, phi, v, 0.1)
        np.testing.assert_array_equal(valid, accepted)
