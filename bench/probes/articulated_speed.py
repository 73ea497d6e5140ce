"""Benchmark: simulate_bag with the articulated truck, a long drive (default 10 minutes).

Run from the repository root::

    .venv/bin/python -m bench.probes.articulated_speed [--duration 600] [--rate 1000] [--repeats 1]
        [--params-file config/tractor_semitrailer.yaml]

Runs the ``simulate_bag`` command (a child process, as a user runs it: interpreter start,
imports, the plant, the sensors, the bag) on the 5-axle defaults over an ISO class C road at
20 m/s, and prints its wall time (time.perf_counter) and the bag's size; then the plant's
batch path alone in this process (:func:`simulate_articulated`, us per sample).
"""
from __future__ import annotations

import argparse
import os
import pathlib
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

REPO = pathlib.Path(__file__).resolve().parents[2]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--duration', type=float, default=600.0, help='drive (s)')
    parser.add_argument('--rate', type=float, default=1000.0, help='sample rate (Hz)')
    parser.add_argument('--repeats', type=int, default=1)
    parser.add_argument('--params-file', type=pathlib.Path,
                        default=REPO / 'config' / 'tractor_semitrailer.yaml')
    args = parser.parse_args(argv)
    exe = pathlib.Path(sys.executable).parent / 'simulate_bag'
    walls = []
    work = pathlib.Path(tempfile.mkdtemp(prefix='articulated_speed_'))
    try:
        for r in range(args.repeats):
            out = work / f'drive{r}'
            start = time.perf_counter()
            subprocess.run([str(exe), '--params-file', str(args.params_file), '--road',
                            'iso8608:C:seed=1', '--speed', '20', '--rate', f'{args.rate:g}',
                            '--duration', f'{args.duration:g}', '--output', str(out),
                            '--no-progress'], check=True, stdout=subprocess.DEVNULL,
                           stderr=subprocess.DEVNULL,
                           env={**os.environ, 'OPENBLAS_NUM_THREADS': '1'})
            walls.append(time.perf_counter() - start)
            size = sum(p.stat().st_size for p in out.glob('*.mcap'))
            shutil.rmtree(out)
        n = int(args.duration * args.rate) + 1
        print(f'simulate_bag, {args.params_file.name}, {args.duration:g} s at {args.rate:g} Hz '
              f'({n} samples): wall {statistics.median(walls):.1f} s (median of '
              f'{args.repeats}; runs {", ".join(f"{w:.1f}" for w in walls)}), bag '
              f'{size / 1e6:.0f} MB')
    finally:
        shutil.rmtree(work, ignore_errors=True)
    from road_force_estimator.core.articulated_plant import simulate_articulated
    from road_force_estimator.core.articulated_setup import ArticulatedDrive
    from road_force_estimator.core.parameters import load_params_file
    from road_force_estimator.core.road import iso8608_profile
    drive = ArticulatedDrive.from_values(load_params_file(args.params_file))
    road = iso8608_profile('C', 20.0 * 60.0 + 20.0, seed=1)
    start = time.perf_counter()
    tr = simulate_articulated(drive.vehicle, road, speed_mps=20.0, rate_hz=args.rate,
                              duration_s=60.0, tire_envelope_m=0.25, model=drive.model)
    wall = time.perf_counter() - start
    print(f'plant alone (batch path, 60 s of drive): {1e6 * wall / len(tr):.1f} us per sample, '
          f'{tr.substeps} RK4 step(s) per sample')
    return 0


if __name__ == '__main__':
    sys.exit(main())
