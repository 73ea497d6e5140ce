"""Fixtures of the estimation tests: plant drives, with and without sensor noise."""
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
