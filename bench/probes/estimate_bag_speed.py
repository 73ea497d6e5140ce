"""Throughput of offline ``estimate_bag`` end to end, on one core.

    .venv/bin/python -m bench.probes.estimate_bag_speed [--duration 600] [--rate 1000] [--repeats
                                                 3] [--ground-truth] [--mode offline]
                                                 [--json FILE]

1. ``simulate_bag`` records a drive as a truck would (ISO 8608 class C, seed 1, 20 m/s,
   10 um / 0.1 mrad sensor noise, GNSS at 10 Hz; ``/suspension/deflections``,
   ``/vehicle/twist``, ``/fix``; ``--ground-truth`` adds the simulator's truth topics, six
   messages per sample instead of two).
2. A child process pinned to one CPU (``taskset -c 0`` when there is one) with one BLAS
   thread imports the package and runs :func:`road_force_estimator.tools.estimate_bag.run` on it
   ``--repeats`` times (bag in; bag of estimates and report without figures out: everything
   the command does but parsing its arguments), then once more stage by stage (read the bag,
   estimate, write the bag, write the report). Samples per second = samples / wall time; the
   first run is listed apart (it pays the first use of fresh memory: on this machine, a
   Firecracker VM, the first touch of a page costs ~10 us).
3. The ``estimate_bag`` command itself, once, as a process: interpreter start and imports
   included.

Numbers go to stdout (Markdown) and, with ``--json``, to a file.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
from pathlib import Path
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

REPO = Path(__file__).resolve().parents[2]
#: One BLAS / OpenMP thread: "on one core".
ONE_THREAD_ENV = {'OPENBLAS_NUM_THREADS': '1', 'OMP_NUM_THREADS': '1', 'MKL_NUM_THREADS': '1'}


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--duration', type=float, default=600.0, help='drive length, s')
    p.add_argument('--rate', type=float, default=1000.0, help='sample rate, Hz')
    p.add_argument('--repeats', type=int, default=3, help='timed runs after the first')
    p.add_argument('--ground-truth', action='store_true',
                   help='record the simulator truth topics too')
    p.add_argument('--mode', choices=('offline', 'online'), default='offline')
    p.add_argument('--tmp', metavar='DIR',
                   help='folder for the bags (default: the system temp folder; /dev/shm '
                        'keeps the disk out of the figures)')
    p.add_argument('--json', metavar='FILE', help='also write the numbers as JSON')
    p.add_argument('--worker', nargs=2, metavar=('BAG', 'TMP'), help=argparse.SUPPRESS)
    return p


def _worker(bag: Path, tmp: Path, mode: str, repeats: int) -> dict:
    """Runs in the pinned child: the timed runs and the stages."""
    t0, c0 = time.perf_counter(), time.process_time()
    from road_force_estimator import bagio
    from road_force_estimator.tools import estimate_bag
    from road_force_estimator.report import write_report
    from road_force_estimator.estimation import estimate_recording
    imports = (time.perf_counter() - t0, time.process_time() - c0)
    runs = []
    for i in range(1 + repeats):
        out = tmp / f'run_{i}'
        w0, p0 = time.perf_counter(), time.process_time()
        res = estimate_bag.run(bag, out, mode=mode, figures=False)
        runs.append({'wall_s': time.perf_counter() - w0, 'cpu_s': time.process_time() - p0})
        shutil.rmtree(out)
    n = int(len(res.drive.stamps_ns))
    vehicle, observer = estimate_bag.load_parameters(None)
    stages = {}
    w0 = time.perf_counter()
    drive = bagio.read_drive_bag(bag)
    stages['read the bag'] = time.perf_counter() - w0
    speed, _ = estimate_bag.drive_speed(drive)
    w0 = time.perf_counter()
    args = (drive.stamps_ns, drive.q_m, drive.roll_rad, speed, vehicle, observer)
    est = (estimate_recording(*args) if mode == 'offline'
           else estimate_bag.estimate_online(*args))
    stages['estimate'] = time.perf_counter() - w0
    w0 = time.perf_counter()
    bagio.write_estimate_bag(tmp / 'stage_bag', est, track_width_m=vehicle.track_width_m)
    stages['write the bag of estimates'] = time.perf_counter() - w0
    w0 = time.perf_counter()
    write_report(tmp / 'stage_report', est, drive, vehicle, observer, mode=mode,
                 input_name=bag.name, figures=False)
    stages['write the report'] = time.perf_counter() - w0
    return {'samples': n, 'imports_s': imports, 'runs': runs, 'stages_s': stages}


def measure(*, duration_s: float = 600.0, rate_hz: float = 1000.0, repeats: int = 3,
            ground_truth: bool = False, mode: str = 'offline', tmp_dir: str | None = None) -> dict:
    """Simulate the drive, time ``estimate_bag`` (see the module notes); the numbers."""
    from road_force_estimator.tools import simulate_bag

    with tempfile.TemporaryDirectory(prefix='estimate_bag_speed_', dir=tmp_dir) as tmp:
        tmp = Path(tmp)
        bag = tmp / 'drive'
        argv = ['--road', 'iso8608:C:seed=1', '--speed', '20', '--rate', f'{rate_hz:g}',
                '--duration', f'{duration_s:g}', '--noise-deflection', '1e-5',
                '--noise-roll', '1e-4', '--seed', '1', '--output', str(bag), '--no-progress']
        if not ground_truth:
            argv.append('--no-ground-truth')
        sink = io.StringIO()
        with contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink):
            code = simulate_bag.main(argv)
        if code != 0:
            raise RuntimeError(f'simulate_bag exit {code}: {sink.getvalue().strip()[-300:]}')
        size = sum(p.stat().st_size for p in bag.iterdir())
        pin = ['taskset', '-c', '0'] if shutil.which('taskset') else []
        env = {**os.environ, **ONE_THREAD_ENV}
        cmd = pin + [sys.executable, '-m', 'bench.probes.estimate_bag_speed', '--mode', mode,
                     '--repeats', str(repeats), '--worker', str(bag), str(tmp)]
        proc = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True)
        if proc.returncode != 0:
            raise RuntimeError(f'worker exit {proc.returncode}: {proc.stderr.strip()[-500:]}')
        doc = json.loads(proc.stdout.strip().splitlines()[-1])
        exe = Path(sys.executable).with_name('estimate_bag')
        cli_cmd = pin + [str(exe) if exe.exists() else 'estimate_bag', str(bag), '--output',
                         str(tmp / 'cli'), '--mode', mode, '--no-figures', '--no-progress']
        w0 = time.perf_counter()
        cli = subprocess.run(cli_cmd, env=env, capture_output=True, text=True)
        cli_wall = time.perf_counter() - w0
        if cli.returncode != 0:
            raise RuntimeError(f'estimate_bag exit {cli.returncode}: {cli.stderr.strip()}')
    n = doc['samples']
    later = doc['runs'][1:] or doc['runs']
    med = statistics.median(r['wall_s'] for r in later)
    return {
        'drive': {'road': 'iso8608:C:seed=1', 'speed_mps': 20.0, 'rate_hz': rate_hz,
                  'duration_s': duration_s, 'ground_truth': ground_truth,
                  'messages_per_sample': 6 if ground_truth else 2, 'bag_bytes': size},
        'mode': mode, 'pinned': bool(pin), 'samples': n,
        'folder': tmp_dir or tempfile.gettempdir(),
        'first_run': {**doc['runs'][0], 'samples_per_s': n / doc['runs'][0]['wall_s']},
        'median_run': {'wall_s': med, 'samples_per_s': n / med,
                       'cpu_s': statistics.median(r['cpu_s'] for r in later)},
        'runs': doc['runs'], 'imports_s': doc['imports_s'],
        'stages': {k: {'wall_s': v, 'samples_per_s': n / v} for k, v in
                   doc['stages_s'].items()},
        'cli': {'wall_s': cli_wall, 'samples_per_s': n / cli_wall},
    }


def markdown(doc: dict, command: str) -> list[str]:
    d = doc['drive']
    n = doc['samples']
    lines = [f'# estimate_bag --mode {doc["mode"]}, end to end: `{command}`', '',
             f'Drive: ISO C, 20 m/s, {d["rate_hz"]:g} Hz, {d["duration_s"]:g} s = {n} samples, '
             f'{d["messages_per_sample"]} messages per sample'
             f'{" (ground truth recorded)" if d["ground_truth"] else ""}, '
             f'{d["bag_bytes"] / 1e6:.0f} MB, in {doc["folder"]}; one CPU (taskset: '
             f'{doc["pinned"]}), one BLAS thread.', '',
             '| what | wall (s) | samples/s |', '|---|---|---|',
             f'| estimate_bag.run, median of {len(doc["runs"]) - 1} runs after the first | '
             f'{doc["median_run"]["wall_s"]:.3f} | {doc["median_run"]["samples_per_s"]:,.0f} |',
             f'| estimate_bag.run, first run in the process | {doc["first_run"]["wall_s"]:.3f} '
             f'| {doc["first_run"]["samples_per_s"]:,.0f} |',
             f'| `estimate_bag` command (process start, imports) | {doc["cli"]["wall_s"]:.3f} '
             f'| {doc["cli"]["samples_per_s"]:,.0f} |']
    for name, v in doc['stages'].items():
        lines.append(f'| stage: {name} | {v["wall_s"]:.3f} | {v["samples_per_s"]:,.0f} |')
    return lines


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.worker:
        doc = _worker(Path(args.worker[0]), Path(args.worker[1]), args.mode, args.repeats)
        print(json.dumps(doc))
        return 0
    doc = measure(duration_s=args.duration, rate_hz=args.rate, repeats=args.repeats,
                  ground_truth=args.ground_truth, mode=args.mode, tmp_dir=args.tmp)
    command = 'python -m bench.probes.estimate_bag_speed ' + ' '.join(argv or sys.argv[1:])
    doc['command'] = command.strip()
    print('\n'.join(markdown(doc, doc['command'])))
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(doc, indent=2) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
