"""What the 4-DOF model leaves out, in the plant and the sensors (MODEL.md "What the model
leaves out", issue 19): leaf-spring friction, progressive springs and bump stops against
scipy's solve_ivp on the equations written again here; the first-order sensor lag against its
analytic response; scale errors, offsets and stamp jitter as documented.
"""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from road_force_estimator.core.parameters import SimulatorParameters, VehicleParameters
from road_force_estimator.core.plant import simulate
from road_force_estimator.core.road import add_event, flat_profile
from road_force_estimator.core.sensors import SensorModel
from road_force_estimator.core.vehicle_model import SpringOptions

G = 9.80665
V_F = 0.01          # the friction's smoothing velocity (m/s), as documented
TRUCK = VehicleParameters(
    sprung_mass_kg=5200.0, roll_inertia_kgm2=2800.0, track_width_m=2.1, cg_height_m=0.7,
    unsprung_mass_kg=(430.0, 470.0), suspension_stiffness_npm=(380e3, 420e3),
    suspension_damping_nspm=(14e3, 16e3), tire_stiffness_npm=(950e3, 1050e3),
    tire_damping_nspm=(0.0, 0.0), leaf_spring_friction_n=(1500.0, 2000.0))
SPRINGS = SpringOptions(progression_per_m=20.0, bump_stop_clearance_m=0.01,
                        bump_stop_stiffness_npm=2e6)


def reference_rhs(p, springs, road_x, road_z, motion, ay):
    """MODEL.md's equations with friction -F_f tanh(dq / v_f) and the spring force
    -k q (1 + a max(-q, 0)) + k_b max(-q - d, 0), written independently of the package."""
    s = p.track_width_m / 2
    m_s, h = p.sprung_mass_kg, p.cg_height_m
    fc = [(m_s / 2 + m) * G for m in p.unsprung_mass_kg]

    def spring(i, q):
        k = p.suspension_stiffness_npm[i]
        f = -k * q * (1.0 + springs.progression_per_m * max(-q, 0.0))
        return f + springs.bump_stop_stiffness_npm * max(-q - springs.bump_stop_clearance_m,
                                                         0.0)

    def rhs(t, y):
        zs, phi, zu1, zu2, dzs, dphi, dzu1, dzu2 = y
        x = motion(t)
        u = [np.interp(x, road_x, road_z[:, i]) for i in (0, 1)]
        q = [zs + s * math.sin(phi) - zu1, zs - s * math.sin(phi) - zu2]
        dq = [dzs + s * math.cos(phi) * dphi - dzu1, dzs - s * math.cos(phi) * dphi - dzu2]
        fb = [spring(i, q[i]) - p.suspension_damping_nspm[i] * dq[i]
              - p.leaf_spring_friction_n[i] * math.tanh(dq[i] / V_F) for i in (0, 1)]
        zu = (zu1, zu2)
        df = [max(p.tire_stiffness_npm[i] * (u[i] - zu[i]), -fc[i]) for i in (0, 1)]
        return [dzs, dphi, dzu1, dzu2, (fb[0] + fb[1]) / m_s,
                (s * math.cos(phi) * (fb[0] - fb[1])
                 + m_s * h * (ay(t) * math.cos(phi) + G * math.sin(phi))) / p.roll_inertia_kgm2,
                (df[0] - fb[0]) / p.unsprung_mass_kg[0], (df[1] - fb[1]) / p.unsprung_mass_kg[1]]

    return rhs


@pytest.mark.parametrize('springs', [SPRINGS, None])
def test_friction_progressive_springs_bump_stops_and_speed_profile_match_solve_ivp(springs):
    # A 6 cm bump (into the bump stops) and a step, braking from 12 m/s to 3 m/s and on, a
    # lateral acceleration ramp (the gravity moment and the roll), friction on both sides;
    # with and without the nonlinear springs (two code paths of the plant).
    knots_t = np.array([0.0, 0.5, 1.0, 1.5])
    knots_v = np.array([12.0, 3.0, 3.0, 10.0])

    def motion(t):
        x = 0.0
        for i in range(len(knots_t) - 1):
            t0, t1 = knots_t[i], knots_t[i + 1]
            a = (knots_v[i + 1] - knots_v[i]) / (t1 - t0)
            tau = min(max(t - t0, 0.0), t1 - t0)
            x += knots_v[i] * tau + 0.5 * a * tau * tau
        return x

    def ay(t):
        return 2.0 * min(t / 0.5, 1.0)

    road = flat_profile(30.0, dx_m=0.05)
    road = add_event(road, 'bump', 'left', 2.0, 0.8, 0.06)
    road = add_event(road, 'step', 'right', 5.0, 0.3, -0.02)
    tr = simulate(TRUCK, road, speed_mps=10.0, rate_hz=1000.0, duration_s=1.5,
                  speed_profile=(knots_t, knots_v), lateral_acceleration=ay, springs=springs)
    assert tr.completed
    rhs = reference_rhs(TRUCK, springs or SpringOptions(), road.distance_m, road.elevation_m,
                        motion, ay)
    sol = solve_ivp(rhs, (0.0, tr.t_s[-1]), np.zeros(8), t_eval=tr.t_s, method='DOP853',
                    rtol=1e-10, atol=1e-12, max_step=2.5e-4)
    assert sol.status == 0
    y = sol.y.T
    got = np.column_stack((tr.body_heave_m, tr.roll_rad, tr.wheel_heave_m,
                           tr.body_heave_rate_mps, tr.roll_rate_radps, tr.wheel_heave_rate_mps))
    for i in range(8):
        err = np.max(np.abs(got[:, i] - y[:, i])) / np.max(np.abs(y[:, i]))
        assert err < 1e-4, (i, err)
    # the effects did act: the bump stop engaged, friction saturated
    assert np.min(tr.q_m[:, 0]) < -SPRINGS.bump_stop_clearance_m or springs is None
    assert np.max(np.abs(tr.dq_mps)) > 10 * V_F
    # and the suspension force reported is the one of the equations
    s = TRUCK.track_width_m / 2
    q_ref = np.column_stack([y[:, 0] + s * np.sin(y[:, 1]) - y[:, 2],
                             y[:, 0] - s * np.sin(y[:, 1]) - y[:, 3]])
    assert np.max(np.abs(tr.q_m - q_ref)) < 1e-4 * np.max(np.abs(q_ref))


def test_without_the_options_the_plant_is_unchanged():
    road = add_event(flat_profile(30.0), 'bump', 'left', 2.0, 0.8, 0.03)
    base = simulate(VehicleParameters(), road, speed_mps=10.0, rate_hz=1000.0, duration_s=1.0)
    off = simulate(VehicleParameters(), road, speed_mps=10.0, rate_hz=1000.0, duration_s=1.0,
                   springs=SpringOptions())
    assert np.array_equal(base.q_m, off.q_m) and np.array_equal(base.wheel_load_n,
                                                                 off.wheel_load_n)
    rub = simulate(VehicleParameters(leaf_spring_friction_n=(1500.0, 1500.0)), road,
                   speed_mps=10.0, rate_hz=1000.0, duration_s=1.0)
    assert np.max(np.abs(rub.q_m - base.q_m)) > 1e-4     # friction changes the motion


def test_steady_curve_with_friction_settles_at_model_md_phi_ss():
    # The smoothed friction has no stiction: in a steady 3 m/s^2 curve the roll settles at
    # MODEL.md's phi_ss = M h a_y / (2 k_e s^2 - M g h) (k_e: suspension and tire in series).
    p = VehicleParameters(leaf_spring_friction_n=(1500.0, 1500.0))
    tr = simulate(p, flat_profile(300.0), speed_mps=20.0, rate_hz=1000.0, duration_s=12.0,
                  lateral_acceleration=lambda t: 3.0 * min(t, 1.0))
    k_e = 400e3 * 1000e3 / 1400e3
    phi_ss = 5000.0 * 0.8 * 3.0 / (2 * k_e * 1.0 - 5000.0 * G * 0.8)
    assert tr.roll_rad[-1] == pytest.approx(phi_ss, rel=3e-3)


@pytest.mark.parametrize('tau', [0.003, 0.02])
def test_sensor_lag_is_the_analytic_first_order_response(tau):
    # y = A sin(w t) from m(0) = y(0) = 0: m = A (sin wt - w tau cos wt + w tau e^(-t/tau))
    # / (1 + (w tau)^2); and a ramp: m = y - r tau (1 - e^(-t/tau)), exact on the sample grid.
    rate = 1000.0
    t = np.arange(2000) / rate
    w, amp = 2 * math.pi * 15.0, 0.01
    wt = w * tau
    sensor = SensorModel(time_constant_s=(tau, tau), rate_hz=rate)
    sine = amp * np.sin(w * t)
    q, _ = sensor.measure(np.column_stack([sine, sine]), np.zeros_like(t))
    expect = amp * (np.sin(w * t) - wt * np.cos(w * t) + wt * np.exp(-t / tau)) / (1 + wt * wt)
    assert np.max(np.abs(q[:, 0] - expect)) < 2e-3 * amp
    r = 0.05
    _, roll = sensor.measure(np.zeros((t.size, 2)), r * t)
    np.testing.assert_allclose(roll, r * t - r * tau * (1 - np.exp(-t / tau)), rtol=0,
                               atol=1e-15)
    # the per-sample path gives the same numbers
    f = sensor.sampler()
    one = np.array([f(np.array([a, a]), 0.0)[0] for a in sine])
    assert np.array_equal(one, q)


def test_only_the_lagged_channel_lags():
    t = np.arange(500) / 1000.0
    y = np.sin(2 * math.pi * 5 * t)
    q, roll = SensorModel(time_constant_s=(0.0, 0.01), rate_hz=1000.0).measure(
        np.column_stack([y, y]), y)
    assert np.array_equal(q[:, 0], y) and not np.allclose(roll, y, atol=1e-3)


def test_scale_error_and_offset_exactly_as_documented():
    rng = np.random.default_rng(5)
    q, phi = rng.normal(size=(100, 2)) * 0.01, rng.normal(size=100) * 0.01
    sensor = SensorModel(scale_error=(0.02, -0.02, 0.01), offset=(0.001, -0.002, 0.0005))
    qm, pm = sensor.measure(q, phi)
    np.testing.assert_allclose(qm, q * [1.02, 0.98] + [0.001, -0.002], rtol=0, atol=1e-17)
    np.testing.assert_allclose(pm, phi * 1.01 + 0.0005, rtol=0, atol=1e-17)
    # with noise: the same draws as without the distortion (one stream, q_1, q_2, phi)
    noisy = SensorModel(1e-5, 1e-4, seed=3, scale_error=(0.02, 0.0, 0.0))
    plain = SensorModel(1e-5, 1e-4, seed=3)
    a, _ = noisy.measure(q, phi)
    b, _ = plain.measure(q, phi)
    np.testing.assert_allclose(a[:, 0] - b[:, 0], 0.02 * q[:, 0], rtol=0, atol=1e-17)


def test_stamp_jitter_is_uniform_within_its_bound_and_leaves_the_noise():
    j = 50e-6
    sensor = SensorModel(1e-5, 1e-4, seed=7, stamp_jitter_s=j)
    off = sensor.stamp_offsets_s(200_000)
    assert np.max(np.abs(off)) <= j
    assert np.max(off) > 0.999 * j and np.min(off) < -0.999 * j
    assert abs(np.mean(off)) < 0.01 * j
    assert np.std(off) == pytest.approx(j / math.sqrt(3.0), rel=0.01)   # uniform
    assert np.mean(np.abs(off) < j / 2) == pytest.approx(0.5, abs=0.01)
    f = sensor.stamp_sampler()
    assert np.array_equal([f() for _ in range(3000)], off[:3000])
    q = np.zeros((50, 2))
    a, _ = sensor.measure(q, np.zeros(50))
    b, _ = SensorModel(1e-5, 1e-4, seed=7).measure(q, np.zeros(50))
    assert np.array_equal(a, b)
    assert np.array_equal(SensorModel().stamp_offsets_s(4), np.zeros(4))


def test_simulator_parameters_refuse_a_jitter_that_reorders_stamps():
    SimulatorParameters(rate_hz=1000.0, stamp_jitter_s=4e-4)
    with pytest.raises(ValueError, match='stamp_jitter'):
        SimulatorParameters(rate_hz=1000.0, stamp_jitter_s=5e-4)
    sim = SimulatorParameters(sensor_scale_error_deflection=(0.02, -0.02),
                              sensor_offset_roll_rad=0.001, stamp_jitter_s=1e-5)
    sensor = SensorModel.from_simulator(sim, VehicleParameters(sensor_time_constant_s=(0.003,
                                                                                        0.0)))
    assert sensor.scale_error == (0.02, -0.02, 0.0)
    assert sensor.offset == (0.0, 0.0, 0.001)
    assert sensor.time_constant_s == (0.003, 0.0) and sensor.rate_hz == 1000.0
    assert sensor.stamp_jitter_s == 1e-5
