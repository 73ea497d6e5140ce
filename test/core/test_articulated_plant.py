"""The articulated plant (MODEL.md "The whole vehicle") against references written apart from
the package (test/articulated_reference.py): scipy's solve_ivp on MODEL.md's equations, the
level-road statics as a force and moment balance, and MODEL.md's own figures."""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from articulated_reference import G, Reference, defaults, statics
from road_force_estimator.core.articulated_model import ArticulatedModel
from road_force_estimator.core.articulated_parameters import ArticulatedParameters
from road_force_estimator.core.articulated_plant import ArticulatedPlant, simulate_articulated
from road_force_estimator.core.lateral_profile import LateralProfile
from road_force_estimator.core.road import flat_profile, iso8608_profile

DEFAULT = ArticulatedParameters.from_parameters({})


def test_static_loads_are_model_md_s_and_sum_to_the_weight():
    """MODEL.md: 6.62 t front, 10.73 t drive, 8.00 / 7.62 / 7.23 t trailer, 40.20 t gross,
    8.56 t on the kingpin (given to 0.01 t); the test's own balance to 1e-9."""
    st = ArticulatedModel(DEFAULT).statics()
    ref = statics(defaults())
    axle_t = st.axle_load_kg / 1000.0
    np.testing.assert_allclose(axle_t, [6.62, 10.73, 8.00, 7.62, 7.23], atol=0.0101)
    assert st.gross_weight_kg / 1000.0 == pytest.approx(40.20, abs=0.005)
    assert st.kingpin_load_n / G / 1000.0 == pytest.approx(8.56, abs=0.005)
    np.testing.assert_allclose(st.wheel_load_n.sum(axis=1), ref['wheel'], rtol=1e-9)
    np.testing.assert_allclose(st.spring_load_n.sum(axis=1), ref['spring'], rtol=1e-9)
    assert st.kingpin_load_n == pytest.approx(ref['kingpin'], rel=1e-9)
    weight = (6500 + 29000 + 900 + 1400 + 3 * 800) * G
    assert st.wheel_load_n.sum() == pytest.approx(weight, rel=1e-9)
    # sides equal on a level road
    np.testing.assert_allclose(st.wheel_load_n[:, 0], st.wheel_load_n[:, 1], rtol=1e-12)


def test_modes_are_stable_and_in_model_md_s_bands():
    """Bodies 1.4-1.8 Hz, tractor roll ~5 Hz, wheel hop 9-12 Hz, axle roll 10-17 Hz, fifth
    wheel ~24 Hz; every pole in the left half-plane."""
    model = ArticulatedModel(DEFAULT)
    assert np.all(model.poles().real < 0.0)
    modes = {m.name: m.frequency_hz for m in model.modes()}
    freq = sorted(m.frequency_hz for m in model.modes())
    assert 1.3 <= freq[0] and freq[3] <= 1.85          # the four body modes
    assert 4.5 <= modes['tractor_roll'] <= 5.5
    hop = [m.frequency_hz for m in model.modes() if m.name.endswith('axle_heave')]
    roll = [m.frequency_hz for m in model.modes() if m.name.endswith('axle_roll')]
    assert len(hop) == 5 and 8.5 <= min(hop) and max(hop) <= 12.5
    assert len(roll) == 5 and 10.0 <= min(roll) and max(roll) <= 17.0
    assert 23.0 <= modes['fifth_wheel'] <= 26.0


def _drive(seconds=10.0, substeps=None):
    """Class C road, 15 m/s, braking at 3 m/s^2 to a stop from 3 s, a curve to 2 m/s^2."""
    tk, vk = np.array([0.0, 3.0, 8.0, 30.0]), np.array([15.0, 15.0, 0.0, 0.0])
    curve = (0.5, 2.0, 1.5, 2.0)
    road = iso8608_profile('C', 200.0, seed=4)
    tr = simulate_articulated(DEFAULT, road, speed_mps=15.0, rate_hz=1000.0,
                              duration_s=seconds, tire_envelope_m=0.25, speed_profile=(tk, vk),
                              lateral_acceleration=LateralProfile.curve(*curve),
                              substeps=substeps)
    return tr, road.enveloped(0.25), tk, vk, curve


def _reference_run(tr, env, tk, vk, curve, p=None):
    p = p or defaults()
    st = statics(p)
    x0 = float(tr.distance_m[0])

    def distance(t):                    # the integral of the piecewise-linear speed
        x = x0
        for i in range(len(tk) - 1):
            a, b = tk[i], tk[i + 1]
            if t <= a:
                break
            tau = min(t, b) - a
            x += vk[i] * tau + 0.5 * (vk[i + 1] - vk[i]) / (b - a) * tau * tau
        return x

    def accel(t):
        i = min(max(int(np.searchsorted(tk, t, side='right')) - 1, 0), len(tk) - 2)
        return (vk[i + 1] - vk[i]) / (tk[i + 1] - tk[i])

    s, r, h, a = curve
    knots_t, knots_a = [s, s + r, s + r + h, s + 2 * r + h], [0.0, a, a, 0.0]
    ex = np.ascontiguousarray(env.distance_m)
    e0, e1 = (np.ascontiguousarray(env.elevation_m[:, i]) for i in (0, 1))
    ref = Reference(p, lambda x: np.stack([np.interp(x, ex, e0), np.interp(x, ex, e1)], -1),
                    distance, accel, lambda t: float(np.interp(t, knots_t, knots_a)),
                    st['spring'], st['wheel'])
    ts = tr.t_s
    end = float(ts[-1])
    breaks = sorted({0.0, end, *[t for t in (*tk, *knots_t) if 0.0 < t < end]})
    loads = np.zeros((ts.size, 2 * len(p['axles'])))
    y = tr.state[0]
    for a0, b0 in zip(breaks[:-1], breaks[1:]):     # a_x and a_y change slope at the knots
        sel = np.flatnonzero((ts >= a0 - 1e-12) & (ts <= b0 + 1e-12))
        sol = solve_ivp(ref, (a0, b0), y, method='RK45', rtol=1e-8, atol=1e-9,
                        t_eval=ts[sel], max_step=2e-3)
        assert sol.success
        for k, i in enumerate(sel):
            loads[i] = ref.wheel_loads(sol.t[k], sol.y[:, k])
        y = sol.y[:, -1]
    return loads, st


def test_plant_against_solve_ivp_braking_stop_and_curve():
    """5 axles, class C, a braking stop from 15 m/s and a curve (2 m/s^2) at once: every
    wheel load within 1e-4 of the dynamic-load RMS of the test's own solve_ivp solution."""
    tr, env, tk, vk, curve = _drive()
    assert tr.completed and tr.substeps == 1
    loads, st = _reference_run(tr, env, tk, vk, curve)
    dynamic = loads - np.repeat(st['wheel'] / 2, 2)
    err = tr.wheel_load_n - loads
    rms_dyn = np.sqrt(np.mean(dynamic ** 2))
    assert rms_dyn > 5e3                                 # a real class C drive
    assert np.sqrt(np.mean(err ** 2)) <= 1e-4 * rms_dyn
    per_wheel = np.sqrt(np.mean(err ** 2, axis=0)) / np.sqrt(np.mean(dynamic ** 2, axis=0))
    assert np.all(per_wheel <= 1e-4)
    # the drive holds what it says: a stop (the road stands still), braking pitch, a curve
    stopped = tr.t_s > 8.05
    assert np.all(tr.speed_mps[stopped] == 0.0)
    assert np.ptp(tr.distance_m[stopped]) == 0.0
    braking = (tr.t_s > 3.5) & (tr.t_s < 7.5)
    assert np.all(tr.longitudinal_accel_mps2[braking] == pytest.approx(-3.0))
    assert tr.lateral_accel_mps2.max() == pytest.approx(2.0)


def test_braking_moves_load_forward_and_a_curve_to_the_outer_wheels():
    """On a flat road: braking at 3 m/s^2 loads the front axle and pitches the laden trailer
    nose down (REP-103 pitch > 0; its kingpin then presses the tractor's rear down: the
    tractor pitches nose up); a left curve (a_y > 0) loads the right wheels, the trailer most
    (MODEL.md: laden, it rolls over first)."""
    road = flat_profile(400.0)
    tr = simulate_articulated(DEFAULT, road, speed_mps=20.0, rate_hz=500.0, duration_s=12.0,
                              speed_profile=([0.0, 1.0, 6.0, 20.0], [20.0, 20.0, 5.0, 5.0]))
    st = ArticulatedModel(DEFAULT).statics().wheel_load_n.reshape(-1)
    during = (tr.t_s > 4.0) & (tr.t_s < 6.0)
    front = tr.wheel_load_n[during][:, :2].mean()
    assert front > st[0] + 1500.0
    assert np.all(tr.state[during][:, 4] > 0.0)          # trailer pitch: nose down
    assert np.all(tr.state[during][:, 1] < 0.0)          # tractor: its rear pressed down
    kingpin = np.mean(tr.wheel_load_n[during][:, :4].sum(1)) - st[:4].sum()
    assert kingpin > 15e3                                # the tractor takes the trailer's share
    tr = simulate_articulated(DEFAULT, road, speed_mps=20.0, rate_hz=500.0, duration_s=8.0,
                              lateral_acceleration=LateralProfile.curve(0.5, 2.0, 5.0, 3.0))
    ltr = tr.wheel_load_n[(tr.t_s > 4.0) & (tr.t_s < 6.0)]
    left, right = ltr[:, 0::2], ltr[:, 1::2]
    quasi = ((right - left) / (right + left)).mean(axis=0)
    assert np.all(quasi > 0.2)
    trailer = (right[:, 2:].sum(1) - left[:, 2:].sum(1)) / (right[:, 2:] + left[:, 2:]).sum(1)
    tractor = (right[:, :2].sum(1) - left[:, :2].sum(1)) / (right[:, :2] + left[:, :2]).sum(1)
    assert trailer.mean() > tractor.mean()
    assert 0.55 < trailer.mean() < 0.85                 # MODEL.md: about 0.7 at 3 m/s^2


def test_per_sample_and_batch_give_the_same_bits():
    road = iso8608_profile('C', 150.0, seed=2)
    kw = dict(speed_mps=18.0, rate_hz=1000.0, tire_envelope_m=0.25,
              lateral_acceleration=LateralProfile.curve(0.2, 0.5, 0.5, 1.0),
              speed_profile=([0.0, 1.0, 2.0], [18.0, 10.0, 10.0]))
    tr = simulate_articulated(DEFAULT, road, duration_s=2.0, **kw)
    plant = ArticulatedPlant(DEFAULT, road, **kw)
    rows = [plant.step().row for _ in range(len(tr))]
    assert np.array_equal(np.array(rows), tr.data)


def test_lift_off_per_wheel_and_the_tire_never_pulls():
    """A 5 cm bump under the left wheels at 3 m/s^2 in a left curve: the inner (left) wheels
    leave the road; loads never below 0 and the tire force floor is -F_c, as in the test's own
    solve_ivp."""
    from road_force_estimator.core.road import add_event
    road = add_event(flat_profile(300.0), 'bump', 'left', 60.0, 0.5, 0.05)
    curve = (0.1, 1.0, 10.0, 3.0)
    tr = simulate_articulated(DEFAULT, road, speed_mps=15.0, rate_hz=1000.0, duration_s=4.0,
                              lateral_acceleration=LateralProfile.curve(*curve))
    off = tr.wheel_load_n <= 0.0
    assert off.any() and np.all(tr.wheel_load_n >= 0.0)
    assert not off[:, 1::2].any()                         # the outer wheels stay down
    floor = -ArticulatedModel(DEFAULT).statics().wheel_load_n.reshape(-1)
    assert np.all(tr.tire_force_dynamic_n >= floor - 1e-9)
    tk, vk = np.array([0.0, 10.0]), np.array([15.0, 15.0])
    loads, st = _reference_run(tr, road, tk, vk, curve)
    dyn = loads - np.repeat(st['wheel'] / 2, 2)
    err = tr.wheel_load_n - loads
    assert np.sqrt(np.mean(err ** 2)) <= 2e-3 * np.sqrt(np.mean(dyn ** 2))


def test_the_equilibrium_is_at_rest_and_the_road_does_not_move_at_a_stop():
    road = iso8608_profile('C', 100.0, seed=8)
    plant = ArticulatedPlant(DEFAULT, road, speed_mps=1.0, rate_hz=1000.0,
                             speed_profile=([0.0], [0.0]))
    first = plant.step()
    for _ in range(500):
        last = plant.step()
    assert np.max(np.abs(np.array(last.state) - np.array(first.state))) < 1e-12
    assert last.distance_m == first.distance_m
    np.testing.assert_allclose(np.array(first.accel), 0.0, atol=1e-9)


def test_crossfall_tilts_the_truck_not_its_springs():
    """A 3 % crossfall (left higher): the bodies roll left side up by about the crossfall
    angle (plus their lean downhill, the gravity moment), the wheel loads shift downhill."""
    angle = math.atan(0.03)
    road = flat_profile(200.0)
    tr = simulate_articulated(DEFAULT, road, speed_mps=10.0, rate_hz=200.0, duration_s=0.5,
                              crossfall_rad=angle)
    roll_t, roll_r = tr.state[-1][2], tr.state[-1][5]
    assert angle < roll_t < 1.3 * angle and angle < roll_r < 1.5 * angle
    loads = tr.wheel_load_n[-1]
    assert np.all(loads[1::2] > loads[0::2])             # the lower (right) wheels carry more
    assert loads.sum() == pytest.approx(40200 * G * math.cos(0.0), rel=1e-3)


def test_a_road_that_arrives_piece_by_piece_gives_the_batch_drive():
    """A live road (simulator.road: topic): the plant built on the first piece that carries
    every axle (its first sample only) and extended as the profile arrives drives as the
    batch plant does on the whole road."""
    road = iso8608_profile('C', 40.0, seed=5)
    kw = dict(speed_mps=20.0, rate_hz=500.0, tire_envelope_m=0.25)
    tr = simulate_articulated(DEFAULT, road, duration_s=60.0, **kw)
    first = road.start_m + 12.22 + 0.25 + 0.01        # the shortest piece: one sample
    plant = ArticulatedPlant(DEFAULT, road.segment(road.start_m, first), **kw)
    assert plant.last_sample_index == 0
    rows, end = [], first
    while True:
        s = plant.step()
        if s is not None:
            rows.append(s.row)
            continue
        if end >= road.end_m:
            break
        end = min(end + 0.3, road.end_m)
        plant.extend_road(road.segment(road.start_m, end))
    np.testing.assert_allclose(np.array(rows), tr.data, rtol=0, atol=1e-9)
