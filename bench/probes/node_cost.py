"""Benchmark: the observer node's CPU per sample in its callbacks, by part (thread CPU time).

Run from the repository root::

    .venv/bin/python -m bench.probes.node_cost [--samples 3000] [--repeats 7] [--articulated]

The observer runs in this process; its outputs go to a subscriber in a child process (every
topic, raw, reliable), as in bench/probes/node_latency.py. The inputs are the bytes our publishers
send (a sinusoidal drive at 1 kHz, a twist with every sample), handed to the node's two
callbacks directly, so the executor and the receiving side of DDS are left out (those are in
bench/probes/node_latency.py's CPU share). Per sample, in microseconds of this thread's CPU time
(``time.thread_time_ns``: another process's load on a shared machine moves it much less than
a wall clock), min and median over ``--repeats`` blocks of ``--samples``:

- callbacks: ``twist_callback`` + ``deflections_callback``, the seven publishes included;
- callbacks, publish a no-op: the same with rclpy's publish replaced (the node's Python and
  the estimator);
- estimator.update: the numeric core alone, on the same inputs;
- publish_raw: one rclpy publish of a serialized ``/observer/states`` (rclpy, rmw, DDS);
- plant_simulator sample: its plant's step and its six publishes of one sample (the
  plant_simulator node made in this process once the observer is gone: the cost of each
  sample its timer publishes).

The node's own Python is the second figure less the third; rclpy's share the first less
the second.

``--articulated``: the observer with ``config/tractor_semitrailer.yaml`` (5 axles), fed the
readings of a simulated class C drive at 20 m/s (:func:`.node_latency.articulated_drive`);
the parts as above with ``WholeVehicleEstimator.step`` for the numeric core (the plant's
sample is left out), the child subscribing to every output of the articulated node. With
``--flush MB`` also ``WholeVehicleEstimator.step, cold``: the step alone timed, an array of
that many MB summed before each (the node's thread sleeps between samples while others run:
its caches are theirs when it wakes).
"""
from __future__ import annotations

import argparse
import math
import os
import statistics
import subprocess
import sys
import time

import rclpy
from rclpy.node import Node

from bench.probes.node_latency import (
    ARTICULATED_CONFIG, ARTICULATED_JOINTS, articulated_drive, input_encoders)
from road_force_estimator.ros.take_loop import Taken
from road_force_estimator import interfaces as api
from road_force_estimator.ros.bag_recorder import message_class
from road_force_estimator.ros.messages import topic_qos

TOPICS = (*api.LOAD, *api.ROAD, api.LTR, api.LOAD_TRANSFER, api.STATES, *api.STATIC_LOAD,
          api.DEFLECTIONS, api.TWIST, *api.TRUE_LOAD, *api.TRUE_ROAD, api.WHEEL_LOADS,
          *api.UNIT_LOAD_TRANSFER, api.STATIC_WHEEL_LOADS, *api.ROAD_FUSED)
T0_NS = 1_700_000_000 * 10**9


def serve_subscriber(seconds: float) -> int:
    """Take every output topic raw for ``seconds``."""
    from rclpy.experimental import EventsExecutor
    rclpy.init()
    node = Node('node_cost_sink')
    for topic in TOPICS:
        node.create_subscription(message_class(api.TOPIC_TYPES[topic]), topic, lambda d: None,
                                 topic_qos(topic, 10000), raw=True)
    executor = EventsExecutor()
    executor.add_node(node)
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.1)
    return 0


class _NoPublish:
    def publish(self, data) -> None:
        pass

    publish_raw = publish


def per_sample_us(fn, blocks, repeats: int) -> tuple[float, float]:
    """(min, median) thread CPU time per item (us) of ``fn`` over ``repeats`` blocks."""
    times = []
    for r in range(repeats):
        block = blocks(r)
        start = time.thread_time_ns()
        for item in block:
            fn(item)
        times.append((time.thread_time_ns() - start) / len(block) / 1e3)
    return min(times), statistics.median(times)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--samples', type=int, default=3000)
    parser.add_argument('--repeats', type=int, default=7)
    parser.add_argument('--articulated', action='store_true',
                        help='vehicle.model: articulated (config/tractor_semitrailer.yaml)')
    parser.add_argument('--flush', type=float, default=0.0, metavar='MB',
                        help='--articulated: also the step with MB of memory read before each')
    parser.add_argument('--serve', type=float, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.serve:
        return serve_subscriber(args.serve)
    os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    drive = []
    if args.articulated:     # (simulated before the child starts: its 600 s run from here)
        drive = articulated_drive(args.samples * (2 * args.repeats + 2) / 1000.0 + 0.5)
    child = subprocess.Popen([sys.executable, '-m', 'bench.probes.node_cost', '--serve', '600'],
                             stderr=subprocess.DEVNULL)
    rclpy.init(args=['--ros-args', '--params-file', str(ARTICULATED_CONFIG)]
               if args.articulated else None)
    from road_force_estimator.estimation import Estimator
    from road_force_estimator.ros.observer import Observer
    observer = Observer()
    try:
        deadline = time.monotonic() + 30.0
        last = observer.whole.pubs[-1] if args.articulated else observer.states_pub
        while last.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.5)
        if args.articulated:
            report_articulated(observer, drive, args)
        else:
            report(observer, Estimator, args)
    finally:
        child.kill()
        rclpy.try_shutdown()
    return 0


def plant_sample_us(args) -> tuple[float, float]:
    """(min, median) thread CPU time (us) of one plant_simulator sample: step and publish."""
    from rclpy.parameter import Parameter

    from road_force_estimator.ros.plant_simulator import PlantSimulator
    plant = PlantSimulator(parameter_overrides=[Parameter('simulator.duration', value=120.0)])
    try:
        def sample(k):
            plant.publish(plant.plant.step(), T0_NS + k * 10**6)

        return per_sample_us(sample, lambda r: range(r * args.samples, (r + 1) * args.samples),
                             args.repeats)
    finally:
        plant.destroy_node()


def report(observer, estimator_class, args) -> None:
    """Time the parts (see the module docstring) and print them."""
    (deflections, twist), n = input_encoders(), args.samples
    inputs = [(T0_NS + k * 10**6, (2e-3 * math.sin(k / 80), 1e-3 * math.cos(k / 50)),
               1e-3 * math.sin(k / 160)) for k in range(n * (2 * args.repeats + 2))]
    data = [(deflections.encode(t, (*q, phi)), twist.encode(t, (20.0,)))
            for t, q, phi in inputs]

    taken = observer.input

    def callbacks(pair):   # one round of the input thread: the twist and the deflections
        taken.take([Taken(taken.twist_index, pair[1], 0, None),
                    Taken(taken.deflection_index, pair[0], 0, None)])

    for pair in data[:n]:   # warm: past the model fit's skip and the first designs
        callbacks(pair)
    rows = [('callbacks', per_sample_us(callbacks, lambda r: data[n * (r + 1):n * (r + 2)],
                                        args.repeats))]
    names = ('send', 'load_pubs', 'road_pubs', 'static_pubs', 'ltr_pub', 'load_transfer_pub',
             'states_pub')
    kept = {k: getattr(observer, k) for k in names if hasattr(observer, k)}
    for k, v in kept.items():   # (an observer without 'send' publishes with Publisher.publish)
        setattr(observer, k, [_NoPublish().publish_raw] * len(v) if k == 'send' else
                [_NoPublish()] * len(v) if isinstance(v, list) else _NoPublish())
    off = n * (args.repeats + 1)
    rows.append(('callbacks, publish a no-op', per_sample_us(
        callbacks, lambda r: data[off + n * r:off + n * (r + 1)], args.repeats)))
    for k, v in kept.items():
        setattr(observer, k, v)
    estimator = estimator_class(*observer.params.config)
    for t, q, phi in inputs[:n]:
        estimator.update(t, q, phi, 20.0)
    rows.append(('estimator.update', per_sample_us(
        lambda s: estimator.update(s[0], s[1], s[2], 20.0),
        lambda r: inputs[n * (r + 1):n * (r + 2)], args.repeats)))
    states = observer.wire.states.encode(T0_NS, (0.0,) * 12)
    raw = observer.states_pub.handle.publish_raw
    rows.append(('publish_raw (/observer/states)', per_sample_us(
        lambda _: raw(states), lambda r: range(n), args.repeats)))
    observer.destroy_node()   # the plant's inputs go to the child alone
    rows.append(('plant_simulator sample', plant_sample_us(args)))
    for name, (low, mid) in rows:
        print(f'{name:32s} min {low:7.2f} us   median {mid:7.2f} us per sample')
    (cb, _), (py, _), (core, _) = rows[0][1], rows[1][1], rows[2][1]
    print(f"node's own Python (min) {py - core:.1f} us, rclpy publish (min) {cb - py:.1f} us "
          f'per sample')


def report_articulated(observer, drive: list, args) -> None:
    """The parts of the articulated node (see the module docstring) and print them."""
    from road_force_estimator.estimation.whole_vehicle import WholeVehicleEstimator
    whole, n = observer.whole, args.samples
    deflections, twist = input_encoders(ARTICULATED_JOINTS)
    data = [(deflections.encode(T0_NS + k * 10**6, r), twist.encode(T0_NS + k * 10**6, (20.0,)))
            for k, r in enumerate(drive)]
    taken = whole.input

    def callbacks(pair):   # one round of the input thread: the twist and the deflections
        taken.take([Taken(taken.twist_index, pair[1], 0, None),
                    Taken(taken.deflection_index, pair[0], 0, None)])

    for pair in data[:n]:   # warm: past the first gain designs
        callbacks(pair)
    rows = [('callbacks', per_sample_us(callbacks, lambda r: data[n * (r + 1):n * (r + 2)],
                                        args.repeats))]
    names = ('send', 'send_static', 'send_road', 'send_fused')
    kept = {k: getattr(whole, k) for k in names}
    for k, v in kept.items():
        setattr(whole, k, [_NoPublish().publish_raw] * len(v))
    off = n * (args.repeats + 1)
    rows.append(('callbacks, publish a no-op', per_sample_us(
        callbacks, lambda r: data[off + n * r:off + n * (r + 1)], args.repeats)))
    for k, v in kept.items():
        setattr(whole, k, v)
    vehicle, settings = whole.params.config[:2]
    estimator = WholeVehicleEstimator(vehicle, settings)
    for k in range(n):
        estimator.step(T0_NS + k * 10**6, drive[k], 20.0)
    rows.append(('WholeVehicleEstimator.step', per_sample_us(
        lambda k: estimator.step(T0_NS + k * 10**6, drive[k], 20.0),
        lambda r: range(n * (r + 1), n * (r + 2)), args.repeats)))
    if args.flush > 0.0:
        rows.append(('WholeVehicleEstimator.step, cold', cold_step_us(
            estimator, drive, n, args.repeats, args.flush)))
    observer.destroy_node()
    for name, (low, mid) in rows:
        print(f'{name:32s} min {low:7.2f} us   median {mid:7.2f} us per sample')
    (cb, _), (py, _), (core, _) = rows[0][1], rows[1][1], rows[2][1]
    print(f"node's own Python (min) {py - core:.1f} us, rclpy publish (min) {cb - py:.1f} us "
          f'per sample')


def cold_step_us(estimator, drive: list, n: int, repeats: int, flush_mb: float
                 ) -> tuple[float, float]:
    """(min, median) thread CPU time (us) of ``estimator.step`` alone on the drive's samples
    after the first ``(repeats + 1) n`` (where the warm blocks left it), ``flush_mb`` MB of
    memory summed before each step (outside its time)."""
    import numpy as np

    junk = np.ones(max(int(flush_mb * 2**20 / 8), 1))
    clock, step = time.thread_time_ns, estimator.step
    times = []
    for r in range(repeats):
        total = 0
        for k in range(n * (r + repeats + 1), n * (r + repeats + 2)):
            junk.sum()
            start = clock()
            step(T0_NS + k * 10**6, drive[k], 20.0)
            total += clock() - start
        times.append(total / n / 1e3)
    return min(times), statistics.median(times)


if __name__ == '__main__':
    sys.exit(main())
