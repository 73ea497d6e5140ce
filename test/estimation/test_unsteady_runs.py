"""Runs that are not one steady stream (issue 19): stamps jittered about a regular sample clock
(estimation/sample_clock.py) and a stop in an offline run (estimation/run_speed.py), against
the plant's truth."""
import numpy as np
import pytest

from road_force_estimator.estimation.models.front_axle import FrontAxleModel
from road_force_estimator.core import metrics
from road_force_estimator.core.parameters import ObserverParameters
from road_force_estimator.core.plant import simulate
from road_force_estimator.core.road import iso8608_profile
from road_force_estimator.core.sensors import SensorModel
from road_force_estimator.estimation import estimate_batch
from road_force_estimator.estimation.smoothing.run_speed import speed_segments, unsteady
from road_force_estimator.estimation.observer.sample_clock import clock_step
from road_force_estimator.estimation.observer.schedule import GainSchedule
from road_force_estimator.estimation.offline import smooth
from model_observer_data import VEHICLE

#: ISO 8608 class C: Gd(n0) = 256e-6 m^3 (the geometric mean of the class).
CLASS_C_GD_M3 = 256e-6


def _load_error(d, est, mask) -> float:
    st = metrics.load_errors(est.wheel_load_n, d.wheel_load_n,
                             np.asarray(VEHICLE.static_load_n), mask=mask)
    return float(np.sqrt(np.mean(np.square(st.rms))))


class TestClockStep:
    rng = np.random.default_rng(3)

    def test_jittered_stamps_give_the_clock(self):
        e = self.rng.uniform(-50e-6, 50e-6, 257)
        t = np.arange(257) * 1e-3 + e
        step = clock_step(np.diff(t))
        # the mean step of a grid is its period, up to (e_end - e_0) / n
        assert step == pytest.approx(1e-3, abs=2 * 50e-6 / 256)

    def test_steps_that_really_vary_are_kept(self):
        assert clock_step(self.rng.uniform(0.9e-3, 1.1e-3, 256)) is None     # independent
        assert clock_step(1e-3 * (1.0 + 0.05 * np.sin(np.arange(256) / 40.0))) is None

    def test_regular_and_rounded_stamps_are_kept(self):
        assert clock_step(np.full(256, 1e-3)) is None
        t = np.round((1.7e9 + np.arange(257) * 1e-3) * 1e9) * 1e-9    # epoch stamps, ns
        assert clock_step(np.diff(t)) is None


@pytest.fixture(scope='module')
def drive():
    road = iso8608_profile('C', 140.0, seed=11)
    d = simulate(VEHICLE, road, speed_mps=20.0, rate_hz=1000.0, duration_s=6.0,
                 tire_envelope_m=0.25)
    q, phi = SensorModel(deflection_std_m=1e-5, roll_std_rad=1e-4, seed=5).measure(
        d.q_m, d.roll_rad)
    return d, q, phi


@pytest.mark.parametrize('latency_s', [0.0, 0.01])
def test_jittered_stamps_estimate_as_the_true_times(drive, latency_s):
    """+-50 us of stamp jitter at 1 kHz, the samples on the clock: after the first block the
    observer steps with the clock, so the load error against the truth is that of the true
    sample times (with each stamp's step it was ~4 % higher)."""
    d, q, phi = drive
    t = np.asarray(d.t_s)
    jitter = np.random.default_rng(9).uniform(-50e-6, 50e-6, t.size)
    obs = ObserverParameters(latency_s=latency_s)
    scored = t >= 2.0
    ref = _load_error(d, estimate_batch(np.round(t * 1e9).astype(np.int64), q, phi, 20.0,
                                        VEHICLE, obs), scored)
    jit = _load_error(d, estimate_batch(np.round((t + jitter) * 1e9).astype(np.int64), q,
                                        phi, 20.0, VEHICLE, obs), scored)
    assert jit <= 1.01 * ref


PROFILE = ((0.0, 5.0, 9.0, 13.0, 17.0, 20.0), (20.0, 20.0, 0.0, 0.0, 20.0, 20.0))


@pytest.fixture(scope='module')
def stop():
    road = iso8608_profile('C', 360.0, seed=11)
    d = simulate(VEHICLE, road, speed_mps=20.0, rate_hz=1000.0, duration_s=20.0,
                 tire_envelope_m=0.25, speed_profile=PROFILE)
    q, phi = SensorModel(deflection_std_m=1e-5, roll_std_rad=1e-4, seed=5).measure(
        d.q_m, d.roll_rad)
    t = np.asarray(d.t_s)
    return d, q, phi, t, np.interp(t, *PROFILE)


def test_a_stop_offline(stop):
    """Braking to a stop, 4 s standing, pulling away: the offline smoother's roughness is
    the road's class (from the samples at speed; with the standing ones it came out ~4x low),
    and standing (after the wheels settled) its load error is a fraction of that at speed
    (the gains of the floor speed there: the road does not move)."""
    d, q, phi, t, v = stop
    est = smooth(np.round(t * 1e9).astype(np.int64), q, phi, v, VEHICLE, ObserverParameters())
    assert CLASS_C_GD_M3 / 1.6 <= est.status.road_roughness_m3 <= 1.6 * CLASS_C_GD_M3
    standing = (t >= 10.0) & (t < 13.0)
    moving = (t >= 2.0) & (t < 5.0) | (t >= 17.0)
    assert _load_error(d, est, standing) < 0.15 * _load_error(d, est, moving)


def test_speed_segments(stop):
    """The stretches cover the run in order; standing, the gains of the floor speed; a steady
    run: none."""
    d, q, phi, t, v = stop
    sched = GainSchedule(FrontAxleModel(VEHICLE), ObserverParameters(noise_deflection_m=1e-5,
                                                     noise_roll_rad=1e-4,
                                                     road_roughness_m3=2.56e-4))
    sched.set_run(1e-3, float(np.median(np.abs(v))))
    run_gains = sched.design(1e-3, 0)
    assert unsteady(np.full(10, 20.0), 20.0) is None
    assert speed_segments(sched, 1e-3, np.full(t.size, 20.0), 20.0) is None
    segs = speed_segments(sched, 1e-3, v, float(np.median(np.abs(v))))
    assert segs[0][0] == 0 and segs[-1][1] == t.size
    assert all(a[1] == b[0] for a, b in zip(segs[:-1], segs[1:]))
    mid = [g for a, b, g in segs if a <= 11000 < b][0]
    assert mid.speed_mps == pytest.approx(1.0, rel=0.1)
    assert sched.gains is run_gains
