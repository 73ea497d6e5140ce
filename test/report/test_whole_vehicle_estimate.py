"""report.whole_vehicle's estimate columns on made-up loads with analytic answers: a sine about
a constant load per wheel (peak = mean + amplitude, DLC = amplitude / sqrt(2) / mean over whole
periods), constant static loads (axle loads and the gross weight their sums), a quasi-static
trailer LTR ramp (its largest |value| in each segment)."""
import numpy as np
import pytest

from road_force_estimator.estimation.whole_vehicle import WholeVehicleArrays
from road_force_estimator.report.whole_vehicle import segment_columns, segment_table

AXLES = ('front', 'rear')


def arrays(m: int = 4000) -> WholeVehicleArrays:
    """Two axles, 1 kHz, 10 m/s: 40 m; every wheel a 5 Hz sine (whole periods in 10 m)."""
    t = np.arange(m) * 1e-3
    x = 10.0 * t
    means = np.array([30e3, 31e3, 50e3, 52e3])
    amps = np.array([3e3, 2e3, 5e3, 1e3])
    load = means[:, None] + amps[:, None] * np.sin(2 * np.pi * 5.0 * t)
    static = np.repeat(means[:, None], m, axis=1)
    qs = np.vstack([np.zeros(m), -x / 100.0, np.zeros(m)])
    return WholeVehicleArrays(
        np.arange(m, dtype=np.int64) * 1_000_000, x, np.ones(m, bool),
        ('front_left', 'front_right', 'rear_left', 'rear_right'), AXLES,
        ('tractor', 'trailer'), load, static, np.zeros((3, m)), qs, np.zeros((2, m)))


def test_the_columns_have_their_analytic_values():
    wv = arrays()
    table = segment_table(wv, [0.0, 10.0, 20.0, 30.0], [10.0, 20.0, 30.0, 40.0])
    assert tuple(table) == segment_columns(AXLES)
    means = {'front_left': 30e3, 'front_right': 31e3, 'rear_left': 50e3, 'rear_right': 52e3}
    amps = {'front_left': 3e3, 'front_right': 2e3, 'rear_left': 5e3, 'rear_right': 1e3}
    for name, mean in means.items():
        axle, side = name.split('_')
        np.testing.assert_allclose(table[f'peak_load_{axle}_{side}_n'], mean + amps[name],
                                   rtol=1e-6)
        np.testing.assert_allclose(table[f'dlc_{axle}_{side}'],
                                   amps[name] / np.sqrt(2) / mean, rtol=1e-3)
    np.testing.assert_allclose(table['static_load_front_n'], 61e3)
    np.testing.assert_allclose(table['static_load_rear_n'], 102e3)
    np.testing.assert_allclose(table['gross_weight_n'], 163e3)
    # |LTR| = x / 100 at each segment's last sample (samples 1 cm apart, x < its end)
    np.testing.assert_allclose(table['max_abs_ltr_trailer_quasi_static'],
                               [0.0999, 0.1999, 0.2999, 0.3999], atol=1e-12)


def test_a_segment_without_samples_is_nan():
    table = segment_table(arrays(), [0.0, 50.0], [50.0, 100.0])
    assert np.isfinite(table['gross_weight_n'][0]) and np.isnan(table['gross_weight_n'][1])
    assert np.isnan(table['dlc_front_left'][1])
    assert segment_table(arrays(), [], [])['gross_weight_n'].size == 0


def test_unconverged_samples_count_as_the_front_axles_do():
    wv = arrays()
    wv.converged[:] = False
    table = segment_table(wv, [0.0], [40.0])
    assert table['gross_weight_n'][0] == pytest.approx(163e3)
