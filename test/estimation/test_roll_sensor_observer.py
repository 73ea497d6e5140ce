"""The roll sensor in the whole vehicle's observer (``vehicle.roll_sensor``, the tractor IMU's
a_y) and the rollover warning's predictor, judged against the plant's truth."""
import pathlib

import numpy as np
import pytest

from road_force_estimator.core.articulated_setup import ArticulatedDrive
from road_force_estimator.core.parameters import (
    ObserverParameters, VehicleParameters, load_params_file)
from road_force_estimator.estimation.rollover_warning import first_reached, predicted_ltr
from road_force_estimator.estimation.whole_vehicle import estimate_whole_vehicle

CONFIG = pathlib.Path(__file__).resolve().parents[2] / 'config' / 'tractor_semitrailer.yaml'
CURVE = 'curve:start=2,ramp=3,hold=3,ay=3'
DURATION_S = 9.0


def _values(extra: dict) -> dict:
    base = load_params_file(CONFIG)
    base.update({'simulator.road': 'iso8608:C:seed=7', 'simulator.speed': 20.0,
                 'simulator.duration': DURATION_S, 'simulator.noise.deflection': 1e-5,
                 'simulator.noise.roll': 1e-5 / 0.45, 'simulator.gnss.rate': 0.0,
                 'simulator.lateral_profile': CURVE, 'vehicle.tractor_imu': True, **extra})
    return base


def _drive(extra: dict) -> dict:
    from road_force_estimator.tools.articulated_simulation import simulate

    drive = ArticulatedDrive.from_values(_values(extra))
    res = simulate(drive, route=None)
    t = res.trajectory.t_s
    return {'t': t, 'stamps': np.round(t * 1e9).astype(np.int64), 'y': res.readings,
            'ay': res.imu[:, 1], 'load': res.trajectory.wheel_load_n.T,
            'ltr': res.truth['unit_ltr'],
            'static': drive.model.statics().output_wheel_load_n.reshape(-1)}


@pytest.fixture(scope='module')
def curves():
    """The curve read by ideal roll sensors and by pendulums (the same road and truck)."""
    return {'ideal': _drive({}), 'pendulum': _drive({'simulator.roll_sensor': 'pendulum'})}


def _vehicle(roll_sensor: str):
    return ArticulatedDrive.from_values(_values({'vehicle.roll_sensor': roll_sensor})).vehicle


def _estimate(drive: dict, roll_sensor: str, imu: bool, latency_s: float = 0.01):
    y = np.column_stack([drive['y'], drive['ay']]) if imu else drive['y']
    return estimate_whole_vehicle(_vehicle(roll_sensor), drive['stamps'], y, 20.0,
                                  observer=ObserverParameters(latency_s=latency_s), imu=imu)


def _worst_axle_pct(drive: dict, est) -> float:
    judged = drive['t'] >= 2.0
    err = (est.load_n - drive['load'])[:, judged].reshape(-1, 2, int(judged.sum()))
    dyn = (drive['load'] - drive['static'][:, None])[:, judged].reshape(err.shape)
    return float(np.max(100.0 * np.sqrt(np.mean(err ** 2, axis=(1, 2))
                                        / np.mean(dyn ** 2, axis=(1, 2)))))


def test_the_parameter_is_read_by_both_models_and_kept():
    assert VehicleParameters.from_parameters({'vehicle.roll_sensor': 'pendulum'}).roll_sensor \
        == 'pendulum'
    v = _vehicle('pendulum')
    assert v.roll_sensor == 'pendulum'
    assert v.to_parameters()['vehicle.roll_sensor'] == 'pendulum'
    assert 'vehicle.roll_sensor' not in _vehicle('ideal').to_parameters()
    with pytest.raises(ValueError, match='roll_sensor'):
        VehicleParameters.from_parameters({'vehicle.roll_sensor': 'laser'})


def test_pendulums_stated_with_the_imu_estimate_the_loads_as_ideal_sensors(curves):
    """Through a curve to 3 m/s^2 pendulums read 0.3 rad of a_y / g as roll: told nothing the
    observer is far off; stated, with the IMU's a_y, within 15 % of the ideal sensors' drive
    (10 ms)."""
    ideal = _worst_axle_pct(curves['ideal'], _estimate(curves['ideal'], 'ideal', False))
    told_nothing = _worst_axle_pct(curves['pendulum'],
                                   _estimate(curves['pendulum'], 'ideal', False))
    stated = _worst_axle_pct(curves['pendulum'], _estimate(curves['pendulum'], 'pendulum', True))
    assert told_nothing > 3.0 * ideal
    assert stated <= 1.15 * ideal


def test_the_predictor_warns_no_later_than_the_truth_and_stays_within_003(curves):
    """The trailer's 0.6 warning at zero latency: the predictor on the estimate's quasi-static
    LTR reaches 0.6 no later than the truth's quasi-static LTR, and stays within 0.03 of it."""
    drive = curves['ideal']
    est = _estimate(drive, 'ideal', False, latency_s=0.0)
    true_qs = drive['ltr'][:, 3]
    pred = predicted_ltr(est.stamps_ns, est.ltr_quasi_static[1])
    k_true = first_reached(true_qs)
    k_pred = first_reached(pred)
    assert k_true is not None and k_pred is not None
    assert k_pred <= k_true
    judged = drive['t'] >= 2.0
    assert np.max(np.abs(pred - true_qs)[judged]) < 0.03


def test_the_predictor_extrapolates_a_ramp_and_leaves_a_constant():
    stamps = np.arange(0, 1_000_000_000, 1_000_000, dtype=np.int64)
    t = stamps * 1e-9
    ramp = predicted_ltr(stamps, 0.3 * t, lead_s=0.005, rate_window_s=0.05)
    after = t >= 0.05
    np.testing.assert_allclose(ramp[after], 0.3 * (t[after] + 0.005), atol=1e-12)
    flat = predicted_ltr(stamps, np.full((2, t.size), 0.4))
    np.testing.assert_array_equal(flat, 0.4)
    assert first_reached(0.3 * t, 0.15) == 500
    assert first_reached(0.3 * t, 0.5) is None
