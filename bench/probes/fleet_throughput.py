"""Drives per minute of ``estimate_fleet`` on a local Dask cluster of 1 and 2 worker processes,
and what the engine costs per drive.

    .venv/bin/python -m bench.probes.fleet_throughput [--drives 8] [--duration 10] [--rate 500]
        [--workers 1,2] [--repeats 3] [--figures] [--mode online|offline]

The drives are simulated first (``simulate_bag``: ISO 8608 class C, 20 m/s, /fix at 10 Hz,
one seed each) into a temporary folder. Then, for each worker count, medians over the repeats:

- engine start: creating the local cluster and its client (s);
- trivial task round trip: ``submit(no-op).result()`` one at a time (ms), and the scheduling
  cost per task when 200 no-ops are submitted at once (ms per task);
- a fresh ``run_fleet`` over every drive (``force``, new output folder): drives per minute of
  the processing phase (first submit to last result) and end to end (with the engine start and
  the tables), the median task time measured inside the task (hash, estimate_bag.run, fixes,
  polylines, rename), and the per-drive overhead ``processing x workers / drives - mean task
  time`` (what the engine adds between tasks when the workers are kept busy);
- input I/O: bag size per drive and the speed of the content hash (MB/s, page cache warm).

Numbers depend on the machine's load: other processes sharing the cores slow the tasks of a
two-worker run more than those of a one-worker run.
"""
from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from road_force_estimator.tools import estimate_fleet
from road_force_estimator.tools import simulate_bag


def make_drives(folder: Path, count: int, duration_s: float, rate_hz: float) -> list[Path]:
    paths = []
    for i in range(count):
        params = folder / f'route{i}.yaml'
        params.write_text('/**:\n  ros__parameters:\n'
                          f'    simulator.gnss.start_latitude: {48.10 + 0.01 * i!r}\n'
                          '    simulator.gnss.start_longitude: 17.10\n'
                          f'    simulator.gnss.heading: {37.0 * i % 360.0!r}\n')
        out = folder / 'drives' / f'drive{i:03d}'
        rc = simulate_bag.main(['--road', f'iso8608:C:seed={i + 1}', '--speed', '20',
                                '--rate', repr(rate_hz), '--duration', repr(duration_s),
                                '--seed', str(i + 1), '--params-file', str(params),
                                '--output', str(out), '--no-progress'])
        if rc != 0:
            raise SystemExit(f'simulate_bag failed for drive {i}')
        paths.append(out)
    return paths


def _noop(x):
    return x


def engine_costs(workers: int, repeats: int) -> dict[str, float]:
    starts, trips, batch = [], [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        with estimate_fleet.dask_client(None, workers) as (client, _):
            starts.append(time.perf_counter() - t0)
            client.submit(_noop, 0, pure=False).result()         # warm the connection
            rt = []
            for i in range(30):
                t = time.perf_counter()
                client.submit(_noop, i, pure=False).result()
                rt.append(time.perf_counter() - t)
            trips.append(statistics.median(rt))
            t = time.perf_counter()
            futures = client.map(_noop, range(200), pure=False)
            client.gather(futures)
            batch.append((time.perf_counter() - t) / 200)
    return {'engine_start_s': statistics.median(starts),
            'round_trip_ms': 1e3 * statistics.median(trips),
            'per_task_ms': 1e3 * statistics.median(batch)}


def fleet_runs(paths: list[Path], folder: Path, workers: int, repeats: int, figures: bool,
               mode: str) -> dict[str, float]:
    rows = []
    for r in range(repeats):
        out = folder / f'out_w{workers}_r{r}'
        res = estimate_fleet.run_fleet([str(p) for p in paths], out, workers=workers,
                                       figures=figures, mode=mode, force=True)
        failed = res.count('failed')
        if failed:
            reasons = [o.reason for o in res.outcomes if o.status == 'failed']
            raise SystemExit(f'{failed} drives failed: {reasons[:3]}')
        tasks = [o.seconds for o in res.outcomes]
        n = len(paths)
        proc = res.timings['processing']
        rows.append({
            'processing_s': proc,
            'total_s': res.seconds,
            'drives_per_min': 60.0 * n / proc,
            'drives_per_min_end_to_end': 60.0 * n / res.seconds,
            'task_median_s': statistics.median(tasks),
            'task_max_s': max(tasks),
            'overhead_per_drive_s': proc * workers / n - float(np.mean(tasks)),
        })
    return {k: statistics.median(row[k] for row in rows) for k in rows[0]}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--drives', type=int, default=8)
    p.add_argument('--duration', type=float, default=10.0, help='s per drive (default 10)')
    p.add_argument('--rate', type=float, default=500.0, help='Hz (default 500)')
    p.add_argument('--workers', default='1,2', help='worker counts (default 1,2)')
    p.add_argument('--repeats', type=int, default=3)
    p.add_argument('--figures', action='store_true', help='reports with figures')
    p.add_argument('--mode', choices=('online', 'offline'), default='online')
    args = p.parse_args(argv)
    counts = [int(w) for w in args.workers.split(',')]
    with tempfile.TemporaryDirectory(prefix='fleet_bench_') as tmp:
        folder = Path(tmp)
        t = time.perf_counter()
        paths = make_drives(folder, args.drives, args.duration, args.rate)
        size = sum(f.stat().st_size for q in paths for f in q.rglob('*') if f.is_file())
        t = time.perf_counter()
        for q in paths:
            estimate_fleet.input_sha256(q)
        hash_s = time.perf_counter() - t
        print(f'{args.drives} drives of {args.duration:g} s at {args.rate:g} Hz '
              f'({args.duration * args.rate:.0f} samples, {size / args.drives / 1e6:.2f} MB '
              f'each); mode {args.mode}, figures {"on" if args.figures else "off"}; '
              f'content hash {size / 1e6 / hash_s:.0f} MB/s')
        print('| workers | engine start (s) | no-op round trip (ms) | no-op per task in a '
              'batch (ms) | drives/min (processing) | drives/min (end to end) | task median '
              '(s) | task max (s) | engine overhead per drive (s) |')
        print('|---:|---:|---:|---:|---:|---:|---:|---:|---:|')
        for w in counts:
            e = engine_costs(w, args.repeats)
            f = fleet_runs(paths, folder, w, args.repeats, args.figures, args.mode)
            print(f'| {w} | {e["engine_start_s"]:.2f} | {e["round_trip_ms"]:.1f} | '
                  f'{e["per_task_ms"]:.2f} | {f["drives_per_min"]:.1f} | '
                  f'{f["drives_per_min_end_to_end"]:.1f} | {f["task_median_s"]:.2f} | '
                  f'{f["task_max_s"]:.2f} | {f["overhead_per_drive_s"]:.3f} |', flush=True)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
