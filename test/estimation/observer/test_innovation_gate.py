"""The innovation gate (observer.innovation_gate, MODEL.md "Sensor faults": a spike costs at
most its own sample), in every mode of the model observer: online, fixed lag, offline.

Truth: the plant's wheel loads (core/plant.py, an RK4 of MODEL.md's equations, itself checked
against solve_ivp in test/core/test_plant.py); the spikes are added to the measured drive here.
"""
from dataclasses import replace

import numpy as np
import pytest

from road_force_estimator.core import metrics
from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
from road_force_estimator.core.plant import simulate
from road_force_estimator.core.road import add_event, iso8608_profile
from road_force_estimator.estimation import estimate_batch, estimate_recording

VEHICLE = VehicleParameters()
SPEED = 20.0
#: five 0.5 mm spikes on the two deflection sensors: (sample, channel, sign)
SPIKES = [(5000, 0, 1), (9000, 1, -1), (13000, 0, -1), (17000, 1, 1), (19500, 0, 1)]
MODES = {'online': ObserverParameters(), '10 ms': ObserverParameters(latency_s=0.01),
         'offline': None}


def _estimate(mode: str, stamps, q, phi, gate: float):
    obs = MODES[mode]
    if obs is None:
        return estimate_recording(stamps, q, phi, SPEED, VEHICLE,
                                  ObserverParameters(innovation_gate=gate))
    return estimate_batch(stamps, q, phi, SPEED, VEHICLE, replace(obs, innovation_gate=gate))


def _drive(road, duration_s: float, envelope_m: float = 0.25, noise_m: float = 1e-5):
    tr = simulate(VEHICLE, road, speed_mps=SPEED, rate_hz=1000.0, duration_s=duration_s,
                  tire_envelope_m=envelope_m)
    rng = np.random.default_rng(3)
    q = tr.q_m + rng.normal(0.0, noise_m, tr.q_m.shape)
    phi = tr.roll_rad + rng.normal(0.0, 10.0 * noise_m, tr.roll_rad.shape)
    return tr, np.round(tr.t_s * 1e9).astype(np.int64), q, phi


@pytest.fixture(scope='module')
def class_c():
    return _drive(iso8608_profile('C', 600.0, seed=11), 22.0)


def _load_pct(tr, est) -> float:
    mask = tr.t_s > 3.0
    e = metrics.load_errors(est.wheel_load_n, tr.wheel_load_n, VEHICLE.static_load_n, mask=mask)
    return float(100.0 * np.sqrt(np.mean(e.rms ** 2)) / np.sqrt(np.mean(e.reference_rms ** 2)))


@pytest.mark.parametrize('mode', sorted(MODES))
def test_five_spikes_cost_their_samples_only_and_are_counted(class_c, mode):
    tr, stamps, q, phi = class_c
    spiky = q.copy()
    for k, ch, sign in SPIKES:
        spiky[k, ch] += sign * 5e-4
    clean = _load_pct(tr, _estimate(mode, stamps, q, phi, 6.0))
    gated = _estimate(mode, stamps, spiky, phi, 6.0)
    fed = _load_pct(tr, _estimate(mode, stamps, spiky, phi, 0.0))
    assert _load_pct(tr, gated) <= 1.1 * clean
    assert gated.status.innovations_gated == {'left_suspension': 3, 'right_suspension': 2,
                                              'roll': 0}
    assert fed > 1.02 * clean         # without the gate the spikes do cost (the test can fail)


@pytest.mark.parametrize('mode', sorted(MODES))
def test_a_clean_drive_is_never_gated(class_c, mode):
    tr, stamps, q, phi = class_c
    on, off = (_estimate(mode, stamps, q, phi, gate) for gate in (6.0, 0.0))
    assert not any(on.status.innovations_gated.values())
    np.testing.assert_array_equal(on.wheel_load_n, off.wheel_load_n)
    np.testing.assert_array_equal(on.road_m, off.road_m)


@pytest.mark.parametrize('mode', sorted(MODES))
def test_real_steps_are_fed_not_gated(mode):
    """A pothole's walls and a step at point contact: excursions that stay outside at the next
    sample are real; the gate undoes its guess, so nothing is counted and (but for the one
    zero-latency estimate published in between) the estimate is the ungated one."""
    road = add_event(iso8608_profile('B', 500.0, seed=12), 'pothole', 'left', 120.0, 0.6, 0.03)
    road = add_event(road, 'step', 'right', 200.0, 0.05, 0.02)
    tr, stamps, q, phi = _drive(road, 14.0, envelope_m=0.0)
    on, off = (_estimate(mode, stamps, q, phi, gate) for gate in (6.0, 0.0))
    assert not any(on.status.innovations_gated.values())
    assert _load_pct(tr, on) <= 1.02 * _load_pct(tr, off)
