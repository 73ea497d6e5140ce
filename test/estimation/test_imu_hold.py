"""The tractor IMU's a_y paired with the samples (estimation/imu_hold.py): the latest at or
before each stamp, stale beyond 0.1 s, missing before the first; the node's per-message form
and the arrays' form against cases worked by hand."""
import numpy as np

from road_force_estimator.estimation.imu_hold import (
    FRESH, IMU_MAX_AGE_S, MISSING, STALE, ImuHold, pair_imu)

MS = 1_000_000
T0 = 1_700_000_000 * 10**9


def test_cases_by_hand():
    # IMU at 0, 10, 20 ms, then 200 ms; samples every 5 ms and a few later ones
    imu_t = T0 + np.array([0, 10, 20, 200]) * MS
    imu_a = np.array([0.5, 1.0, 1.5, -2.0])
    samples = T0 + np.array([-1, 0, 5, 10, 19, 20, 120, 121, 199, 200, 301]) * MS
    want_a = [0.0, 0.5, 0.5, 1.0, 1.0, 1.5, 1.5, 1.5, 1.5, -2.0, -2.0]
    # 120 ms is 100 ms after 20 ms: still fresh (at most IMU_MAX_AGE_S); 121 ms is not
    want_c = [MISSING, FRESH, FRESH, FRESH, FRESH, FRESH, FRESH, STALE, STALE, FRESH, STALE]
    assert IMU_MAX_AGE_S == 0.1
    ay, code = pair_imu(samples, imu_t, imu_a)
    assert ay.tolist() == want_a and code.tolist() == want_c
    hold = ImuHold()
    got = []
    pending = list(zip(imu_t.tolist(), imu_a.tolist()))
    for s in samples.tolist():             # each message pushed before the samples after it
        while pending and pending[0][0] <= s:
            hold.push(*pending.pop(0))
        got.append(hold.at(s))
    assert got == list(zip(want_a, want_c))


def test_no_imu_at_all_is_missing_everywhere():
    ay, code = pair_imu(T0 + np.arange(5) * MS, np.zeros(0, np.int64), np.zeros(0))
    assert ay.tolist() == [0.0] * 5 and code.tolist() == [MISSING] * 5
    assert ImuHold().at(T0) == (0.0, MISSING)


def test_an_older_message_after_a_newer_one_is_dropped():
    # the node drops it as it comes; the arrays' form the same
    ay, code = pair_imu([T0 + 30 * MS], T0 + np.array([0, 20, 10]) * MS, [1.0, 2.0, 3.0])
    assert ay.tolist() == [2.0] and code.tolist() == [FRESH]
    hold = ImuHold()
    for t, a in ((0, 1.0), (20, 2.0), (10, 3.0)):
        hold.push(T0 + t * MS, a)
    assert hold.at(T0 + 30 * MS) == (2.0, FRESH)


def test_samples_waiting_behind_newer_messages_still_get_theirs():
    # the node's samples held until the first twist: several IMU messages arrive first
    hold = ImuHold()
    for t in range(0, 50, 10):
        hold.push(T0 + t * MS, float(t))
    assert [hold.at(T0 + s * MS) for s in (5, 15, 49)] == [(0.0, FRESH), (10.0, FRESH),
                                                           (40.0, FRESH)]
