"""body_heave.py against the analytic responses of its filters.

Per sample: ``z_s = H(s) a / s^2`` with ``H = 1 - G``, ``G = (n w^(n-1) s + w^n) / (s + w)^n``
(n = 8), written here from that formula, not from the module's coefficients. Offline:
``z = -|H_B(j Omega)|^2 a / Omega^2`` with ``H_B`` the Butterworth high-pass of even order.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from road_force_estimator.estimation import body_heave

DT = 1e-3
SPEED = 20.0
CUTOFF_M = 100.0
W = 2.0 * math.pi * SPEED / CUTOFF_M


def _h_over_s2(omega: float, n: int = body_heave.ORDER) -> complex:
    s = 1j * omega
    g = (n * W ** (n - 1) * s + W ** n) / (s + W) ** n
    return (1.0 - g) / (s * s)


def _run(accel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    wcps = body_heave.cutoff_per_speed(CUTOFF_M)
    state = body_heave.start(float(accel[0]))
    z = np.zeros(accel.size)
    dz = np.zeros(accel.size)
    for k in range(1, accel.size):
        state = body_heave.step(state, float(accel[k]), DT, SPEED, wcps)
        z[k], dz[k] = state[-2], state[-1]
    return z, dz


@pytest.mark.parametrize('wavelength_m', [5.0, 30.0, 190.0, 600.0])
def test_sinusoid_follows_the_analytic_response(wavelength_m):
    # a = sin(Omega t): after the start transient (~t^7 exp(-w t)), z_s and dz_s are the
    # steady-state responses H / s^2 and H / s (Tustin warping: (Omega dt)^2 / 12 ~ 1e-5)
    omega = 2.0 * math.pi * SPEED / wavelength_m
    t = np.arange(int(70.0 / DT)) * DT
    z, dz = _run(np.sin(omega * t))
    late = t > 55.0
    h = _h_over_s2(omega)
    z_ref = np.imag(h * np.exp(1j * omega * t))
    dz_ref = np.imag(1j * omega * h * np.exp(1j * omega * t))
    scale = abs(h)
    assert np.max(np.abs(z[late] - z_ref[late])) < 1e-3 * scale
    assert np.max(np.abs(dz[late] - dz_ref[late])) < 1e-3 * omega * scale
    if wavelength_m <= 30.0:        # in the band: the plain double integral to 0.1 %
        assert abs(abs(h) * omega ** 2 - 1.0) < 1e-3


def test_constant_bias_settles_at_the_dc_gain():
    # H / s^2 -> C(n, 2) / w^2 at s = 0
    z, dz = _run(np.full(int(90.0 / DT), 0.05))
    assert z[-1] == pytest.approx(math.comb(body_heave.ORDER, 2) * 0.05 / W ** 2, rel=1e-4)
    assert abs(dz[-1]) < 1e-6


@pytest.mark.parametrize('order', [2, 4, 6])
def test_zero_phase_gain(order):
    t = np.arange(160000) * DT
    for wavelength_m in (30.0, 100.0, 300.0):
        omega = 2.0 * math.pi * SPEED / wavelength_m
        z = body_heave.zero_phase(-omega ** 2 * np.sin(omega * t), DT, W, order)
        r2n = (omega / W) ** (2 * order)
        mid = slice(60000, -60000)
        np.testing.assert_allclose(z[mid], r2n / (1.0 + r2n) * np.sin(omega * t[mid]),
                                   rtol=0, atol=2e-4)


def test_zero_phase_rejects_odd_orders_and_passes_short_input():
    with pytest.raises(ValueError, match='order'):
        body_heave.zero_phase(np.zeros(100), DT, W, 3)
    assert np.array_equal(body_heave.zero_phase(np.ones(5), DT, W), np.zeros(5))


def _run_speeds(accel: float, speeds: np.ndarray, state=None):
    wcps = body_heave.cutoff_per_speed(CUTOFF_M)
    state = body_heave.start(accel) if state is None else state
    z = np.zeros(speeds.size)
    for k, v in enumerate(speeds):
        state = body_heave.step(state, accel, DT, float(v), wcps)
        z[k] = state[-2]
    return z, state


def test_a_speed_change_never_amplifies_and_standing_holds():
    # a constant acceleration bias b settles at z_s = C(8, 2) b / w^2 (the final-value
    # theorem on H / s^2: (1 - G) / s^2 -> C(n, 2) / w^2 at s = 0); at 2 m/s
    b = 1e-4
    slow = 2.0
    w0 = 2.0 * math.pi * slow / CUTOFF_M
    z, state = _run_speeds(b, np.full(200_000, slow))
    assert z[-1] == pytest.approx(math.comb(8, 2) * b / w0 ** 2, rel=1e-3)
    # standing: held exactly
    z_still, state = _run_speeds(b, np.zeros(5000), state)
    assert np.all(z_still == z[-1])
    # pulling away to 20 m/s at once: no jump (kept y_k would give (w / w0)^6 = 1e6 times)
    # and it settles at the new steady value
    z_fast, _ = _run_speeds(b, np.full(100_000, SPEED), state)
    assert abs(z_fast[0] - z[-1]) < 1e-3 * abs(z[-1])
    assert np.max(np.abs(z_fast)) <= abs(z[-1]) * (1.0 + 1e-9)
    assert z_fast[-1] == pytest.approx(math.comb(8, 2) * b / W ** 2, rel=1e-3)
    # slowing down again: z_s does not grow beyond the new (slow) steady value either
    z_slow, _ = _run_speeds(b, np.full(5000, slow), _run_speeds(b, np.full(100_000, SPEED),
                                                                state)[1])
    assert np.max(np.abs(z_slow)) <= abs(z[-1]) * (1.0 + 1e-9)
