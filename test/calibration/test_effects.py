"""Calibration of the leaf-spring friction, its tanh velocity v_f and the sensor lag (issues
20, 30): a truck with friction and lagging sensors, driven over a surveyed ISO 8608 class C
road (plant RK4, tire envelope, :class:`SensorModel` lag), calibrated from a nominal file 10 %
off with friction 1000 N and lags 2 ms / 1 ms. The truth is the simulator's, never the fit's."""
from dataclasses import replace

import numpy as np
import pytest

from road_force_estimator.core.parameters import VehicleParameters
from road_force_estimator.core.plant import simulate
from road_force_estimator.core.road_files import road_from_source
from road_force_estimator.core.sensors import SensorModel
from road_force_estimator.calibration.calibrate import (
    CalibrationError, CalibrationOptions, calibrate)
from road_force_estimator.calibration.model import (
    FREE_START, SLOTS, freed_start, slot_value, vehicle_with)

RATE = 200.0
SPEED = 20.0
START = 30.0
ODOMETER = 1.015
FRICTION = 'vehicle.leaf_spring_friction'
LAG = 'vehicle.sensor_time_constant'
V_F = 'vehicle.leaf_spring_friction_velocity'
BASE = VehicleParameters()
_PHYSICAL = [s for s in SLOTS if s.physical and not s.plant_only]
_SIGNS = (1, -1, 1, -1, 1, 1, -1, -1, 1, 1, -1)


def _with(vehicle, friction, lag):
    params = vehicle.to_parameters()
    params[FRICTION], params[LAG] = list(friction), list(lag)
    return VehicleParameters.from_parameters(params)


#: The truck: the defaults 10 % off (mixed signs), friction 1500 N, lags 3 ms / 2 ms.
TRUCK = _with(vehicle_with(BASE, {s: slot_value(BASE, s) * (1 + 0.1 * g)
                                  for s, g in zip(_PHYSICAL, _SIGNS)}),
              (1500.0, 1500.0), (3e-3, 2e-3))
NOMINAL = _with(BASE, (1000.0, 1000.0), (2e-3, 1e-3))


@pytest.fixture(scope='module')
def road():
    return road_from_source('iso8608:C:seed=7', length_m=300.0)


def _drive(road, noise_m, duration_s=8.0, truck=None):
    truck = TRUCK if truck is None else truck
    traj = simulate(truck, road, speed_mps=SPEED, rate_hz=RATE, duration_s=duration_s,
                    tire_envelope_m=0.25, start_m=START)
    sensors = SensorModel(noise_m, 10.0 * noise_m, seed=3,
                          time_constant_s=truck.sensor_time_constant_s, rate_hz=RATE)
    q, roll = sensors.measure(traj.q_m, traj.roll_rad)
    stamps = np.rint(traj.t_s * 1e9).astype(np.int64) + 10**18
    return stamps, q, roll, np.full(stamps.size, SPEED / ODOMETER)


def _calibrate(road, drive, nominal=NOMINAL, **kw):
    return calibrate(*drive, road, nominal,
                     options=CalibrationOptions(start_offset_m=20.0,
                                                static_load_n=TRUCK.static_load_n, **kw))


def _effects(result):
    return {e.slot.label: e for e in result.parameters
            if e.slot.name in (FRICTION, LAG)}


def test_noise_free_drive_recovers_friction_and_lags(road):
    result = _calibrate(road, _drive(road, 0.0, duration_s=6.0))
    effects = _effects(result)
    assert len(effects) == 4
    for label, e in effects.items():
        truth = slot_value(TRUCK, e.slot)
        # measured: below 1e-6 relative (the plant's own least squares converges; before it,
        # with the defect updates alone, 0.3 % on the masses and 16-24 % on the lags)
        assert e.status == 'fitted', label
        assert e.value == pytest.approx(truth, rel=1e-4), label
    for e in result.parameters:
        if e.slot.physical:
            assert e.value == pytest.approx(slot_value(TRUCK, e.slot), rel=1e-4), e.slot.label


def test_ten_micron_drive_recovers_friction_and_lags_within_their_intervals(road):
    result = _calibrate(road, _drive(road, 1e-5))
    for label, e in _effects(result).items():
        truth = slot_value(TRUCK, e.slot)
        # measured: friction +0.08 % / 0.00 % (95 % half-widths 0.2 %), lags +1.1 % / +2.4 %
        # (half-widths 2.7 % / 4.8 %)
        assert e.value == pytest.approx(truth, rel=0.05 if e.slot.name == LAG else 0.01), label
        assert e.low <= truth <= e.high, label
    for e in result.parameters:
        if e.slot.physical and e.slot.name not in (FRICTION, LAG):
            assert e.value == pytest.approx(slot_value(TRUCK, e.slot), rel=0.01), e.slot.label


def test_a_friction_sharper_than_the_file_is_fitted_and_the_rest_stays_unbiased(road):
    """The plant's tanh v_f 0.005 m/s, the file's 0.01 (10 um, 8 s): v_f is fitted like the
    friction (through the plant's defect) and every 95 % interval holds the truth. Measured:
    v_f 0.00495 [0.00481, 0.00510], friction 1501 / 1500 N, lags 3.03 / 2.05 ms. Without the
    v_f slot (the file's 0.01 held) the friction came out 1524 / 1531 N and the lags 3.37 /
    2.33 ms, every interval missing the truth."""
    truck = replace(TRUCK, leaf_spring_friction_velocity_mps=0.005)
    result = _calibrate(road, _drive(road, 1e-5, truck=truck))
    by_label = {e.slot.label: e for e in result.parameters}
    v_f = by_label[V_F]
    assert v_f.status == 'fitted'
    assert v_f.value == pytest.approx(0.005, rel=0.05)
    assert v_f.low <= 0.005 <= v_f.high
    assert result.vehicle.leaf_spring_friction_velocity_mps == v_f.value
    for label, e in _effects(result).items():
        truth = slot_value(truck, e.slot)
        assert e.low <= truth <= e.high, label
        assert e.value == pytest.approx(truth, rel=0.05 if e.slot.name == LAG else 0.01), label


def test_v_f_is_not_freed_without_a_tanh_friction():
    """No friction in the file, or the stick law: v_f has nothing to act on, so it is not
    freed (reported fixed, not 'not identifiable')."""
    from road_force_estimator.calibration.calibrate import _free_slots

    none = _with(BASE, (0.0, 0.0), (2e-3, 1e-3))
    stick = replace(NOMINAL, leaf_spring_friction_model='stick')
    for vehicle in (none, stick):
        assert V_F not in {s.name for s in _free_slots(vehicle, set(), set(), None)}
    assert V_F in {s.name for s in _free_slots(NOMINAL, set(), set(), None)}


def test_zero_nominal_stays_fixed_unless_freed():
    zero = _with(BASE, (0.0, 0.0), (0.0, 0.0))
    assert freed_start(zero, ()) == zero
    started = freed_start(zero, {FRICTION})
    assert started.leaf_spring_friction_n == (FREE_START[FRICTION],) * 2
    assert started.sensor_time_constant_s == (0.0, 0.0)
    # a side already positive keeps its value
    assert freed_start(_with(BASE, (800.0, 0.0), (0.0, 0.0)), {FRICTION}) \
        .leaf_spring_friction_n == (800.0, FREE_START[FRICTION])
    with pytest.raises(ValueError, match='only vehicle.leaf_spring_friction'):
        freed_start(zero, {'vehicle.sprung_mass'})


def test_free_with_an_unknown_name_is_one_line(road):
    with pytest.raises(CalibrationError, match='--free vehicle.sprung_mass'):
        _calibrate(road, _drive(road, 0.0, duration_s=1.0), free=frozenset({
            'vehicle.sprung_mass'}))
