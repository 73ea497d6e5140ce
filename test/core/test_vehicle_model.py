"""Vehicle model (MODEL.md "States and plant dynamics"): checked against the equations written
again here from MODEL.md, against finite differences, and against the figures MODEL.md quotes.
"""
import math

import numpy as np
import pytest

from road_force_estimator.core.parameters import GRAVITY_MPS2, VehicleParameters
from road_force_estimator.core.vehicle_model import State, VehicleModel

# An asymmetric vehicle (every left/right pair differs) with tire damping, so that index and
# sign slips show up.
ASYM = VehicleParameters(
    sprung_mass_kg=5200.0, roll_inertia_kgm2=2800.0, track_width_m=2.1, cg_height_m=0.7,
    unsprung_mass_kg=(430.0, 470.0), suspension_stiffness_npm=(380e3, 420e3),
    suspension_damping_nspm=(14e3, 16e3), tire_stiffness_npm=(950e3, 1050e3),
    tire_damping_nspm=(1500.0, 2500.0))


G_MPS2 = 9.80665     # standard gravity (the gravity moment M g h sin(phi) of MODEL.md)


def reference_rhs(p, y, u, du, ay):
    """MODEL.md's equations of motion, written independently of vehicle_model."""
    M, Ix, s, h = p.sprung_mass_kg, p.roll_inertia_kgm2, p.track_width_m / 2, p.cg_height_m
    zs, phi, zu1, zu2, dzs, dphi, dzu1, dzu2 = y
    q1 = zs + s * math.sin(phi) - zu1
    q2 = zs - s * math.sin(phi) - zu2
    dq1 = dzs + s * math.cos(phi) * dphi - dzu1
    dq2 = dzs - s * math.cos(phi) * dphi - dzu2
    fb1 = -(p.suspension_stiffness_npm[0] * q1 + p.suspension_damping_nspm[0] * dq1)
    fb2 = -(p.suspension_stiffness_npm[1] * q2 + p.suspension_damping_nspm[1] * dq2)
    fc1 = (M / 2 + p.unsprung_mass_kg[0]) * GRAVITY_MPS2
    fc2 = (M / 2 + p.unsprung_mass_kg[1]) * GRAVITY_MPS2
    df1 = max(p.tire_stiffness_npm[0] * (u[0] - zu1) + p.tire_damping_nspm[0] * (du[0] - dzu1),
              -fc1)
    df2 = max(p.tire_stiffness_npm[1] * (u[1] - zu2) + p.tire_damping_nspm[1] * (du[1] - dzu2),
              -fc2)
    return np.array([
        dzs, dphi, dzu1, dzu2,
        (fb1 + fb2) / M,
        (s * math.cos(phi) * (fb1 - fb2) + M * h * (ay * math.cos(phi) + G_MPS2 * math.sin(phi)))
        / Ix,
        (-fb1 + df1) / p.unsprung_mass_kg[0],
        (-fb2 + df2) / p.unsprung_mass_kg[1],
    ])


def reference_matrices(p):
    """M, C, K of the small-motion model, from the potential and dissipation energies
    V = 1/2 sum k_i q_i^2 + kt_i (z_ui - u_i)^2 + M g h cos(phi) with q_i = z_s +- s phi - z_ui
    (the body's weight at h above the roll axis: -M g h in the roll stiffness)."""
    s = p.track_width_m / 2
    # q = G x for x = (z_s, phi, z_u1, z_u2); tire deflection = E x.
    G = np.array([[1.0, s, -1.0, 0.0], [1.0, -s, 0.0, -1.0]])
    E = np.array([[0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
    K = G.T @ np.diag(p.suspension_stiffness_npm) @ G + E.T @ np.diag(p.tire_stiffness_npm) @ E
    K[1, 1] -= p.sprung_mass_kg * G_MPS2 * p.cg_height_m
    C = G.T @ np.diag(p.suspension_damping_nspm) @ G + E.T @ np.diag(p.tire_damping_nspm) @ E
    mass = np.diag([p.sprung_mass_kg, p.roll_inertia_kgm2, *p.unsprung_mass_kg])
    return mass, C, K


def test_state_slots():
    assert [s.name for s in State] == ['Z_S', 'PHI', 'Z_U1', 'Z_U2', 'DZ_S', 'DPHI', 'DZ_U1',
                                       'DZ_U2']


@pytest.mark.parametrize('vehicle', [VehicleParameters(), ASYM])
def test_derivatives_match_model_md_equations(vehicle):
    model = VehicleModel(vehicle)
    fast = model.make_accelerations()
    rng = np.random.default_rng(3)
    for _ in range(200):
        y = rng.normal(size=8) * [0.02, 0.05, 0.01, 0.01, 0.2, 0.3, 0.5, 0.5]
        u = rng.normal(size=2) * 0.01
        du = rng.normal(size=2) * 0.3
        ay = rng.normal() * 3.0
        ref = reference_rhs(vehicle, y, u, du, ay)
        np.testing.assert_allclose(model.derivatives(y, u, du, ay), ref, rtol=1e-12,
                                   atol=1e-9)
        np.testing.assert_allclose(fast(*y, *u, *du, ay), ref[4:], rtol=1e-12, atol=1e-9)


def test_array_path_broadcasts_over_samples():
    model = VehicleModel(ASYM)
    rng = np.random.default_rng(4)
    y = rng.normal(size=(50, 8)) * 0.01
    u = rng.normal(size=(50, 2)) * 0.01
    du = rng.normal(size=(50, 2)) * 0.1
    ay = rng.normal(size=50)
    batch = model.derivatives(y, u, du, ay)
    for i in range(50):
        np.testing.assert_allclose(batch[i], reference_rhs(ASYM, y[i], u[i], du[i], ay[i]),
                                   rtol=1e-12, atol=1e-9)


def test_outputs_function_agrees_with_evaluate_and_load_identity():
    model = VehicleModel(ASYM)
    outputs = model.make_outputs()
    rng = np.random.default_rng(5)
    fc = np.array(ASYM.static_load_n)
    for _ in range(100):
        y = rng.normal(size=8) * 0.01
        u, du, ay = rng.normal(size=2) * 0.01, rng.normal(size=2) * 0.1, rng.normal()
        o = outputs(*y, *u, *du, ay)
        e = model.evaluate(y, u, du, ay)
        np.testing.assert_allclose(o[0:2], e.q_m, rtol=1e-13, atol=1e-15)
        np.testing.assert_allclose(o[6:8], e.tire_force_dynamic_n, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(o[8:10], e.wheel_load_n, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(o[10:14], model.derivatives(y, u, du, ay)[4:], rtol=1e-12,
                                   atol=1e-9)
        # MODEL.md: F_n1 + F_n2 = F_c1 + F_c2 + M ddz_s + m_1 ddz_u1 + m_2 ddz_u2.
        rhs = (fc.sum() + ASYM.sprung_mass_kg * o[10] + ASYM.unsprung_mass_kg[0] * o[12]
               + ASYM.unsprung_mass_kg[1] * o[13])
        assert o[8] + o[9] == pytest.approx(rhs, rel=1e-12)


def test_tire_never_pulls():
    model = VehicleModel(VehicleParameters())
    fc = VehicleParameters().static_load_n[0]
    # Wheel 5 cm above the road: the free tire force would be -50 kN, beyond -F_c.
    y = np.array([0.05, 0.0, 0.05, 0.0, 0.0, 0.0, 0.0, 0.0])
    out = model.evaluate(y, [0.0, 0.0])
    assert out.tire_force_dynamic_n[0] == -fc
    assert out.wheel_load_n[0] == 0.0
    assert out.lift_off.tolist() == [True, False]
    # The lifted wheel only feels its suspension: m_1 ddz_u1 = -F_b1 - F_c1.
    assert out.wheel_accel_mps2[0] == pytest.approx(
        (-out.suspension_force_n[0] - fc) / 450.0, rel=1e-12)
    g = model.make_outputs()(*y, 0.0, 0.0, 0.0, 0.0, 0.0)
    assert g[6] == -fc and g[8] == 0.0


def test_sign_conventions():
    model = VehicleModel(VehicleParameters())
    # Left road higher: the body rolls left side up (phi > 0).
    eq = model.equilibrium([0.02, 0.0])
    assert eq[State.PHI] > 0.0
    # A left turn (a_y > 0) rolls the body outward, to the right: left side up, phi > 0, the
    # left suspension extends and the right (outer) wheel carries more load.
    eq = model.equilibrium([0.0, 0.0], lateral_accel_mps2=3.0)
    out = model.evaluate(eq, [0.0, 0.0], lateral_accel_mps2=3.0)
    assert eq[State.PHI] > 0.0
    assert out.q_m[0] > 0.0 > out.q_m[1]
    assert out.wheel_load_n[1] > out.wheel_load_n[0]
    # Load transfer s cos(phi) (F_n2 - F_n1) = M h (a_y cos(phi) + g sin(phi)) (moments
    # about the roll axis, with the gravity moment of the rolled body).
    phi = eq[State.PHI]
    assert (out.wheel_load_n[1] - out.wheel_load_n[0]) * 1.0 * math.cos(phi) == pytest.approx(
        5000.0 * 0.8 * (3.0 * math.cos(phi) + G_MPS2 * math.sin(phi)), rel=1e-12)


@pytest.mark.parametrize('ay', [0.0, 4.0, -7.5])
def test_equilibrium_is_at_rest(ay):
    model = VehicleModel(ASYM)
    u = [0.013, -0.008]
    eq = model.equilibrium(u, lateral_accel_mps2=ay)
    np.testing.assert_allclose(reference_rhs(ASYM, eq, u, [0.0, 0.0], ay), 0.0, atol=1e-9)
    # With a road moving at a common rate the axle follows it: no force, no acceleration.
    eq = model.equilibrium(u, [0.3, 0.3], lateral_accel_mps2=ay)
    np.testing.assert_allclose(reference_rhs(ASYM, eq, u, [0.3, 0.3], ay)[4:], 0.0, atol=1e-9)


def test_equilibrium_beyond_rollover_is_refused():
    model = VehicleModel(VehicleParameters())
    # Lift-off when M h (a_y + g tan(phi)) / (2 s) > F_c, at the roll of that load transfer:
    # 2 s sin(phi) = F_c (2/k + 2/kt), a_y > 2 s F_c / (M h) - g tan(phi) = 13.3 m/s^2.
    fc = VehicleParameters().static_load_n[0]
    phi = math.asin(fc * (2 / 400e3 + 2 / 1000e3) / 2.0)
    limit = 2 * 1.0 * fc / (5000.0 * 0.8) - G_MPS2 * math.tan(phi)
    assert 13.0 < limit < 13.6
    model.equilibrium([0.0, 0.0], lateral_accel_mps2=0.99 * limit)
    with pytest.raises(ValueError, match='rollover'):
        model.equilibrium([0.0, 0.0], lateral_accel_mps2=1.01 * limit)


@pytest.mark.parametrize('vehicle', [VehicleParameters(), ASYM])
def test_linearised_matrices_match_energy_derivation(vehicle):
    lin = VehicleModel(vehicle).linearised()
    mass, C, K = reference_matrices(vehicle)
    np.testing.assert_allclose(lin.mass, mass, rtol=1e-14)
    np.testing.assert_allclose(lin.stiffness, K, rtol=1e-14, atol=1e-6)
    np.testing.assert_allclose(lin.damping, C, rtol=1e-14, atol=1e-9)
    kt1, kt2 = vehicle.tire_stiffness_npm
    ct1, ct2 = vehicle.tire_damping_nspm
    np.testing.assert_allclose(lin.road_stiffness, [[0, 0], [0, 0], [kt1, 0], [0, kt2]])
    np.testing.assert_allclose(lin.road_damping, [[0, 0], [0, 0], [ct1, 0], [0, ct2]])
    np.testing.assert_allclose(lin.lateral, [0, vehicle.sprung_mass_kg * vehicle.cg_height_m,
                                             0, 0])


def test_state_matrices_are_the_jacobian_of_the_nonlinear_model():
    model = VehicleModel(ASYM)
    a, b = model.linearised().state_matrices()
    eps = 1e-7
    zero_in = np.zeros(5)

    def f(y, inp):
        return reference_rhs(ASYM, y, inp[0:2], inp[2:4], inp[4])

    jac_y = np.column_stack([(f(eps * e, zero_in) - f(-eps * e, zero_in)) / (2 * eps)
                             for e in np.eye(8)])
    jac_u = np.column_stack([(f(np.zeros(8), eps * e) - f(np.zeros(8), -eps * e)) / (2 * eps)
                             for e in np.eye(5)])
    np.testing.assert_allclose(a, jac_y, rtol=1e-6, atol=1e-3)
    np.testing.assert_allclose(b, jac_u, rtol=1e-6, atol=1e-3)


@pytest.mark.parametrize('vehicle', [VehicleParameters(), ASYM])
def test_modes_match_reference_eigenvalues(vehicle):
    modes = {m.name: m for m in VehicleModel(vehicle).modes()}
    assert set(modes) == {'bounce', 'roll', 'wheel_hop', 'wheel_tramp'}
    mass, C, K = reference_matrices(vehicle)
    w2 = np.sort(np.linalg.eigvals(np.linalg.solve(mass, K)).real)
    np.testing.assert_allclose(sorted(m.frequency_hz for m in modes.values()),
                               np.sqrt(w2) / (2 * np.pi), rtol=1e-10)
    # Damped poles of the first-order system built here.
    a = np.block([[np.zeros((4, 4)), np.eye(4)],
                  [-np.linalg.solve(mass, K), -np.linalg.solve(mass, C)]])
    lam = np.linalg.eigvals(a)
    lam = lam[lam.imag > 0]
    got = sorted(m.damped_frequency_hz for m in modes.values())
    np.testing.assert_allclose(got, np.sort(lam.imag) / (2 * np.pi), rtol=1e-9)
    for m in modes.values():
        pole = lam[np.argmin(np.abs(lam.imag / (2 * np.pi) - m.damped_frequency_hz))]
        assert m.damping_ratio == pytest.approx(-pole.real / abs(pole), rel=1e-9)


def test_roll_stiffness_is_lowered_by_the_gravity_moment():
    # MODEL.md: roll stiffness 2 k s^2 - M g h (the rigid-tire roll mode, by hand).
    p = VehicleParameters()
    lin = VehicleModel(p).linearised()
    assert lin.stiffness[1, 1] == pytest.approx(2 * 400e3 * 1.0 - 5000.0 * G_MPS2 * 0.8,
                                                rel=1e-14)
    rigid = VehicleParameters(tire_stiffness_npm=(1e9, 1e9))     # (series share 4e-4)
    f = VehicleModel(rigid).natural_frequencies_hz()
    assert f['roll'] == pytest.approx(
        math.sqrt((2 * 400e3 - 5000.0 * G_MPS2 * 0.8) / 3000.0) / (2 * math.pi), rel=1e-3)


@pytest.mark.parametrize('ay', [1.0, 3.0, -4.0])
def test_steady_curve_roll_is_model_md_phi_ss(ay):
    # MODEL.md: phi_ss = M h a_y / (2 k s^2 - M g h) for equal sides, k the suspension in
    # series with the tire (the tires roll the axle too); small angles: O(phi^2).
    p = VehicleParameters()
    k_e = 400e3 * 1000e3 / 1400e3
    phi_ss = 5000.0 * 0.8 * ay / (2 * k_e * 1.0 - 5000.0 * G_MPS2 * 0.8)
    eq = VehicleModel(p).equilibrium([0.0, 0.0], lateral_accel_mps2=ay)
    assert eq[State.PHI] == pytest.approx(phi_ss, rel=2e-3)
    # (near) rigid tires: the suspension alone, as MODEL.md writes it
    eq = VehicleModel(VehicleParameters(tire_stiffness_npm=(1e9, 1e9))).equilibrium(
        [0.0, 0.0], lateral_accel_mps2=ay)
    assert eq[State.PHI] == pytest.approx(5000.0 * 0.8 * ay / (2 * 400e3 - 5000 * G_MPS2 * 0.8),
                                          rel=3e-3)


def test_default_truck_frequencies_are_those_of_model_md():
    f = VehicleModel(VehicleParameters()).natural_frequencies_hz()
    # MODEL.md: body bounce ~1.7 Hz, wheel hop ~9 Hz.
    assert f['bounce'] == pytest.approx(1.7, rel=0.03)
    assert f['wheel_hop'] == pytest.approx(9.0, rel=0.03)
    # Bounce by hand: two corners, each the suspension in series with the tire.
    k_series = 400e3 * 1000e3 / (1400e3)
    assert f['bounce'] == pytest.approx(math.sqrt(2 * k_series / 5000) / (2 * math.pi),
                                        rel=0.02)
    assert f['bounce'] < f['roll'] < f['wheel_hop'] < f['wheel_tramp']


def test_bad_vehicle_type():
    with pytest.raises(TypeError):
        VehicleModel({'vehicle.sprung_mass': 5000.0})
