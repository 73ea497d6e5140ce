"""The operating point (estimation/schedule.py): noise and roughness estimated online on the plant.
"""

import pytest

from road_force_estimator.core.parameters import ObserverParameters
from model_observer_data import SPEED, VEHICLE, to_stamps
from road_force_estimator.estimation import estimate_batch


class TestOnlineStatistics:
    def test_online_estimates_on_the_plant(self, drive, noisy):
        q, phi = noisy
        est = estimate_batch(to_stamps(drive.t_s), q, phi, SPEED, VEHICLE, ObserverParameters())
        st = est.status
        assert st.noise_deflection_m == pytest.approx(1e-5, rel=0.1)
        assert st.noise_roll_rad == pytest.approx(1e-4, rel=0.1)
        # ISO class C: Gd(n0) = 256e-6 m^3 (geometric mean of the class)
        assert 256e-6 / 1.5 <= st.road_roughness_m3 <= 256e-6 * 1.5
        assert st.gain_designs <= 10

