"""Leaf-spring friction (MODEL.md "Friction that sticks", core.friction) in both plants: the
stick element against the elastic-plastic element's exact response and solve_ivp, a parked
start, the tanh law's v_f a parameter."""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from articulated_reference import G, Reference, defaults, statics
from road_force_estimator.core.articulated_model import ArticulatedModel
from road_force_estimator.core.articulated_parameters import ArticulatedParameters
from road_force_estimator.core.articulated_plant import ArticulatedPlant, simulate_articulated
from road_force_estimator.core.friction import FrictionLaw, Sliders, stick_force, tanh_force
from road_force_estimator.core.parameters import VehicleParameters
from road_force_estimator.core.plant import Plant, simulate
from road_force_estimator.core.road import flat_profile, iso8608_profile

FF, K = 1500.0, 400e3
STICK = VehicleParameters(leaf_spring_friction_n=(FF, FF), leaf_spring_friction_model='stick')


def jenkins(q, kf, ff):
    """The elastic-plastic element's force for an extension history q (from f = 0 at q[0]),
    written as the loading and unloading branches of a hysteresis loop: elastic from the last
    reversal point until the force reaches +-F_f."""
    out, anchor_q, anchor_f = [0.0], q[0], 0.0
    for k in range(1, len(q)):
        f = anchor_f + kf * (q[k] - anchor_q)
        if abs(f) >= ff:                        # sliding: hold, re-anchor at the slip point
            f = math.copysign(ff, f)
            anchor_q, anchor_f = q[k], f
        out.append(f)
        if k + 1 < len(q) and (q[k + 1] - q[k]) * (q[k] - q[k - 1]) < 0.0:   # a reversal
            anchor_q, anchor_f = q[k], f
    return np.array(out)


def test_the_stick_element_is_the_elastic_plastic_loop():
    kf = 8.0 * K
    t = np.linspace(0.0, 3.0, 3001)
    q = 2e-3 * np.sin(2 * math.pi * t) * (1.0 + 0.3 * t)   # 2-4 mm: slips every half cycle
    sliders = Sliders([kf], [FF])
    sliders.start([q[0]], [0.0])
    got = [-sliders.forces([q[0]])[0]]
    for v in q[1:]:
        sliders.advance([v])
        got.append(-sliders.forces([v])[0])
    np.testing.assert_allclose(got, jenkins(q, kf, FF), atol=1e-9)
    assert np.max(got) == pytest.approx(FF) and np.min(got) == pytest.approx(-FF)
    # the band: at q = 0 the element holds about +-F_f after a slip (the static hysteresis)
    assert np.ptp(np.array(got)[np.abs(q) < 1e-5]) > 1.9 * FF
    assert stick_force(0.0, kf, 1e-5, FF) == pytest.approx(-kf * 1e-5)
    assert tanh_force(FF, 0.02, 100.0) == -FF * math.tanh(2.0)


def _front_reference(p, road, speed, law, vf=0.01):
    """MODEL.md's front axle with the friction as an ODE: tanh, or the stick element's force
    f as a state, df/dt = k_f dq while |f| < F_f or moving back (written apart)."""
    s = p.track_width_m / 2
    fc = [(p.sprung_mass_kg / 2 + m) * G for m in p.unsprung_mass_kg]
    x, z = road.distance_m, road.elevation_m
    kf = [8.0 * k for k in p.suspension_stiffness_npm]

    def parts(t, y):
        zs, phi, zu1, zu2, dzs, dphi, dzu1, dzu2 = y[:8]
        u = [np.interp(x[0] + speed * t, x, z[:, i]) for i in (0, 1)]
        q = [zs + s * math.sin(phi) - zu1, zs - s * math.sin(phi) - zu2]
        dq = [dzs + s * math.cos(phi) * dphi - dzu1, dzs - s * math.cos(phi) * dphi - dzu2]
        fb = []
        for i in (0, 1):
            f = -p.suspension_stiffness_npm[i] * q[i] - p.suspension_damping_nspm[i] * dq[i]
            if law == 'tanh':
                f -= p.leaf_spring_friction_n[i] * math.tanh(dq[i] / vf)
            else:
                f -= min(max(y[8 + i], -FF), FF)
            fb.append(f)
        zu = (zu1, zu2)
        df = [max(p.tire_stiffness_npm[i] * (u[i] - zu[i]), -fc[i]) for i in (0, 1)]
        return q, dq, fb, df

    def rhs(t, y):
        phi = y[1]
        q, dq, fb, df = parts(t, y)
        out = [y[4], y[5], y[6], y[7], (fb[0] + fb[1]) / p.sprung_mass_kg,
               (s * math.cos(phi) * (fb[0] - fb[1]) + p.sprung_mass_kg * p.cg_height_m * G
                * math.sin(phi)) / p.roll_inertia_kgm2,
               (df[0] - fb[0]) / p.unsprung_mass_kg[0], (df[1] - fb[1]) / p.unsprung_mass_kg[1]]
        if law == 'stick':
            for i in (0, 1):
                f = y[8 + i]
                out.append(kf[i] * dq[i] if abs(f) < FF or f * dq[i] < 0.0 else 0.0)
        return out

    def loads(t, y):
        df = parts(t, y)[3]
        return [fc[0] + df[0], fc[1] + df[1]]

    return rhs, loads


@pytest.mark.parametrize('law, vf', [('stick', 0.01), ('tanh', 0.005)])
def test_front_axle_friction_against_solve_ivp(law, vf):
    """A class C drive: the stick element (its force a state of the reference) and the tanh
    law with a v_f of 0.005 m/s (vehicle.leaf_spring_friction_velocity): the loads within
    1e-3 of the dynamic-load RMS of the test's solve_ivp."""
    p = VehicleParameters(leaf_spring_friction_n=(FF, FF), leaf_spring_friction_model=law,
                          leaf_spring_friction_velocity_mps=vf)
    road = iso8608_profile('C', 80.0, seed=5)
    tr = simulate(p, road, speed_mps=15.0, rate_hz=1000.0, duration_s=2.0)
    rhs, loads = _front_reference(p, road, 15.0, law, vf)
    y0 = np.concatenate([[tr.body_heave_m[0], tr.roll_rad[0], *tr.wheel_heave_m[0],
                          tr.body_heave_rate_mps[0], tr.roll_rate_radps[0],
                          *tr.wheel_heave_rate_mps[0]], [0.0, 0.0] if law == 'stick' else []])
    sol = solve_ivp(rhs, (0.0, tr.t_s[-1]), y0, t_eval=tr.t_s, method='RK45', rtol=1e-9,
                    atol=1e-10, max_step=2.5e-4)
    assert sol.status == 0
    ref = np.array([loads(t, y) for t, y in zip(sol.t, sol.y.T)])
    fc = np.array(p.static_load_n)
    err = tr.wheel_load_n - ref
    assert np.sqrt(np.mean(err ** 2)) <= 1e-3 * np.sqrt(np.mean((ref - fc) ** 2))
    if law == 'stick':                              # it did stick and slip
        held = sol.y[8]
        assert np.mean(np.abs(held) >= FF - 1e-6) > 0.05 and np.mean(np.abs(held) < FF) > 0.2


def test_a_parked_start_hides_the_friction_and_a_road_shakes_it_loose():
    """simulator.leaf_spring_friction_start = 1: loaded while parked, each slider carries F_f
    upward, each spring F_f less: the deflections read F_f / k extended (a zero-load reading
    F_f low per spring). A flat road keeps it; already a class A road at 20 m/s (a dynamic
    load of about 1.8 kN RMS per wheel, above F_f = 1.5 kN) shakes it out."""
    flat = flat_profile(500.0)
    plant = Plant(STICK, flat, speed_mps=10.0, rate_hz=500.0, friction_start=1.0)
    first = plant.step()
    np.testing.assert_allclose(first.q_m, FF / K, rtol=1e-9)
    np.testing.assert_allclose(first.wheel_load_n, STICK.static_load_n, rtol=1e-12)
    kept = simulate(STICK, flat, speed_mps=20.0, rate_hz=500.0, duration_s=20.0,
                    friction_start=1.0)
    smooth = simulate(STICK, iso8608_profile('A', 500.0, seed=3), speed_mps=20.0,
                      rate_hz=500.0, duration_s=20.0, friction_start=1.0, tire_envelope_m=0.25)
    late = smooth.t_s > 15.0
    np.testing.assert_allclose(kept.q_m[late], FF / K, rtol=1e-9)
    assert abs(np.mean(smooth.q_m[late])) < 0.1 * FF / K
    with pytest.raises(ValueError, match='needs vehicle.leaf_spring_friction_model = stick'):
        Plant(VehicleParameters(leaf_spring_friction_n=(FF, FF)), flat, speed_mps=10.0,
              rate_hz=500.0, friction_start=1.0)


def test_the_articulated_plant_sticks_per_axle():
    v = ArticulatedParameters.from_parameters({
        'vehicle.leaf_spring_friction_model': 'stick',
        'vehicle.axle.drive.leaf_spring_friction': [2000.0, 2000.0],
        'vehicle.axle.trailer_2.leaf_spring_friction': [1500.0, 1000.0]})
    plant = ArticulatedPlant(v, flat_profile(200.0), speed_mps=10.0, rate_hz=500.0,
                             friction_start=1.0)
    s = plant.step()
    base = ArticulatedPlant(ArticulatedParameters.from_parameters({}), flat_profile(200.0),
                            speed_mps=10.0, rate_hz=500.0).step()
    q = np.array(s.q_m) - np.array(base.q_m)
    k = np.array([kk for a in v.axles for kk in a.suspension_stiffness_npm])
    # the sliders carry 7.5 kN that the springs, hence the deflections, do not show: the
    # springs with friction extend, and the springs' forces drop by the sliders' sum exactly
    # (the bodies settle, so the share of each spring is the statics' to decide)
    assert np.all(q[[2, 3, 6, 7]] > 0.0)
    assert np.sum(k * q) == pytest.approx(2 * 2000.0 + 1500.0 + 1000.0, rel=1e-6)
    # the gross weight stays; how the indeterminate trailer shares it moves with the sliders
    assert np.sum(s.wheel_load_n) == pytest.approx(np.sum(base.wheel_load_n), rel=1e-9)
    assert not np.allclose(s.wheel_load_n, base.wheel_load_n, rtol=1e-3)
    assert FrictionLaw('stick').steepest_damping_nspm(1500.0) == 0.0


def test_the_articulated_tanh_friction_against_solve_ivp():
    """Tanh friction on every axle (v_f 0.01 m/s), class C, 2 s: the loads within 1e-4 of
    the dynamic RMS of the test's reference with the same friction."""
    v = ArticulatedParameters.from_parameters({'vehicle.leaf_spring_friction': [1500.0, 1500.0]})
    road = iso8608_profile('C', 120.0, seed=9)
    tr = simulate_articulated(v, road, speed_mps=15.0, rate_hz=1000.0, duration_s=2.0)
    p = defaults()
    st = statics(p)

    class WithFriction(Reference):
        def forces(self, t, y):
            q, spring, tire = super().forces(t, y)
            n, bi = self.n, self.bi
            pos, vel = y[:n], y[n:]
            dq = (vel[bi] + self.d * np.cos(pos[bi + 1]) * vel[bi + 1])[:, None] + np.array(
                [1.0, -1.0]) * (self.s * np.cos(pos[bi + 2]) * vel[bi + 2]
                                - self.s * np.cos(pos[7::2]) * vel[7::2])[:, None] \
                - vel[6::2][:, None]
            return q, spring - 1500.0 * np.tanh(dq / 0.01), tire

    r = WithFriction(p, lambda x: np.stack([np.interp(x, road.distance_m, road.elevation_m[:, i])
                                            for i in (0, 1)], -1),
                     lambda t: tr.distance_m[0] + 15.0 * t, lambda t: 0.0, lambda t: 0.0,
                     st['spring'], st['wheel'])
    sol = solve_ivp(r, (0.0, 2.0), tr.state[0], method='RK45', rtol=1e-8, atol=1e-9,
                    t_eval=tr.t_s, max_step=1e-3)
    ref = np.array([r.wheel_loads(t, y) for t, y in zip(sol.t, sol.y.T)])
    dyn = ref - np.repeat(st['wheel'] / 2, 2)
    assert np.sqrt(np.mean((tr.wheel_load_n - ref) ** 2)) <= 1e-4 * np.sqrt(np.mean(dyn ** 2))
    assert ArticulatedModel(v).has_friction
