"""Static loads and payload from deflections read from a mechanical zero (estimation.static_load,
issue 19): against the truth parameter file of the plant, MODEL.md's scale relation, and the
equilibrium path."""
from dataclasses import replace

import numpy as np
import pytest

from road_force_estimator.core.parameters import (
    GRAVITY_MPS2, ObserverParameters, VehicleParameters)
from road_force_estimator.core.plant import simulate
from road_force_estimator.core.road import iso8608_profile
from road_force_estimator.core.segments import SEGMENT_COLUMNS, segment_table
from road_force_estimator.core.sensors import SensorModel
from road_force_estimator.estimation.estimator import Estimator, estimate_batch
from road_force_estimator.estimation.offline import estimate_recording
from road_force_estimator.estimation.static_load import StaticLoadTracker, track_arrays
from road_force_estimator.tools.fleet_drives import FLEET_COLUMNS

NOMINAL = VehicleParameters(deflection_reference='zero_load')
#: The truck with a payload 40 % above the nominal sprung mass (the roll inertia with it).
LOADED = replace(NOMINAL, sprung_mass_kg=1.4 * NOMINAL.sprung_mass_kg,
                 roll_inertia_kgm2=1.4 * NOMINAL.roll_inertia_kgm2)


@pytest.fixture(scope='module')
def payload_drive():
    """Class C, 20 m/s, 1 kHz, 10 um / 0.1 mrad noise, 12 s, the loaded truck, the
    deflections read from the spring's unloaded length."""
    dur = 12.0
    road = iso8608_profile('C', 20.0 * dur + 5.0, seed=4)
    tr = simulate(LOADED, road, speed_mps=20.0, rate_hz=1000.0, duration_s=dur,
                  tire_envelope_m=0.25)
    q, phi = SensorModel(1e-5, 1e-4, seed=2,
                         deflection_offset_m=LOADED.deflection_offset_m).measure(
        tr.q_m, tr.roll_rad)
    stamps = np.round(tr.t_s * 1e9).astype(np.int64)
    return tr, stamps, q, phi


def test_sensor_offset_is_the_static_sprung_deflection():
    # MODEL.md: q_meas,i = q_i - (F_s,i - F_0,i) / k_i with F_s,i = F_c,i - m_i g.
    v = replace(LOADED, deflection_zero_load_n=(2000.0, 500.0))
    fs = 0.5 * 7000.0 * GRAVITY_MPS2
    expected = (-(fs - 2000.0) / 400e3, -(fs - 500.0) / 400e3)
    np.testing.assert_allclose(v.deflection_offset_m, expected, rtol=1e-12)
    assert VehicleParameters().deflection_offset_m == (0.0, 0.0)
    q, _ = SensorModel(deflection_offset_m=expected).measure(np.zeros((3, 2)), np.zeros(3))
    np.testing.assert_allclose(q, np.tile(expected, (3, 1)), rtol=0, atol=0)


def test_tracker_reads_the_scale_of_a_constant_reading():
    # F_c,i = m_i g + F_0,i - k_i mean(q_meas,i) and M = (F_s,1 + F_s,2) / g, by hand.
    v = replace(NOMINAL, deflection_zero_load_n=(1000.0, 0.0),
                suspension_stiffness_npm=(350e3, 420e3))
    tracker = StaticLoadTracker(v)
    for _ in range(50):
        out = tracker.update(-0.07, -0.08, 1e-3)
    fc = (450.0 * GRAVITY_MPS2 + 1000.0 + 350e3 * 0.07, 450.0 * GRAVITY_MPS2 + 420e3 * 0.08)
    np.testing.assert_allclose(tracker.static_n, fc, rtol=1e-12)
    assert tracker.sprung_mass_kg == pytest.approx((350e3 * 0.07 + 1000.0 + 420e3 * 0.08)
                                                   / GRAVITY_MPS2, rel=1e-12)
    assert out == pytest.approx((0.0, 0.0), abs=1e-15)


def test_payload_static_loads_converge_within_two_percent(payload_drive):
    tr, stamps, q, phi = payload_drive
    est = estimate_batch(stamps, q, phi, 20.0, NOMINAL, ObserverParameters())
    truth = np.array(LOADED.static_load_n)          # the plant's truth file
    err = est.static_load_n / truth - 1.0
    after = tr.t_s >= 10.0
    assert np.max(np.abs(err[after])) < 0.02
    assert est.status.sprung_mass_kg == pytest.approx(LOADED.sprung_mass_kg, rel=0.02)
    assert est.status.gain_designs >= 2             # designed again for the estimated mass
    # the loads use the estimated static loads: their mean follows the truth's
    mean_err = np.mean(est.wheel_load_n[after], axis=0) / np.mean(tr.wheel_load_n[after],
                                                                  axis=0) - 1.0
    assert np.max(np.abs(mean_err)) < 0.02
    # the dynamic-load error stays that of the observer told the true file (within 2 points)
    eq = replace(LOADED, deflection_reference='equilibrium')
    q_eq, phi_eq = SensorModel(1e-5, 1e-4, seed=2).measure(tr.q_m, tr.roll_rad)
    told = estimate_batch(stamps, q_eq, phi_eq, 20.0, eq, ObserverParameters())
    ok = tr.t_s >= 2.0
    dyn = np.sqrt(np.mean((tr.wheel_load_n[ok] - truth) ** 2))

    def pct(e):
        return 100.0 * np.sqrt(np.mean((e.wheel_load_n[ok] - tr.wheel_load_n[ok]) ** 2)) / dyn
    assert pct(est) < pct(told) + 2.0


def test_per_sample_batch_and_offline_static_loads_are_identical(payload_drive):
    tr, stamps, q, phi = payload_drive
    n = 3000
    batch = estimate_batch(stamps[:n], q[:n], phi[:n], 20.0, NOMINAL, ObserverParameters())
    est = Estimator(NOMINAL, ObserverParameters())
    rows = [est.update(int(s), qq, p, 20.0) for s, qq, p in zip(stamps[:n], q[:n], phi[:n])]
    np.testing.assert_array_equal(np.array([r.static_load_n for r in rows]),
                                  batch.static_load_n)
    np.testing.assert_array_equal(np.array([r.wheel_load_n for r in rows]),
                                  batch.wheel_load_n)
    for scheme in ('model', 'implicit'):
        off = estimate_recording(stamps[:n], q[:n], phi[:n], 20.0, NOMINAL,
                                 ObserverParameters(discretization=scheme))
        np.testing.assert_array_equal(off.static_load_n, batch.static_load_n)
    steps = np.r_[0.0, np.diff(stamps[:n]) * 1e-9]
    _, static, _ = track_arrays(NOMINAL, q[:n], steps)
    np.testing.assert_array_equal(static, batch.static_load_n)


def test_equilibrium_carries_the_configured_static_loads(payload_drive):
    tr, stamps, q, phi = payload_drive
    v = VehicleParameters(static_load_setting_n=(30e3, 31e3))
    est = Estimator(v, ObserverParameters())
    assert est.static_load is None
    n = 500
    q_eq = tr.q_m[:n]
    batch = estimate_batch(stamps[:n], q_eq, tr.roll_rad[:n], 20.0, v, ObserverParameters())
    assert (batch.static_load_n == (30e3, 31e3)).all()
    off = estimate_recording(stamps[:n], q_eq, tr.roll_rad[:n], 20.0, v, ObserverParameters())
    assert (off.static_load_n == (30e3, 31e3)).all()
    # a parameter at its default is not written out (the bags' recorded parameters stay)
    assert 'vehicle.deflection_reference' not in v.to_parameters()
    assert NOMINAL.to_parameters()['vehicle.deflection_reference'] == 'zero_load'


def test_segments_carry_the_mean_static_loads_before_the_quasi_static_ltr():
    i = SEGMENT_COLUMNS.index('static_load_left_n')
    assert SEGMENT_COLUMNS[i:i + 3] == ('static_load_left_n', 'static_load_right_n',
                                        'max_abs_ltr_quasi_static')
    j = FLEET_COLUMNS.index('end_lon')
    assert FLEET_COLUMNS[j + 1:j + 4] == ('static_load_left_n', 'static_load_right_n',
                                          'max_abs_ltr_quasi_static')
    x = np.linspace(0.0, 250.0, 2501)
    static = np.column_stack([30e3 + x, 31e3 - x])
    table = segment_table(x, np.full((x.size, 2), 3e4), np.zeros(x.size),
                          np.zeros((x.size, 2), bool), static_load_n=static)
    for k, (a, b) in enumerate(zip(table['start_m'], table['end_m'])):
        inside = (x >= a) & ((x < b) | (k == len(table['start_m']) - 1))
        assert table['static_load_left_n'][k] == pytest.approx(static[inside, 0].mean())
        assert table['static_load_right_n'][k] == pytest.approx(static[inside, 1].mean())
    none = segment_table(x, np.full((x.size, 2), 3e4), np.zeros(x.size),
                         np.zeros((x.size, 2), bool))
    assert np.isnan(none['static_load_left_n']).all()


def test_latency_and_a_gap_per_sample_equals_batch(payload_drive):
    # a 0.2 s gap (a restart) with 10 ms latency: every accepted sample gets one estimate,
    # the per-sample path's (update, then flush) are the batch rows, the static loads go on
    tr, stamps, q, phi = payload_drive
    keep = np.r_[0:1500, 1700:3000]
    s, qq, pp = stamps[keep], q[keep], phi[keep]
    obs = ObserverParameters(latency_s=0.01)
    batch = estimate_batch(s, qq, pp, 20.0, NOMINAL, obs)
    est = Estimator(NOMINAL, obs)
    rows = [r for r in (est.update(int(a), b, c, 20.0) for a, b, c in zip(s, qq, pp)) if r]
    rows += est.flush()
    # every sample but the first after the gap (held, then lost: the next confirms the jump)
    assert est.status.resets == 1 and len(rows) == keep.size - 1
    np.testing.assert_array_equal(np.array([r.static_load_n for r in rows]),
                                  batch.static_load_n[batch.valid])
    np.testing.assert_array_equal(np.array([r.wheel_load_n for r in rows]),
                                  batch.wheel_load_n[batch.valid])
    truth = np.array(LOADED.static_load_n)
    assert np.max(np.abs(batch.static_load_n[-1] / truth - 1.0)) < 0.03
