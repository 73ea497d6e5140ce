"""Sensor model (MODEL.md "Measurements"): noise statistics, quantisation, seeding, and the
per-sample path against the batch path."""
import numpy as np
import pytest

from road_force_estimator.core.parameters import SimulatorParameters
from road_force_estimator.core.sensors import SensorModel


def truth(n, seed=0):
    rng = np.random.default_rng(seed)
    return rng.normal(size=(n, 2)) * 0.01, rng.normal(size=n) * 0.02


def test_noise_statistics():
    q, phi = truth(200_000)
    sensor = SensorModel(deflection_std_m=1e-5, roll_std_rad=1e-4, seed=11)
    qm, pm = sensor.measure(q, phi)
    noise = np.column_stack((qm - q, pm - phi))
    # Standard error of a std estimate from n samples: std / sqrt(2 n) = 0.16 %.
    np.testing.assert_allclose(noise.std(axis=0), [1e-5, 1e-5, 1e-4], rtol=0.01)
    np.testing.assert_allclose(noise.mean(axis=0) / [1e-5, 1e-5, 1e-4], 0.0, atol=0.01)
    corr = np.corrcoef(noise.T)
    assert np.max(np.abs(corr - np.eye(3))) < 0.01     # independent channels
    # Gaussian: 4th moment 3 sigma^4 (kurtosis), within sampling error.
    z = noise[:, 0] / noise[:, 0].std()
    assert np.mean(z ** 4) == pytest.approx(3.0, abs=0.05)


def test_per_sample_gives_the_batch_numbers():
    q, phi = truth(3000, seed=1)
    sensor = SensorModel(2e-5, 3e-4, deflection_quantum_m=1e-6, roll_quantum_rad=1e-5,
                         seed=5)
    qm, pm = sensor.measure(q, phi)
    measure_one = sensor.sampler()
    rows = [measure_one(q[i], phi[i]) for i in range(len(phi))]   # crosses drawing blocks
    assert np.array_equal(np.array([r[0] for r in rows]), qm)
    assert np.array_equal(np.array([r[1] for r in rows]), pm)
    assert isinstance(rows[0][1], float) and rows[0][0].shape == (2,)
    # A second sampler starts again from the seed.
    again = sensor.sampler()
    assert np.array_equal(again(q[0], phi[0])[0], qm[0])


def test_seeds():
    q, phi = truth(100)
    a = SensorModel(1e-5, 1e-4, seed=1).measure(q, phi)
    b = SensorModel(1e-5, 1e-4, seed=1).measure(q, phi)
    c = SensorModel(1e-5, 1e-4, seed=2).measure(q, phi)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert not np.array_equal(a[0], c[0])


def test_quantisation():
    q, phi = truth(1000, seed=2)
    exact = SensorModel(deflection_quantum_m=1e-4, roll_quantum_rad=1e-3)
    qm, pm = exact.measure(q, phi)
    # Without noise: the nearest multiple of the quantum, error at most half a quantum.
    np.testing.assert_allclose(qm / 1e-4, np.round(qm / 1e-4), atol=1e-9)
    assert np.max(np.abs(qm - q)) <= 0.5e-4 + 1e-15
    assert np.max(np.abs(pm - phi)) <= 0.5e-3 + 1e-15
    assert np.std(qm - q) == pytest.approx(1e-4 / np.sqrt(12), rel=0.1)
    # Zero noise and no quantum: the truth itself.
    qm, pm = SensorModel().measure(q, phi)
    assert np.array_equal(qm, q) and np.array_equal(pm, phi)


def test_from_simulator_parameters():
    sim = SimulatorParameters(noise_deflection_m=2e-5, noise_roll_rad=3e-4, seed=9)
    s = SensorModel.from_simulator(sim)
    assert (s.deflection_std_m, s.roll_std_rad, s.seed) == (2e-5, 3e-4, 9)


def test_bad_values():
    with pytest.raises(ValueError, match='deflection_std_m = -1'):
        SensorModel(deflection_std_m=-1.0)
    with pytest.raises(ValueError, match='roll_quantum_rad = nan'):
        SensorModel(roll_quantum_rad=float('nan'))
    with pytest.raises(ValueError, match='seed'):
        SensorModel(seed=-3)
    with pytest.raises(ValueError, match='shape'):
        SensorModel().measure(np.zeros((5, 3)), np.zeros(5))
