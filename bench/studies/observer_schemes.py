"""Benchmark of the differentiator schemes inside the estimator (issue 4).

Drive: ISO 8608 class C (road seed 1), 20 m/s, 1 kHz, tire envelope 0.25 m (the simulator's
defaults), ``--duration`` seconds. Sensors: :class:`road_force_estimator.core.sensors.SensorModel`
(seed 1), deflection noise 0, 10 and 100 um; roll noise "to match" = 10 rad/m times the
deflection noise (0, 100, 1000 urad), the ratio of the simulator's defaults (1e-5 m, 1e-4 rad).

For each scheme (``euler`` = the paper's, ``taylor``, ``implicit``) and noise level:
wheel-load error after a 2 s skip (RMS and peak, % of the true dynamic-load RMS, mean of both
wheels; RMS also as % of the static load), band-passed (0.5-30 m) profile error after a 6 s
skip and away from the last 40 m (RMS, % of the band's RMS and mm), LTR RMS error, and the
convergence time t_0: the worst over six starts in mid-drive (the differentiators start at
``(f, 0, 0)`` while the signal moves) of the first time after which its load errors stay
within 1.2 times the peak error of the estimator that ran from the start, on the same samples
(see :func:`convergence`). With ``--tune``, also the best L_q of a grid per row.

Cost: median over repeats of the CPU time (``time.process_time``, so that other processes on
a shared machine disturb it less than wall time) of :meth:`Estimator.update` per sample
(``--cost-samples`` samples per repeat), and of :func:`estimate_batch`.

Run: ``.venv/bin/python -m bench.studies.observer_schemes [--duration 30] [--tune]``.

What it found: docs/notes/observer_schemes.md.
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time

import numpy as np

from road_force_estimator.core import metrics
from road_force_estimator.estimation import SCHEMES, Estimator, estimate_batch
from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
from road_force_estimator.core.plant import simulate
from road_force_estimator.core.road import iso8608_profile
from road_force_estimator.core.sensors import SensorModel

NOISE_M = (0.0, 10e-6, 100e-6)
ROLL_PER_DEFLECTION = 10.0   # rad/m
SPEED = 20.0
RATE = 1000.0
LOAD_SKIP_S = 2.0
PROFILE_SKIP_S = 6.0
TUNE_GRID = (1000.0, 2000.0, 3000.0, 5000.0, 10000.0)
T0_MARGIN = 1.2


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--duration', type=float, default=30.0, help='drive length (s)')
    p.add_argument('--tune', action='store_true', help='also sweep L_q over a grid per row')
    p.add_argument('--cost-samples', type=int, default=5000)
    p.add_argument('--repeats', type=int, default=7)
    return p


def drive(duration_s: float):
    vehicle = VehicleParameters()
    road = iso8608_profile('C', SPEED * duration_s + 50.0, seed=1)
    return vehicle, simulate(vehicle, road, speed_mps=SPEED, rate_hz=RATE,
                             duration_s=duration_s, tire_envelope_m=0.25)


def score(vehicle, tr, est) -> dict:
    t = tr.t_s
    after = t >= LOAD_SKIP_S
    loads = metrics.load_errors(est.wheel_load_n, tr.wheel_load_n, vehicle.static_load_n,
                                mask=after)
    x = est.distance_m
    judged = (t >= PROFILE_SKIP_S) & (x <= x[-1] - 40.0)
    prof = metrics.profile_errors(x, est.road_m, tr.road_m, mask=judged)
    true_ltr = (tr.wheel_load_n[:, 1] - tr.wheel_load_n[:, 0]) / tr.wheel_load_n.sum(axis=1)
    ltr = metrics.ltr_stats(est.ltr, true_ltr, mask=after)
    return dict(load_rms=loads.rms_pct.mean(), load_peak=loads.peak_pct.mean(),
                load_static=loads.rms_pct_static.mean(), prof_rms=prof.rms_pct.mean(),
                prof_mm=1e3 * prof.rms.mean(), ltr=ltr['rms_error'])


def convergence(vehicle, tr, q, phi, observer, reference) -> float:
    """Worst t_0 over starts in mid-drive (the plant's own start is at rest, too easy).

    A fresh estimator started at a mid-drive sample (differentiators at ``(f, 0, 0)`` while
    the signal moves) runs over 2 s of samples. Its tolerance is the accuracy the estimator
    that ran from the start (``reference``, an :class:`EstimateArrays`) reaches on the same
    samples: :data:`T0_MARGIN` times its peak load error there, per wheel. t_0 is the first
    time after which the fresh load errors stay inside.
    """
    worst = 0.0
    n = int(2.0 * RATE)
    for start_s in (3.0, 5.5, 8.0, 10.5, 13.0, 15.5):
        sl = slice(int(start_s * RATE), int(start_s * RATE) + n)
        stamps = np.round(tr.t_s[sl] * 1e9).astype(np.int64)
        est = estimate_batch(stamps, q[sl], phi[sl], SPEED, vehicle, observer)
        tol = T0_MARGIN * np.abs(reference.wheel_load_n[sl] - tr.wheel_load_n[sl]).max(axis=0)
        err = est.wheel_load_n - tr.wheel_load_n[sl]
        worst = max(worst, metrics.convergence_time(est.t_s, err, tol))
    return worst


def cost(observer: ObserverParameters, tr, q, phi, n: int, repeats: int) -> tuple[float, float]:
    n = min(n, len(tr.t_s))
    stamps = np.round(tr.t_s[:n] * 1e9).astype(np.int64)
    st, ql, pl = stamps.tolist(), q[:n].tolist(), phi[:n].tolist()
    per, batch = [], []
    for _ in range(repeats):
        est = Estimator(VehicleParameters(), observer)
        update = est.update
        t0 = time.process_time()
        for k in range(n):
            update(st[k], ql[k], pl[k], SPEED)
        per.append((time.process_time() - t0) / n)
        t0 = time.process_time()
        estimate_batch(stamps, q[:n], phi[:n], SPEED, VehicleParameters(), observer)
        batch.append((time.process_time() - t0) / n)
    return 1e6 * float(np.median(per)), 1e6 * float(np.median(batch))


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    if not args.duration >= 10.0:
        print('observer_schemes: --duration must be >= 10 s', file=sys.stderr)
        return 2
    vehicle, tr = drive(args.duration)
    stamps = np.round(tr.t_s * 1e9).astype(np.int64)
    dyn = np.sqrt(np.mean(tr.tire_force_dynamic_n ** 2, axis=0)).mean()
    print(f'ISO 8608 C, {SPEED:g} m/s, {RATE:g} Hz, {args.duration:g} s: true dynamic-load RMS '
          f'{dyn:.0f} N on a static load of {vehicle.static_load_n[0]:.0f} N; max |dddq| '
          f'{np.abs(np.diff(tr.q_m, 3, axis=0)).max() * RATE ** 3:.0f} m/s^3, max |dddphi| '
          f'{np.abs(np.diff(tr.roll_rad, 3)).max() * RATE ** 3:.0f} rad/s^3\n')
    base = ObserverParameters()
    head = ('| scheme | noise q (um) | noise phi (urad) | L_q (m/s^3) | L_phi (rad/s^3) | '
            'load RMS (% dyn) | load peak (% dyn) | load RMS (% static) | profile RMS (% band) '
            '| profile RMS (mm) | LTR RMS | t_0 (s) |')
    print(head)
    print('|' + '---|' * head.count(' | ') + '---|')
    rows_tuned = []
    measured = {}
    for noise in NOISE_M:
        sensor = SensorModel(deflection_std_m=noise, roll_std_rad=ROLL_PER_DEFLECTION * noise,
                             seed=1)
        q, phi = sensor.measure(tr.q_m, tr.roll_rad)
        measured[noise] = (q, phi)
        for scheme in SCHEMES:
            obs = dataclasses.replace(base, discretization=scheme)
            est = estimate_batch(stamps, q, phi, SPEED, vehicle, obs)
            s = score(vehicle, tr, est)
            s['t0'] = convergence(vehicle, tr, q, phi, obs, est)
            print(f'| {scheme} | {1e6 * noise:g} | {1e6 * ROLL_PER_DEFLECTION * noise:g} | '
                  f'{obs.lipschitz_deflection_mps3:g} | {obs.lipschitz_roll_radps3:g} | '
                  f'{s["load_rms"]:.1f} | {s["load_peak"]:.0f} | {s["load_static"]:.2f} | '
                  f'{s["prof_rms"]:.1f} | {s["prof_mm"]:.2f} | {s["ltr"]:.4f} | '
                  f'{s["t0"]:.3f} |', flush=True)
            if args.tune:
                best = None
                for lq in TUNE_GRID:
                    o = dataclasses.replace(obs, lipschitz_deflection_mps3=lq)
                    r = score(vehicle, tr, estimate_batch(stamps, q, phi, SPEED, vehicle, o))
                    if best is None or r['load_rms'] < best[1]['load_rms']:
                        best = (lq, r)
                rows_tuned.append((scheme, noise, best))
    if rows_tuned:
        print('\nBest L_q of the grid', TUNE_GRID, '(L_phi default), same drive:\n')
        print('| scheme | noise q (um) | best L_q | load RMS (% dyn) | profile RMS (% band) |')
        print('|---|---|---|---|---|')
        for scheme, noise, (lq, r) in rows_tuned:
            print(f'| {scheme} | {1e6 * noise:g} | {lq:g} | {r["load_rms"]:.1f} | '
                  f'{r["prof_rms"]:.1f} |')
    print('\nCPU time per sample (median of', args.repeats, 'repeats of', args.cost_samples,
          'samples, 10 um noise):\n')
    print('| scheme | Estimator.update (us/sample) | estimate_batch (us/sample) |')
    print('|---|---|---|')
    q, phi = measured[NOISE_M[1]]
    for scheme in SCHEMES:
        per, batch = cost(dataclasses.replace(base, discretization=scheme), tr, q, phi,
                          args.cost_samples, args.repeats)
        print(f'| {scheme} | {per:.2f} | {batch:.2f} |', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
