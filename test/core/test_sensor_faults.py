"""Sensor faults and roll-sensor physics (MODEL.md "Sensor faults"; core.sensor_faults,
core.roll_sensors) in both plants' sensor models: where they strike, what they add, the
batch and per-sample paths alike, one-line refusals."""
import math

import numpy as np
import pytest

from road_force_estimator.core.articulated_parameters import ArticulatedParameters
from road_force_estimator.core.articulated_plant import simulate_articulated
from road_force_estimator.core.articulated_sensors import ArticulatedSensors, channel_layout
from road_force_estimator.core.parameters import GRAVITY_MPS2, SimulatorParameters
from road_force_estimator.core.roll_sensors import RollSensor
from road_force_estimator.core.road import iso8608_profile
from road_force_estimator.core.sensor_faults import FaultPlan, parse_faults
from road_force_estimator.core.sensors import SensorModel
from road_force_estimator.interfaces import DEFLECTION_JOINTS, articulated_deflection_joints

RATE = 1000.0


def _sim(**kw):
    return SimulatorParameters(rate_hz=RATE, duration_s=10.0, noise_deflection_m=0.0,
                               noise_roll_rad=0.0, **kw)


def test_spikes_stuck_and_drift_are_where_and_what_the_spec_says():
    spec = ('spikes@left_suspension:count=5,size=5e-4,start=2,end=8; '
            'stuck@right_suspension:start=3,duration=2; drift@roll:rate=1e-4,start=1')
    sensors = SensorModel.from_simulator(_sim(sensor_faults=spec), channels=DEFLECTION_JOINTS)
    n = 10001
    t = np.arange(n) / RATE
    q = np.column_stack([1e-3 * np.sin(t), 2e-3 * np.cos(3 * t)])
    phi = 0.01 * np.sin(0.5 * t)
    qm, pm = sensors.measure(q, phi)
    d = qm[:, 0] - q[:, 0]
    hit = np.flatnonzero(d != 0.0)
    assert hit.size == 5 and np.all((hit >= 2000) & (hit <= 8000))
    np.testing.assert_allclose(np.abs(d[hit]), 5e-4, rtol=1e-12)
    stuck = (t >= 3.0) & (t < 5.0)
    assert np.all(qm[stuck, 1] == qm[3000, 1]) and qm[3000, 1] == q[3000, 1]
    np.testing.assert_array_equal(qm[~stuck, 1], q[~stuck, 1])
    np.testing.assert_allclose(pm - phi, np.where(t >= 1.0, 1e-4 * (t - 1.0), 0.0),
                               atol=1e-15)
    truth = sensors.faults.truth()
    assert truth[0]['samples'] == hit.tolist() and truth[1]['window'] == [3000, 5000]
    # the per-sample path gives the same numbers
    one = sensors.sampler()
    rows = [one(q[k], phi[k]) for k in range(n)]
    assert np.array_equal(np.array([r[0] for r in rows]), qm)
    assert np.array_equal(np.array([r[1] for r in rows]), pm)


def test_the_spikes_are_seeded_and_counted_per_fault():
    faults = parse_faults('spikes@a:count=40,size=1e-3; spikes@a:count=3,size=1', ('a', 'b'))
    one = FaultPlan(faults, ('a', 'b'), 100.0, 60.0, seed=7)
    two = FaultPlan(faults, ('a', 'b'), 100.0, 60.0, seed=7)
    other = FaultPlan(faults, ('a', 'b'), 100.0, 60.0, seed=8)
    assert one.spikes == two.spikes and one.spikes != other.spikes
    assert [len(f['samples']) for f in one.truth()] == [40, 3]
    assert not one.spikes[1]


@pytest.mark.parametrize('text, message', [
    ('spike@left_suspension:count=1,size=1', r'KIND one of spikes, stuck, drift'),
    ('spikes@front_left_suspension:count=1,size=1',
     r"no channel 'front_left_suspension' \(the channels: left_suspension, right_suspension, "
     r'roll\)'),
    ('stuck@roll:start=1', r'duration not given'),
    ('drift@roll:rate=x', r"'rate=x' is not KEY=NUMBER"),
    ('spikes@roll:count=2.5,size=1', r'count must be a whole number'),
    ('drift@roll:rate=1,speed=2', r"unknown key 'speed'"),
])
def test_a_bad_fault_is_refused_in_one_line(text, message):
    with pytest.raises(ValueError, match=message) as err:
        SensorModel.from_simulator(_sim(sensor_faults=text), channels=DEFLECTION_JOINTS)
    assert '\n' not in str(err.value) and str(err.value).startswith('simulator.sensor_faults')


def test_too_many_spikes_are_refused():
    with pytest.raises(ValueError, match='do not fit'):
        FaultPlan(parse_faults('spikes@a:count=20,size=1', ('a',)), ('a',), 10.0, 1.0, 1)


def test_a_pendulum_reads_the_lateral_acceleration_and_a_gyro_drifts():
    n = 20001
    t = np.arange(n) / RATE
    phi = 0.02 * np.sin(t)
    ay = 2.5 * np.sin(0.3 * t)
    pendulum = RollSensor('pendulum', rate_hz=RATE)
    np.testing.assert_array_equal(pendulum.read(phi, t, ay), phi + ay / GRAVITY_MPS2)
    drift = RollSensor('gyro', drift_radps=1e-3, rate_hz=RATE)
    np.testing.assert_allclose(drift.read(phi, t) - phi, 1e-3 * t, atol=1e-15)
    # the random walk's spread grows as sigma_w sqrt(t): 400 independent walks of 20 s
    walks = np.array([RollSensor('gyro', random_walk=2e-3, rate_hz=RATE, seed=s).read(
        np.zeros(n), t)[-1] for s in range(400)])
    assert np.std(walks) == pytest.approx(2e-3 * math.sqrt(20.0), rel=0.12)
    for sensor in (pendulum, drift, RollSensor('gyro', 1e-4, 1e-3, RATE, 3)):
        one = sensor.sampler()
        got = [one(float(p), float(tt), float(a)) for p, tt, a in zip(phi, t, ay)]
        assert np.array_equal(got, sensor.read(phi, t, ay))


def test_the_front_axle_sensors_take_the_roll_physics_before_the_lag():
    sim = _sim(roll_sensor='pendulum')
    sensors = SensorModel.from_simulator(sim, channels=DEFLECTION_JOINTS)
    t = np.arange(1000) / RATE
    _, pm = sensors.measure(np.zeros((1000, 2)), np.zeros(1000), 3.0 * np.ones(1000))
    np.testing.assert_allclose(pm, 3.0 / GRAVITY_MPS2, rtol=1e-15)
    assert SensorModel.from_simulator(_sim(), channels=DEFLECTION_JOINTS).roll_sensor is None
    assert t.size == pm.size


def test_the_articulated_sensors_every_option_per_channel():
    v = ArticulatedParameters.from_parameters({
        'vehicle.axle.trailer_2.instrumented': False, 'vehicle.trailer_roll_sensor': False,
        'vehicle.axle.drive.sensor_time_constant': 0.003,
        'simulator.axle.front.sensor_scale_error': [0.02, 0.0],
        'simulator.axle.trailer_3.sensor_offset': [0.0, 1e-3],
        'vehicle.tractor_imu': True})
    road = iso8608_profile('C', 200.0, seed=4)
    tr = simulate_articulated(v, road, speed_mps=20.0, rate_hz=RATE, duration_s=3.0,
                              tire_envelope_m=0.25, lateral_acceleration=2.0)
    names = articulated_deflection_joints(
        [a.name for a in v.axles if a.instrumented], v.trailer_roll_sensor)
    assert names[-1] == 'tractor_roll' and 'trailer_2_left_suspension' not in names
    sim = SimulatorParameters(rate_hz=RATE, duration_s=3.0, noise_deflection_m=0.0,
                              noise_roll_rad=0.0, roll_sensor='pendulum',
                              sensor_faults='spikes@drive_right_suspension:count=3,size=1e-3')
    sensors = ArticulatedSensors(tr.model, sim, names)
    sensors.set_imu_noise(0.05, 0.002)
    y = sensors.measure(tr)
    layout = channel_layout(tr.model)
    assert len(layout) == len(names) == y.shape[1] == 9
    q = tr.q_m
    np.testing.assert_allclose(y[:, 0], 1.02 * q[:, 0], rtol=1e-12)       # front left
    np.testing.assert_allclose(y[:, 8], tr.state[:, 2] + 2.0 / GRAVITY_MPS2, rtol=1e-12)
    assert np.max(np.abs(y[:, 2] - q[:, 2])) > 0.0                       # the lag acts
    np.testing.assert_allclose(y[:, 7], q[:, 9] + 1e-3, rtol=1e-12)      # trailer_3 right
    clean = ArticulatedSensors(tr.model, SimulatorParameters(
        rate_hz=RATE, duration_s=3.0, noise_deflection_m=0.0, noise_roll_rad=0.0,
        roll_sensor='pendulum'), names).measure(tr)
    spiked = np.flatnonzero(y[:, 3] != clean[:, 3])
    assert spiked.size == 3
    np.testing.assert_allclose(np.abs(y[spiked, 3] - clean[spiked, 3]), 1e-3, rtol=1e-9)
    np.testing.assert_array_equal(np.delete(y, 3, axis=1), np.delete(clean, 3, axis=1))
    imu = sensors.imu(tr)
    assert imu.shape == (len(tr), 6)
    assert np.mean(imu[:, 2]) == pytest.approx(GRAVITY_MPS2, abs=0.05)   # reads +g at rest
    assert np.mean(imu[:, 1]) == pytest.approx(2.0, abs=0.01)
    assert np.mean(imu[:, 5]) == pytest.approx(2.0 / 20.0, abs=0.001)  # yaw rate = a_y / v
