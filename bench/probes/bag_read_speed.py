"""Samples per second of bagio.read_drive_bag: a 1 kHz drive without ground truth (2
messages per sample) and one with it (6 per sample), 10 Hz GNSS fixes in both, written by
write_drive_bag into a temporary folder and read back whole (bag decode and checks included).

    .venv/bin/python -m bench.probes.bag_read_speed [--seconds 600 120] [--walk]

Prints, per drive, the median of 3 reads: wall and CPU (time.process_time) seconds and
samples/s; ``--walk`` also times the record-by-record walk (the reference path, chunks read
without their message index). Targets (issue 11, one core): 2,000,000 samples/s without
ground truth, 800,000 with it.
"""
from __future__ import annotations

import argparse
from pathlib import Path
import statistics
import tempfile
import time
from types import SimpleNamespace

import numpy as np

from road_force_estimator import bagio
from road_force_estimator.bagio import reader as bag_reader


def write_drive(path: Path, seconds: float, ground_truth: bool, rate_hz: float = 1000.0) -> int:
    """A drive of ``seconds`` at ``rate_hz`` (random numbers: the read cost does not depend
    on them); returns its samples."""
    n = int(round(seconds * rate_hz)) + 1
    rng = np.random.default_rng(1)
    t = np.arange(n) / rate_hz
    trajectory = SimpleNamespace(t_s=t, distance_m=20.0 * t, speed_mps=20.0,
                                 wheel_load_n=rng.normal(25000.0, 800.0, (n, 2)),
                                 road_m=rng.normal(0.0, 0.004, (n, 2)))
    tf = t[::int(rate_hz // 10)]
    fixes = SimpleNamespace(time_s=tf, latitude_deg=48.1 + 1e-6 * np.arange(tf.size),
                            longitude_deg=np.full(tf.size, 17.1))
    bagio.write_drive_bag(path, trajectory, rng.normal(0.0, 0.01, (n, 2)),
                           rng.normal(0.0, 0.002, n), fixes=fixes, ground_truth=ground_truth)
    return n


def timed_read(path: Path, repeats: int = 3) -> tuple[float, float, int]:
    """Median wall and CPU seconds of read_drive_bag, and the samples read."""
    walls, cpus = [], []
    samples = 0
    for _ in range(repeats):
        w0, c0 = time.perf_counter(), time.process_time()
        drive = bagio.read_drive_bag(path)
        cpus.append(time.process_time() - c0)
        walls.append(time.perf_counter() - w0)
        samples = drive.stamps_ns.size
    return statistics.median(walls), statistics.median(cpus), samples


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seconds', type=float, nargs=2, default=(600.0, 120.0),
                        metavar=('NO_TRUTH', 'TRUTH'),
                        help='drive lengths (s) without and with ground truth, default 600 120')
    parser.add_argument('--walk', action='store_true',
                        help='also time the record-by-record walk (no message index)')
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        for seconds, truth in zip(args.seconds, (False, True)):
            path = Path(tmp) / f'drive_{int(seconds)}s_{"truth" if truth else "no_truth"}'
            write_drive(path, seconds, truth)
            size = sum(f.stat().st_size for f in path.glob('*.mcap'))
            label = f'{seconds:.0f} s, {"with" if truth else "no"} ground truth, ' \
                    f'{size / 1e6:.0f} MB'
            paths = [('index', True)] + ([('walk', False)] if args.walk else [])
            for name, indexed in paths:
                bag_reader.USE_MESSAGE_INDEX = indexed
                try:
                    wall, cpu, n = timed_read(path)
                finally:
                    bag_reader.USE_MESSAGE_INDEX = True
                print(f'read_drive_bag ({name}) {label}: {n} samples, wall {wall:.3f} s '
                      f'{n / wall:>12,.0f}/s, cpu {cpu:.3f} s {n / cpu:>12,.0f}/s')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
