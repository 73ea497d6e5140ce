"""The estimated profile as profilers are judged (issue 21), per mode, at its own distance.

``.venv/bin/python -m bench.studies.profile_correlation [--scenarios NAME ...] [--duration S]
[--speed-scale K ...] [--output FILE]``

For each scenario of :mod:`bench.accuracy.scenarios` (default: C20-1k-10um, profile_1, jpcp) and
each speed scale K (default 1 and 1.015: the recorded speed reads K x the true speed, an odometer
scale error; the truth is unchanged), the package defaults estimate the drive in three modes:
zero latency (``estimate_batch``), 10 ms (``observer.latency = 0.01``) and offline
(``estimate_recording``, what ``estimate_bag --mode offline`` runs).

Each estimated profile is rated with the IRI-filtered cross correlation
(:mod:`road_force_estimator.core.profile_correlation`) against the true profile: the estimate
at the distance the estimator integrated from the recorded speed, the truth at the distance
truly travelled (as :mod:`road_force_estimator.report` does), from 30 m after the convergence
skip. Figures: the lower wheel over the drive, the lowest 100 m segment, and the best offset
of the last segment with its rating (how far the estimate has placed the road from where it
is, found within the +-1 m search only: a low rating says it is further off).

What it found: docs/notes/profile_correlation.md.
"""
from __future__ import annotations

import argparse
from dataclasses import replace
import math
from pathlib import Path
import sys
import time

import numpy as np

from bench.accuracy.scenarios import PROFILE_BAND_M, build_drive, scenario_by_name

DEFAULT_SCENARIOS = ('C20-1k-10um', 'profile_1', 'jpcp')
MODES = ('zero latency', '10 ms', 'offline')


def estimate(drive, mode: str, speed_scale: float):
    """The package defaults' estimate of ``drive`` in ``mode``, the speed read x scale."""
    from road_force_estimator.core.parameters import ObserverParameters
    from road_force_estimator.estimation import estimate_batch, estimate_recording

    speed = drive.speed_mps * speed_scale
    args = (drive.stamps_ns, drive.q_m, drive.roll_rad, speed, drive.vehicle_observer)
    if mode == 'offline':
        return estimate_recording(*args, ObserverParameters())
    obs = ObserverParameters() if mode == 'zero latency' else \
        ObserverParameters.from_parameters({'observer.latency': 0.01})
    return estimate_batch(*args, obs)


def rate(drive, est) -> dict[str, float]:
    """Ratings of one estimate: ``xcorr`` (lower wheel), ``seg_min``, ``last_lag_m``,
    ``last_rating``, ``last_end_m`` (the last segment's end, m of true distance)."""
    from road_force_estimator.core import profile_correlation as pc

    stamps = np.asarray(est.stamp_ns, dtype=np.int64)
    valid = np.asarray(est.valid, dtype=bool)
    x = np.asarray(est.distance_m, dtype=float)[valid]
    road = np.asarray(est.road_m, dtype=float)[valid]
    k = np.searchsorted(drive.stamps_ns, stamps[valid])
    xt = drive.truth['distance_m'][k]
    xt = xt - xt[0] + x[0]
    up = np.concatenate([[True], np.diff(x) > 0]) & np.concatenate([[True], np.diff(xt) > 0])
    x, road, xt, truth = x[up], road[up], xt[up], drive.truth['road_m'][k][up]
    start = float(xt[np.searchsorted(drive.t_s[k][up], drive.t_s[drive.skip])]) + \
        PROFILE_BAND_M[1]
    whole, seg, last = [], [], []
    for side in (0, 1):
        res = pc.segment_correlation(x, road[:, side], xt, truth[:, side], start_m=start)
        whole.append(res.whole.rating)
        seg += [c.rating for c in res.segments]
        last.append(res.segments[-1])
        end = float(res.edges_m[-1])
    worst_last = min(last, key=lambda c: c.rating)
    return {'xcorr': min(whole), 'seg_min': float(np.nanmin(seg)),
            'last_lag_m': worst_last.lag_m, 'last_rating': worst_last.rating,
            'last_end_m': end}


def run(names, duration_s: float | None, scales, log=None) -> list[dict]:
    rows = []
    for name in names:
        sc = scenario_by_name(name)
        if duration_s is not None:
            sc = replace(sc, duration_s=duration_s)
        t0 = time.perf_counter()
        drive = build_drive(sc)
        for scale in scales:
            for mode in MODES:
                rows.append({'scenario': name, 'scale': scale, 'mode': mode,
                             **rate(drive, estimate(drive, mode, scale))})
        if log:
            log(f'{name}: {len(drive.t_s)} samples, {time.perf_counter() - t0:.1f} s')
    return rows


def markdown(rows: list[dict], command: str) -> str:
    lines = [f'Command: `{command}`', '',
             '| scenario | speed read | mode | xcorr, lower wheel | lowest 100 m segment | '
             'last segment: best offset (m) / its rating | at (m) |',
             '|---|---:|---|---:|---:|---:|---:|']
    for r in rows:
        lag = r['last_lag_m']
        lag_text = 'n/a' if not math.isfinite(lag) else f'{lag:+.2f}'
        lines.append(f"| {r['scenario']} | x {r['scale']:g} | {r['mode']} | {r['xcorr']:.3f} | "
                     f"{r['seg_min']:.3f} | {lag_text} / {r['last_rating']:.3f} | "
                     f"{r['last_end_m']:.0f} |")
    return '\n'.join(lines) + '\n'


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog='python -m bench.studies.profile_correlation',
                                description=__doc__.split('\n')[0])
    p.add_argument('--scenarios', nargs='+', default=list(DEFAULT_SCENARIOS))
    p.add_argument('--duration', type=float, default=None, help='drive duration (s)')
    p.add_argument('--speed-scale', type=float, nargs='+', default=[1.0, 1.015])
    p.add_argument('--output', type=Path, default=None)
    args = p.parse_args(argv)
    try:
        for n in args.scenarios:
            scenario_by_name(n)
    except ValueError as exc:
        print(f'profile_correlation: {exc}', file=sys.stderr)
        return 2
    rows = run(args.scenarios, args.duration, args.speed_scale,
               log=lambda s: print(s, file=sys.stderr))
    text = markdown(rows, 'python -m bench.studies.profile_correlation ' + ' '.join(
        sys.argv[1:] if argv is None else argv))
    print(text)
    if args.output:
        args.output.write_text(text)
    return 0


if __name__ == '__main__':
    sys.exit(main())
