"""Plant simulator (MODEL.md "States and plant dynamics"): the fixed-step RK4 trajectory against
scipy's solve_ivp on the equations written again here, natural frequencies of the free response
against the eigenvalues of matrices built here, and the identities MODEL.md lists.
"""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from road_force_estimator.core.parameters import GRAVITY_MPS2, VehicleParameters
from road_force_estimator.core.plant import Plant, PlantSample, Trajectory, simulate
from road_force_estimator.core.road import RoadProfile, add_event, flat_profile, iso8608_profile

ASYM = VehicleParameters(
    sprung_mass_kg=5200.0, roll_inertia_kgm2=2800.0, track_width_m=2.1, cg_height_m=0.7,
    unsprung_mass_kg=(430.0, 470.0), suspension_stiffness_npm=(380e3, 420e3),
    suspension_damping_nspm=(14e3, 16e3), tire_stiffness_npm=(950e3, 1050e3),
    tire_damping_nspm=(1500.0, 2500.0))
DEFAULT = VehicleParameters()
G_MPS2 = 9.80665     # standard gravity (the gravity moment M g h sin(phi) of MODEL.md)


class Reference:
    """MODEL.md's equations with the road linearly interpolated in distance, written
    independently of the package (vehicle_model is not used)."""

    def __init__(self, p, x_knots, z_knots, speed, x0=None, ay=lambda t: 0.0):
        self.p = p
        self.x = np.asarray(x_knots, dtype=float)
        self.z = np.asarray(z_knots, dtype=float)
        self.slope = np.diff(self.z, axis=0) / np.diff(self.x)[:, None]
        self.v = speed
        self.x0 = self.x[0] if x0 is None else x0
        self.ay = ay
        self.s = p.track_width_m / 2
        self.fc = [(p.sprung_mass_kg / 2 + m) * GRAVITY_MPS2 for m in p.unsprung_mass_kg]

    def road(self, t):
        if callable(self.v):    # a speed profile: (distance(t), speed(t))
            x, v = self.v(t)
            x += self.x0
        else:
            x, v = self.x0 + self.v * t, self.v
        u = [np.interp(x, self.x, self.z[:, i]) for i in (0, 1)]
        j = min(max(int(np.searchsorted(self.x, x, side='right')) - 1, 0), len(self.x) - 2)
        return u, [v * self.slope[j, 0], v * self.slope[j, 1]]

    def forces(self, t, y):
        p, s = self.p, self.s
        zs, phi, zu1, zu2, dzs, dphi, dzu1, dzu2 = y
        u, du = self.road(t)
        q = [zs + s * math.sin(phi) - zu1, zs - s * math.sin(phi) - zu2]
        dq = [dzs + s * math.cos(phi) * dphi - dzu1, dzs - s * math.cos(phi) * dphi - dzu2]
        fb = [-(p.suspension_stiffness_npm[i] * q[i] + p.suspension_damping_nspm[i] * dq[i])
              for i in (0, 1)]
        zu, dzu = [zu1, zu2], [dzu1, dzu2]
        df = [max(p.tire_stiffness_npm[i] * (u[i] - zu[i])
                  + p.tire_damping_nspm[i] * (du[i] - dzu[i]), -self.fc[i]) for i in (0, 1)]
        return q, fb, df

    def rhs(self, t, y):
        p, s = self.p, self.s
        _, fb, df = self.forces(t, y)
        phi = y[1]
        return [y[4], y[5], y[6], y[7],
                (fb[0] + fb[1]) / p.sprung_mass_kg,
                (s * math.cos(phi) * (fb[0] - fb[1])
                 + p.sprung_mass_kg * p.cg_height_m
                 * (self.ay(t) * math.cos(phi) + G_MPS2 * math.sin(phi)))
                / p.roll_inertia_kgm2,
                (df[0] - fb[0]) / p.unsprung_mass_kg[0],
                (df[1] - fb[1]) / p.unsprung_mass_kg[1]]

    def solve(self, y0, t_eval, **kw):
        opts = dict(method='DOP853', rtol=1e-10, atol=1e-12)
        opts.update(kw)
        sol = solve_ivp(self.rhs, (0.0, t_eval[-1]), y0, t_eval=t_eval, **opts)
        assert sol.status == 0, sol.message
        y = sol.y.T
        q = np.array([self.forces(t, yi)[0] for t, yi in zip(t_eval, y)])
        df = np.array([self.forces(t, yi)[2] for t, yi in zip(t_eval, y)])
        return y, q, df


def states(tr: Trajectory) -> np.ndarray:
    return np.column_stack((tr.body_heave_m, tr.roll_rad, tr.wheel_heave_m,
                            tr.body_heave_rate_mps, tr.roll_rate_radps,
                            tr.wheel_heave_rate_mps))


def relative_error(a, b):
    return np.max(np.abs(a - b)) / np.max(np.abs(b))


def test_bump_and_step_match_solve_ivp():
    # A 5 cm bump under the left wheel, a 3 cm step under the right, an asymmetric vehicle
    # with tire damping and a varying lateral acceleration: every term of the model is active.
    road = flat_profile(40.0, dx_m=0.05)
    road = add_event(road, 'bump', 'left', 5.0, 0.6, 0.05)
    road = add_event(road, 'step', 'right', 8.0, 0.4, 0.03)

    def ay(t):
        return 2.0 * math.sin(2 * math.pi * 0.7 * t)

    speed, rate = 15.0, 1000.0
    tr = simulate(ASYM, road, speed_mps=speed, rate_hz=rate, duration_s=1.2,
                  lateral_acceleration=ay)
    assert tr.substeps == 4 and tr.completed
    ref = Reference(ASYM, road.distance_m, road.elevation_m, speed, ay=ay)
    y, q, df = ref.solve(np.zeros(8), tr.t_s)
    got = states(tr)
    # Measured: at most 1.3e-9 relative (wheel rates); 1e-7 leaves margin.
    for i in range(8):
        assert relative_error(got[:, i], y[:, i]) < 1e-7, i
    assert relative_error(tr.q_m, q) < 1e-7
    assert relative_error(tr.tire_force_dynamic_n, df) < 1e-7
    np.testing.assert_allclose(tr.road_m, [ref.road(t)[0] for t in tr.t_s], atol=1e-15)


def test_speed_profile_with_braking_a_stop_and_pulling_away_matches_solve_ivp():
    # simulator.speed_profile: accelerate 5 -> 15 m/s, brake to a stop, stand 0.3 s, pull
    # away; distance = the integral of the speed, written here by hand (trapezoids of the
    # linear interpolation).
    knots_t = np.array([0.0, 0.4, 0.8, 1.1, 1.5])
    knots_v = np.array([5.0, 15.0, 0.0, 0.0, 8.0])

    def motion(t):
        x = 0.0
        for i in range(len(knots_t) - 1):
            t0, t1 = knots_t[i], knots_t[i + 1]
            a = (knots_v[i + 1] - knots_v[i]) / (t1 - t0)
            tau = min(max(t - t0, 0.0), t1 - t0)
            x += knots_v[i] * tau + 0.5 * a * tau * tau
        return x, float(np.interp(t, knots_t, knots_v))

    road = flat_profile(30.0, dx_m=0.05)
    road = add_event(road, 'bump', 'left', 3.0, 0.6, 0.03)
    road = add_event(road, 'step', 'right', 7.9, 0.4, 0.02)
    tr = simulate(ASYM, road, speed_mps=10.0, rate_hz=1000.0, duration_s=1.5,
                  speed_profile=(knots_t, knots_v))
    assert tr.completed
    ref = Reference(ASYM, road.distance_m, road.elevation_m, motion)
    y, q, df = ref.solve(np.zeros(8), tr.t_s, max_step=1e-3)
    got = states(tr)
    np.testing.assert_allclose(tr.distance_m, [motion(t)[0] for t in tr.t_s], rtol=1e-12,
                               atol=1e-12)
    for i in range(8):
        assert relative_error(got[:, i], y[:, i]) < 1e-5, i
    assert relative_error(tr.q_m, q) < 1e-5
    assert relative_error(tr.tire_force_dynamic_n, df) < 1e-5
    # standing still: the road under the tires does not move
    still = (tr.t_s >= 0.8) & (tr.t_s <= 1.1)
    assert np.ptp(tr.distance_m[still]) < 1e-12
    assert np.ptp(tr.road_m[still], axis=0).max() < 1e-15
    assert np.all(tr.road_rate_mps[still] == 0.0)


def test_iso_road_with_default_substeps_matches_solve_ivp():
    # The accuracy behind MAX_SUBSTEP_S: a class C road with tire enveloping at a speed whose
    # RK4 stage points do not fall on the road's knots, with tire damping.
    vehicle = VehicleParameters(tire_damping_nspm=(2000.0, 2000.0))
    road = iso8608_profile('C', 40.0, seed=2).enveloped(0.25)
    speed = 19.3
    tr = simulate(vehicle, road, speed_mps=speed, rate_hz=1000.0, duration_s=0.8)
    ref = Reference(vehicle, road.distance_m, road.elevation_m, speed)
    y0 = states(tr)[0]
    y, q, df = ref.solve(y0, tr.t_s, rtol=1e-9, atol=1e-11, max_step=1e-3)
    # Measured: wheel heave 1.2e-6 relative, tire force 0.03 N max on a 5 kN RMS.
    assert relative_error(tr.wheel_heave_m, y[:, 2:4]) < 1e-5
    err = np.max(np.abs(tr.tire_force_dynamic_n - df))
    assert err < 1e-4 * np.std(df)


def test_wheel_lift_off_in_a_pothole_matches_solve_ivp_and_never_pulls():
    # 8 cm deep, 0.5 m long pothole at 20 m/s: the left wheel cannot fall as fast as the road
    # drops (its free-fall acceleration is about F_c / m = 64 m/s^2), so the tire lifts off.
    road = add_event(flat_profile(30.0, dx_m=0.05), 'pothole', 'left', 6.0, 0.5, 0.08)
    speed = 20.0
    tr = simulate(DEFAULT, road, speed_mps=speed, rate_hz=1000.0, duration_s=0.8)
    loads = tr.wheel_load_n
    assert np.all(loads >= 0.0)
    lifted = loads[:, 0] == 0.0
    assert lifted.sum() >= 5
    assert np.all(tr.lift_off[:, 0] == lifted)
    assert np.all(tr.tire_force_dynamic_n[lifted, 0] == -DEFAULT.static_load_n[0])
    ref = Reference(DEFAULT, road.distance_m, road.elevation_m, speed)
    y, q, df = ref.solve(np.zeros(8), tr.t_s, max_step=2e-4)
    # RK4 steps over the contact switch (a kink in the force): first-order error there.
    # Measured at 4 substeps: 2.5e-4 relative wheel heave, 5.4 N of tire force (on 29 kN).
    assert relative_error(tr.wheel_heave_m, y[:, 2:4]) < 1e-3
    assert np.max(np.abs(tr.tire_force_dynamic_n - df)) < 1e-3 * np.max(np.abs(df))
    assert np.sum((df[:, 0] == -DEFAULT.static_load_n[0]) != lifted) <= 2


def test_huge_lateral_acceleration_lifts_the_inner_wheel_to_zero_load():
    # A 0.3 s haversine pulse of 18 m/s^2 to the left (beyond the rollover limit
    # 2 s F_c / (M h) = 14.5 m/s^2): the left (inner) wheel unloads to exactly zero first
    # (later, on the rebound, the right one lifts too).
    def ay(t):
        return 18.0 * math.sin(math.pi * (t - 0.2) / 0.3) ** 2 if 0.2 <= t <= 0.5 else 0.0

    tr = simulate(DEFAULT, flat_profile(40.0), speed_mps=20.0, rate_hz=1000.0,
                  duration_s=1.5, lateral_acceleration=ay)
    loads = tr.wheel_load_n
    assert np.all(loads >= 0.0)
    first_left = np.argmax(loads[:, 0] == 0.0)
    assert loads[first_left, 0] == 0.0 and 0.2 < tr.t_s[first_left] < 0.5
    assert np.all(loads[:first_left + 1, 1] > 0.0)
    assert np.array_equal(tr.lift_off, loads == 0.0)
    # Total vertical load identity holds through the lift-off.
    total = (sum(DEFAULT.static_load_n) + 5000.0 * tr.body_accel_mps2
             + 450.0 * tr.wheel_accel_mps2.sum(axis=1))
    np.testing.assert_allclose(loads.sum(axis=1), total, rtol=1e-11)


def matrix_pencil_poles(y, dt, order):
    """Continuous-time poles of a multichannel sum of damped exponentials (matrix pencil)."""
    n = y.shape[1]
    L = n // 2
    hankel = np.vstack([np.array([c[i:i + L + 1] for i in range(n - L)]) for c in y])
    _, _, vt = np.linalg.svd(hankel, full_matrices=False)
    v = vt[:order].T
    z = np.linalg.eigvals(np.linalg.pinv(v[:-1]) @ v[1:])
    return np.log(z.astype(complex)) / dt


@pytest.mark.parametrize('vehicle', [DEFAULT, ASYM])
def test_free_response_frequencies_match_linear_eigenvalues(vehicle):
    # A 2 mm step under the left wheel only excites all four modes (bounce, roll, wheel hop,
    # wheel tramp); after it the road is flat and the response is free.
    road = add_event(flat_profile(20.0, dx_m=0.05), 'step', 'left', 3.0, 0.05, 0.002)
    tr = simulate(vehicle, road, speed_mps=10.0, rate_hz=1000.0, duration_s=1.2)
    free = tr.t_s >= 0.31
    # The response decays to the rest state on the stepped road: with the gravity moment
    # the 2 mm cross slope leaves a constant deflection, removed here (written by hand).
    _, f = roll_equilibrium_by_hand(vehicle, 0.002, 0.0)
    (k1, k2), (kt1, kt2) = vehicle.suspension_stiffness_npm, vehicle.tire_stiffness_npm
    rest = np.array([-f / k1, f / k2, f / kt1, -f / kt2])
    signals = np.vstack((tr.q_m[free].T, (tr.road_m - tr.wheel_heave_m)[free].T)) - rest[:, None]
    poles = matrix_pencil_poles(signals[:, :700], 1e-3, 8)
    poles = poles[poles.imag > 0]
    poles = poles[np.argsort(poles.imag)]
    # Eigenvalues of the small-motion model, built here from MODEL.md.
    s = vehicle.track_width_m / 2
    G = np.array([[1.0, s, -1.0, 0.0], [1.0, -s, 0.0, -1.0]])
    E = np.array([[0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
    K = G.T @ np.diag(vehicle.suspension_stiffness_npm) @ G + E.T @ np.diag(
        vehicle.tire_stiffness_npm) @ E
    K[1, 1] -= vehicle.sprung_mass_kg * G_MPS2 * vehicle.cg_height_m   # gravity moment
    C = G.T @ np.diag(vehicle.suspension_damping_nspm) @ G + E.T @ np.diag(
        vehicle.tire_damping_nspm) @ E
    mass = np.diag([vehicle.sprung_mass_kg, vehicle.roll_inertia_kgm2,
                    *vehicle.unsprung_mass_kg])
    a = np.block([[np.zeros((4, 4)), np.eye(4)],
                  [-np.linalg.solve(mass, K), -np.linalg.solve(mass, C)]])
    lam = np.linalg.eigvals(a)
    lam = lam[lam.imag > 0]
    lam = lam[np.argsort(lam.imag)]
    assert poles.size == 4
    # Measured: 3.7e-6 (frequencies) and 7.8e-6 (decay rates) relative.
    np.testing.assert_allclose(poles.imag / (2 * np.pi), lam.imag / (2 * np.pi), rtol=5e-5)
    np.testing.assert_allclose(poles.real, lam.real, rtol=1e-4)
    if vehicle is DEFAULT:
        # MODEL.md: bounce ~1.7 Hz, wheel hop ~9 Hz (damped: 1.70 and 8.3 Hz).
        assert poles[0].imag / (2 * np.pi) == pytest.approx(1.70, abs=0.05)
        assert 8.0 < poles[-1].imag / (2 * np.pi) < 9.0


def test_zero_road_no_motion():
    tr = simulate(ASYM, flat_profile(50.0), speed_mps=20.0, rate_hz=1000.0, duration_s=2.0)
    for name in ('q_m', 'roll_rad', 'body_heave_m', 'wheel_heave_m', 'tire_force_dynamic_n',
                 'body_accel_mps2', 'roll_accel_radps2', 'wheel_accel_mps2', 'dq_mps'):
        assert np.all(getattr(tr, name) == 0.0), name
    assert np.all(tr.wheel_load_n == np.array(ASYM.static_load_n))


def test_identical_tracks_no_roll():
    road = iso8608_profile('D', 80.0, seed=4, coherence='identical')
    assert np.array_equal(road.left_m, road.right_m)
    tr = simulate(DEFAULT, road, speed_mps=20.0, rate_hz=1000.0, duration_s=3.0,
                  tire_envelope_m=0.25)
    assert np.max(np.abs(tr.q_m)) > 1e-3            # the road does move the truck ...
    assert np.all(tr.roll_rad == 0.0)               # ... but never rolls it
    assert np.array_equal(tr.q_m[:, 0], tr.q_m[:, 1])
    assert np.array_equal(tr.wheel_load_n[:, 0], tr.wheel_load_n[:, 1])


def test_total_load_identity_to_round_off():
    road = iso8608_profile('D', 100.0, seed=5)
    tr = simulate(ASYM, road, speed_mps=25.0, rate_hz=1000.0, duration_s=3.0,
                  lateral_acceleration=lambda t: 3.0 * math.sin(t), tire_envelope_m=0.25)
    m1, m2 = ASYM.unsprung_mass_kg
    rhs = (sum(ASYM.static_load_n) + ASYM.sprung_mass_kg * tr.body_accel_mps2
           + m1 * tr.wheel_accel_mps2[:, 0] + m2 * tr.wheel_accel_mps2[:, 1])
    lhs = tr.wheel_load_n.sum(axis=1)
    assert np.max(np.abs(lhs - rhs)) < 1e-10 * np.max(lhs)
    np.testing.assert_array_equal(tr.wheel_load_n,
                                  np.array(ASYM.static_load_n) + tr.tire_force_dynamic_n)


def roll_equilibrium_by_hand(p, du, ay):
    """The rest state's (phi, F) of MODEL.md written here: F_b1 = -F_b2 = F with
    2 s cos(phi) F + M h (a_y cos(phi) + g sin(phi)) = 0 and the kinematics
    2 s sin(phi) = du - F (1/k_1 + 1/k_2 + 1/kt_1 + 1/kt_2) (bisection)."""
    s = p.track_width_m / 2
    comp = sum(1 / k for k in p.suspension_stiffness_npm) + sum(1 / k for k in
                                                               p.tire_stiffness_npm)
    mh = p.sprung_mass_kg * p.cg_height_m

    def res(phi):
        return 2 * s * math.sin(phi) - du - mh * (ay + G_MPS2 * math.tan(phi)) * comp / (2 * s)

    lo, hi = -0.5, 0.5
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if res(mid) * res(lo) > 0 else (lo, mid)
    phi = 0.5 * (lo + hi)
    return phi, -mh * (ay + G_MPS2 * math.tan(phi)) / (2 * s)


def test_starts_at_equilibrium_on_a_sloped_road():
    # A 2 % grade, with the left track 3 cm above the right. The axle follows such a road
    # without a transient; on the cross slope the rolled body's weight (the gravity moment)
    # loads the lower, right side, a constant deflection from the start on.
    x = np.linspace(0.0, 60.0, 1201)
    road = RoadProfile(x, np.column_stack((0.02 * x + 0.03, 0.02 * x)))
    tr = simulate(ASYM, road, speed_mps=20.0, rate_hz=1000.0, duration_s=1.5, start_m=17.3)
    assert tr.distance_m[0] == 17.3
    phi, f = roll_equilibrium_by_hand(ASYM, 0.03, 0.0)
    k1, k2 = ASYM.suspension_stiffness_npm
    np.testing.assert_allclose(tr.q_m, np.tile([-f / k1, f / k2], (len(tr), 1)), rtol=1e-9,
                               atol=1e-12)
    np.testing.assert_allclose(tr.tire_force_dynamic_n, np.tile([f, -f], (len(tr), 1)),
                               rtol=1e-8, atol=1e-6)
    np.testing.assert_allclose(tr.roll_rad, phi, rtol=1e-10)
    assert phi > math.asin(0.03 / 2.1)          # the weight rolls it further down the slope
    np.testing.assert_allclose(tr.wheel_heave_rate_mps, 0.4, rtol=1e-9)


def test_starts_at_equilibrium_under_a_steady_lateral_acceleration():
    tr = simulate(DEFAULT, flat_profile(30.0), speed_mps=20.0, rate_hz=1000.0,
                  duration_s=1.0, lateral_acceleration=4.0)
    # Static load transfer: s cos(phi) (F_n2 - F_n1) = M h (a_y cos(phi) + g sin(phi)),
    # shared equally: 8000 N per side without the gravity moment, about 8500 N with it.
    phi, f = roll_equilibrium_by_hand(DEFAULT, 0.0, 4.0)
    assert -8700.0 < f < -8300.0
    fc = DEFAULT.static_load_n[0]
    np.testing.assert_allclose(tr.wheel_load_n[:, 0], fc + f, rtol=1e-9)
    np.testing.assert_allclose(tr.wheel_load_n[:, 1], fc - f, rtol=1e-9)
    # Left spring extends by -F / 400 kN/m, right compresses as much.
    np.testing.assert_allclose(tr.q_m, np.tile([-f / 400e3, f / 400e3], (len(tr), 1)),
                               atol=1e-12)
    np.testing.assert_allclose(tr.roll_rad, phi, rtol=1e-10)


def test_steady_curve_roll_settles_at_model_md_phi_ss():
    # Entering a 3 m/s^2 curve from the straight (a ramp over 1 s): the plant settles at
    # MODEL.md's phi_ss = M h a_y / (2 k s^2 - M g h), k the suspension in series with the
    # tire for equal sides (small angles, O(phi^2)), and at the exact rest state (unequal
    # sides: ASYM).
    for p in (DEFAULT, ASYM):
        tr = simulate(p, flat_profile(200.0), speed_mps=20.0, rate_hz=1000.0, duration_s=8.0,
                      lateral_acceleration=lambda t: 3.0 * min(t, 1.0))
        phi, _ = roll_equilibrium_by_hand(p, 0.0, 3.0)
        assert tr.roll_rad[-1] == pytest.approx(phi, rel=1e-6)
        if p is DEFAULT:
            k_e = 400e3 * 1000e3 / 1400e3
            phi_ss = 5000.0 * 0.8 * 3.0 / (2 * k_e * 1.0 - 5000.0 * G_MPS2 * 0.8)
            assert tr.roll_rad[-1] == pytest.approx(phi_ss, rel=2e-3)


def test_plant_steps_give_the_simulate_numbers():
    road = iso8608_profile('C', 60.0, seed=6)
    kw = dict(speed_mps=22.0, rate_hz=1000.0, lateral_acceleration=lambda t: math.cos(3 * t),
              tire_envelope_m=0.25, substeps=3)
    tr = simulate(ASYM, road, duration_s=1.3, **kw)      # crosses a prepared-block boundary
    plant = Plant(ASYM, road, **kw)
    samples = [plant.step() for _ in range(len(tr))]
    assert all(isinstance(s, PlantSample) for s in samples)
    for name in ('t_s', 'distance_m', 'q_m', 'roll_rad', 'wheel_heave_m', 'road_m',
                 'road_rate_mps', 'tire_force_dynamic_n', 'wheel_load_n', 'body_accel_mps2',
                 'wheel_accel_mps2', 'lateral_accel_mps2', 'dq_mps', 'roll_rate_radps'):
        got = np.array([getattr(s, name) for s in samples])
        assert np.array_equal(got, getattr(tr, name)), name
    assert tr.sample(700).wheel_load_n.tolist() == samples[700].wheel_load_n.tolist()
    plant.reset()
    again = plant.step()
    assert again.t_s == 0.0 and np.array_equal(again.q_m, samples[0].q_m)
    assert np.array_equal(plant.step().wheel_load_n, samples[1].wheel_load_n)


def test_numbers_do_not_depend_on_the_preparation_blocks(monkeypatch):
    import road_force_estimator.core.plant as plant_module
    road = iso8608_profile('C', 30.0, seed=8)
    kw = dict(speed_mps=17.0, rate_hz=800.0, duration_s=1.0, tire_envelope_m=0.25,
              lateral_acceleration=lambda t: 2.0 * math.sin(5 * t))
    tr = simulate(ASYM, road, **kw)
    monkeypatch.setattr(plant_module, '_CHUNK_SAMPLES', 7)
    small = simulate(ASYM, road, **kw)
    assert np.array_equal(states(tr), states(small))
    assert np.array_equal(tr.wheel_load_n, small.wheel_load_n)


def test_stops_at_the_end_of_the_road():
    road = flat_profile(10.0)
    tr = simulate(DEFAULT, road, speed_mps=20.0, rate_hz=1000.0, duration_s=2.0)
    assert not tr.completed
    assert len(tr) == 501 and tr.distance_m[-1] == 10.0
    assert 'end of road' in tr.stop_reason and 'truncated at 501 of 2001' in tr.stop_reason
    plant = Plant(DEFAULT, road, speed_mps=20.0, rate_hz=1000.0)
    n = 0
    while plant.step() is not None:
        n += 1
    assert n == 501 and plant.finished and 'end of road' in plant.stop_reason
    assert plant.step() is None
    # With a tire envelope the road the tire sees is shorter by the envelope length.
    tr = simulate(DEFAULT, road, speed_mps=20.0, rate_hz=1000.0, duration_s=2.0,
                  tire_envelope_m=0.5)
    assert tr.distance_m[0] == 0.25 and tr.distance_m[-1] <= 9.75 and len(tr) == 476


def test_duration_reached_exactly():
    tr = simulate(DEFAULT, flat_profile(100.0), speed_mps=20.0, rate_hz=500.0, duration_s=0.5)
    assert tr.completed and len(tr) == 251 and tr.t_s[-1] == 0.5
    assert tr.substeps == 8      # 0.25 ms step at most


def test_bad_arguments_are_refused():
    road = flat_profile(10.0)
    with pytest.raises(ValueError, match='speed_mps'):
        Plant(DEFAULT, road, speed_mps=0.0, rate_hz=1000.0)
    with pytest.raises(ValueError, match='rate_hz'):
        Plant(DEFAULT, road, speed_mps=10.0, rate_hz=float('nan'))
    with pytest.raises(ValueError, match='substeps'):
        Plant(DEFAULT, road, speed_mps=10.0, rate_hz=1000.0, substeps=0)
    stiff = VehicleParameters(tire_damping_nspm=(1e6, 1e6))
    with pytest.raises(ValueError, match='unstable'):
        Plant(stiff, road, speed_mps=10.0, rate_hz=100.0, substeps=1)
    assert Plant(stiff, road, speed_mps=10.0, rate_hz=100.0).substeps >= 40
    with pytest.raises(ValueError, match='start_m'):
        Plant(DEFAULT, road, speed_mps=10.0, rate_hz=1000.0, start_m=10.0)
    with pytest.raises(ValueError, match='duration_s'):
        simulate(DEFAULT, road, speed_mps=10.0, rate_hz=1000.0, duration_s=-1.0)
    with pytest.raises(ValueError, match='not finite'):
        Plant(DEFAULT, road, speed_mps=10.0, rate_hz=1000.0,
              lateral_acceleration=lambda t: float('nan'))
    with pytest.raises(ValueError, match='rollover'):
        Plant(DEFAULT, road, speed_mps=10.0, rate_hz=1000.0, lateral_acceleration=20.0)
    with pytest.raises(TypeError):
        Plant(DEFAULT, np.zeros((10, 2)), speed_mps=10.0, rate_hz=1000.0)
