"""Benchmark of the observer node under a flood: its memory and its /diagnostics, second by
second.

Run from the repository root::

    .venv/bin/python -m bench.probes.observer_flood [--rate 15000] [--seconds 60] [--steady 10]
        [--observer FILE] [--json FILE]

An ``observer`` runs in its own process. A talker in this process publishes
``/suspension/deflections`` (a drive's worth of plausible samples, stamped 1/rate apart: the
bytes serialized once, the stamp and values patched in) and ``/vehicle/twist`` at 100 Hz:
first at 1 kHz for ``--steady`` s (the steady state), then at ``--rate`` for ``--seconds`` s
(the flood), then 1 kHz again for 5 s. Every second: the observer's resident memory
(``/proc/<pid>/status`` VmRSS), the ``/diagnostics`` messages that came in that second, and
what the input status said (received, published, missed); and the longest wait for a
``/diagnostics`` during the flood. ``--observer FILE`` runs another
version of the node's module (e.g. from git history) to compare. The machine is shared (other
work may run): figures vary between runs.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import pathlib
import struct
import subprocess
import sys
import tempfile
import threading
import time

REPO = pathlib.Path(__file__).resolve().parents[2]
os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
_STAMP = struct.Struct('<iI')
_T0_NS = 1_700_000_000 * 10**9


def rss_kb(pid: int) -> int:
    with open(f'/proc/{pid}/status') as f:
        for line in f:
            if line.startswith('VmRSS:'):
                return int(line.split()[1])
    return 0


class Talker:
    """Deflections at a rate that can change, a twist at 100 Hz of stamps (see module)."""

    def __init__(self, node) -> None:
        from geometry_msgs.msg import TwistStamped
        from rclpy.serialization import serialize_message
        from sensor_msgs.msg import JointState

        from road_force_estimator.ros.messages import (
            deflections_msg, reliable_qos, sensor_qos, twist_msg)
        self.defl = node.create_publisher(JointState, '/suspension/deflections',
                                          sensor_qos(1000))
        self.twist = node.create_publisher(TwistStamped, '/vehicle/twist', reliable_qos())
        self.defl_bytes = bytearray(serialize_message(deflections_msg(_T0_NS, (0.0, 0.0), 0.0)))
        self.twist_msg = twist_msg
        # the three positions: the float64s after name[] (found by value: 0.125, 0.25, 0.5)
        probe = bytes(serialize_message(deflections_msg(_T0_NS, (0.125, 0.25), 0.5)))
        self.pos_at = probe.index(struct.pack('<d', 0.125))
        self.rate = 1000.0
        self.sent = 0
        self.stopping = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        k, stamp, next_twist = 0, _T0_NS, _T0_NS
        t_next = time.monotonic()
        buf = self.defl_bytes
        while not self.stopping.is_set():
            rate = self.rate
            step_ns = int(1e9 / rate)
            if stamp >= next_twist:
                self.twist.publish(self.twist_msg(stamp, 20.0))
                next_twist += 10_000_000
            x = 20.0 * (stamp - _T0_NS) * 1e-9
            _STAMP.pack_into(buf, 4, stamp // 10**9, stamp % 10**9)
            struct.pack_into('<ddd', buf, self.pos_at, 1e-3 * math.sin(x), 1e-3 * math.cos(x),
                             1e-4 * math.sin(0.3 * x))
            self.defl.publish(bytes(buf))
            self.sent += 1
            k += 1
            stamp += step_ns
            t_next += 1.0 / rate
            left = t_next - time.monotonic()
            if left > 0.0005:
                time.sleep(left)
            elif left < -0.5:                 # behind by far: keep the rate from now
                t_next = time.monotonic()


def main(argv=None) -> int:
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.context import Context
    from rclpy.experimental import EventsExecutor
    from rclpy.node import Node

    from road_force_estimator.ros.messages import reliable_qos
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--rate', type=float, default=15000.0)
    p.add_argument('--seconds', type=float, default=60.0)
    p.add_argument('--steady', type=float, default=10.0)
    p.add_argument('--observer', metavar='FILE')
    p.add_argument('--json', metavar='FILE')
    args = p.parse_args(argv)
    context = Context()
    rclpy.init(context=context)
    env = dict(os.environ, PYTHONUNBUFFERED='1')
    command = [args.observer] if args.observer else ['-m', 'road_force_estimator.ros.observer']
    log = tempfile.TemporaryFile('w+')
    observer = subprocess.Popen([sys.executable, *command], cwd=REPO, env=env, stderr=log)
    node = Node('flood_talker', context=context)
    diags: list[tuple[float, dict]] = []

    def on_diag(m) -> None:
        for st in m.status:
            if st.name == 'observer: input':
                diags.append((time.monotonic(), {v.key: v.value for v in st.values}))

    node.create_subscription(DiagnosticArray, '/diagnostics', on_diag, reliable_qos(1000))
    talker = Talker(node)
    executor = EventsExecutor(context=context)
    executor.add_node(node)
    seconds = []
    try:
        deadline = time.monotonic() + 60.0
        while not diags and time.monotonic() < deadline:   # the observer is up
            executor.spin_once(timeout_sec=0.05)
        talker.thread.start()
        phases = [(args.steady, 1000.0, 'steady'), (args.seconds, args.rate, 'flood'),
                  (5.0, 1000.0, 'after')]
        for length, rate, phase in phases:
            talker.rate = rate
            if phase == 'flood':
                flood_from = time.monotonic()
            if phase == 'after':
                flood_to = time.monotonic()
            end = time.monotonic() + length
            while time.monotonic() < end:
                second_end = time.monotonic() + 1.0
                n0, s0 = len(diags), talker.sent
                while time.monotonic() < second_end:
                    executor.spin_once(timeout_sec=0.02)
                last = diags[-1][1] if len(diags) > n0 else {}
                seconds.append({'phase': phase, 'rss_kb': rss_kb(observer.pid),
                                'diagnostics': len(diags) - n0, 'sent': talker.sent - s0,
                                'received': int(last.get('received', 0) or 0),
                                'published': int(last.get('published', 0) or 0),
                                'missed': int(last.get('missed', 0) or 0)})
                print(json.dumps(seconds[-1]), flush=True)
    finally:
        talker.stopping.set()
        observer.terminate()
        observer.wait(30)
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        log.close()
    steady = [s['rss_kb'] for s in seconds if s['phase'] == 'steady'][-3:]
    # the longest wait for a /diagnostics during the flood (s): from its start, between two,
    # and to its end
    times = [flood_from] + [t for t, _ in diags if flood_from <= t <= flood_to] + [flood_to]
    max_gap = max(b - a for a, b in zip(times, times[1:]))
    flood = [s for s in seconds if s['phase'] == 'flood']
    summary = {'rate_hz': args.rate, 'steady_rss_mb': max(steady) / 1024 if steady else None,
               'flood_max_rss_mb': max(s['rss_kb'] for s in flood) / 1024 if flood else None,
               'flood_seconds_without_diagnostics': sum(s['diagnostics'] == 0 for s in flood),
               'flood_longest_wait_for_diagnostics_s': round(max_gap, 3),
               'flood_diagnostics': sum(s['diagnostics'] for s in flood),
               'flood_published': sum(s['published'] for s in flood),
               'flood_sent': sum(s['sent'] for s in flood)}
    print(json.dumps(summary))
    if args.json:
        pathlib.Path(args.json).write_text(json.dumps({'summary': summary,
                                                       'seconds': seconds}, indent=1) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
