"""The noise estimate (estimation/noise.py) on known white noise, even and uneven sampling.
"""
import math

import numpy as np
import pytest

from road_force_estimator.estimation.observer.noise import noise_std


class TestNoiseEstimate:
    @pytest.mark.parametrize('sigma', [1e-6, 1e-5, 5e-5])
    def test_recovers_a_known_noise_std(self, sigma):
        rng = np.random.default_rng(11)
        t = np.arange(4000) * 1e-3
        smooth = 5e-3 * np.sin(2 * math.pi * 1.7 * t) + 1e-3 * np.sin(2 * math.pi * 9.0 * t)
        x = smooth + rng.normal(0.0, sigma, t.size)
        assert noise_std(x) == pytest.approx(sigma, rel=0.05)
        # uneven sampling: the divided differences
        tu = np.cumsum(rng.uniform(0.5e-3, 1.5e-3, 4000))
        xu = 5e-3 * np.sin(2 * math.pi * 1.7 * tu) + rng.normal(0.0, sigma, tu.size)
        assert noise_std(xu, tu) == pytest.approx(sigma, rel=0.05)
