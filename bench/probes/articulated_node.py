"""Benchmark: the plant_simulator node with the articulated truck, at its rate in real time.

Run from the repository root::

    .venv/bin/python -m bench.probes.articulated_node [--rate 1000] [--seconds 30] [--imu]
        [--params-file config/tractor_semitrailer.yaml]

The node runs its ``main`` in a child process on a ROS domain of its own (this host only),
driving the default 5-axle combination (``config/tractor_semitrailer.yaml``) over its default
ISO road at ``--rate`` Hz for ``--seconds`` of drive, in real time. This process subscribes,
raw, to every topic the node publishes (the measurements with the sensor-data QoS, the truth
reliable), as a recorder does. ``--front`` runs the front-axle node (the package defaults)
the same way, every one of its topics subscribed: the bar to compare with
(bench.probes.node_latency --plant subscribes to the deflections only; ``--only-deflections`` does
so here). Printed: the samples of each topic received within the drive (+0.5 s) out of those the
drive has, and the node process's CPU time (user + system, psutil) over the drive's wall time, in %
of one core (the median of ``--repeats`` runs).
"""
from __future__ import annotations

import argparse
import math
import os
import statistics
import pathlib
import subprocess
import sys
import time

import psutil
import rclpy
from rclpy.context import Context
from rclpy.node import Node

from road_force_estimator import interfaces as api
from road_force_estimator.ros.bag_recorder import message_class
from road_force_estimator.ros.messages import topic_qos

REPO = pathlib.Path(__file__).resolve().parents[2]
TOPICS = (api.DEFLECTIONS, api.TWIST, *api.TRUE_LOAD, *api.TRUE_ROAD, api.TRUE_WHEEL_LOADS,
          api.TRUE_LOAD_TRANSFER_RATIOS, api.IMU)


FRONT_TOPICS = (api.DEFLECTIONS, api.TWIST, *api.TRUE_LOAD, *api.TRUE_ROAD)


def measure(rate_hz: float, seconds: float, params_file: pathlib.Path | None,
            imu: bool, only_deflections: bool = False) -> dict:
    """Run the node; its CPU share and what arrived (see the module notes)."""
    os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    context = Context()
    rclpy.init(context=context)
    from rclpy.experimental import EventsExecutor
    executor = EventsExecutor(context=context)
    node = Node('articulated_node_bench', context=context)
    topics = TOPICS if params_file is not None else FRONT_TOPICS
    if only_deflections:
        topics = (api.DEFLECTIONS,)
    got = {t: [] for t in topics}
    for topic in topics:
        node.create_subscription(message_class(api.TOPIC_TYPES[topic]), topic,
                                 lambda data, t=topic: got[t].append(time.monotonic()),
                                 topic_qos(topic, 5000), raw=True)
    executor.add_node(node)
    cmd = [sys.executable, '-m', 'road_force_estimator.ros.plant_simulator', '--ros-args',
           '-p', f'simulator.rate:={rate_hz:g}', '-p', f'simulator.duration:={seconds:g}']
    if params_file is not None:
        cmd += ['--params-file', str(params_file),
                '-p', f'vehicle.tractor_imu:={str(imu).lower()}']
    child = subprocess.Popen(cmd, cwd=REPO, stderr=subprocess.DEVNULL, stdout=subprocess.DEVNULL)
    proc = psutil.Process(child.pid)
    first = got[api.DEFLECTIONS]
    try:
        while not first and child.poll() is None:
            executor.spin_once(timeout_sec=0.01)
        cpu0, wall0 = sum(proc.cpu_times()[:2]), first[0] if first else time.monotonic()
        cpu1, wall1 = cpu0, wall0
        while child.poll() is None and time.monotonic() < wall0 + seconds + 0.5:
            executor.spin_once(timeout_sec=0.01)
            if time.monotonic() < wall0 + seconds:
                cpu1, wall1 = sum(proc.cpu_times()[:2]), time.monotonic()
    finally:
        child.send_signal(2)
        child.wait(30)
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    expected = int(math.floor(seconds * rate_hz + 1e-9)) + 1
    cpu = 100.0 * (cpu1 - cpu0) / max(wall1 - wall0, 1e-9)
    return {'expected': expected, 'cpu_percent_of_one_core': cpu,
            'received': {t: sum(x <= wall0 + seconds + 0.5 for x in got[t]) for t in topics
                         if got[t] or t != api.IMU}}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--rate', type=float, default=1000.0, help='sample rate (Hz)')
    parser.add_argument('--seconds', type=float, default=30.0, help='drive duration (s)')
    parser.add_argument('--params-file', type=pathlib.Path,
                        default=REPO / 'config' / 'tractor_semitrailer.yaml')
    parser.add_argument('--imu', action='store_true', help='the tractor IMU fitted')
    parser.add_argument('--front', action='store_true',
                        help='the front-axle node instead (package defaults)')
    parser.add_argument('--repeats', type=int, default=1)
    parser.add_argument('--only-deflections', action='store_true',
                        help='subscribe to /suspension/deflections only (as '
                             'bench.probes.node_latency --plant does)')
    args = parser.parse_args(argv)
    what = ('front axle (package defaults)' if args.front else
            f'articulated ({args.params_file.name}), IMU {"on" if args.imu else "off"}')
    cpus = []
    for _ in range(args.repeats):
        r = measure(args.rate, args.seconds, None if args.front else args.params_file,
                    args.imu, args.only_deflections)
        cpus.append(r['cpu_percent_of_one_core'])
    if args.only_deflections:
        what += ', only /suspension/deflections subscribed'
    print(f'plant_simulator, {what}, {args.rate:g} Hz for {args.seconds:g} s: CPU '
          f'{statistics.median(cpus):.1f} % of one core (median of {len(cpus)}: '
          f'{", ".join(f"{c:.1f}" for c in cpus)})')
    for topic, count in r['received'].items():
        print(f'  {topic}: {count} of {r["expected"]} samples within the drive (+0.5 s)',
              flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
