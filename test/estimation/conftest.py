"""Fixtures of the estimation tests: plant drives, with and without sensor noise."""
import pathlib

import numpy as np
import pytest

from road_force_estimator.core.plant import simulate
from road_force_estimator.core.road import iso8608_profile
from road_force_estimator.core.sensors import SensorModel
from model_observer_data import SPEED, VEHICLE


@pytest.fixture(scope='module')
def drive():
    """8 s of ISO 8608 class C at 20 m/s, 1 kHz, tire envelope 0.25 m."""
    road = iso8608_profile('C', 220.0, seed=5)
    return simulate(VEHICLE, road, speed_mps=SPEED, rate_hz=1000.0, duration_s=8.0,
                    tire_envelope_m=0.25)


@pytest.fixture(scope='module')
def noisy(drive):
    q, phi = SensorModel(deflection_std_m=1e-5, roll_std_rad=1e-4, seed=7).measure(
        drive.q_m, drive.roll_rad)
    return q, phi


@pytest.fixture(scope='module')
def drive_c():
    """12 s on ISO 8608 class C at 20 m/s, 1 kHz, tire envelope 0.25 m."""
    road = iso8608_profile('C', 300.0, seed=3)
    return simulate(VEHICLE, road, speed_mps=SPEED, rate_hz=1000.0, duration_s=12.0,
                    tire_envelope_m=0.25)


ARTICULATED_CONFIG = (pathlib.Path(__file__).resolve().parents[2] / 'config'
                      / 'tractor_semitrailer.yaml')
ARTICULATED_DURATION_S = 8.0


@pytest.fixture(scope='session')
def articulated_c():
    """The whole vehicle (config/tractor_semitrailer.yaml): 8 s of class C at 20 m/s, 1 kHz,
    10 um of deflection noise; ``(drive setup, plant trace, stamps ns, readings)``."""
    from road_force_estimator.core.articulated_plant import simulate_articulated
    from road_force_estimator.core.articulated_setup import ArticulatedDrive
    from road_force_estimator.core.parameters import load_params_file
    from road_force_estimator.estimation.models.articulated import channel_names

    base = load_params_file(ARTICULATED_CONFIG)
    base.update({'simulator.noise.deflection': 1e-5, 'simulator.noise.roll': 1e-5 / 0.45,
                 'simulator.duration': ARTICULATED_DURATION_S})
    d = ArticulatedDrive.from_values(base)
    road = iso8608_profile('C', d.road_length_m, seed=11)
    tr = simulate_articulated(d.vehicle, road, speed_mps=20.0, rate_hz=1000.0,
                              duration_s=ARTICULATED_DURATION_S, tire_envelope_m=0.25,
                              model=d.model)
    y = d.sensors(channel_names(d.model)).measure(tr)
    return d, tr, np.round(tr.t_s * 1e9).astype(np.int64), y
