"""The friction's v_f fitted from the drive (estimation.offline.fit_friction_velocity,
observer.friction_velocity_fit; issue 30): the likelihood of the online observer's innovations
picks the plant's v_f from the grid around the file's.

Truth: the plant's tanh friction velocity (core/plant.py, its friction checked against solve_ivp
in test/core/test_friction.py); the file always states 0.01 m/s.
"""
from dataclasses import replace

import numpy as np
import pytest

from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
from road_force_estimator.core.plant import simulate
from road_force_estimator.core.road import iso8608_profile
from road_force_estimator.core.sensors import SensorModel
from road_force_estimator.estimation.offline import fit_friction_velocity

FILE = replace(VehicleParameters(), leaf_spring_friction_n=(1500.0, 1500.0),
               sensor_time_constant_s=(0.003, 0.003))


@pytest.mark.parametrize('truth_vf', [0.005, 0.01, 0.02])
def test_the_fit_finds_the_plants_friction_velocity(truth_vf):
    plant = replace(FILE, leaf_spring_friction_velocity_mps=truth_vf)
    tr = simulate(plant, iso8608_profile('C', 300.0, seed=4), speed_mps=20.0, rate_hz=1000.0,
                  duration_s=12.0, tire_envelope_m=0.25)
    q, phi = SensorModel(deflection_std_m=1e-5, roll_std_rad=1e-4, seed=5,
                         time_constant_s=plant.sensor_time_constant_s,
                         rate_hz=1000.0).measure(tr.q_m, tr.roll_rad)
    stamps = np.round(tr.t_s * 1e9).astype(np.int64)
    restart = np.zeros(stamps.size, bool)
    restart[0] = True
    fitted = fit_friction_velocity(FILE, ObserverParameters(), stamps, q, phi,
                                   np.full(stamps.size, 20.0), restart)
    assert fitted.leaf_spring_friction_velocity_mps == pytest.approx(truth_vf)
    off = fit_friction_velocity(FILE, ObserverParameters(friction_velocity_fit=0), stamps,
                                q, phi, np.full(stamps.size, 20.0), restart)
    assert off is FILE
