"""The roll sensors' drift with the tractor IMU (issue 30 on the articulated model;
estimation.sensor_health's TractorDrift with each unit's roll balance against the IMU's a_y):
the faults put into the plant's readings by the plant's own fault module (core.sensor_faults)
or by the plant's gyro (core.roll_sensors), the flags judged against where they struck."""
import numpy as np
import pytest

from road_force_estimator.core.parameters import ObserverParameters
from road_force_estimator.core.sensor_faults import FaultPlan, parse_faults
from road_force_estimator.estimation.models.articulated import ArticulatedObserverModel
from road_force_estimator.estimation.sensor_health import (
    TRACTOR_PERSIST_S, FaultDetector, FaultSettings, detect_faults, tractor_check)
from road_force_estimator.estimation.whole_vehicle import estimate_whole_vehicle

from conftest import ARTICULATED_CONFIG

DURATION_S = 36.0
RATE = 1e-3 / 60.0                  # 1 mrad/min (rad/s)


def drive(values: dict, duration_s: float, seed: int, lateral: bool = False,
          road: str = 'C') -> dict:
    """The file's combination on ISO 8608 ``road`` (class C) at 20 m/s, 1 kHz, 10 um of
    deflection noise, with ``values``: the plant's trajectory, the drive's setup and the
    channel names."""
    from road_force_estimator.core.articulated_plant import simulate_articulated
    from road_force_estimator.core.articulated_setup import ArticulatedDrive
    from road_force_estimator.core.parameters import load_params_file
    from road_force_estimator.core.road import iso8608_profile
    from road_force_estimator.estimation.models.articulated import channel_names

    base = load_params_file(ARTICULATED_CONFIG)
    base.update({'simulator.noise.deflection': 1e-5, 'simulator.noise.roll': 1e-5 / 0.45,
                 'simulator.duration': duration_s, **values})
    d = ArticulatedDrive.from_values(base)
    tr = simulate_articulated(d.vehicle, iso8608_profile(road, d.road_length_m, seed=seed),
                              speed_mps=20.0, rate_hz=1000.0, duration_s=duration_s,
                              tire_envelope_m=0.25, model=d.model,
                              lateral_acceleration=d.lateral if lateral else None,
                              crossfall_rad=d.sim.road_crossfall_rad)
    return {'setup': d, 'tr': tr, 'names': tuple(channel_names(d.model)), 'base': base,
            'stamps': np.round(tr.t_s * 1e9).astype(np.int64),
            'speed': np.full((len(tr.t_s), 1), 20.0)}


def readings(dr: dict, values: dict | None = None) -> tuple:
    """The plant's readings and the IMU's a_y of ``dr``'s trajectory, by the sensors of its
    setup with ``values`` (e.g. the roll sensors' physics)."""
    from road_force_estimator.core.articulated_setup import ArticulatedDrive

    d = ArticulatedDrive.from_values({**dr['base'], **(values or {})}) if values else dr['setup']
    sensors = d.sensors(dr['names'])
    return sensors.measure(dr['tr']), sensors.imu(dr['tr'])[:, 1], d.vehicle


def faulted(names, y, spec: str):
    """The readings with ``spec``'s faults (the plant's module) and its truth."""
    plan = FaultPlan(parse_faults(spec, names), names, 1000.0, DURATION_S, 1)
    return plan.hold(plan.apply(np.array(y, float))), plan.truth()


def flags(vehicle, dr: dict, y, ay=None):
    """The detector's counts over the drive, with the IMU's a_y as a channel when given."""
    imu = ay is not None
    settings = FaultSettings.of_whole_vehicle(ObserverParameters(),
                                              ArticulatedObserverModel(vehicle, imu))
    values = np.column_stack([y, ay]) if imu else y
    counts, _ = detect_faults(settings, dr['stamps'], values, dr['speed'])
    return counts


def raised(counts) -> dict:
    return {n: (counts.stuck_episodes[n], counts.drift_episodes[n])
            for n in counts.flags if counts.stuck_episodes[n] or counts.drift_episodes[n]}


@pytest.fixture(scope='module')
def straight():
    """36 s of class C (seed 11) with the tractor IMU: the drive, its readings, a_y."""
    dr = drive({'vehicle.tractor_imu': True}, DURATION_S, 11)
    y, ay, vehicle = readings(dr)
    return dr, y, ay, vehicle


@pytest.mark.parametrize('channel, sign', [('tractor_roll', 1.0), ('trailer_roll', -1.0),
                                           ('tractor_roll', -1.0)])
def test_with_the_imu_a_drifting_roll_sensor_is_named_alone(straight, channel, sign):
    """1 mrad/min on one roll sensor from 3 s (the plant's drift): with the IMU that sensor
    alone is flagged drift, after the 6 s persistence and within 30 s of the drift's start;
    without it both roll sensors are (the roll difference only)."""
    dr, y, ay, vehicle = straight
    bad, (fault,) = faulted(dr['names'], y, f'drift@{channel}:rate={sign * RATE:.6g},start=3')
    counts = flags(vehicle, dr, bad, ay)
    assert raised(counts) == {channel: (0, 1)}
    began = dr['stamps'][fault['first_sample']]
    assert TRACTOR_PERSIST_S * 1e9 < counts.first_ns[channel]['drift'] - began <= 30e9
    assert raised(flags(vehicle, dr, bad)) == {'tractor_roll': (0, 1), 'trailer_roll': (0, 1)}


@pytest.mark.parametrize('sign', [1.0, -1.0])
def test_with_the_imu_a_drift_common_to_both_roll_sensors_is_flagged_on_both(straight, sign):
    """1 mrad/min on both roll sensors from 3 s (the plant's drift, the same on each): with the
    IMU both flagged drift within 30 s; without it, not flagged (the balances see the roll
    difference only)."""
    dr, y, ay, vehicle = straight
    spec = ';'.join(f'drift@{ch}:rate={sign * RATE:.6g},start=3'
                    for ch in ('tractor_roll', 'trailer_roll'))
    bad, truth = faulted(dr['names'], y, spec)
    counts = flags(vehicle, dr, bad, ay)
    assert raised(counts) == {'tractor_roll': (0, 1), 'trailer_roll': (0, 1)}
    began = dr['stamps'][truth[0]['first_sample']]
    for ch in ('tractor_roll', 'trailer_roll'):
        assert TRACTOR_PERSIST_S * 1e9 < counts.first_ns[ch]['drift'] - began <= 30e9
    assert raised(flags(vehicle, dr, bad)) == {}


def test_the_plants_gyro_drift_is_flagged_with_the_imu(straight):
    """The plant's gyro roll sensors (``simulator.roll_gyro_drift`` 1 mrad/min on both from
    the drive's start): with the IMU both flagged drift within 30 s, without it nothing; the
    clean drive raises nothing with the IMU."""
    dr, y, ay, vehicle = straight
    assert raised(flags(vehicle, dr, y, ay)) == {}
    gyro, ay_g, _ = readings(dr, {'simulator.roll_sensor': 'gyro',
                                  'simulator.roll_gyro_drift': RATE})
    roll = dr['names'].index('tractor_roll')
    assert gyro[-1, roll] - y[-1, roll] == pytest.approx(RATE * DURATION_S, rel=1e-6)
    counts = flags(vehicle, dr, gyro, ay_g)
    assert raised(counts) == {'tractor_roll': (0, 1), 'trailer_roll': (0, 1)}
    assert counts.first_ns['tractor_roll']['drift'] - dr['stamps'][0] <= 30e9
    assert raised(flags(vehicle, dr, gyro)) == {}


def test_with_the_imu_a_curve_on_a_crossfall_raises_nothing():
    """30 s of class C through a curve ramping to 3 m/s^2 on a 3 % crossfall (the plant's
    lateral profile and road plane), with the IMU: no flag, with ideal roll sensors and with
    pendulums (read with the IMU: each unit's balance holds g phi + a_y, the reading). Without
    the IMU pendulums get the check too, with no candidate for a drift common to both
    (test_whole_vehicle_health_pendulum.py)."""
    dr = drive({'vehicle.tractor_imu': True, 'simulator.road_crossfall': 0.03,
                'simulator.lateral_profile': 'curve:start=5,ramp=3,hold=6,ay=3'}, 30.0, 5,
               lateral=True)
    assert np.max(np.abs(dr['tr'].lateral_accel_mps2)) > 2.9
    y, ay, vehicle = readings(dr)
    assert raised(flags(vehicle, dr, y, ay)) == {}
    pend = {'simulator.roll_sensor': 'pendulum', 'vehicle.roll_sensor': 'pendulum'}
    yp, ayp, vp = readings(dr, pend)
    roll = dr['names'].index('tractor_roll')
    assert np.max(np.abs(yp[:, roll] - y[:, roll])) > 0.25   # the pendulums read a_y / g
    assert len(tractor_check(ArticulatedObserverModel(vp), 2e-4, set())[4]) == 6
    assert len(tractor_check(ArticulatedObserverModel(vp, True), 2e-4, set())[4]) == 7
    assert raised(flags(vp, dr, yp, ayp)) == {}


def test_with_the_imu_a_rough_clean_drive_raises_nothing():
    """60 s clean of class D at 20 m/s (seed 1), with the IMU: no flag. The IMU's a_y enters
    the tractor's balances only; the trailer's drift statistic (UnitDrift, the deflections
    over the triangular window) is the one without it and stays below half the limit (a
    table measured before that window listed a trailer flag here: docs/articulated.md)."""
    dr = drive({'vehicle.tractor_imu': True}, 60.0, 1, road='D')
    y, ay, vehicle = readings(dr)
    settings = FaultSettings.of_whole_vehicle(ObserverParameters(),
                                              ArticulatedObserverModel(vehicle, True))
    det = FaultDetector(settings)
    values = np.column_stack([y, ay])
    for stamp, row, v in zip(dr['stamps'].tolist(), values.tolist(), dr['speed'].tolist()):
        det.step(stamp, row, tuple(v))
    assert raised(det.counts()) == {}
    assert 0.0 < det.units.peak[0] < settings.drift_offset_m / 2.0


@pytest.mark.parametrize('channel, sign', [('tractor_roll', 1.0), ('trailer_roll', -1.0)])
def test_with_the_imu_a_drifting_pendulum_is_named_alone(channel, sign):
    """Pendulum roll sensors (the plant's and the file's) with the IMU, 36 s of class C:
    1 mrad/min on one from 3 s named alone, after the 6 s persistence and within 30 s; a
    drift common to both flags both; the clean drive nothing."""
    pend = {'vehicle.tractor_imu': True, 'simulator.roll_sensor': 'pendulum',
            'vehicle.roll_sensor': 'pendulum'}
    dr = drive(pend, DURATION_S, 11)
    y, ay, vehicle = readings(dr)
    assert vehicle.roll_sensor == 'pendulum'
    assert raised(flags(vehicle, dr, y, ay)) == {}
    bad, (fault,) = faulted(dr['names'], y, f'drift@{channel}:rate={sign * RATE:.6g},start=3')
    counts = flags(vehicle, dr, bad, ay)
    assert raised(counts) == {channel: (0, 1)}
    began = dr['stamps'][fault['first_sample']]
    assert TRACTOR_PERSIST_S * 1e9 < counts.first_ns[channel]['drift'] - began <= 30e9
    spec = ';'.join(f'drift@{ch}:rate={sign * RATE:.6g},start=3'
                    for ch in ('tractor_roll', 'trailer_roll'))
    assert raised(flags(vehicle, dr, faulted(dr['names'], y, spec)[0], ay)) == {
        'tractor_roll': (0, 1), 'trailer_roll': (0, 1)}


@pytest.fixture(scope='module')
def curve():
    """30 s of class C through a curve ramping to 3 m/s^2 (from 5 s, 3 s of ramp, 6 s held),
    with the IMU: the drive, its readings, a_y."""
    dr = drive({'vehicle.tractor_imu': True,
                'simulator.lateral_profile': 'curve:start=5,ramp=3,hold=6,ay=3'}, 30.0, 5,
               lateral=True)
    y, ay, vehicle = readings(dr)
    return dr, y, ay, vehicle


def test_an_imu_that_falls_silent_through_a_curve_raises_no_drift_flag(curve):
    """The IMU silent from 3 s to 20 s (its last a_y held, as the pairing feeds it: stale) while
    the curve's a_y rises to 3 m/s^2: held, it would read as a roll offset of a_y / g common
    to both roll sensors (the check before IMU_HELD_S flagged both); the windows wait for a
    fresh a_y instead: no flag. The same for an IMU that never speaks (0 fed: missing)."""
    dr, y, ay, vehicle = curve
    assert np.max(np.abs(ay)) > 2.5
    assert raised(flags(vehicle, dr, y, ay)) == {}
    t = (dr['stamps'] - dr['stamps'][0]) * 1e-9
    held = ay.copy()
    silent = (t >= 3.0) & (t < 20.0)
    held[silent] = ay[np.flatnonzero(t < 3.0)[-1]]
    assert raised(flags(vehicle, dr, y, held)) == {}
    assert raised(flags(vehicle, dr, y, np.zeros_like(ay))) == {}


def test_the_estimator_flags_what_the_detector_flags_with_the_imu(straight):
    """estimate_whole_vehicle(imu=True) online: the trailer roll sensor's drift named alone, the
    per-sample flags those of the detector over the same readings."""
    dr, y, ay, vehicle = straight
    bad, _ = faulted(dr['names'], y, f'drift@trailer_roll:rate={RATE:.6g},start=3')
    wv = estimate_whole_vehicle(vehicle, dr['stamps'], np.column_stack([bad, ay]),
                                dr['speed'][:, 0], observer=ObserverParameters(), imu=True)
    assert {n: c for n, c in wv.faults.drift_episodes.items() if c} == {'trailer_roll': 1}
    settings = FaultSettings.of_whole_vehicle(ObserverParameters(),
                                              ArticulatedObserverModel(vehicle, True))
    _, codes = detect_faults(settings, dr['stamps'], np.column_stack([bad, ay]), dr['speed'])
    np.testing.assert_array_equal(wv.fault_flags, codes.T)


def test_without_the_imu_the_roll_candidate_is_the_pair(straight):
    """Without the IMU one roll candidate (the pair's difference, both named) and three
    balances; with it three (each sensor, both) and four balances."""
    vehicle = straight[3]
    without = tractor_check(ArticulatedObserverModel(vehicle), 2e-4, set())
    with_imu = tractor_check(ArticulatedObserverModel(vehicle, True), 2e-4, set())
    assert len(without) == 7 and len(without[0]) == 3
    assert len(with_imu[0]) == 4 and with_imu[4][-3:] == ((10,), (11,), (10, 11))
    assert without[4][-1] == (10, 11)
