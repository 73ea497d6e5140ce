"""Benchmark of the observer node: per-message latency, CPU share, highest sustained input rate.

Run from the repository root::

    .venv/bin/python bench/node_latency.py [--rate 1000] [--seconds 10] [--executor events]
        [--sweep 1000,2000,4000,8000,12000] [--sweep-seconds 4] [--json FILE]

The observer runs in its own process (as ``ros2 run`` starts it: its ``main`` with the
EventsExecutor, or ``--executor single`` for rclpy's SingleThreadedExecutor). This process is
the driver: it publishes ``/suspension/deflections`` (sensor-data QoS) and ``/vehicle/twist``
(as the plant_simulator does, with every sample) at a steady rate, a sinusoidal deflection well
inside the estimator's range, and takes
``/observer/states`` (the last of the six messages the observer publishes per input).

- latency: from the driver's ``publish`` of a sample to its receipt of ``/observer/states`` with
  that sample's stamp (one clock, this process): DDS both ways, the observer's callback,
  :meth:`Estimator.update` and its six publishes; median and 99th percentile;
- CPU share: the observer process's user + system CPU time over the run's wall time (psutil),
  in % of one core;
- sustained rate: the highest rate of ``--sweep`` up to which every sample gets its output and
  the median latency stays below 5 ms (no backlog builds up: beyond the rate the node sustains,
  the queue and so the median grow through the run; the median, unlike the 99th percentile,
  is not moved by the short stalls other processes cause on a shared machine).

The machine is shared (other work may run): numbers vary by tens of percent between runs.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import pathlib
import subprocess
import sys
import time

import numpy as np
import psutil
import rclpy
from rclpy.context import Context
from rclpy.node import Node
from sensor_msgs.msg import JointState

from road_force_estimator.ros.messages import (
    deflections_msg, reliable_qos, sensor_qos, stamp_to_ns, twist_msg)

REPO = pathlib.Path(__file__).resolve().parents[1]
MAX_MEDIAN_S = 0.005


def serve_observer(executor_kind: str) -> int:
    """The observer node, spun like its main() does, with the chosen executor."""
    if executor_kind == 'events':
        from road_force_estimator.ros.observer import main
        return main(['observer'])
    from rclpy.executors import SingleThreadedExecutor

    from road_force_estimator.ros.observer import Observer
    rclpy.init()
    node = Observer()
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        while rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


class Driver(Node):
    def __init__(self, context):
        super().__init__('latency_driver', context=context)
        self.deflections = self.create_publisher(JointState, '/suspension/deflections',
                                                 sensor_qos(1000))
        self.twist = self.create_publisher(type(twist_msg(0, 0.0)), '/vehicle/twist',
                                           reliable_qos())
        self.sent: dict[int, int] = {}
        self.latency_ns: list[int] = []
        self.create_subscription(JointState, '/observer/states', self.states_callback,
                                 reliable_qos(10000))

    def states_callback(self, msg) -> None:
        now = time.perf_counter_ns()
        sent = self.sent.pop(stamp_to_ns(msg.header.stamp), None)
        if sent is not None:
            self.latency_ns.append(now - sent)


def run(executor, driver: Driver, rate_hz: float, seconds: float, stamp0_ns: int) -> dict:
    """Publish at ``rate_hz`` for ``seconds``; wait for the outputs; the figures."""
    driver.sent.clear()
    driver.latency_ns.clear()
    n = int(rate_hz * seconds)
    period_ns = 1e9 / rate_hz
    start = time.perf_counter_ns()
    for k in range(n):
        due = start + int(k * period_ns)
        while (left := due - time.perf_counter_ns()) > 0:  # take outputs while waiting
            executor.spin_once(timeout_sec=left * 1e-9)
        stamp = stamp0_ns + int(k * period_ns)
        q = (2e-3 * math.sin(2 * math.pi * 2.0 * k / rate_hz), 0.0)
        msg = deflections_msg(stamp, q, 1e-3 * math.sin(2 * math.pi * 1.0 * k / rate_hz))
        driver.sent[stamp] = time.perf_counter_ns()
        driver.twist.publish(twist_msg(stamp, 20.0))  # as the plant_simulator: every sample
        driver.deflections.publish(msg)
    sent_s = (time.perf_counter_ns() - start) * 1e-9
    deadline = time.monotonic() + 2.0
    while driver.sent and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.01)
    lat = np.array(driver.latency_ns) * 1e-9
    return {'rate_hz': rate_hz, 'sent': n, 'achieved_rate_hz': n / sent_s,
            'received': len(lat), 'lost': len(driver.sent),
            'median_ms': float(np.median(lat) * 1e3) if len(lat) else math.nan,
            'p99_ms': float(np.percentile(lat, 99) * 1e3) if len(lat) else math.nan}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--rate', type=float, default=1000.0)
    parser.add_argument('--seconds', type=float, default=10.0)
    parser.add_argument('--executor', choices=('events', 'single'), default='events')
    parser.add_argument('--sweep', default='1000,2000,4000,8000,12000')
    parser.add_argument('--sweep-seconds', type=float, default=4.0)
    parser.add_argument('--json', type=pathlib.Path)
    parser.add_argument('--serve-observer', choices=('events', 'single'), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.serve_observer:
        return serve_observer(args.serve_observer)
    os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    child = subprocess.Popen([sys.executable, __file__, '--serve-observer', args.executor],
                             cwd=REPO, stderr=subprocess.DEVNULL)
    context = Context()
    rclpy.init(context=context)
    from rclpy.experimental import EventsExecutor
    executor = EventsExecutor(context=context)
    driver = Driver(context)
    executor.add_node(driver)
    results = {'executor': args.executor}
    try:
        deadline = time.monotonic() + 30.0
        while (driver.deflections.get_subscription_count() == 0
               or driver.twist.get_subscription_count() == 0) and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        stamp0 = 1_700_000_000 * 10**9
        run(executor, driver, args.rate, 1.0, stamp0)  # warm-up
        proc = psutil.Process(child.pid)
        cpu0, wall0 = sum(proc.cpu_times()[:2]), time.monotonic()
        main_run = run(executor, driver, args.rate, args.seconds, stamp0 + 2 * 10**9)
        cpu = (sum(proc.cpu_times()[:2]) - cpu0) / (time.monotonic() - wall0)
        main_run['observer_cpu_percent_of_one_core'] = 100.0 * cpu
        results['main'] = main_run
        print(f"{args.executor}: {args.rate:g} Hz for {args.seconds:g} s: latency median "
              f"{main_run['median_ms']:.3f} ms, p99 {main_run['p99_ms']:.3f} ms, lost "
              f"{main_run['lost']} of {main_run['sent']}, observer CPU {100 * cpu:.1f} % "
              f"of one core")
        sustained, failed = None, False
        results['sweep'] = []
        t0 = stamp0 + int((4 + args.seconds) * 1e9)
        for i, rate in enumerate(float(r) for r in args.sweep.split(',')):
            r = run(executor, driver, rate, args.sweep_seconds, t0 + i * 10**11)
            results['sweep'].append(r)
            ok = r['lost'] == 0 and r['median_ms'] < MAX_MEDIAN_S * 1e3
            print(f"  sweep {rate:g} Hz (achieved {r['achieved_rate_hz']:.0f} Hz): lost "
                  f"{r['lost']}, median {r['median_ms']:.3f} ms, p99 {r['p99_ms']:.3f} ms"
                  f"{'' if ok else '  <- not sustained'}")
            failed = failed or not ok
            if not failed:
                sustained = rate
        results['sustained_rate_hz'] = sustained
        print(f'highest sustained rate (no loss, median < {MAX_MEDIAN_S * 1e3:g} ms): '
              f'{sustained} Hz')
    finally:
        child.send_signal(2)
        child.wait(10)
        executor.shutdown()
        driver.destroy_node()
        rclpy.try_shutdown(context=context)
    if args.json:
        args.json.write_text(json.dumps(results, indent=2))
    return 0


if __name__ == '__main__':
    sys.exit(main())
