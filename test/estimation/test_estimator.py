"""Estimator, the front door (estimation/estimator.py): robustness (rejections, gaps,
convergence flag, arguments) and the per-sample and batch paths, bit-identical.
"""
import math

import numpy as np
import pytest

from road_force_estimator.core import metrics
from road_force_estimator.estimation import (
    GAP_THRESHOLD_S, PAIR_FIELDS, SCALAR_FIELDS, Estimate, Estimator, estimate_batch)
from road_force_estimator.estimation.estimator import BatchRun
from road_force_estimator.estimation.outputs import FIELD_COLUMNS, N_COLUMNS, Column
from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
from model_observer_data import to_stamps as _stamps

VEHICLE = VehicleParameters()
SPEED = 20.0


class TestRobustness:
    def test_first_sample_initialises(self):
        est = Estimator(VEHICLE, ObserverParameters())
        out = est.update(5_000_000_000, (0.01, -0.02), 0.003, 15.0)
        assert isinstance(out, Estimate)
        assert out.stamp_ns == 5_000_000_000 and out.q_m == (0.01, -0.02)
        assert out.dq == (0.0, 0.0) and out.ddq == (0.0, 0.0) and out.droll == 0.0
        assert out.distance_m == 0.0 and not out.converged
        assert est.status.accepted == 1 and est.status.resets == 0

    @pytest.mark.parametrize('bad', [
        dict(q=(math.nan, 0.0)), dict(q=(0.0, math.inf)), dict(phi=math.nan),
        dict(v=-math.inf), dict(stamp=None), dict(stamp='soon'), dict(q=None), dict(q=(0.0,)),
        dict(q=('a', 0.0))])
    def test_nonfinite_samples_are_rejected_and_the_estimate_held(self, bad):
        est = Estimator(VEHICLE, ObserverParameters())
        for k in range(50):
            held = est.update(k * 1_000_000, (1e-3 * k, 0.0), 0.0, SPEED)
        args = dict(stamp=50 * 1_000_000, q=(1e-3, 0.0), phi=0.0, v=SPEED)
        args.update(bad)
        assert est.update(args['stamp'], args['q'], args['phi'], args['v']) is None
        assert est.status.rejected_nonfinite == 1
        assert est.last is held
        nxt = est.update(51 * 1_000_000, (0.051, 0.0), 0.0, SPEED)
        assert est.status.last_dt_s == pytest.approx(2e-3)   # the real dt, over the hole
        assert all(math.isfinite(x) for x in np.concatenate([np.ravel(f) for f in nxt[1:]]))

    def test_impossible_values_are_rejected(self):
        est = Estimator(VEHICLE, ObserverParameters())
        est.update(0, (0.0, 0.0), 0.0, SPEED)
        assert est.update(1_000_000, (2.0, 0.0), 0.0, SPEED) is None
        assert est.update(2_000_000, (0.0, 0.0), 2.0, SPEED) is None
        assert est.update(3_000_000, (0.0, 0.0), 0.0, 1e3) is None
        assert est.update(4_000_000, (0.0, 0.0), 0.0, -1.0) is None
        st = est.status
        assert (st.rejected_range, st.rejected_speed, st.rejected) == (2, 2, 4)

    def test_duplicate_and_backward_stamps_are_rejected(self):
        est = Estimator(VEHICLE, ObserverParameters())
        for k in range(10):
            est.update(k * 1_000_000, (0.0, 0.0), 0.0, SPEED)
        assert est.update(9 * 1_000_000, (0.0, 0.0), 0.0, SPEED) is None
        assert est.update(3 * 1_000_000, (0.0, 0.0), 0.0, SPEED) is None
        assert est.status.rejected_time == 2 and est.status.accepted == 10
        assert est.update(10 * 1_000_000, (0.0, 0.0), 0.0, SPEED) is not None

    def test_gap_resets_and_reconverges(self, drive_c):
        tr = drive_c
        stamps = _stamps(tr.t_s)
        cut = (tr.t_s > 4.0) & (tr.t_s < 4.5)      # 0.5 s of lost samples
        keep = ~cut
        est = estimate_batch(stamps[keep], tr.q_m[keep], tr.roll_rad[keep], SPEED, VEHICLE,
                             ObserverParameters())
        assert est.status.gaps == 1 and est.status.resets == 1
        t = tr.t_s[keep]
        after = np.argmax(t >= 4.5) + 1       # (the first after the gap is held, then lost)
        assert not est.valid[after - 1] and not est.converged[after]
        assert est.converged[-1] and est.status.converged
        # The distance continues across the gap.
        np.testing.assert_allclose(est.distance_m[est.valid], SPEED * t[est.valid], rtol=1e-12,
                                   atol=1e-9)
        # Reconverged: the loads are as good as before once converged again.
        ok = est.converged & (t > 4.5)
        loads = metrics.load_errors(est.wheel_load_n, tr.wheel_load_n[keep],
                                    VEHICLE.static_load_n, mask=ok)
        assert np.all(loads.rms_pct <= 8.0)
        assert np.all(loads.peak_pct <= 25.0)
        assert est.status.settling_time_s < GAP_THRESHOLD_S + 0.2

    def test_converged_flag_is_honest(self, drive_c):
        # From several starting points: once the flag is up, errors are within the bound.
        tr = drive_c
        for start in (0, 2500, 5100, 7700):
            sl = slice(start, start + 1500)
            est = estimate_batch(_stamps(tr.t_s[sl]), tr.q_m[sl], tr.roll_rad[sl], SPEED,
                                 VEHICLE, ObserverParameters())
            assert not est.converged[0] and est.converged[-1]
            err = np.abs(est.wheel_load_n - tr.wheel_load_n[sl])[est.converged]
            dyn = np.sqrt(np.mean(tr.tire_force_dynamic_n ** 2, axis=0))
            assert np.all(err.max(axis=0) <= 0.25 * dyn)

    def test_bad_constructor_arguments(self):
        with pytest.raises(ValueError, match='gap_threshold_s'):
            Estimator(VEHICLE, ObserverParameters(), gap_threshold_s=0.0)
        with pytest.raises(ValueError, match=r'expected \(n,\), \(n, 2\), \(n,\)'):
            estimate_batch(np.arange(3), np.zeros((3, 3)), np.zeros(3), SPEED)


class TestPaths:
    @pytest.mark.parametrize('scheme', ['implicit', 'taylor', 'euler', 'filtering'])
    def test_per_sample_and_batch_are_identical(self, drive_c, scheme):
        tr = drive_c
        n = 4000
        rng = np.random.default_rng(9)
        stamps = _stamps(tr.t_s[:n]) + rng.integers(-200_000, 200_000, n)   # jitter
        stamps[2000:] += 300_000_000                                         # a gap
        q = tr.q_m[:n] + rng.normal(0.0, 1e-5, (n, 2))
        phi = tr.roll_rad[:n] + rng.normal(0.0, 1e-5, n)
        speed = np.full(n, SPEED)
        q[100] = np.nan
        phi[200] = np.inf
        stamps[300] = stamps[299]          # duplicate
        stamps[400] = stamps[398]          # backwards
        obs = ObserverParameters(discretization=scheme)
        batch = estimate_batch(stamps, q, phi, speed, VEHICLE, obs)
        est = Estimator(VEHICLE, obs)
        outs = [est.update(int(stamps[k]), q[k], phi[k], speed[k]) for k in range(n)]
        valid = np.array([o is not None for o in outs])
        np.testing.assert_array_equal(valid, batch.valid)
        assert est.status == batch.status
        # 4 bad samples, and the first after the gap (held: the next one confirms the jump)
        assert batch.status.rejected == 5 and batch.status.resets == 1
        good = [o for o in outs if o is not None]
        np.testing.assert_array_equal([o.stamp_ns for o in good], batch.stamp_ns[valid])
        for name in PAIR_FIELDS + SCALAR_FIELDS:
            per_sample = np.array([getattr(o, name) for o in good])
            np.testing.assert_array_equal(per_sample, getattr(batch, name)[valid], name)
        # Rejected samples hold the previous estimate in the batch.
        np.testing.assert_array_equal(batch.wheel_load_n[100], batch.wheel_load_n[99])

    @pytest.mark.parametrize('latency', [0.0, 0.01])
    def test_blocks_of_any_size_are_the_per_sample_path(self, drive_c, latency):
        """BatchRun fed in uneven blocks (the streaming path of estimate_bag) returns, in
        order, exactly the per-sample path's estimates (update, then flush)."""
        tr = drive_c
        n = 1500
        stamps = _stamps(tr.t_s[:n])
        stamps[900:] += 300_000_000                                         # a gap
        q = tr.q_m[:n].copy()
        q[50] = np.nan
        phi = tr.roll_rad[:n]
        obs = ObserverParameters(latency_s=latency)
        est = Estimator(VEHICLE, obs)
        outs = [est.update(int(stamps[k]), q[k], phi[k], SPEED) for k in range(n)]
        good = [o for o in outs if o is not None] + est.flush()
        run = BatchRun(VEHICLE, obs)
        valid, rows = [], []
        edges = [0, 1, 8, 341, 899, 900, 1207, n]
        for a, b in zip(edges[:-1], edges[1:]):
            ok, _, part = run.feed(stamps[a:b], q[a:b], phi[a:b], np.full(b - a, SPEED))
            valid.append(ok)
            rows.append(part)
        rows.append(run.finish())
        rows = np.concatenate(rows)
        # the NaN, and the first sample after the gap (held: the next confirms the jump)
        assert np.count_nonzero(np.concatenate(valid)) == len(good) == rows.shape[0] == n - 2
        per_sample = np.zeros((len(good), N_COLUMNS))
        for name, slots in FIELD_COLUMNS.items():
            per_sample[:, list(slots)] = np.array([getattr(o, name) for o in good],
                                                  dtype=float).reshape(len(good), -1)
        np.testing.assert_array_equal(rows, per_sample)
        status = run.estimator.status        # the per-sample path counts them as they leave
        status.negative_load_samples = int(np.count_nonzero(
            (rows[:, Column.FN1] <= 0.0) | (rows[:, Column.FN2] <= 0.0)))
        assert status == est.status



class TestQuasiStaticLtr:
    """MODEL.md step 8: the rollover warning's LTR, low-passed below the wheel hop."""

    @staticmethod
    def _low_passed_ltr(loads, dt, cutoff_hz=2.0):
        # two first-order lags in cascade, -3 dB at cutoff_hz, from the first sample (here)
        from scipy.signal import lfilter
        e = math.exp(-dt * 2 * math.pi * cutoff_hz / math.sqrt(math.sqrt(2) - 1))
        out = []
        for side in (0, 1):
            x = np.maximum(loads[:, side], 0.0)
            y, _ = lfilter([1 - e], [1, -e], x[1:], zi=[e * x[0]])
            z, _ = lfilter([1 - e], [1, -e], y, zi=[e * x[0]])
            out.append(np.r_[x[0], z])
        return (out[1] - out[0]) / (out[0] + out[1])

    def test_straight_class_c_road_stays_near_zero(self, drive_c):
        tr = drive_c
        rng = np.random.default_rng(5)
        q = tr.q_m + rng.normal(0.0, 1e-5, tr.q_m.shape)
        phi = tr.roll_rad + rng.normal(0.0, 1e-4, tr.roll_rad.shape)
        est = estimate_batch(_stamps(tr.t_s), q, phi, SPEED, VEHICLE, ObserverParameters())
        after = tr.t_s > 1.0
        inst = np.abs(est.ltr[after]).max()
        assert inst > 0.4           # wheel hop swings it (measured 0.43)
        # what is left is the body's own roll on the rough road (~1.5 Hz, passes the 2 Hz
        # low-pass; measured: max 0.15, RMS 0.047), far from a rollover warning's 0.6-0.8
        quasi = est.ltr_quasi_static[after]
        assert np.abs(quasi).max() < 0.2 and np.abs(quasi).max() < 0.4 * inst
        assert np.sqrt(np.mean(quasi ** 2)) < 0.06
        truth = self._low_passed_ltr(tr.wheel_load_n, 1e-3)
        assert np.abs(truth[after]).max() < 0.2

    def test_steady_curve_matches_the_truths_low_passed_ltr(self):
        from road_force_estimator.core.plant import simulate
        from road_force_estimator.core.road import iso8608_profile
        road = iso8608_profile('C', 260.0, seed=8)
        tr = simulate(VEHICLE, road, speed_mps=SPEED, rate_hz=1000.0, duration_s=12.0,
                      tire_envelope_m=0.25, lateral_acceleration=lambda t: 3.0 * min(t / 2, 1))
        rng = np.random.default_rng(6)
        q = tr.q_m + rng.normal(0.0, 1e-5, tr.q_m.shape)
        phi = tr.roll_rad + rng.normal(0.0, 1e-4, tr.roll_rad.shape)
        est = estimate_batch(_stamps(tr.t_s), q, phi, SPEED, VEHICLE, ObserverParameters())
        truth = self._low_passed_ltr(tr.wheel_load_n, 1e-3)
        steady = tr.t_s > 4.0
        # 3 m/s^2: M h (a_y + g phi_ss) / s over the axle load (MODEL.md's phi_ss), 0.223
        g = 9.80665
        phi_ss = 5000 * 0.8 * 3.0 / (2 * (400e3 * 1000e3 / 1400e3) - 5000 * g * 0.8)
        ratio = 5000 * 0.8 * (3.0 + g * phi_ss) / sum(VEHICLE.static_load_n)
        assert truth[steady].mean() == pytest.approx(ratio, abs=0.005)
        err = est.ltr_quasi_static[steady] - truth[steady]
        assert np.abs(err).max() < 0.03
        assert abs(err.mean()) < 0.01
        # per sample and in the batch: the same numbers
        single = Estimator(VEHICLE, ObserverParameters())
        stamps = _stamps(tr.t_s)
        got = [single.update(int(s), tuple(qq), float(p), SPEED) for s, qq, p in
               zip(stamps[:3000], q[:3000], phi[:3000])]
        np.testing.assert_array_equal([g.ltr_quasi_static for g in got],
                                      est.ltr_quasi_static[:3000])


class TestVaryingSpeed:
    """A drive that brakes to a stop, stands 3 s and pulls away (simulator.speed_profile):
    the estimator follows the measured speed per sample."""

    def test_standstill_keeps_the_loads_and_holds_the_profile(self):
        from road_force_estimator.core.plant import simulate
        from road_force_estimator.core.road import iso8608_profile
        from road_force_estimator.estimation.body_heave import SPEED_FLOOR_MPS
        assert SPEED_FLOOR_MPS > 0.0        # the body-heave cutoff's low-speed floor
        knots = (np.array([0.0, 3.0, 6.0, 9.0, 12.0, 15.0]),
                 np.array([20.0, 20.0, 0.0, 0.0, 15.0, 15.0]))
        road = iso8608_profile('C', 300.0, seed=12)
        tr = simulate(VEHICLE, road, speed_mps=20.0, rate_hz=1000.0, duration_s=15.0,
                      tire_envelope_m=0.25, speed_profile=knots)
        speed = np.interp(tr.t_s, *knots)
        rng = np.random.default_rng(8)
        q = tr.q_m + rng.normal(0.0, 1e-5, tr.q_m.shape)
        phi = tr.roll_rad + rng.normal(0.0, 1e-4, tr.roll_rad.shape)
        est = estimate_batch(_stamps(tr.t_s), q, phi, speed, VEHICLE, ObserverParameters())
        assert est.valid.all() and np.isfinite(est.wheel_load_n).all()
        still = (tr.t_s >= 6.5) & (tr.t_s <= 9.0)
        # standing: the distance does not move, the loads are still estimated (static)
        assert np.ptp(est.distance_m[still]) < 1e-9
        assert np.ptp(tr.distance_m[still]) < 1e-9
        fc = np.array(VEHICLE.static_load_n)
        err = np.abs(est.wheel_load_n[still] - tr.wheel_load_n[still])
        assert err.max() < 0.01 * fc.min()
        # the profile at the one standing distance: no jump; the body heave (a filter in
        # distance) holds once the speed check trusts the standing speed (here from 7.14 s:
        # the wheel hop of this abrupt stop contradicts it for ~1 s), so the road moves only
        # with the suspension settling (measured 1.7 mm; the high-pass run in time at its
        # 1 m/s floor forgot the body's level: 8.7 mm over 2.5 s)
        assert np.isfinite(est.road_m[still]).all()
        assert np.abs(np.diff(est.road_m[still], axis=0)).max() < 5e-4   # noise: 0.2 mm
        held = (tr.t_s >= 7.5) & (tr.t_s <= 9.0)
        assert np.ptp(est.body_heave_m[held]) == 0.0
        assert np.ptp(est.road_m[held], axis=0).max() < 2.5e-3
        # per sample and in the batch: the same numbers through the stop
        single = Estimator(VEHICLE, ObserverParameters())
        stamps = _stamps(tr.t_s)
        part = slice(5500, 7500)
        ref = estimate_batch(stamps[part], q[part], phi[part], speed[part], VEHICLE,
                             ObserverParameters())
        got = [single.update(int(s), tuple(qq), float(p), float(v)) for s, qq, p, v in
               zip(stamps[part], q[part], phi[part], speed[part])]
        np.testing.assert_array_equal([g.wheel_load_n for g in got], ref.wheel_load_n)
        np.testing.assert_array_equal([g.road_m for g in got], ref.road_m)


def test_loads_after_a_stop_are_as_good_as_before():
    # (issue 19: the gains kept their 1 m/s design after a stop, since the speed band of the
    # floor level, open below, held every -v; measured now 0.163 against 0.160)
    from road_force_estimator.core.plant import simulate
    from road_force_estimator.core.road import iso8608_profile
    knots = (np.array([0.0, 3.0, 6.0, 9.0, 12.0, 15.0]),
             np.array([20.0, 20.0, 0.0, 0.0, 15.0, 15.0]))
    road = iso8608_profile('C', 300.0, seed=12)
    fc = np.array(VEHICLE.static_load_n)

    def late_error(profile):
        tr = simulate(VEHICLE, road, speed_mps=20.0, rate_hz=1000.0, duration_s=15.0,
                      tire_envelope_m=0.25, speed_profile=profile)
        rng = np.random.default_rng(8)
        q = tr.q_m + rng.normal(0.0, 1e-5, tr.q_m.shape)
        phi = tr.roll_rad + rng.normal(0.0, 1e-4, tr.roll_rad.shape)
        est = estimate_batch(_stamps(tr.t_s), q, phi, np.interp(tr.t_s, *profile), VEHICLE,
                             ObserverParameters())
        late = tr.t_s > 12.0
        e = est.wheel_load_n[late] - tr.wheel_load_n[late]
        return np.sqrt(np.mean(e ** 2)) / np.sqrt(np.mean((tr.wheel_load_n[late] - fc) ** 2))
    steady = late_error((np.array([0.0, 15.0]), np.array([15.0, 15.0])))
    assert late_error(knots) < 1.25 * steady
