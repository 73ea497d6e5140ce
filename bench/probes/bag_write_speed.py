"""Rows per second of bag writing: write_estimate_bag and write_drive_bag, end to end.

    .venv/bin/python -m bench.probes.bag_write_speed [--seconds 600] [--rate 1000] [--repeats 3]

An estimate bag of a drive of ``--seconds`` at ``--rate`` Hz: 6 topics per row (2 wheel
loads, 2 road points, the load transfer ratio, the observer states) and one /diagnostics
message per second (as estimate_bag writes them), 1 % of the rows invalid. A drive bag of the
same drive: twist, deflections, 4 ground-truth topics per row and /fix at 10 Hz. Prints, for
each, rows, MB written and rows/s by wall clock and by CPU time (``time.process_time``), the
median of ``--repeats`` runs (the first run of a process also pays for first-touch memory).
"""
from __future__ import annotations

import argparse
from pathlib import Path
import shutil
import statistics
import tempfile
import time
from types import SimpleNamespace

import numpy as np

from road_force_estimator import bagio


def fake_estimates(n: int, rate_hz: float, seed: int = 1):
    """Estimate arrays of an n-row drive (1 % invalid rows) and one diagnostic per second."""
    rng = np.random.default_rng(seed)
    stamps = bagio.DEFAULT_START_STAMP_NS + np.round(np.arange(n) / rate_hz * 1e9).astype(
        np.int64)

    def pair(scale: float) -> np.ndarray:
        return rng.normal(0.0, scale, (n, 2))

    est = SimpleNamespace(
        stamp_ns=stamps, wheel_load_n=25000.0 + pair(800.0), distance_m=np.arange(n) * 0.02,
        road_m=pair(0.004), ltr=rng.normal(0.0, 0.05, n), q_m=pair(0.01),
        roll_rad=rng.normal(0.0, 0.002, n), body_heave_m=rng.normal(0.0, 0.01, n),
        wheel_heave_m=pair(0.003), dq=pair(0.1), droll=rng.normal(0.0, 0.02, n),
        body_heave_rate=rng.normal(0.0, 0.1, n), wheel_heave_rate=pair(0.2),
        valid=rng.random(n) > 0.01)
    per_second = int(round(rate_hz))
    diagnostics = []
    for end in range(per_second - 1, n, per_second):
        values = {'samples': per_second, 'converged': True, 'lift_off_samples': 0,
                  'max_abs_ltr': float(abs(est.ltr[end]))}
        diagnostics.append((int(stamps[end]), [{
            'name': 'bench: estimator', 'level': 0, 'message': 'ok',
            'hardware_id': 'bench', 'values': values}]))
    return est, diagnostics


def fake_drive(n: int, rate_hz: float, seed: int = 2):
    """A trajectory, measurements and 10 Hz fixes of an n-sample drive."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate_hz
    trajectory = SimpleNamespace(t_s=t, distance_m=20.0 * t, speed_mps=20.0,
                                 wheel_load_n=rng.normal(25000.0, 800.0, (n, 2)),
                                 road_m=rng.normal(0.0, 0.004, (n, 2)))
    tf = np.arange(0.0, t[-1], 0.1)
    fixes = SimpleNamespace(time_s=tf, latitude_deg=48.0 + 1e-6 * tf,
                            longitude_deg=11.0 + 1e-6 * tf)
    return trajectory, rng.normal(0.0, 0.01, (n, 2)), rng.normal(0.0, 0.002, n), fixes


def timed(func, repeats: int, folder: Path) -> tuple[float, float]:
    """Median wall and CPU seconds of ``func()`` over ``repeats`` runs (``folder``, the bag
    it writes, is removed before each run, untimed)."""
    walls, cpus = [], []
    for _ in range(repeats):
        shutil.rmtree(folder, ignore_errors=True)
        w, c = time.perf_counter(), time.process_time()
        func()
        cpus.append(time.process_time() - c)
        walls.append(time.perf_counter() - w)
    return statistics.median(walls), statistics.median(cpus)


def report(label: str, rows: int, folder: Path, wall: float, cpu: float) -> None:
    mbytes = sum(p.stat().st_size for p in folder.iterdir()) / 1e6
    print(f'{label:<18s} {rows:>9d} rows {mbytes:8.1f} MB   wall {wall:6.3f} s '
          f'{rows / wall:>11,.0f} rows/s   cpu {cpu:6.3f} s {rows / cpu:>11,.0f} rows/s')


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seconds', type=float, default=600.0, help='drive length (s)')
    parser.add_argument('--rate', type=float, default=1000.0, help='sample rate (Hz)')
    parser.add_argument('--repeats', type=int, default=3, help='runs per measurement')
    args = parser.parse_args(argv)
    n = int(round(args.seconds * args.rate)) + 1
    est, diagnostics = fake_estimates(n, args.rate)
    trajectory, q, roll, fixes = fake_drive(n, args.rate)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / 'bag'

        def estimate() -> None:
            bagio.write_estimate_bag(folder, est, diagnostics=diagnostics)

        def drive() -> None:
            bagio.write_drive_bag(folder, trajectory, q, roll, fixes=fixes)

        wall, cpu = timed(estimate, args.repeats, folder)
        report('write_estimate_bag', n, folder, wall, cpu)
        wall, cpu = timed(drive, args.repeats, folder)
        report('write_drive_bag', n, folder, wall, cpu)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
