"""The calibration's linear plant: modal simulation and free responses against scipy."""
import numpy as np
import pytest
from scipy import signal

from road_force_estimator.core.parameters import VehicleParameters
from road_force_estimator.core.vehicle_model import VehicleModel
from road_force_estimator.calibration.model import (
    SLOTS, free_response, linear_plant, output_matrix, simulate_outputs, slot_value,
    vehicle_with)

VEHICLE = VehicleParameters(unsprung_mass_kg=(400.0, 500.0), tire_damping_nspm=(300.0, 200.0))


def _lsim(road, du, rate, x0):
    model = VehicleModel(VEHICLE)
    a, b = model.linearised().state_matrices()
    t = np.arange(road.shape[0]) / rate
    system = signal.StateSpace(a, b[:, :4], output_matrix(model), np.zeros((3, 4)))
    _, y, _ = signal.lsim(system, np.column_stack([road, du]), t, X0=x0, interp=True)
    return y


def test_modal_simulation_matches_lsim_under_first_order_hold():
    rate = 500.0
    road = np.random.default_rng(1).standard_normal((2000, 2)).cumsum(axis=0) * 1e-4
    du = np.gradient(road, axis=0) * rate
    x0 = VehicleModel(VEHICLE).equilibrium(road[0], du[0])
    want = _lsim(road, du, rate, x0)
    got = simulate_outputs(linear_plant(VEHICLE), road, du, 1.0 / rate)
    assert np.max(np.abs(got - want)) < 1e-6 * np.max(np.abs(want))


def test_free_responses_span_every_initial_state():
    plant = linear_plant(VEHICLE)
    t = np.arange(400) / 400.0
    basis = free_response(plant, t)
    assert basis.shape == (400, 3, 8)
    x0 = np.array([0.01, 0.002, -0.003, 0.004, 0.1, -0.02, 0.3, 0.1])
    a, _ = VehicleModel(VEHICLE).linearised().state_matrices()
    system = signal.StateSpace(a, np.zeros((8, 1)), output_matrix(VehicleModel(VEHICLE)),
                               np.zeros((3, 1)))
    _, want, _ = signal.lsim(system, np.zeros(t.size), t, X0=x0)
    coef, *_ = np.linalg.lstsq(basis.reshape(-1, 8), want.ravel(), rcond=None)
    assert np.allclose(basis @ coef, want, atol=1e-9 * np.max(np.abs(want)))


def test_slots_read_and_set_the_vehicle():
    values = {s: slot_value(VEHICLE, s) * 1.1 for s in SLOTS if s.physical}
    changed = vehicle_with(VEHICLE, values)
    for slot, value in values.items():
        assert slot_value(changed, slot) == pytest.approx(value)
    assert changed.track_width_m == VEHICLE.track_width_m
    labels = [s.label for s in SLOTS]
    assert len(set(labels)) == len(labels) and 'vehicle.tire_stiffness[right]' in labels
