"""``estimate_bag`` as a user runs it: the command as a process, figures on.

    .venv/bin/python -m bench.probes.estimate_bag_process [--duration 600] [--repeats 3]
                                                   [--modes offline online] [--json FILE]
                                                   [--articulated] [--memory-limit MB]

1. ``simulate_bag`` records two drives as a truck would (ISO 8608 class C, seed 1, 20 m/s,
   1 kHz, 10 um / 0.1 mrad sensor noise, GNSS at 10 Hz, no ground truth): 1 s and
   ``--duration`` s.
2. The ``estimate_bag`` command (the console script of this interpreter, one BLAS thread)
   runs on each, figures on, ``--repeats`` times per mode; each run's wall time, CPU time
   (user + system) and peak resident memory (``/usr/bin/time``'s maximum resident set size,
   see :func:`run_child`).
3. Start-up = the median wall time on the 1 s drive; throughput = (samples of the long drive
   - samples of the 1 s drive) / (median wall time on the long drive - that on the 1 s one),
   and the same with CPU times (on a shared machine the wall time waits for the others).

``--memory-limit MB``: ``estimate_bag.run`` with that memory limit in a child python (what
``estimate_fleet`` gives a worker): a drive past :func:`road_force_estimator.pipeline.plan.
stream_threshold` goes in blocks (on an articulated drive online: the front axle's stage in
blocks beside the whole vehicle's).

``--articulated``: the drives are the 5-axle tractor and semi-trailer's
(``config/tractor_semitrailer.yaml``, its own sensor noise, no GNSS), and ``estimate_bag``
gets the same file: the whole vehicle's estimator beside the front axle's
(:mod:`road_force_estimator.pipeline.whole_vehicle`).

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

#: One BLAS / OpenMP thread.
ONE_THREAD_ENV = {'OPENBLAS_NUM_THREADS': '1', 'OMP_NUM_THREADS': '1', 'MKL_NUM_THREADS': '1'}


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--duration', type=float, default=600.0, help='long drive, s')
    p.add_argument('--repeats', type=int, default=3, help='runs per drive and mode (median)')
    p.add_argument('--modes', nargs='+', choices=('offline', 'online'),
                   default=['offline', 'online'])
    p.add_argument('--json', metavar='FILE', help='also write the numbers as JSON')
    p.add_argument('--memory-limit', type=float, metavar='MB',
                   help='run estimate_bag.run with this memory limit (an estimate_fleet '
                        "worker's: pipeline.plan's threshold, so a drive of more than "
                        'MB / 2 kB samples goes in blocks) in a child python')
    p.add_argument('--articulated', action='store_true',
                   help='a 5-axle articulated drive estimated whole (config/'
                        'tractor_semitrailer.yaml)')
    return p


#: The articulated drive's parameter file (``--articulated``).
ARTICULATED = Path(__file__).resolve().parents[2] / 'config' / 'tractor_semitrailer.yaml'


def simulate(bag: Path, duration_s: float, articulated: bool = False) -> None:
    """``simulate_bag`` in this process: the drive of the module notes."""
    from road_force_estimator.tools import simulate_bag

    sink = io.StringIO()
    own = (['--params-file', str(ARTICULATED), '--gnss-rate', '0'] if articulated else
           ['--noise-deflection', '1e-5', '--noise-roll', '1e-4'])
    with contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink):
        code = simulate_bag.main([
            '--road', 'iso8608:C:seed=1', '--speed', '20', '--rate', '1000',
            '--duration', f'{duration_s:g}', *own, '--seed', '1', '--no-ground-truth',
            '--output', str(bag), '--no-progress'])
    if code != 0:
        raise RuntimeError(f'simulate_bag exit {code}: {sink.getvalue().strip()[-300:]}')


def command(name: str) -> str:
    """The console script ``name`` of this interpreter (else from the PATH)."""
    exe = Path(sys.executable).with_name(name)
    return str(exe) if exe.exists() else name


def run_child(argv: list[str]) -> dict:
    """Run a command; its wall time (s), CPU time (s) and peak RSS (MB).

    Through ``/usr/bin/time`` when there is one: a child started straight from this process
    (``vfork``) would inherit this process's peak RSS in its ``ru_maxrss`` (Linux keeps the
    largest of the address spaces a process had, the parent's included before ``exec``);
    ``time`` forks it from a small process. Else ``os.wait4``'s figures (then a peak below
    this process's own is not seen).

    Raises
    ------
    RuntimeError
        A non-zero exit (its stderr's end in the message).
    """
    timer = shutil.which('time', path='/usr/bin')
    with tempfile.TemporaryFile() as err, tempfile.NamedTemporaryFile('r') as report:
        cmd = ([timer, '-q', '-f', '%M %U %S', '-o', report.name] if timer else []) + argv
        w0 = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err,
                                env={**os.environ, **ONE_THREAD_ENV})
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - w0
        proc.returncode = os.waitstatus_to_exitcode(status)
        if proc.returncode != 0:
            err.seek(0)
            raise RuntimeError(f'{argv[0]} exit {proc.returncode}: '
                               f'{err.read().decode(errors="replace").strip()[-500:]}')
        if timer:
            kb, user, system = report.read().split()[-3:]
            return {'wall_s': wall, 'cpu_s': float(user) + float(system),
                    'peak_rss_mb': int(kb) / 1024.0}
    return {'wall_s': wall, 'cpu_s': usage.ru_utime + usage.ru_stime,
            'peak_rss_mb': usage.ru_maxrss / 1024.0}


def estimate(bag: Path, out: Path, mode: str, articulated: bool = False,
             memory_limit_mb: float | None = None) -> dict:
    """One ``estimate_bag`` run (figures on) into ``out`` (removed after); with
    ``memory_limit_mb``, :func:`~road_force_estimator.tools.estimate_bag.run` with that limit
    in a child python (the command line has no such option: ``estimate_fleet`` sets it)."""
    own = ['--params-file', str(ARTICULATED)] if articulated else []
    if memory_limit_mb is not None:
        code = ('import sys\n'
                'from road_force_estimator.tools.estimate_bag import load_parameters, run\n'
                'v, o = load_parameters(sys.argv[4]) if len(sys.argv) > 4 else (None, None)\n'
                'run(sys.argv[1], sys.argv[2], vehicle=v, observer=o, mode=sys.argv[3], '
                f'memory_limit_bytes={memory_limit_mb * 2.0 ** 20!r})\n')
        argv = [sys.executable, '-c', code, str(bag), str(out), mode,
                *([str(ARTICULATED)] if articulated else [])]
    else:
        argv = [command('estimate_bag'), str(bag), '--output', str(out), '--mode', mode,
                '--no-progress', *own]
    try:
        return run_child(argv)
    finally:
        shutil.rmtree(out, ignore_errors=True)


def _median(runs: list[dict]) -> dict:
    return {k: statistics.median(r[k] for r in runs) for k in runs[0]}


def measure(duration_s: float, repeats: int, modes, articulated: bool = False,
            memory_limit_mb: float | None = None) -> dict:
    """Simulate the two drives and time the command on them (see the module notes)."""
    from road_force_estimator import bagio

    doc: dict = {'duration_s': duration_s, 'repeats': repeats, 'modes': {},
                 'articulated': articulated}
    with tempfile.TemporaryDirectory(prefix='estimate_bag_process_') as tmp:
        tmp = Path(tmp)
        bags = {'short': tmp / 'drive_1s', 'long': tmp / 'drive_long'}
        simulate(bags['short'], 1.0, articulated)
        simulate(bags['long'], duration_s, articulated)
        n = {k: len(bagio.read_drive_bag(b).stamps_ns) for k, b in bags.items()}
        doc['samples'] = n
        for mode in modes:
            runs = {k: [estimate(b, tmp / 'out', mode, articulated, memory_limit_mb)
                        for _ in range(repeats)]
                    for k, b in bags.items()}
            med = {k: _median(v) for k, v in runs.items()}
            added = n['long'] - n['short']
            doc['modes'][mode] = {
                'runs': runs, 'median': med, 'startup_s': med['short']['wall_s'],
                'startup_cpu_s': med['short']['cpu_s'],
                'samples_per_s': added / (med['long']['wall_s'] - med['short']['wall_s']),
                'samples_per_cpu_s': added / (med['long']['cpu_s'] - med['short']['cpu_s']),
                'bytes_per_sample': (med['long']['peak_rss_mb'] - med['short']['peak_rss_mb'])
                * 2.0 ** 20 / added}
    return doc


def markdown(doc: dict) -> list[str]:
    n = doc['samples']
    drive = ('the 5-axle tractor and semi-trailer (config/tractor_semitrailer.yaml, its '
             'noise, no GNSS), estimated whole' if doc.get('articulated') else
             '10 um / 0.1 mrad noise, GNSS 10 Hz')
    lines = [f'# estimate_bag as a process, figures on: `{doc["command"]}`', '',
             f'Drives: ISO C, 20 m/s, 1 kHz, {drive}, no truth; '
             f'{n["short"]} and {n["long"]} samples; median of {doc["repeats"]} runs; one '
             'BLAS thread; start-up subtracted from the throughput.', '',
             '| mode | start-up (s, wall / CPU) | long drive (s, wall / CPU) | samples/s (wall) '
             '| samples/s (CPU) | peak RSS (MB, 1 s / long) | added B/sample |',
             '|---|---|---|---|---|---|---|']
    for mode, m in doc['modes'].items():
        s, lg = m['median']['short'], m['median']['long']
        lines.append(
            f'| {mode} | {s["wall_s"]:.2f} / {s["cpu_s"]:.2f} | {lg["wall_s"]:.2f} / '
            f'{lg["cpu_s"]:.2f} | {m["samples_per_s"]:,.0f} | {m["samples_per_cpu_s"]:,.0f} | '
            f'{s["peak_rss_mb"]:.0f} / {lg["peak_rss_mb"]:.0f} | {m["bytes_per_sample"]:.0f} |')
    return lines


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    doc = measure(args.duration, args.repeats, args.modes, args.articulated,
                  args.memory_limit)
    doc['command'] = ('python -m bench.probes.estimate_bag_process '
                      + ' '.join(argv if argv is not None else sys.argv[1:])).strip()
    print('\n'.join(markdown(doc)))
    if args.json:
        Path(args.json).write_text(json.dumps(doc, indent=2) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
