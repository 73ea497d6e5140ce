"""Harness of the launch-free node tests: collect messages, spin nodes, run a node's main."""
from __future__ import annotations

import os
import pathlib
import signal
import subprocess
import sys

from rclpy.node import Node

from road_force_estimator.ros.bag_recorder import message_class
from road_force_estimator.interfaces import TOPIC_TYPES
from road_force_estimator.ros.messages import stamp_to_ns, topic_qos

try:  # the executor the nodes' main() use
    from rclpy.experimental import EventsExecutor as Executor
except ImportError:  # pragma: no cover
    from rclpy.executors import SingleThreadedExecutor as Executor

REPO = pathlib.Path(__file__).resolve().parents[1]


class Collector(Node):
    """Subscribes to ``topics`` (types and QoS of INTERFACES.md, deep queues) and keeps all."""

    def __init__(self, context, topics, name: str = 'collector'):
        super().__init__(name, context=context)
        self.messages: dict[str, list] = {}
        for topic in topics:
            self.messages[topic] = []
            self.create_subscription(message_class(TOPIC_TYPES[topic]), topic,
                                     self.messages[topic].append, topic_qos(topic, 10000))

    def count(self, topic: str) -> int:
        return len(self.messages[topic])

    def stamps(self, topic: str) -> list[int]:
        return [stamp_to_ns(m.header.stamp) for m in self.messages[topic]]


def make_executor(context, *nodes):
    executor = Executor(context=context)
    for node in nodes:
        executor.add_node(node)
    return executor


def close(executor, *nodes) -> None:
    executor.shutdown()
    for node in nodes:
        node.destroy_node()


def run_main(module: str, *args: str, **popen) -> subprocess.Popen:
    """Start ``python -m road_force_estimator.ros.<module> *args`` (same ROS domain as tests)."""
    env = dict(os.environ)
    env.setdefault('PYTHONUNBUFFERED', '1')
    return subprocess.Popen([sys.executable, '-m', f'road_force_estimator.ros.{module}', *args],
                            cwd=popen.pop('cwd', REPO), env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, **popen)


def finish(process: subprocess.Popen, timeout_s: float = 60.0) -> tuple[int, str, str]:
    """Wait for ``process``; (exit code, stdout, stderr). Killed (and failing) on timeout."""
    try:
        out, err = process.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        process.send_signal(signal.SIGUSR1)   # our nodes print every thread's stack on it
        try:
            out, err = process.communicate(timeout=5.0)
        except subprocess.TimeoutExpired:
            process.kill()
            out, err = process.communicate()
        raise AssertionError(f'process did not exit within {timeout_s} s: {err[-6000:]}')
    return process.returncode, out, err


def recorder_received(collector, topics) -> dict[str, int]:
    """What the bag recorder's latest /diagnostics (in ``collector``) says it received, per
    topic of ``topics``."""
    counts: dict[str, int] = {}
    for msg in collector.messages['/diagnostics']:
        for status in msg.status:
            values = {v.key: v.value for v in status.values}
            if status.name == 'bag_recorder':
                counts = {t: int(values.get(f'{t}.received', '0')) for t in topics}
    return counts
