"""body_heave's whole-run steps done in chunks against references written here from numpy /
scipy primitives (the whole-run way: ``np.polyfit``, ``sosfilt``, ``sosfiltfilt``, ``cumsum``).

Bit for bit where no whole-run polynomial is fitted; with the fit within a bound of the RMS of
what the trend is taken off. (The memory itself is measured by ``bench.probes.body_heave_memory``,
not here: the numbers are in the report of that work.)
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from road_force_estimator.estimation import body_heave

DT = 1e-3
CHUNK = body_heave.CHUNK
#: the fit against np.polyfit, of the RMS of the data (measured 1.3e-14 at most)
FIT_TOL = 1e-12


def _rms(x) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def _polyfit_trend(z, degree):
    tt = np.linspace(-1.0, 1.0, z.size)
    return np.polyval(np.polyfit(tt, z, degree), tt)


@pytest.mark.parametrize('m, degree', [
    (m, d) for m in (5, 6, 9, 57, 99, 1000, CHUNK - 1, CHUNK + 1, 2 * CHUNK + 17)
    for d in (0, 1, 3, 5) if m > d + 1])
def test_polynomial_fit_is_polyfits(m, degree):
    rng = np.random.default_rng(m + 10 * degree)
    tt = np.linspace(-1.0, 1.0, m)
    z = rng.standard_normal(m) + 40.0 * tt ** 3 - 5.0 * tt + 7.0
    got = body_heave.polynomial_values(body_heave.polynomial_fit(z, degree), m)
    assert np.max(np.abs(got - _polyfit_trend(z, degree))) < FIT_TOL * _rms(z)
    # in pieces as whole
    coef = body_heave.polynomial_fit(z, degree)
    parts = [body_heave.polynomial_values(coef, m, i, min(m, i + 7)) for i in range(0, m, 7)]
    assert np.array_equal(np.concatenate(parts), got)


def test_polynomial_fit_interpolates_few_samples_and_refuses_a_negative_degree():
    z = np.array([1.0, -2.0, 0.5])
    got = body_heave.polynomial_values(body_heave.polynomial_fit(z, 3), 3)
    assert np.allclose(got, z, rtol=0.0, atol=1e-12)
    with pytest.raises(ValueError):
        body_heave.polynomial_fit(z, -1)


def test_subtract_polynomial_is_in_place():
    rng = np.random.default_rng(4)
    z = rng.standard_normal(CHUNK + 3)
    ref = z - _polyfit_trend(z, 3)
    out = body_heave.subtract_polynomial(z, 3)
    assert out is z
    assert np.max(np.abs(out - ref)) < FIT_TOL * _rms(ref + 1.0)


@pytest.mark.parametrize('start, stop, num', [(-1.0, 1.0, 2), (-1.0, 1.0, 9), (0.0, 5e-320, 20),
                                              (0.0, 66812.37, 3 * CHUNK + 5)])
def test_linspace_part_is_linspaces_bits(start, stop, num):
    ref = np.linspace(start, stop, num)
    for i, j in [(0, num), (0, 2), (max(0, num - 3), num), (1, num - 1)]:
        assert np.array_equal(body_heave._linspace_part(start, stop, num, i, j), ref[i:j])


def _ref_zero_phase(a, w, order=body_heave.ZERO_PHASE_ORDER):
    """zero_phase the whole-run way (sosfilt over the run, then its reverse)."""
    _, poles, _ = signal.butter(order, w, btype='high', analog=True, output='zpk')
    out = a
    for n_zeros, reverse in ((order - 2, False), (order, True)):
        sos = signal.zpk2sos(*signal.bilinear_zpk(np.zeros(n_zeros), poles, 1.0, 1.0 / DT))
        x = out[::-1] if reverse else out
        y, _ = signal.sosfilt(sos, x, zi=signal.sosfilt_zi(sos) * x[0])
        out = y[::-1] if reverse else y
    return out


def _ref_in_distance(a, t, v, wavelength, level, degree, order=body_heave.ZERO_PHASE_ORDER):
    """in_distance the whole-run way (cumsum, np.interp, np.polyfit, sosfiltfilt)."""
    v = np.abs(v)
    dt = np.diff(t)
    standing = (v[1:] == 0.0) & (v[:-1] == 0.0)
    vel = np.concatenate([[0.0], np.cumsum(0.5 * (a[1:] + a[:-1]) * dt)])
    z = np.concatenate([[0.0], np.cumsum(0.5 * (vel[1:] + vel[:-1]) * dt)])
    edges = np.flatnonzero(np.diff(np.concatenate([[0], standing.astype(np.int8), [0]])))
    kt, kc, bias = [], [], []
    for s0, s1 in zip(edges[0::2], edges[1::2]):
        if s1 + 1 - s0 < body_heave.MIN_REST_SAMPLES:
            continue
        tt = t[s0:s1 + 1] - t[s0]
        scale = max(float(tt[-1]), 1e-9)
        p = np.polyfit(tt / scale, z[s0:s1 + 1] + level[s0:s1 + 1], 2)
        kt.append(t[s0:s1 + 1])
        kc.append((p[1] + 2.0 * p[0] * tt / scale) / scale)
        bias.append(2.0 * p[0] / (scale * scale))
    if kt:
        kt, kc = np.concatenate(kt), np.concatenate(kc)
        c = np.interp(t, kt, kc)
        c = np.where(t < kt[0], kc[0] + bias[0] * (t - kt[0]), c)
        c = np.where(t > kt[-1], kc[-1] + bias[-1] * (t - kt[-1]), c)
        vel = vel - c
        z = np.concatenate([[0.0], np.cumsum(0.5 * (vel[1:] + vel[:-1]) * dt)])
    dx = 0.5 * (v[1:] + v[:-1]) * dt
    x = np.concatenate([[0.0], np.cumsum(dx)])
    moving = np.concatenate([[True], dx > 0.0])
    xm, zm = x[moving], z[moving]
    grid = np.linspace(0.0, xm[-1], max(8, math.ceil(xm[-1] / np.median(np.diff(xm))) + 1))
    zg = np.interp(grid, xm, zm)
    trend = _polyfit_trend(zg, degree) if degree >= 0 else np.zeros_like(zg)
    sos = signal.butter(order, 2.0 * (grid[1] - grid[0]) / wavelength, btype='high',
                        output='sos')
    rest = zg - trend
    trend = trend + (rest - signal.sosfiltfilt(sos, rest))
    return z - np.interp(x, grid, trend), z


def _run(m: int, stops: bool, seed: int = 1):
    """``(accel, level, t, v)``: white noise plus a sine; 20 m/s, with two stops of 10 % of
    the run between ramps of 20 % each when ``stops``."""
    rng = np.random.default_rng(seed)
    t = DT * np.arange(m)
    a = rng.standard_normal(m) + 0.1 * np.sin(2.0 * np.pi * 0.5 * t)
    level = 1e-3 * rng.standard_normal(m)
    v = np.full(m, 20.0)
    if stops:
        for c in (t[-1] / 3.0, 2.0 * t[-1] / 3.0):
            d = np.clip(np.abs(t - c) - 0.05 * t[-1], 0.0, 0.1 * t[-1])
            v = np.minimum(v, d * (20.0 / (0.1 * t[-1])))
    return a, level, t, v


@pytest.mark.parametrize('m', [8, 100, 2 * CHUNK + 17])
def test_zero_phase_is_the_whole_run_filters_bit_for_bit(m):
    a = _run(m, False)[0]
    w = 2.0 * math.pi * 20.0 / 100.0
    assert np.array_equal(body_heave.zero_phase(a, DT, w), _ref_zero_phase(a, w))


def test_offline_profile_steady_is_zero_phase_less_polyfit():
    m = 3 * CHUNK + 11
    a, level, t, v = _run(m, False)
    zs = _ref_zero_phase(a, 2.0 * math.pi * 20.0 / 1e4)
    ref = zs - _polyfit_trend(zs, 3)
    got = body_heave.offline_profile(a, level, t, v, DT, 20.0, 100.0, 100.0, 3)
    assert np.max(np.abs(got - ref)) < FIT_TOL * _rms(zs)


@pytest.mark.parametrize('degree', [-1, 3])
def test_offline_profile_over_stops_is_in_distance_the_whole_run_way(degree):
    # 200 s, two stops: the stop path (in_distance at 100 m: its high-pass at 4e-4 of the grid's
    # rate; at the 10 km of the smoother, 4e-6, the high-pass's own rounding is ~1e-9 of the
    # double integral: docs/notes/body_heave_bits.md)
    m = 3 * CHUNK + 11
    a, level, t, v = _run(m, True)
    assert body_heave.rest_stretches(v) == 2
    ref, z = _ref_in_distance(a, t, v, 100.0, level, degree)
    if degree < 0:                                  # nothing fitted: the same bits
        got = body_heave.in_distance(a, t, v, 100.0, level=level, degree=-1)
        assert np.array_equal(got, ref)
    else:
        got = body_heave.offline_profile(a, level, t, v, DT, 20.0, 10.0, 10.0, degree)
        assert np.max(np.abs(got - ref)) < FIT_TOL * _rms(z)
