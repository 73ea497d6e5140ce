"""What OpenBLAS's thread pool costs a node, on the whole vehicle's online model fit.

One verdict (:class:`road_force_estimator.estimation.axle_fit.OnlineAxleFit`) timed slice by
slice, in a child process with the BLAS threads as numpy finds them and in one with one thread (as
the nodes' entry points set it: :mod:`road_force_estimator.ros.launcher`).

Run from the repository root::

    .venv/bin/python -m bench.probes.blas_threads [--repeats 3] [--causal]

The verdict's data: five axles reading the same analytic road (40 sines of 0.7-20 m
wavelength, 1 mm each), 20 m/s at 1 kHz, 45 s (900 m: one verdict over the 800 m window).
Per child: the CPU time of the calling thread per slice (``time.thread_time``; the pool's
other threads not counted), its sum and largest, and the verdict's wall time, the median
over ``--repeats`` verdicts. ``--causal``: the zero-latency statistic
(``OnlineAxleFit(causal=True)``), one wheel reading the road 10 % larger so that its second
pass (the culprit left out of the others' medians) runs too.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

from road_force_estimator.ros.launcher import BLAS_THREAD_VARIABLES


def child(repeats: int, causal: bool = False) -> dict:
    """One verdict's slices, ``repeats`` times (this process's BLAS threads)."""
    import time

    import numpy as np

    from road_force_estimator.estimation.axle_fit import OnlineAxleFit

    rng = np.random.default_rng(1)
    xi = np.array([0.0, 3.7, 9.6, 10.91, 12.22])
    waves = rng.uniform(0.7, 20.0, size=(2, 40))
    phase = rng.uniform(0.0, 2.0 * np.pi, size=(2, 40))
    names = ('front', 'drive', 'trailer_1', 'trailer_2', 'trailer_3')
    t = np.arange(45001) * 1e-3
    x = 20.0 * t
    road = np.array([1e-3 * np.sin(2.0 * np.pi * (x - xi[j])[:, None] / waves[s]
                                   + phase[s]).sum(axis=1) for j in range(5) for s in (0, 1)])
    if causal:
        road[6] *= 1.1                    # trailer_2_left: a culprit, the second pass runs
    load = np.full(10, 4e4)
    sums, peaks, walls = [], [], []
    for _ in range(repeats):
        fit = OnlineAxleFit(xi, names, causal=causal)
        stamps = np.round(t * 1e9).astype(np.int64)
        for k in range(t.size):
            fit.push(int(stamps[k]), float(x[k]), road[:, k], load, load)
        job = fit.verdict_job()
        slices = []
        wall = time.perf_counter()
        while True:
            c = time.thread_time()
            try:
                next(job)
            except StopIteration:
                slices.append(time.thread_time() - c)
                break
            slices.append(time.thread_time() - c)
        walls.append(time.perf_counter() - wall)
        sums.append(sum(slices))
        peaks.append(max(slices))
    return {'slices': len(slices), 'cpu_ms': 1e3 * float(np.median(sums)),
            'largest_ms': 1e3 * float(np.median(peaks)), 'wall_ms': 1e3 * float(np.median(walls))}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog='python -m bench.probes.blas_threads',
                                description=__doc__.splitlines()[0])
    p.add_argument('--repeats', type=int, default=3)
    p.add_argument('--causal', action='store_true',
                   help='the zero-latency statistic, with a culprit')
    p.add_argument('--child', action='store_true', help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.child:
        print(json.dumps(child(args.repeats, args.causal)))
        return 0
    print('| BLAS threads | slices | CPU of the verdict (ms) | largest slice (ms) | wall (ms) |')
    print('|---|---:|---:|---:|---:|')
    base = {k: v for k, v in os.environ.items() if k not in BLAS_THREAD_VARIABLES}
    for label, env in (('as numpy finds them', base),
                       ('one', {**base, **{k: '1' for k in BLAS_THREAD_VARIABLES}})):
        out = subprocess.run([sys.executable, '-m', 'bench.probes.blas_threads', '--child',
                              '--repeats', str(args.repeats)]
                             + (['--causal'] if args.causal else []), env=env, capture_output=True,
                             text=True, check=True)
        r = json.loads(out.stdout.strip().splitlines()[-1])
        print(f'| {label} | {r["slices"]} | {r["cpu_ms"]:.1f} | {r["largest_ms"]:.2f} | '
              f'{r["wall_ms"]:.1f} |', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
