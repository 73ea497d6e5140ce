"""Pendulum roll sensors' drift without the tractor IMU (issue 30 on the articulated model;
estimation.sensor_health's TractorDrift on each unit's roll balance with g times its
pendulum's reading, which holds the balance's g phi + a_y whole): the faults put into the
plant's readings by the plant's own fault module (core.sensor_faults), the flags judged
against where they struck."""
import numpy as np
import pytest

from road_force_estimator.core.parameters import ObserverParameters
from road_force_estimator.estimation.models.articulated import ArticulatedObserverModel
from road_force_estimator.estimation.sensor_health import (
    TRACTOR_PERSIST_S, FaultSettings, detect_faults, tractor_check)
from road_force_estimator.estimation.whole_vehicle import estimate_whole_vehicle

from test_whole_vehicle_health_imu import (
    DURATION_S, RATE, drive, faulted, flags, raised, readings)

PENDULUM = {'simulator.roll_sensor': 'pendulum', 'vehicle.roll_sensor': 'pendulum'}


@pytest.fixture(scope='module')
def straight():
    """36 s of class C (seed 11), pendulum roll sensors in the plant and the file, no IMU:
    the drive, its readings, the vehicle."""
    dr = drive(PENDULUM, DURATION_S, 11)
    y, _, vehicle = readings(dr)
    assert vehicle.roll_sensor == 'pendulum' and not vehicle.tractor_imu
    return dr, y, vehicle


def test_without_the_imu_pendulums_get_the_check_with_each_sensor_a_candidate(straight):
    """Four balances (P, T, I_t, I_r) and six candidates: the tractor's four deflections and
    each pendulum alone (no candidate for a drift common to both: module notes)."""
    vehicle = straight[2]
    check = tractor_check(ArticulatedObserverModel(vehicle), 2e-4, set())
    assert check is not None and len(check[0]) == 4
    assert check[4] == ((0,), (1,), (2,), (3,), (10,), (11,))


@pytest.mark.parametrize('channel, sign', [('tractor_roll', 1.0), ('trailer_roll', -1.0),
                                           ('tractor_roll', -1.0)])
def test_without_the_imu_a_drifting_pendulum_is_named_alone(straight, channel, sign):
    """1 mrad/min on one pendulum from 3 s: that sensor alone flagged, after the 6 s
    persistence and within 30 s; the clean drive nothing."""
    dr, y, vehicle = straight
    assert raised(flags(vehicle, dr, y)) == {}
    bad, (fault,) = faulted(dr['names'], y, f'drift@{channel}:rate={sign * RATE:.6g},start=3')
    counts = flags(vehicle, dr, bad)
    assert raised(counts) == {channel: (0, 1)}
    began = dr['stamps'][fault['first_sample']]
    assert TRACTOR_PERSIST_S * 1e9 < counts.first_ns[channel]['drift'] - began <= 30e9


def test_without_the_imu_a_drifting_tractor_deflection_is_named_beside_pendulums(straight):
    """1 mm/min on the drive axle's right deflection from 3 s: that sensor alone, within 30 s
    (no pendulum named)."""
    dr, y, vehicle = straight
    channel = 'drive_right_suspension'
    bad, (fault,) = faulted(dr['names'], y, f'drift@{channel}:rate={-RATE:.6g},start=3')
    counts = flags(vehicle, dr, bad)
    assert raised(counts) == {channel: (0, 1)}
    began = dr['stamps'][fault['first_sample']]
    assert 0 < counts.first_ns[channel]['drift'] - began <= 30e9


def test_without_the_imu_a_drift_common_to_both_pendulums_names_neither_alone(straight):
    """1 mrad/min on both pendulums: the balances see it as g times it (0.002 m/s^2 at the
    limit), less than what a curve on a crossfall leaves there; not flagged, and neither
    pendulum named alone."""
    dr, y, vehicle = straight
    spec = ';'.join(f'drift@{ch}:rate={RATE:.6g},start=3' for ch in ('tractor_roll',
                                                                      'trailer_roll'))
    assert raised(flags(vehicle, dr, faulted(dr['names'], y, spec)[0])) == {}


def test_without_the_imu_a_curve_on_a_crossfall_raises_nothing_with_pendulums():
    """30 s of class C through a curve ramping to 3 m/s^2 on a 3 % crossfall (the plant's
    lateral profile and road plane), pendulums without the IMU: they read a_y / g (0.3 rad),
    and no flag."""
    dr = drive({**PENDULUM, 'simulator.road_crossfall': 0.03,
                'simulator.lateral_profile': 'curve:start=5,ramp=3,hold=6,ay=3'}, 30.0, 5,
               lateral=True)
    assert np.max(np.abs(dr['tr'].lateral_accel_mps2)) > 2.9
    y, _, vehicle = readings(dr)
    roll = dr['names'].index('tractor_roll')
    assert np.max(np.abs(y[:, roll])) > 0.3
    assert raised(flags(vehicle, dr, y)) == {}


def test_without_the_imu_the_estimator_flags_what_the_detector_flags_in_every_mode(straight):
    """estimate_whole_vehicle online, at 10 ms and offline: the trailer pendulum's drift named
    alone, the per-sample flags those of the detector over the same readings."""
    dr, y, vehicle = straight
    bad, _ = faulted(dr['names'], y, f'drift@trailer_roll:rate={RATE:.6g},start=3')
    settings = FaultSettings.of_whole_vehicle(ObserverParameters(),
                                              ArticulatedObserverModel(vehicle))
    _, codes = detect_faults(settings, dr['stamps'], bad, dr['speed'])
    for obs, offline in ((ObserverParameters(), False),
                         (ObserverParameters(latency_s=0.01), False),
                         (ObserverParameters(), True)):
        wv = estimate_whole_vehicle(vehicle, dr['stamps'], bad, dr['speed'][:, 0],
                                    observer=obs, offline=offline)
        assert {n: c for n, c in wv.faults.drift_episodes.items() if c} == {
            'trailer_roll': 1}
        np.testing.assert_array_equal(wv.fault_flags, codes.T)
