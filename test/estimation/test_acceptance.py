"""The rejection and gap rules (estimation/acceptance.py): one sample at a time, and over
arrays exactly as per sample."""
import math

import numpy as np

from road_force_estimator.core.parameters import ObserverParameters
from road_force_estimator.estimation import Estimator, EstimatorStatus
from model_observer_data import VEHICLE
from road_force_estimator.estimation.acceptance import SampleGate, accept_arrays


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
        assert counts['gaps'] > 20 and counts['rejected_time'] == 3



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
        # a step of 0.2 s > max(0.1 s, 10 x 1 ms): a gap, the typical step restarts
        assert gate.check(201_000_000, 0.0, 0.0, 0.0, 10.0)[6:] == (True, 0.0)
        assert status.gaps == status.resets == 1
