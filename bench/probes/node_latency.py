"""Benchmark of the observer node: per-message latency, CPU share, highest sustained input rate.

Run from the repository root::

    .venv/bin/python bench/probes/node_latency.py [--rate 1000] [--seconds 10] [--repeats 1]
        [--executor events] [--node observer|bare|take] [--sweep 1000,2000,5000,8000,12000]
        [--sweep-seconds 4] [--json FILE]
    .venv/bin/python bench/probes/node_latency.py --plant 5000 [--seconds 10]
    python -m bench.probes.node_latency --articulated [--node observer|bare|take] [--sweep '']
        [--warm-up 1]

The observer runs in its own process (as ``ros2 run`` starts it: its ``main`` with the
EventsExecutor, or ``--executor single`` for rclpy's SingleThreadedExecutor). This process is
the driver: it publishes ``/suspension/deflections`` (sensor-data QoS) and ``/vehicle/twist``
(as the plant_simulator does, with every sample) at a steady rate, a sinusoidal deflection well
inside the estimator's range, as serialized bytes (the bytes rmw sends for the messages
:mod:`.messages` builds, so the driver's own cost stays small at 5 kHz and more), and takes
``/observer/states`` raw (the last of the seven messages the observer publishes per input).

``--node bare`` runs, instead of the observer, the floor of any rclpy node with the observer's
topics: it takes both inputs raw and publishes, per deflection message, seven cached messages
of the observer's types and QoS (``/observer/states`` last, with the input's stamp copied in)
and the two static loads every 100th: rclpy, rmw and DDS alone, no estimate.
``--node take`` is the bare node with its inputs taken as the observer takes them (a
:class:`.take_loop.TakeLoop` thread: ``/vehicle/twist`` riding with the deflections), not
by the executor's callbacks: the floor of the observer's input design; the observer less it
is the estimate and its Python.
``--repeats`` runs the main measurement that many times and reports each and their medians.

- latency: from the driver's ``publish`` of a sample to its receipt of ``/observer/states`` with
  that sample's stamp (one clock, this process): DDS both ways, the observer's callback,
  :meth:`Estimator.update` and its six publishes; median and 99th percentile;
- CPU share: the observer process's user + system CPU time over the run's wall time (psutil),
  in % of one core;
- sustained rate: the highest rate of ``--sweep`` up to which every sample gets its output and
  the median latency stays below 5 ms (no backlog builds up: beyond the rate the node sustains,
  the queue and so the median grow through the run; the median, unlike the 99th percentile,
  is not moved by the short stalls other processes cause on a shared machine).

``--plant RATE`` measures the plant_simulator node instead (``main`` in its own process, the
default ISO road, ``--seconds`` of drive at ``RATE`` Hz, real time): its CPU share and whether
it kept up (every sample arrived here within the drive's time, its lag in the diagnostics).

``--articulated``: the observer with ``config/tractor_semitrailer.yaml`` (``vehicle.model:
articulated``, 5 axles): the driver publishes the 12 joints of ``/suspension/deflections``
(both sides of 5 axles and both rolls, sinusoids) and takes ``/load_transfer``, the last of the
seven messages the node publishes per input (``/wheel_loads``, the three units' load
transfer, the front axle's two loads and ``/load_transfer``); the bare node publishes seven
cached messages of the same types and sizes (``/load_transfer`` last, the input's stamp
copied in), the three static-load messages every 100th, and the road as the observer does at
20 m/s (``/road_profile/left|right`` with every input, ``/road_profile/fused/left|right``
with every 5th: a point per 0.1 m).

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

import statistics
import struct

import numpy as np
import psutil
import rclpy
from rclpy.context import Context
from rclpy.node import Node

from road_force_estimator import interfaces as api
from road_force_estimator.serde import CdrEncoder, message_template
from road_force_estimator.ros.bag_recorder import message_class
from road_force_estimator.ros.messages import reliable_qos, sensor_qos

REPO = pathlib.Path(__file__).resolve().parents[2]
MAX_MEDIAN_S = 0.005
STAMP0_NS = 1_700_000_000 * 10**9
STAMP = struct.Struct('<iI')   # header.stamp, right after the 4-byte CDR encapsulation header
OUTPUTS = (*api.LOAD, *api.ROAD, api.LTR, api.LOAD_TRANSFER, api.STATES)  # states last
#: --articulated: MODEL.md's 5-axle combination and its channels
ARTICULATED_CONFIG = REPO / 'config' / 'tractor_semitrailer.yaml'
AXLES = ('front', 'drive', 'trailer_1', 'trailer_2', 'trailer_3')
ARTICULATED_JOINTS = api.articulated_deflection_joints(AXLES, True)
ARTICULATED_OUTPUTS = (api.WHEEL_LOADS, *api.UNIT_LOAD_TRANSFER, *api.LOAD,
                       api.LOAD_TRANSFER)   # /load_transfer last, as the node sends them


def input_encoders(joints=api.DEFLECTION_JOINTS) -> tuple[CdrEncoder, CdrEncoder]:
    """Encoders of ``/suspension/deflections`` (of ``joints``) and ``/vehicle/twist`` as our
    publishers send them (test_wire: the bytes rmw sends for
    :func:`.messages.deflections_msg` and :func:`.messages.twist_msg`)."""
    return (CdrEncoder(api.JOINT_STATE, message_template(
        api.JOINT_STATE, api.BASE_FRAME, joints), ['position']),
            CdrEncoder(api.TWIST_STAMPED, message_template(api.TWIST_STAMPED, api.BASE_FRAME),
                       ['twist.linear.x']))


def articulated_drive(seconds: float) -> list[tuple]:
    """The readings of ``/suspension/deflections`` of MODEL.md's combination on class C at
    20 m/s and 1 kHz (``simulate_bag``, sensor noise of the file), ``seconds`` long: what the
    articulated observer takes in a drive (its noise and roughness estimates settle, as they
    do on a road; sinusoids kept it designing new gains)."""
    import tempfile

    from road_force_estimator.bagio.articulated_readings import read_articulated_readings
    from road_force_estimator.tools.simulate_bag import main as simulate_bag
    with tempfile.TemporaryDirectory() as tmp:
        bag = pathlib.Path(tmp) / 'drive'
        simulate_bag(['--params-file', str(ARTICULATED_CONFIG), '--road', 'iso8608:C:seed=1',
                      '--duration', f'{seconds:g}', '--output', str(bag), '--no-progress'])
        got = read_articulated_readings(bag, ARTICULATED_JOINTS)
    return [tuple(r) for r in got.readings.tolist()]


def stamp_ns_of(data: bytes) -> int:
    """``header.stamp`` (ns) of a serialized stamped message."""
    sec, nanosec = STAMP.unpack_from(data, 4)
    return sec * 1_000_000_000 + nanosec


class BareNode(Node):
    """The floor: the observer's subscriptions and publishers, cached bytes out, no estimate
    (``take``: the inputs taken by :func:`take_inputs`)."""

    def __init__(self, take: bool = False):
        super().__init__('observer')
        from road_force_estimator.ros.wire import Wire
        wire, t = Wire(), 1_700_000_000 * 10**9
        self.pubs = [self.create_publisher(message_class(api.TOPIC_TYPES[topic]), topic,
                                           reliable_qos()) for topic in OUTPUTS]
        self.static_pubs = [self.create_publisher(message_class(api.WRENCH), topic,
                                                  reliable_qos()) for topic in api.STATIC_LOAD]
        self.cached = [wire.loads[0].encode(t, (1.0,)), wire.loads[1].encode(t, (1.0,)),
                       wire.road.encode(t, (1.0, 1.0, 0.0)), wire.road.encode(t, (1.0, -1.0, 0.0)),
                       wire.ltr.encode(None, (0.0,)), wire.load_transfer.encode(t, (0, 0, 0))]
        self.static = self.cached[:2]
        self.states = wire.states.encode(t, (0.0,) * 12)
        self.k = 0
        if take:
            take_inputs(self, self.deflections_callback)
            return
        self.create_subscription(message_class(api.JOINT_STATE), api.DEFLECTIONS,
                                 self.deflections_callback, sensor_qos(1000), raw=True)
        self.create_subscription(message_class(api.TWIST_STAMPED), api.TWIST,
                                 lambda data: None, sensor_qos(10), raw=True)

    def deflections_callback(self, data: bytes) -> None:
        for pub, out in zip(self.pubs, self.cached):
            pub.publish(out)
        self.pubs[-1].publish(self.states[:4] + data[4:12] + self.states[12:])
        self.k += 1
        if self.k % 100 == 0:
            for pub, out in zip(self.static_pubs, self.static):
                pub.publish(out)


def take_inputs(node: Node, callback) -> None:
    """``node``'s two inputs taken as the observer takes them (its :class:`.TakeLoop`, the
    twist riding with the deflections, the same depths), ``callback(data)`` per deflection
    message (in the loop's thread); the executor's subscriptions are not made."""
    from road_force_estimator.ros.observer_input import QUEUE_DEPTH, TWIST_DEPTH
    from road_force_estimator.ros.take_loop import TakeLoop
    loop = TakeLoop(node.get_name(), node.context, batch=QUEUE_DEPTH)
    loop.add(message_class(api.TWIST_STAMPED), api.TWIST, sensor_qos(TWIST_DEPTH), wakes=False)
    index = loop.add(message_class(api.JOINT_STATE), api.DEFLECTIONS, sensor_qos(QUEUE_DEPTH))

    def sink(batch) -> None:
        for m in batch:
            if m.index == index:
                callback(m.data)

    loop.start(sink)
    node.take_loop = loop


class BareArticulatedNode(Node):
    """The floor of the articulated observer: its subscriptions, seven cached messages of its
    types and sizes per input, the three static-load messages every 100th; the road as the
    observer publishes it at the driver's 20 m/s: ``/road_profile/left|right`` per input,
    ``/road_profile/fused/left|right`` every 5th (a point per 0.1 m,
    :data:`.fused_stream.FUSED_SPACING_M`); no estimate."""

    def __init__(self, take: bool = False):
        super().__init__('observer')
        base, t = api.BASE_FRAME, STAMP0_NS
        wheels = api.wheel_joints(AXLES)
        loads = CdrEncoder(api.JOINT_STATE, message_template(api.JOINT_STATE, base, wheels,
                                                             effort=True), ['effort'])
        vector = CdrEncoder(api.VECTOR3_STAMPED, message_template(api.VECTOR3_STAMPED, base),
                            ['vector.x', 'vector.y', 'vector.z'])
        wrench = [CdrEncoder(api.WRENCH, message_template(api.WRENCH, f), ['wrench.force.z'])
                  for f in api.WHEEL_FRAMES]
        self.cached = [loads.encode(t, (1.0,) * len(wheels)), *(
            vector.encode(t, (0.0, 0.0, 0.0)) for _ in range(3)),
            *(w.encode(t, (1.0,)) for w in wrench)]
        self.last = vector.encode(t, (0.0, 0.0, 0.0))
        self.static = [self.cached[0], *self.cached[4:6]]
        types = {api.WHEEL_LOADS: api.JOINT_STATE, api.LOAD_TRANSFER: api.VECTOR3_STAMPED,
                 **{u: api.VECTOR3_STAMPED for u in api.UNIT_LOAD_TRANSFER},
                 **{w: api.WRENCH for w in api.LOAD}}
        pubs = [self.create_publisher(message_class(types[topic]), topic, reliable_qos(1000))
                for topic in ARTICULATED_OUTPUTS]
        self.send = [p.handle.publish_raw for p in pubs[:-1]]
        self.send_last = pubs[-1].handle.publish_raw
        static = [self.create_publisher(message_class(api.JOINT_STATE),
                                        api.STATIC_WHEEL_LOADS, reliable_qos(1000))]
        static += [self.create_publisher(message_class(api.WRENCH), topic, reliable_qos(1000))
                   for topic in api.STATIC_LOAD]
        self.send_static = [p.handle.publish_raw for p in static]
        point = CdrEncoder(api.POINT, message_template(api.POINT, api.ROAD_FRAME),
                           ['point.x', 'point.y', 'point.z'])
        self.road = [point.encode(t, (1.0, y, 0.0)) for y in (1.0, -1.0)]
        self.send_road = [self.create_publisher(message_class(api.POINT), topic,
                                                reliable_qos(1000)).handle.publish_raw
                          for topic in api.ROAD]
        self.send_fused = [self.create_publisher(message_class(api.POINT), topic,
                                                 reliable_qos(1000)).handle.publish_raw
                           for topic in api.ROAD_FUSED]
        self.k = 0
        if take:
            take_inputs(self, self.deflections_callback)
            return
        self.create_subscription(message_class(api.JOINT_STATE), api.DEFLECTIONS,
                                 self.deflections_callback, sensor_qos(1000), raw=True)
        self.create_subscription(message_class(api.TWIST_STAMPED), api.TWIST,
                                 lambda data: None, sensor_qos(10), raw=True)

    def deflections_callback(self, data: bytes) -> None:
        for send, out in zip(self.send, self.cached):
            send(out)
        self.send_last(self.last[:4] + data[4:12] + self.last[12:])
        for send, out in zip(self.send_road, self.road):
            send(out)
        self.k += 1
        if self.k % 5 == 0:
            for send, out in zip(self.send_fused, self.road):
                send(out)
        if self.k % 100 == 0:
            for send, out in zip(self.send_static, self.static):
                send(out)


def serve_observer(executor_kind: str, bare: bool = False, articulated: bool = False,
                   take: bool = False) -> int:
    """The observer node (or the bare node), spun like its main() does, with the chosen
    executor; ``articulated``: with MODEL.md's combination (or its bare floor); ``take``: the
    bare node taking its inputs as the observer does."""
    if bare:
        from road_force_estimator.ros.node_runner import run_node
        cls = BareArticulatedNode if articulated else BareNode
        return run_node('bare', 'bare node', (), ['bare'], lambda: cls(take=take))
    if executor_kind == 'events':
        from road_force_estimator.ros.observer import main
        return main(['observer'] + (['--ros-args', '--params-file', str(ARTICULATED_CONFIG)]
                                    if articulated else []))
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
    def __init__(self, context, articulated: bool = False):
        super().__init__('latency_driver', context=context)
        self.articulated = articulated
        self.drive: list[tuple] = []
        self.deflections = self.create_publisher(message_class(api.JOINT_STATE),
                                                 api.DEFLECTIONS, sensor_qos(1000))
        self.twist = self.create_publisher(message_class(api.TWIST_STAMPED), api.TWIST,
                                           reliable_qos())
        self.encoders = input_encoders(ARTICULATED_JOINTS if articulated else
                                       api.DEFLECTION_JOINTS)
        self.next_stamp_ns = STAMP0_NS
        self.sent: dict[int, int] = {}
        self.latency_ns: list[int] = []
        last = ((api.VECTOR3_STAMPED, api.LOAD_TRANSFER) if articulated else
                (api.JOINT_STATE, api.STATES))
        self.create_subscription(message_class(last[0]), last[1],
                                 self.states_callback, reliable_qos(10000), raw=True)

    def readings(self, t: float) -> tuple:
        """The deflections (m) and rolls (rad) at ``t`` (s): sinusoids inside the range; the
        articulated truck's: a simulated drive's readings (:func:`articulated_drive`),
        sample ``round(t * 1000)``, from its start again at its end."""
        if self.articulated:
            return self.drive[round(t * 1000.0) % len(self.drive)]
        return (2e-3 * math.sin(2 * math.pi * 2.0 * t), 0.0,
                1e-3 * math.sin(2 * math.pi * 1.0 * t))

    def states_callback(self, data: bytes) -> None:
        now = time.perf_counter_ns()
        sent = self.sent.pop(stamp_ns_of(data), None)
        if sent is not None:
            self.latency_ns.append(now - sent)


def run(executor, driver: Driver, rate_hz: float, seconds: float) -> dict:
    """Publish at ``rate_hz`` for ``seconds``; wait for the outputs; the figures. The stamps
    go on from the last run's, one period on (no gap: the estimator does not restart)."""
    driver.sent.clear()
    driver.latency_ns.clear()
    n = int(rate_hz * seconds)
    period_ns = 1e9 / rate_hz
    deflections, twist = driver.encoders
    start = time.perf_counter_ns()
    for k in range(n):
        due = start + int(k * period_ns)
        while (left := due - time.perf_counter_ns()) > 0:  # take outputs while waiting
            executor.spin_once(timeout_sec=left * 1e-9)
        stamp = driver.next_stamp_ns + int(k * period_ns)
        t = (stamp - STAMP0_NS) * 1e-9
        data = deflections.encode(stamp, driver.readings(t))
        speed = twist.encode(stamp, (20.0,))
        driver.sent[stamp] = time.perf_counter_ns()
        driver.twist.publish(speed)  # as the plant_simulator: every sample
        driver.deflections.publish(data)
    sent_s = (time.perf_counter_ns() - start) * 1e-9
    driver.next_stamp_ns += int(n * period_ns)
    deadline = time.monotonic() + 2.0
    while driver.sent and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.01)
    lat = np.array(driver.latency_ns) * 1e-9
    return {'rate_hz': rate_hz, 'sent': n, 'achieved_rate_hz': n / sent_s,
            'received': len(lat), 'lost': len(driver.sent),
            'median_ms': float(np.median(lat) * 1e3) if len(lat) else math.nan,
            'p99_ms': float(np.percentile(lat, 99) * 1e3) if len(lat) else math.nan}


def measure(executor, driver: Driver, pid: int, args) -> dict:
    """The main run(s) at ``--rate`` with the node's CPU share; the medians of the repeats."""
    proc = psutil.Process(pid)
    runs = []
    for i in range(args.repeats):
        cpu0, wall0 = sum(proc.cpu_times()[:2]), time.monotonic()
        r = run(executor, driver, args.rate, args.seconds)
        cpu = (sum(proc.cpu_times()[:2]) - cpu0) / (time.monotonic() - wall0)
        r['observer_cpu_percent_of_one_core'] = 100.0 * cpu
        runs.append(r)
        print(f"{args.node} ({args.executor}): {args.rate:g} Hz for {args.seconds:g} s: "
              f"latency median {r['median_ms']:.3f} ms, p99 {r['p99_ms']:.3f} ms, lost "
              f"{r['lost']} of {r['sent']}, CPU {100 * cpu:.1f} % of one core", flush=True)
    main_run = {k: statistics.median(r[k] for r in runs) for k in runs[0]}
    if args.repeats > 1:
        print(f"median of {args.repeats}: latency median {main_run['median_ms']:.3f} ms, p99 "
              f"{main_run['p99_ms']:.3f} ms, lost {main_run['lost']:g}, CPU "
              f"{main_run['observer_cpu_percent_of_one_core']:.1f} % of one core")
    return {'main': main_run, 'repeats': runs}


def sweep(executor, driver: Driver, args) -> dict:
    """Rising rates: the highest up to which every output came and the median stayed low."""
    sustained, failed, rows = None, False, []
    for i, rate in enumerate(float(r) for r in args.sweep.split(',') if r):
        r = run(executor, driver, rate, args.sweep_seconds)
        rows.append(r)
        ok = r['lost'] == 0 and r['median_ms'] < MAX_MEDIAN_S * 1e3
        print(f"  sweep {rate:g} Hz (achieved {r['achieved_rate_hz']:.0f} Hz): lost "
              f"{r['lost']}, median {r['median_ms']:.3f} ms, p99 {r['p99_ms']:.3f} ms"
              f"{'' if ok else '  <- not sustained'}", flush=True)
        failed = failed or not ok
        if not failed:
            sustained = rate
    print(f'highest sustained rate (no loss, median < {MAX_MEDIAN_S * 1e3:g} ms): '
          f'{sustained} Hz')
    return {'sweep': rows, 'sustained_rate_hz': sustained}


def isolated_ros() -> None:
    """This process and its children on a ROS domain of their own, on this host only."""
    os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'


def measure_plant(rate_hz: float, seconds: float) -> dict:
    """The plant_simulator's ``main`` at ``rate_hz`` for ``seconds`` of drive, real time: its
    CPU share, and the samples that arrived here by the drive's end (+0.5 s)."""
    isolated_ros()
    context = Context()
    rclpy.init(context=context)
    from rclpy.experimental import EventsExecutor
    executor = EventsExecutor(context=context)
    node = Node('plant_counter', context=context)
    got = []
    node.create_subscription(message_class(api.JOINT_STATE), api.DEFLECTIONS,
                             lambda data: got.append(time.monotonic()), sensor_qos(1000),
                             raw=True)
    executor.add_node(node)
    cmd = [sys.executable, '-m', 'road_force_estimator.ros.plant_simulator', '--ros-args',
           '-p', f'simulator.rate:={rate_hz:g}', '-p', f'simulator.duration:={seconds:g}',
           '-p', 'start_subscribers:=1']        # the counter here subscribes to one topic
    child = subprocess.Popen(cmd, cwd=REPO, stderr=subprocess.DEVNULL,
                             stdout=subprocess.DEVNULL)
    proc = psutil.Process(child.pid)
    try:
        while not got and child.poll() is None:
            executor.spin_once(timeout_sec=0.01)
        cpu0, wall0 = sum(proc.cpu_times()[:2]), got[0] if got else time.monotonic()
        cpu1, wall1 = cpu0, wall0
        while child.poll() is None and time.monotonic() < wall0 + seconds + 0.5:
            executor.spin_once(timeout_sec=0.01)
            if time.monotonic() < wall0 + seconds:
                cpu1, wall1 = sum(proc.cpu_times()[:2]), time.monotonic()
        in_time = sum(t <= wall0 + seconds + 0.5 for t in got)
    finally:
        child.send_signal(2)
        child.wait(30)
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    expected = int(math.floor(seconds * rate_hz + 1e-9)) + 1
    cpu = 100.0 * (cpu1 - cpu0) / max(wall1 - wall0, 1e-9)
    print(f'plant_simulator at {rate_hz:g} Hz for {seconds:g} s: {in_time} of {expected} '
          f'samples within the drive (+0.5 s), CPU {cpu:.1f} % of one core')
    return {'rate_hz': rate_hz, 'seconds': seconds, 'expected': expected,
            'received_in_time': in_time, 'received': len(got), 'cpu_percent_of_one_core': cpu}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--rate', type=float, default=1000.0)
    parser.add_argument('--seconds', type=float, default=10.0)
    parser.add_argument('--repeats', type=int, default=1)
    parser.add_argument('--executor', choices=('events', 'single'), default='events')
    parser.add_argument('--node', choices=('observer', 'bare', 'take'), default='observer')
    parser.add_argument('--warm-up', type=float, default=1.0, metavar='S',
                        help='seconds of input before the measurement (the articulated '
                             "estimator's first gain designs take about 1 s of CPU)")
    parser.add_argument('--articulated', action='store_true',
                        help='vehicle.model: articulated, 5 axles, every output')
    parser.add_argument('--sweep', default='1000,2000,5000,8000,12000')
    parser.add_argument('--sweep-seconds', type=float, default=4.0)
    parser.add_argument('--plant', type=float, metavar='RATE')
    parser.add_argument('--json', type=pathlib.Path)
    parser.add_argument('--verbose', action='store_true', help="the node's log on stderr")
    parser.add_argument('--serve-observer', choices=('events', 'single'), help=argparse.SUPPRESS)
    parser.add_argument('--serve-bare', action='store_true', help=argparse.SUPPRESS)
    parser.add_argument('--serve-take', action='store_true', help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.serve_observer or args.serve_bare or args.serve_take:
        return serve_observer(args.serve_observer, args.serve_bare or args.serve_take,
                              args.articulated, args.serve_take)
    if args.plant:
        results = measure_plant(args.plant, args.seconds)
    else:
        results = measure_node(args)
    if args.json:
        args.json.write_text(json.dumps(results, indent=2))
    return 0


def measure_node(args) -> dict:
    """The observer (or bare) node in a child process, driven from this one."""
    isolated_ros()
    serve = {'bare': ['--serve-bare'], 'take': ['--serve-take']}.get(
        args.node, ['--serve-observer', args.executor])
    serve += ['--articulated'] if args.articulated else []
    child = subprocess.Popen([sys.executable, __file__, *serve], cwd=REPO,
                             stderr=None if args.verbose else subprocess.DEVNULL)
    context = Context()
    rclpy.init(context=context)
    from rclpy.experimental import EventsExecutor
    executor = EventsExecutor(context=context)
    driver = Driver(context, args.articulated)
    if args.articulated:     # the warm-up, the repeats and the sweep, then from the start
        driver.drive = articulated_drive(args.warm_up + args.seconds * args.repeats + 0.5)
    executor.add_node(driver)
    results = {'executor': args.executor, 'node': args.node,
               'vehicle': 'articulated' if args.articulated else 'front_axle'}
    try:
        deadline = time.monotonic() + 30.0
        while (driver.deflections.get_subscription_count() == 0
               or driver.twist.get_subscription_count() == 0) and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        run(executor, driver, args.rate, args.warm_up)  # warm-up
        results.update(measure(executor, driver, child.pid, args))
        results.update(sweep(executor, driver, args))
    finally:
        child.send_signal(2)
        child.wait(10)
        executor.shutdown()
        driver.destroy_node()
        rclpy.try_shutdown(context=context)
    return results


if __name__ == '__main__':
    sys.exit(main())
