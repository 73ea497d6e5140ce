"""Stuck and drifting sensors flagged by name (estimation.sensor_health; issue 30's acceptance:
a sensor stuck for 2 s flagged within 1 s, one drifting by 1 mm/min within 30 s, no flag on
the clean drives: class A, class C, a stop, five spikes).

Truth: where the faults were put into the plant's readings here (core/plant.py, checked against
solve_ivp in test/core/test_plant.py); the detector is never told.
"""
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
from road_force_estimator.core.plant import simulate
from road_force_estimator.core.road import iso8608_profile
from road_force_estimator.estimation import Estimator, estimate_batch, estimate_recording
from road_force_estimator.estimation.offline_stream import OfflineStream
from road_force_estimator.estimation.sensor_health import (
    FaultDetector, FaultSettings, detect_faults, flag_codes, left_out)

VEHICLE = VehicleParameters()
DRIFT = 1e-3 / 60.0          # 1 mm/min (m/s)
NAMES = ('left_suspension', 'right_suspension', 'roll')


def _drive(road_class: str, duration_s: float, speed_profile=None, seed: int = 1):
    road = iso8608_profile(road_class, 20.0 * duration_s + 60.0, seed=seed)
    tr = simulate(VEHICLE, road, speed_mps=20.0, rate_hz=1000.0, duration_s=duration_s,
                  tire_envelope_m=0.25, speed_profile=speed_profile)
    rng = np.random.default_rng(seed + 7)
    q = tr.q_m + rng.normal(0.0, 1e-5, tr.q_m.shape)
    phi = tr.roll_rad + rng.normal(0.0, 1e-4, tr.roll_rad.shape)
    speed = (np.full(tr.t_s.size, 20.0) if speed_profile is None
             else np.interp(tr.t_s, *speed_profile))
    return tr.t_s, np.round(tr.t_s * 1e9).astype(np.int64), q, phi, speed


def _status(stamps, q, phi, speed, observer=None):
    return estimate_batch(stamps, q, phi, speed, VEHICLE, observer or ObserverParameters()
                          ).status


def _flagged(st) -> dict:
    return {n: k for n in NAMES for k in ('stuck', 'drift')
            if (st.stuck_episodes if k == 'stuck' else st.drift_episodes)[n]}


@pytest.fixture(scope='module')
def class_c():
    return _drive('C', 20.0)


@pytest.mark.parametrize('channel', [0, 1, 2])
def test_a_sensor_stuck_for_2_s_is_flagged_within_1_s_by_name(class_c, channel):
    t, stamps, q, phi, speed = class_c
    q, phi = q.copy(), phi.copy()
    k0 = 8000                                  # stuck from 8 s for 2 s
    if channel < 2:
        q[k0:k0 + 2000, channel] = q[k0, channel]
    else:
        phi[k0:k0 + 2000] = phi[k0]
    st = _status(stamps, q, phi, speed)
    name = NAMES[channel]
    assert _flagged(st) == {name: 'stuck'}
    assert st.stuck_episodes[name] == 1
    assert 0.0 < st.fault_first_ns[name]['stuck'] * 1e-9 - t[k0] <= 1.0
    # flagged until the reading moves again (at 10 s): no sample of the stuck window after
    # the flag is missed, none after it counted
    assert st.stuck_samples[name] == 2000 - round(ObserverParameters().fault_stuck_time_s * 1e3)
    assert st.sensor_faults[name] == 'ok'


@pytest.mark.parametrize('road_class, channel, sign', [('C', 0, 1.0), ('C', 1, 1.0),
                                                       ('A', 1, -1.0)])
def test_a_drift_of_1_mm_per_min_is_flagged_within_30_s_by_name(road_class, channel, sign):
    t, stamps, q, phi, speed = _drive(road_class, 50.0, seed=2)
    q = q.copy()
    q[:, channel] += sign * np.where(t > 10.0, (t - 10.0) * DRIFT, 0.0)
    st = _status(stamps, q, phi, speed)
    name = NAMES[channel]
    assert _flagged(st) == {name: 'drift'}
    assert st.fault_first_ns[name]['drift'] * 1e-9 - 10.0 <= 30.0
    assert st.sensor_faults[name] == 'drift'        # still drifting at the end


@pytest.mark.parametrize('drive', ['A', 'C', 'stop', 'spikes'])
def test_clean_drives_raise_no_flag(class_c, drive):
    if drive == 'C':
        t, stamps, q, phi, speed = class_c
    elif drive == 'stop':    # braking to a stand (8-12 s), 10 s standing, pulling away
        t, stamps, q, phi, speed = _drive('C', 34.0, ((0.0, 8.0, 12.0, 22.0, 26.0, 34.0),
                                                      (20.0, 20.0, 0.0, 0.0, 20.0, 20.0)))
    else:
        t, stamps, q, phi, speed = _drive('A' if drive == 'A' else 'C', 40.0, seed=3)
    if drive == 'spikes':
        q = q.copy()
        for k, ch, sign in [(5000, 0, 1), (9000, 1, -1), (13000, 0, -1), (17000, 1, 1),
                            (19500, 0, 1)]:
            q[k, ch] += sign * 5e-4
    st = _status(stamps, q, phi, speed)
    assert _flagged(st) == {}


def test_a_standing_truck_is_not_a_stuck_sensor():
    """Every channel still (a truck standing, no noise) flags nothing, nor do two still while
    one moves (which one is wrong is not known); one still while both others move does."""
    det = FaultDetector(FaultSettings(NAMES))
    for k in range(3000):
        det.step(k * 1_000_000, (0.001, -0.002, 0.01))
    for k in range(3000, 4000):
        det.step(k * 1_000_000, (0.001, -0.002, 0.01 + 1e-6 * (k % 2)))
    assert det.counts().stuck_episodes == dict.fromkeys(NAMES, 0)
    for k in range(4000, 5000):
        det.step(k * 1_000_000, (0.001, -0.002 + 1e-6 * (k % 2), 0.01 + 1e-6 * (k % 2)))
    assert det.counts().stuck_episodes == {NAMES[0]: 1, NAMES[1]: 0, NAMES[2]: 0}
    # flagged at the first sample at which both others had moved (it had been still 4 s)
    assert det.counts().first_ns[NAMES[0]]['stuck'] == 4001 * 1_000_000


def test_per_sample_and_batch_give_the_same_flags(class_c):
    """The node's path (Estimator.update, sample by sample) and estimate_batch; and the
    detector's own batch function against its steps."""
    t, stamps, q, phi, speed = class_c
    n = 12000
    q, phi = q[:n].copy(), phi[:n].copy()
    q[6000:7500, 1] = q[6000, 1]
    obs = replace(ObserverParameters(), fault_drift_window_s=2.0, fault_drift_offset_m=1e-5)
    est = Estimator(VEHICLE, obs)
    for k in range(n):
        est.update(int(stamps[k]), q[k], float(phi[k]), 20.0)
    one, batch = est.status, _status(stamps[:n], q, phi, speed[:n], obs)
    for key in ('sensor_faults', 'stuck_episodes', 'stuck_samples', 'drift_episodes',
                'drift_samples', 'fault_first_ns'):
        assert getattr(one, key) == getattr(batch, key), key
    assert one.stuck_episodes['right_suspension'] == 1
    values = np.column_stack([q, phi])
    rates = np.column_stack([np.sin(np.arange(n) * 0.01), np.cos(np.arange(n) * 0.02)])
    settings = FaultSettings.of(obs, VEHICLE, NAMES)
    det = FaultDetector(settings)
    flags = []
    for k in range(n):
        det.step(int(stamps[k]), values[k].tolist(), tuple(rates[k]))
        flags.append(list(det.flags))
    counts, codes = detect_faults(settings, stamps[:n], values, rates)
    assert counts == det.counts()
    assert codes.tolist() == [[{'ok': 0, 'stuck': 1, 'drift': 2}[f] for f in row]
                              for row in flags]


def test_the_bag_diagnostics_name_the_flagged_sensor_each_second():
    """batch_diagnostics with the flags per sample: each second's status reads each sensor's
    flag at its last row and WARNs naming the faulty ones; the totals on the last."""
    from road_force_estimator.estimation.diagnostics import (
        WARN, batch_diagnostics, sensor_totals)
    from road_force_estimator.estimation.outputs import EstimatorStatus

    n = 3000
    stamps = np.arange(n, dtype=np.int64) * 1_000_000
    codes = np.zeros((n, 3), np.int8)
    codes[1500:2200, 0] = 1          # left stuck from 1.5 s to 2.2 s
    codes[2500:, 1] = 2              # right drifting from 2.5 s
    st = EstimatorStatus(innovations_gated={'left_suspension': 3, 'right_suspension': 2,
                                            'roll': 0},
                         stuck_episodes={'left_suspension': 1, 'right_suspension': 0, 'roll': 0},
                         drift_episodes={'left_suspension': 0, 'right_suspension': 1, 'roll': 0})
    out = batch_diagnostics(stamps, np.ones(n, bool), np.ones(n, bool), np.zeros((n, 2), bool),
                            np.zeros(n), np.zeros(n), sensor_totals(st), 'est', 'hw',
                            sensors=(NAMES, codes))
    statuses = [s[1][0] for s in out]
    vals = [dict(s.values) for s in statuses]
    assert [v['sensor.left_suspension'] for v in vals] == ['ok', 'stuck', 'ok']
    assert [v['sensor.right_suspension'] for v in vals] == ['ok', 'ok', 'drift']
    assert statuses[1].message == 'sensor fault: left_suspension stuck'
    assert statuses[1].level == WARN and statuses[0].message == 'ok'
    assert statuses[2].message == 'sensor fault: right_suspension drift'
    assert vals[2]['total.innovations_gated.left_suspension'] == '3'
    assert vals[2]['total.stuck.left_suspension'] == '1'
    assert vals[2]['total.drift.right_suspension'] == '1'


def _stuck_roll_drive():
    duration = 14.0
    road = iso8608_profile('C', 20.0 * duration + 60.0, seed=3)
    tr = simulate(VEHICLE, road, speed_mps=20.0, rate_hz=1000.0, duration_s=duration,
                  tire_envelope_m=0.25)
    rng = np.random.default_rng(11)
    q = tr.q_m + rng.normal(0.0, 1e-5, tr.q_m.shape)
    phi = tr.roll_rad + rng.normal(0.0, 1e-4, tr.roll_rad.shape)
    return tr, np.round(tr.t_s * 1e9).astype(np.int64), q, phi


def _estimate(mode: str, stamps, q, phi, speed):
    """The estimate in ``mode``: 0 ms, 10 ms, offline, offline as the stream goes (in
    windows of 4 s with 1 s of overlap), or offline with every 7th sample from 5 s to 12 s
    lost (the smoother's grid completed between the samples left)."""
    if mode == 'offline':
        return estimate_recording(stamps, q, phi, speed, VEHICLE, ObserverParameters())
    if mode == 'offline lost samples':
        keep = np.ones(stamps.size, bool)
        keep[5000:12000:7] = False
        return estimate_recording(stamps[keep], q[keep], phi[keep], speed[keep], VEHICLE,
                                  ObserverParameters())
    if mode == 'offline windows':
        stream = OfflineStream(VEHICLE, ObserverParameters(), window=(4000, 1000))
        stream.feed(stamps, q, phi, speed)
        pieces = list(stream.finish())
        return SimpleNamespace(**{f: np.concatenate([getattr(p, f) for p in pieces])
                                  for f in ('stamp_ns', 'tire_force_dynamic_n')})
    obs = replace(ObserverParameters(), latency_s=0.01 if mode == '10 ms' else 0.0)
    return estimate_batch(stamps, q, phi, speed, VEHICLE, obs)


@pytest.mark.parametrize('mode', ['0 ms', '10 ms', 'offline', 'offline windows',
                                  'offline lost samples'])
def test_the_estimate_carries_on_through_a_stuck_roll_sensor(mode):
    """A roll sensor stuck for 2 s is left out while flagged (its prediction taken for its
    reading; offline its stretch, held readings before the flag too, smoothed without it):
    the load error against the plant's stays near the clean drive's (offline measured
    1.02 x). Fed, the same fault cost 4-30 x online, 3.10 x offline (before the smoother
    left it out)."""
    tr, stamps, q, phi = _stuck_roll_drive()
    speed = np.full(stamps.size, 20.0)
    stuck = phi.copy()
    stuck[8000:10000] = stuck[8000]
    judged = tr.t_s >= 3.0
    true_dyn = tr.tire_force_dynamic_n[judged]

    def error(roll) -> float:
        est = _estimate(mode, stamps, q, roll, speed)
        at = np.searchsorted(est.stamp_ns, stamps[judged])
        ok = est.stamp_ns[np.minimum(at, est.stamp_ns.size - 1)] == stamps[judged]
        return float(np.sqrt(np.mean((est.tire_force_dynamic_n[at[ok]] - true_dyn[ok]) ** 2)))

    clean, faulty = error(phi), error(stuck)
    bound = {'0 ms': 1.1, '10 ms': 1.5}.get(mode, 1.1)
    assert faulty <= bound * clean, (clean, faulty)


@pytest.mark.parametrize('channel', [0, 1])
def test_offline_a_stuck_deflection_is_smoothed_without_it(channel):
    """Offline, a deflection sensor stuck for 2 s is left out of the smoother: the other
    deflection and the roll carry the estimate. That wheel's road is not seen for those 2 s
    (40 m), so the error grows: measured 3.09 / 3.12 x here (left / right), fed (before
    this was built) 21.1 / 19.9 x."""
    tr, stamps, q, phi = _stuck_roll_drive()
    speed = np.full(stamps.size, 20.0)
    stuck = q.copy()
    stuck[8000:10000, channel] = stuck[8000, channel]
    judged = tr.t_s >= 3.0
    true_dyn = tr.tire_force_dynamic_n[judged]

    def error(deflections) -> float:
        est = estimate_recording(stamps, deflections, phi, speed, VEHICLE,
                                 ObserverParameters())
        at = np.searchsorted(est.stamp_ns, stamps[judged])
        return float(np.sqrt(np.mean((est.tire_force_dynamic_n[at] - true_dyn) ** 2)))

    clean, faulty = error(q), error(stuck)
    assert faulty <= 3.5 * clean, (clean, faulty)


def test_offline_the_held_readings_are_left_out_from_the_first_repeat():
    """The stretch the offline smoother leaves out (:func:`.sensor_health.left_out`) is the
    held readings put in here: from the sample after the last real reading to the last held
    one, the 0.05 s before the flag included; every other reading is fed."""
    tr, stamps, q, phi = _stuck_roll_drive()
    stuck = phi.copy()
    stuck[8000:10000] = stuck[8000]           # 8000: the last real reading, then held
    det = FaultDetector(FaultSettings.of(ObserverParameters(), VEHICLE, NAMES))
    values = np.column_stack([q, stuck])
    for s, v in zip(stamps.tolist(), values.tolist()):
        det.step(s, v)
    out = left_out(flag_codes(det.events, stamps.size, 3), det.stuck_since, stamps)
    expected = np.zeros((stamps.size, 3), bool)
    expected[8001:10000, 2] = True
    np.testing.assert_array_equal(out, expected)
    assert left_out(flag_codes([], stamps.size, 3), [], stamps) is None


def test_the_stuck_rule_sample_by_sample_against_its_statement():
    """The stuck flags of every sample against the rule written out here (module notes: a
    channel still, within the tolerance, for the stuck time while every other judged channel
    moves is flagged; a move clears it): noisy readings with one channel held, two held
    together, moves of exactly the tolerance (still) and just above it (moving), so that both
    the common case (every channel moved) and the per-channel rule are taken."""
    names = ('a', 'b', 'c', 'd')
    tol, still_s = 2.0 ** -20, 0.05                  # (moves of tol and 1.5 tol exact)
    rng = np.random.default_rng(3)
    v = np.cumsum(rng.normal(0.0, 1e-4, (3000, 4)), axis=0)
    v[1000:1200, 1] = v[1000, 1]                        # b held 0.2 s: flagged
    v[2000:2100, 2:] = v[2000, 2:]                      # c and d held together: not flagged
    v[2500:2700, 0] = 0.25 + tol * (np.arange(200) % 2)        # a moves by tol: still
    v[2800:2900, 3] = 0.25 + 1.5 * tol * (np.arange(100) % 2)  # d moves beyond it
    rows = [[float(x) for x in r] for r in v]
    det = FaultDetector(FaultSettings(names, stuck_time_s=still_s, stuck_tolerance=tol))
    run, flags, got, want = [0.0] * 4, [False] * 4, [], []
    for k, r in enumerate(rows):
        det.step(k * 1_000_000, r)
        got.append(list(det.stuck))
        t = k * 1e-3
        if k == 0:
            run = [t] * 4
        else:
            still = []
            for ch in range(4):
                if abs(r[ch] - rows[k - 1][ch]) > tol:
                    run[ch], flags[ch] = t, False
                elif run[ch] <= t - still_s:
                    still.append(ch)
            if len(still) == 1:
                flags[still[0]] = True
        want.append(list(flags))
    assert got == want
    held = [k for k, f in enumerate(got) if f[1]]
    assert held[0] == 1050 and held[-1] == 1199          # b: after 0.05 s still, until it moves
    assert not any(f[2] or f[3] for f in got)
    assert any(f[0] for f in got[2500:2700])
