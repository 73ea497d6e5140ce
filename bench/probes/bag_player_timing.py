"""Benchmark of bag_player: lateness against the bag's timing, /clock, the highest lossless rate.

Run from the repository root::

    .venv/bin/python -m bench.probes.bag_player_timing [--seconds 5] [--drive-seconds 10]
        [--rates 1,2,5,10,20] [--json FILE]

- lateness: a bag with one 1 kHz topic (``/suspension/deflections`` of a simulated drive) is
  played (``--rate 1``) by a :class:`BagPlayer` in this process; each message's lateness is
  the time of its ``publish`` against its scheduled wall time ``start + (t - t0) / rate``,
  and, at a subscriber in another node of this process, its receipt against the same
  schedule (DDS included); median and 99th percentile.
- ``--clock 100``: the ticks' lateness against their schedule and the intervals between
  ticks at the subscriber (median, p99).
- lossless rate: a simulated drive (``--drive-seconds`` at 1 kHz) is played with
  ``bag_player DRIVE --topics /suspension/deflections /vehicle/twist --rate R`` (its own
  process) into an ``observer`` (its own process, restarted for each rate); this process counts
  the ``/observer/states`` that come back. The highest R of ``--rates`` with one output per
  input (and all the rates below it lossless too) is reported, and whether the observer
  process died on the way (with its last line).

The machine is shared (other work may run): figures vary between runs.
"""
from __future__ import annotations

import argparse
import json
import os
import pathlib
import subprocess
import sys
import tempfile
import time

import numpy as np
import rclpy
from rclpy.context import Context
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from road_force_estimator.bagio.playback import open_playback
from road_force_estimator.ros.bag_player import BagPlayer, build_parser
from road_force_estimator.ros.messages import reliable_qos, stamp_to_ns

REPO = pathlib.Path(__file__).resolve().parents[2]
os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')


def simulate(folder: pathlib.Path, seconds: float) -> None:
    from road_force_estimator.tools.simulate_bag import main
    code = main(['--road', 'iso8608:C:seed=3', '--speed', '20', '--rate', '1000', '--duration',
                 str(seconds), '--output', str(folder), '--no-progress'])
    if code:
        raise SystemExit(f'simulate_bag failed ({code})')


def percentiles(values) -> dict:
    a = np.asarray(values, dtype=float) * 1e3
    return {'median_ms': float(np.median(a)), 'p99_ms': float(np.percentile(a, 99)),
            'max_ms': float(a.max()), 'n': int(a.size)}


def lateness(drive: pathlib.Path) -> dict:
    """Publish and receipt lateness at 1 kHz, /clock at 100 Hz (one in-process run)."""
    context = Context()
    rclpy.init(context=context)
    received: list[tuple[float, int]] = []
    ticks: list[float] = []
    try:
        listener = Node('timing_listener', context=context)
        listener.create_subscription(
            JointState, '/suspension/deflections',
            lambda m: received.append((time.monotonic(), stamp_to_ns(m.header.stamp))),
            QoSProfile(depth=10000, reliability=ReliabilityPolicy.BEST_EFFORT))
        listener.create_subscription(Clock, '/clock', lambda m: ticks.append(time.monotonic()),
                                     QoSProfile(depth=1000,
                                                reliability=ReliabilityPolicy.BEST_EFFORT))
        options = build_parser().parse_args([str(drive), '--topics', '/suspension/deflections',
                                             '--clock', '100', '--wait-for', 'timing_listener'])
        from rclpy.experimental import EventsExecutor
        player = BagPlayer(open_playback(drive), options, context=context)
        executor = EventsExecutor(context=context)
        executor.add_node(listener)
        executor.add_node(player)
        deadline = time.monotonic() + 120.0
        while not player.done and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        end = time.monotonic() + 2.0
        while len(received) < len(player.lateness_s) and time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
        start_wall, first_ns = player.schedule
        # The stamps of a simulated drive are its log times (bag_recorder's receive times
        # differ): the schedule of a message is that of its stamp's offset.
        arrival = [t - (start_wall + (s - first_ns) * 1e-9) for t, s in received]
        player.stop()
        executor.shutdown()
        result = {'publish': percentiles(player.lateness_s), 'receipt': percentiles(arrival),
                  'lost': len(player.lateness_s) - len(received),
                  'clock_publish': percentiles(player.clock_lateness_s),
                  'clock_interval': percentiles(np.diff(ticks)) if len(ticks) > 2 else {},
                  'clock_ticks': player.clock_ticks}
    finally:
        rclpy.try_shutdown(context=context)
    return result


def lossless_rates(drive: pathlib.Path, rates: list[float]) -> dict:
    """States that come back per input, per rate (observer and player in their processes)."""
    env = dict(os.environ, PYTHONUNBUFFERED='1')
    context = Context()
    rclpy.init(context=context)
    results = {}
    n_inputs = open_playback(drive).topics['/suspension/deflections'].count
    try:
        for rate in rates:
            states: list[int] = []
            node = Node('rate_listener', context=context)
            node.create_subscription(JointState, '/observer/states',
                                     lambda m: states.append(stamp_to_ns(m.header.stamp)),
                                     reliable_qos(100000))
            from rclpy.experimental import EventsExecutor
            executor = EventsExecutor(context=context)
            executor.add_node(node)
            log = tempfile.TemporaryFile('w+')
            observer = subprocess.Popen(
                [sys.executable, '-m', 'road_force_estimator.ros.observer'], cwd=REPO, env=env,
                stderr=log)
            t0 = time.monotonic()
            player = subprocess.Popen(
                [sys.executable, '-m', 'road_force_estimator.ros.bag_player', str(drive),
                 '--topics', '/suspension/deflections', '/vehicle/twist', '--rate', str(rate),
                 '--wait', '30'], cwd=REPO, env=env, stderr=subprocess.PIPE, text=True)
            while player.poll() is None:
                executor.spin_once(timeout_sec=0.05)
            last, quiet = len(states), time.monotonic()
            while time.monotonic() - quiet < 1.0:  # until nothing more comes for 1 s
                executor.spin_once(timeout_sec=0.05)
                if len(states) != last:
                    last, quiet = len(states), time.monotonic()
            crashed = observer.poll() is not None  # it must still run: it ends on a signal
            observer.terminate()
            observer.wait(30)
            log.seek(0)
            lines = [line for line in log.read().splitlines() if line.strip()]
            log.close()
            executor.shutdown()
            node.destroy_node()
            results[rate] = {'inputs': n_inputs, 'outputs': len(set(states)),
                             'wall_s': time.monotonic() - t0, 'observer_died': crashed,
                             'observer_last_line': lines[-1] if crashed and lines else ''}
            print(f'rate {rate:g}: {len(set(states))} of {n_inputs} outputs'
                  + (f'; the observer died: {lines[-1] if lines else "?"}' if crashed else ''),
                  file=sys.stderr)
    finally:
        rclpy.try_shutdown(context=context)
    best = 0.0
    for rate in sorted(results):
        if results[rate]['outputs'] != results[rate]['inputs']:
            break
        best = rate
    return {'per_rate': results, 'highest_lossless_rate': best}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--seconds', type=float, default=5.0, help='timing drive length (s)')
    p.add_argument('--drive-seconds', type=float, default=10.0, help='lossless drive (s)')
    p.add_argument('--rates', default='1,2,5,10,20')
    p.add_argument('--json', type=pathlib.Path)
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        timing_drive = pathlib.Path(tmp) / 'timing'
        simulate(timing_drive, args.seconds)
        timing = lateness(timing_drive)
        drive = pathlib.Path(tmp) / 'drive'
        simulate(drive, args.drive_seconds)
        rates = lossless_rates(drive, [float(r) for r in args.rates.split(',')])
    out = {'lateness_1khz': timing, 'lossless': rates}
    pub, rec = timing['publish'], timing['receipt']
    print(f"1 kHz publish lateness: median {pub['median_ms']:.3f} ms, p99 {pub['p99_ms']:.3f} ms"
          f"; at the subscriber: median {rec['median_ms']:.3f} ms, p99 {rec['p99_ms']:.3f} ms, "
          f"{timing['lost']} lost")
    clk, iv = timing['clock_publish'], timing['clock_interval']
    print(f"/clock 100 Hz: {timing['clock_ticks']} ticks, lateness median "
          f"{clk['median_ms']:.3f} ms, p99 {clk['p99_ms']:.3f} ms; interval at the subscriber "
          f"median {iv.get('median_ms', float('nan')):.3f} ms, p99 "
          f"{iv.get('p99_ms', float('nan')):.3f} ms")
    per_rate = ', '.join(f"{r:g}: {v['outputs']}/{v['inputs']}"
                         for r, v in rates['per_rate'].items())
    print(f"highest --rate with no loss into the observer: {rates['highest_lossless_rate']:g} "
          f'({per_rate})')
    if args.json:
        args.json.write_text(json.dumps(out, indent=2))
    return 0


if __name__ == '__main__':
    sys.exit(main())
