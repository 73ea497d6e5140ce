"""Benchmark: how long the plant takes to simulate a drive (default 60 s at 1 kHz).

Run from the repository root::

    .venv/bin/python bench/probes/plant_speed.py [--duration 60] [--rate 1000] [--repeats 5]

Prints the median wall time (time.perf_counter) of the batch path (``simulate``) and of the
per-sample path (``Plant.step``, as the plant_simulator node uses it), each over ``--repeats``
runs, on an ISO 8608 road with the default tire envelope.
"""
from __future__ import annotations

import argparse
import pathlib
import statistics
import sys
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[2]))

from road_force_estimator.core.parameters import VehicleParameters  # noqa: E402
from road_force_estimator.core.plant import Plant, simulate  # noqa: E402
from road_force_estimator.bagio import road_from_source  # noqa: E402


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--duration', type=float, default=60.0, help='simulated time (s)')
    parser.add_argument('--rate', type=float, default=1000.0, help='output rate (Hz)')
    parser.add_argument('--speed', type=float, default=20.0, help='speed (m/s)')
    parser.add_argument('--road', default='iso8608:C:seed=1', help='road source')
    parser.add_argument('--envelope', type=float, default=0.25, help='tire envelope (m)')
    parser.add_argument('--substeps', type=int, default=None, help='RK4 substeps per sample')
    parser.add_argument('--repeats', type=int, default=5, help='timed runs per path')
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.repeats < 1 or args.duration <= 0.0:
        print('plant_speed: --repeats must be >= 1 and --duration > 0', file=sys.stderr)
        return 2
    vehicle = VehicleParameters()
    try:
        road = road_from_source(args.road, length_m=args.speed * args.duration + 10.0)
    except ValueError as exc:
        print(f'plant_speed: {exc}', file=sys.stderr)
        return 2
    kw = dict(speed_mps=args.speed, rate_hz=args.rate, substeps=args.substeps,
              tire_envelope_m=args.envelope)
    batch, single = [], []
    samples = substeps = 0
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        tr = simulate(vehicle, road, duration_s=args.duration, **kw)
        batch.append(time.perf_counter() - t0)
        samples, substeps = len(tr), tr.substeps
        t0 = time.perf_counter()
        plant = Plant(vehicle, road, **kw)
        for _ in range(samples):
            plant.step()
        single.append(time.perf_counter() - t0)
    what = (f'{args.duration:g} s at {args.rate:g} Hz ({samples} samples, {substeps} RK4 '
            f'substeps) on {args.road} at {args.speed:g} m/s')
    for name, times in (('simulate()', batch), ('Plant.step()', single)):
        median = statistics.median(times)
        print(f'{name:13s} {what}: median {median:.3f} s over {len(times)} runs '
              f'({args.duration / median:.1f}x real time, {1e6 * median / samples:.1f} us '
              f'per sample)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
