"""The model_fit diagnostic (estimation/model_fit.py) both ways: matched drives never trip it,
every parameter off by 10 % (seeded signs) always does. Drives from the plant (core.plant),
noise from a seeded generator; the verdict against the truth of which file was given."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
from road_force_estimator.estimation import estimate_batch
from road_force_estimator.estimation import fit_check as model_fit

VEHICLE = VehicleParameters()


def _off(vehicle: VehicleParameters, frac: float, seed: int) -> VehicleParameters:
    rng = np.random.default_rng(seed)

    def f() -> float:
        return 1.0 + frac * float(rng.choice([-1.0, 1.0]))

    def pair(p):
        return tuple(f() * x for x in p)

    return replace(vehicle, sprung_mass_kg=f() * vehicle.sprung_mass_kg,
                   roll_inertia_kgm2=f() * vehicle.roll_inertia_kgm2,
                   cg_height_m=f() * vehicle.cg_height_m,
                   unsprung_mass_kg=pair(vehicle.unsprung_mass_kg),
                   suspension_stiffness_npm=pair(vehicle.suspension_stiffness_npm),
                   suspension_damping_nspm=pair(vehicle.suspension_damping_nspm),
                   tire_stiffness_npm=pair(vehicle.tire_stiffness_npm),
                   static_load_setting_n=tuple(vehicle.static_load_n))


def _drive(road_class: str, speed: float, noise: float):
    from road_force_estimator.core.plant import simulate
    from road_force_estimator.core.road import iso8608_profile
    road = iso8608_profile(road_class, speed * 6.0 + 20.0, seed=5)
    tr = simulate(VEHICLE, road, speed_mps=speed, rate_hz=1000.0, duration_s=6.0,
                  tire_envelope_m=0.25)
    rng = np.random.default_rng(11)
    q = tr.q_m + rng.normal(0.0, noise, tr.q_m.shape)
    phi = tr.roll_rad + rng.normal(0.0, 10.0 * noise, tr.roll_rad.shape)
    return np.round(tr.t_s * 1e9).astype(np.int64), q, phi, np.full(tr.t_s.size, speed)


def _verdict(drive, vehicle):
    stamps, q, phi, v = drive
    est = estimate_batch(stamps, q, phi, v, vehicle, ObserverParameters())
    return model_fit.assess(est, vehicle, ObserverParameters(), v)


@pytest.mark.parametrize('road_class,speed,noise', [
    ('A', 10.0, 0.0), ('B', 30.0, 1e-5), ('C', 10.0, 1e-5), ('C', 30.0, 0.0),
    ('A', 30.0, 1e-6)])
def test_matched_ok_and_every_parameter_off_by_10_percent_trips(road_class, speed, noise):
    drive = _drive(road_class, speed, noise)
    ratio, word = _verdict(drive, VEHICLE)
    assert word == model_fit.OK, ratio
    for seed in (1, 2):
        ratio, word = _verdict(drive, _off(VEHICLE, 0.10, seed))
        assert word == model_fit.MISMATCH, (seed, ratio)


def test_residual_ratio_of_white_noise_is_the_band_fraction():
    # white noise of std sigma through the band-pass keeps sqrt(2 B dt) of it, B the noise
    # bandwidth: a Butterworth low-pass of order n has (pi / 2n) / sin(pi / 2n) x its cutoff,
    # and the band-pass made from the n = 2 prototype that factor x its width
    rng = np.random.default_rng(3)
    t = np.arange(60_000) * 1e-3
    r = rng.normal(0.0, 1.0, t.size)
    lo, hi = model_fit.BAND_HZ
    expected = np.sqrt(2.0 * (np.pi / 4.0) / np.sin(np.pi / 4.0) * (hi - lo) * 1e-3)
    assert model_fit.residual_ratio(t, r, 1.0) == pytest.approx(expected, rel=0.05)
    assert model_fit.verdict(float('nan')) == model_fit.OK


def test_the_monitor_is_scipys_band_pass():
    # reference: scipy.signal.sosfilt of the same design, started at the skip
    from scipy import signal
    rng = np.random.default_rng(4)
    t = np.arange(8000) * 1e-3
    r = np.cumsum(rng.normal(0.0, 1.0, t.size)) + 50.0 * np.sin(2 * np.pi * 2.0 * t)
    sos = signal.butter(2, model_fit.BAND_HZ, btype='bandpass', fs=1000.0, output='sos')
    keep = t >= 2.0
    band = signal.sosfilt(sos, r[keep] - r[keep][0])
    settled = t[keep] >= 2.0 + model_fit.SETTLE_S - 1e-9
    expected = np.sqrt(np.mean(band[settled] ** 2)) / 7.0
    assert model_fit.residual_ratio(t, r, 7.0) == pytest.approx(expected, rel=1e-9)


def test_residual_ratio_is_the_monitor_sample_by_sample_to_the_bit():
    # the node's per-sample monitor is the reference of the vectorised batch path: repeated
    # stamps, non-finite residuals, jittered steps and short drives included
    rng = np.random.default_rng(5)
    for trial in range(40):
        n = int(rng.integers(10, 9000))
        dt = (1e-3, 2e-3, 1e-2)[trial % 3]
        t = 50.0 + np.cumsum(dt * (1.0 + 1e-6 * rng.standard_normal(n)))
        if trial % 4 == 0:
            t[2000:2004] = t[2000] if n > 2004 else t[2000:2004]
        r = np.cumsum(rng.standard_normal(n)) * 10.0 ** rng.uniform(-2.0, 4.0)
        if trial % 5 == 0:
            r[rng.integers(0, n, 30)] = np.nan
        if trial % 7 == 0:
            r[:n // 2] = np.inf
        if trial % 6 == 1:            # gaps (the core restarts): one mid-drive, one at 2 s
            t[n // 2:] += 0.3
            t[np.searchsorted(t, t[0] + 2.0):] += 0.5
        mon = model_fit.ModelFitMonitor()
        for tk, rk in zip(t.tolist(), r.tolist()):
            mon.update(tk, rk)
        want, got = mon.ratio(3.0), model_fit.residual_ratio(t, r, 3.0)
        assert (np.isnan(want) and np.isnan(got)) or want == got, (trial, want, got)


def test_a_gap_restarts_the_band_pass_and_the_sums_go_on():
    # reference: scipy's band-pass run apart on the two stretches around a 0.5 s gap (the
    # first designed at the skip), each from its first residual, squares from SETTLE_S on;
    # a gap where the band-pass would be designed (0.6 s after 1.9 s) is not designed at
    from scipy import signal
    rng = np.random.default_rng(6)
    t = np.arange(12000) * 1e-3
    t[1900:] += 0.6
    t[7000:] += 0.5
    r = np.cumsum(rng.normal(0.0, 1.0, t.size)) + 30.0 * np.sin(2 * np.pi * 1.5 * t)
    sos = signal.butter(2, model_fit.BAND_HZ, btype='bandpass', fs=1000.0, output='sos')
    squares = []
    for piece in (slice(1901, 7000), slice(7000, None)):
        band = signal.sosfilt(sos, r[piece] - r[piece][0])
        squares.append(band[t[piece] >= t[piece][0] + model_fit.SETTLE_S - 1e-9] ** 2)
    expected = np.sqrt(np.mean(np.concatenate(squares))) / 5.0
    assert model_fit.residual_ratio(t, r, 5.0) == pytest.approx(expected, rel=1e-9)
