"""Benchmark: the articulated observer node's own work per sample in this process, in
instructions (callgrind) or thread CPU time, its publishes a no-op.

Run from the repository root::

    python -m bench.probes.node_instructions [--warm 3000] [--samples 2000] [--part node]
    python -m bench.probes.node_instructions --callgrind [--samples 256,2304] [--part node]

The observer node (``config/tractor_semitrailer.yaml``: 5 axles, every output) is made in
this process, no subscriber, its rclpy publishes replaced by a no-op; it is fed the bytes of a
class C drive at 20 m/s and 1 kHz (:func:`.node_latency.articulated_drive`, kept in
``--cache``) through its input's callback (twist and deflections, one round per sample, as
:mod:`.node_cost` does): per sample, the readings parsed from the bytes, the estimator's
step, the sensor health, the load transfer, the fused profile and the output bytes built.
The executor, DDS and rclpy's publish are left out (the bare node of :mod:`.node_latency`
pays those too). ``--part``: ``node`` (all of the above), ``step``
(``WholeVehicleEstimator.step`` alone on the same readings), ``online`` (its model observer
alone: ``ArticulatedOnline.step`` on the readings as the step hands them).

Without ``--callgrind``: thread CPU time per sample (us) of ``--samples`` after ``--warm``,
min and median of ``--repeats``. With ``--callgrind``: this script run under ``valgrind
--tool=callgrind`` twice side by side, after the same ``--warm`` samples, for each of the two
sample counts of ``--samples``; instructions per sample = the difference of the runs' totals
over the difference of the counts (start-up, imports and warm-up cancel), the main thread's
alone (DDS's threads run by the wall clock), Python's hash seed fixed and one BLAS thread
(a random seed, or OpenBLAS's pool sharing out the gain designs' products by the clock, moves
the start-up's count by more than thousands of samples take). Make the difference a multiple of
256 samples (the observer's noise statistics run once a block of 256). Instruction counts do
not move with the machine's load, unlike times.
"""
from __future__ import annotations

import argparse
import os
import pathlib
import re
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

from road_force_estimator.ros.launcher import BLAS_THREAD_VARIABLES

T0_NS = 1_700_000_000 * 10**9
CACHE = pathlib.Path(tempfile.gettempdir()) / 'node_instructions_drive.npy'


def drive(samples: int, cache: pathlib.Path) -> np.ndarray:
    """The drive's readings (samples, 12), simulated once and kept in ``cache``."""
    if cache.is_file():
        got = np.load(cache)
        if len(got) >= samples:
            return got
    from bench.probes.node_latency import articulated_drive
    got = np.array(articulated_drive(samples / 1000.0 + 0.5))
    np.save(cache, got)
    return got


class _NoPublish:
    def __call__(self, data) -> None:
        pass


def runner(part: str, readings: np.ndarray):
    """``(run(k), close())``: one sample ``k`` of ``part`` (module notes)."""
    import rclpy

    from bench.probes.node_latency import ARTICULATED_CONFIG, ARTICULATED_JOINTS, input_encoders
    from road_force_estimator.ros.take_loop import Taken
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    rclpy.init(args=['--ros-args', '--params-file', str(ARTICULATED_CONFIG)])
    from road_force_estimator.ros.observer import Observer
    observer = Observer()
    whole = observer.whole
    whole.input.loop.stop()       # the callback is called here, not from the take thread
    rows = [tuple(r) for r in readings.tolist()]

    def close() -> None:
        observer.destroy_node()
        rclpy.try_shutdown()

    if part == 'node':
        for name in ('send', 'send_static', 'send_road', 'send_fused'):
            setattr(whole, name, [_NoPublish()] * len(getattr(whole, name)))
        deflections, twist = input_encoders(ARTICULATED_JOINTS)
        data = [(deflections.encode(T0_NS + k * 10**6, r), twist.encode(T0_NS + k * 10**6,
                                                                          (20.0,)))
                for k, r in enumerate(rows)]
        taken = whole.input

        def run(k: int) -> None:
            twist_data, deflection_data = data[k][1], data[k][0]
            taken.take([Taken(taken.twist_index, twist_data, 0, None),
                        Taken(taken.deflection_index, deflection_data, 0, None)])
        return run, close
    from road_force_estimator.estimation.whole_vehicle import WholeVehicleEstimator
    vehicle, settings = whole.params.config[:2]
    estimator = WholeVehicleEstimator(vehicle, settings)
    if part == 'step':
        step = estimator.step
        return (lambda k: step(T0_NS + k * 10**6, rows[k], 20.0)), close
    online = estimator.online
    ys = [list(r) for r in rows]
    return (lambda k: online.step(T0_NS + k * 10**6, list(ys[k]), 20.0)), close


def measure_once(part: str, warm: int, samples: int, cache: pathlib.Path) -> None:
    """Run ``warm + samples`` samples (the callgrind child: its total is the count)."""
    run, close = runner(part, drive(warm + samples, cache))
    for k in range(warm + samples):
        run(k)
    close()


def callgrind_totals(part: str, warm: int, counts: list, cache: pathlib.Path) -> list:
    """The instructions callgrind counts in the main thread of a run of ``warm + n`` samples,
    for each ``n`` of ``counts`` (the runs side by side; Python's hash seed fixed, 0, so that
    the start-up's dictionaries take the same instructions in every run; one BLAS thread, as
    the nodes run, so that no gain design's products are shared out by the clock)."""
    env = {**os.environ, 'PYTHONHASHSEED': '0', **dict.fromkeys(BLAS_THREAD_VARIABLES, '1')}
    with tempfile.TemporaryDirectory() as tmp:
        outs = [pathlib.Path(tmp) / f'callgrind.out.{n}' for n in counts]
        runs = [subprocess.Popen(
            ['valgrind', '--tool=callgrind', '--separate-threads=yes',
             f'--callgrind-out-file={out}',
             sys.executable, '-m', 'bench.probes.node_instructions', '--child', '--part',
             part, '--warm', str(warm), '--samples', str(n), '--cache', str(cache)],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env)
            for n, out in zip(counts, outs)]
        totals = []
        for run, out in zip(runs, outs):
            _, err = run.communicate()
            main_thread = pathlib.Path(f'{out}-01')
            found = re.findall(r'^(?:summary|totals): (\d+)', main_thread.read_text()
                               if main_thread.is_file() else '', re.M)
            if run.returncode or not found:
                raise RuntimeError(err[-2000:])
            totals.append(int(found[-1]))
    return totals


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--part', choices=('node', 'step', 'online'), default='node')
    parser.add_argument('--warm', type=int, default=3000)
    parser.add_argument('--samples', default='2000',
                        help='samples measured (with --callgrind two counts: a,b)')
    parser.add_argument('--repeats', type=int, default=5)
    parser.add_argument('--callgrind', action='store_true')
    parser.add_argument('--cache', type=pathlib.Path, default=CACHE)
    parser.add_argument('--child', action='store_true', help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))
    counts = [int(s) for s in args.samples.split(',')]
    if args.child:
        measure_once(args.part, args.warm, counts[0], args.cache)
        return 0
    if args.callgrind:
        if len(counts) != 2 or counts[1] <= counts[0]:
            parser.error('--callgrind: --samples a,b with b > a')
        drive(args.warm + counts[1], args.cache)        # simulated outside valgrind
        a, b = callgrind_totals(args.part, args.warm, counts, args.cache)
        print(f'{args.part}: {(b - a) / (counts[1] - counts[0]):,.0f} instructions per sample '
              f'({counts[1] - counts[0]} samples after {args.warm + counts[0]})')
        return 0
    n = counts[0]
    total = args.warm + n * args.repeats
    run, close = runner(args.part, drive(total, args.cache))
    for k in range(args.warm):
        run(k)
    times = []
    for r in range(args.repeats):
        start = time.thread_time_ns()
        for k in range(args.warm + r * n, args.warm + (r + 1) * n):
            run(k)
        times.append((time.thread_time_ns() - start) / n / 1e3)
    close()
    print(f'{args.part}: min {min(times):.1f} us, median {statistics.median(times):.1f} us '
          f'per sample ({args.repeats} x {n} after {args.warm})')
    return 0


if __name__ == '__main__':
    sys.exit(main())
