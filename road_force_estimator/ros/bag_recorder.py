"""``bag_recorder`` node: records topics, as received (serialized), to a rosbag2 MCAP bag.

Parameters (node-local): ``topics`` (default: every topic of INTERFACES.md) and ``output`` (the
bag folder; default ``rosbag2_<date>-<time>`` as ``ros2 bag record`` names it; an existing
folder is refused, never overwritten). Messages are taken raw (CDR bytes, no deserialization)
and written through :class:`road_force_estimator.bagio.BagWriter` with their receive time
(node clock, ns).

QoS: the topics of INTERFACES.md with the QoS their publishers use (sensor-data best effort for
the sensor streams, reliable for the others; deep queues so that bursts are not lost); a topic
not in INTERFACES.md is subscribed once a publisher appears, with its type and its publishers'
reliability. SIGINT and SIGTERM stop the recording: what is already waiting in the
subscriptions' queues is taken and written, then the bag is closed.
"""
from __future__ import annotations

from datetime import datetime
import importlib
import os
import sys

from rclpy.node import Node
from rclpy.qos import ReliabilityPolicy

from road_force_estimator.bagio import BagWriteError, BagWriter
from road_force_estimator.interfaces import TOPIC_TYPES
from road_force_estimator.ros.messages import reliable_qos, sensor_qos, topic_qos
from road_force_estimator.ros.node_runner import run_node
from road_force_estimator.ros.ros_parameters import ParameterError, ParameterGuard, local_spec

QUEUE_DEPTH = 1000  # messages per topic held between two callbacks (1 s at 1 kHz)
SPECS = (
    local_spec('topics', 'string_list', sorted(TOPIC_TYPES), '',
               'topics to record (default: every topic of INTERFACES.md)'),
    local_spec('output', 'string', '', '',
               'bag folder to create; empty = rosbag2_<date>-<time> in the working directory'),
)


def message_class(msgtype: str):
    """The Python class of ``'pkg/msg/Name'``."""
    package, _, name = msgtype.split('/')
    return getattr(importlib.import_module(f'{package}.msg'), name)


class BagRecorder(Node):
    """Subscribes raw to ``topics`` and writes every message received into ``output``."""

    def __init__(self, **kwargs):
        super().__init__('bag_recorder', **kwargs)
        self.params = ParameterGuard(self, SPECS, dict, read_only=True)
        try:
            topics = list(dict.fromkeys(self.resolve_topic_name(t) for t in
                                        self.params.values['topics']))
        except Exception as exc:  # rclpy's name validation errors
            raise ParameterError(f'bag_recorder: refused topics = '
                                 f'{list(self.params.values["topics"])}: {exc}') from None
        output = self.params.values['output'] or datetime.now().strftime(
            'rosbag2_%Y_%m_%d-%H_%M_%S')
        if os.path.exists(output):
            raise ParameterError(f'bag_recorder: refused output = {output!r}: it exists '
                                 f'(a bag is never overwritten)')
        self.output = output
        self.writer = BagWriter(output)
        try:
            self.writer.open()
        except (BagWriteError, OSError) as exc:
            raise ParameterError(f'bag_recorder: refused output = {output!r}: {exc}') from None
        self.counts = {topic: 0 for topic in topics}
        self.waiting = [t for t in topics if t not in TOPIC_TYPES]
        for topic in topics:
            if topic in TOPIC_TYPES:
                self.record(topic, TOPIC_TYPES[topic], topic_qos(topic, QUEUE_DEPTH))
        self.discovery_timer = self.create_timer(0.5, self.discovery_callback)
        self.get_logger().info(f'recording {len(topics)} topics to {output}')

    def record(self, topic: str, msgtype: str, qos) -> None:
        best_effort = qos.reliability == ReliabilityPolicy.BEST_EFFORT
        self.writer.add_topic(topic, msgtype, qos='sensor_data' if best_effort else 'reliable')

        def callback(data: bytes, topic=topic) -> None:
            if self.writer is not None:
                self.writer.write_raw(topic, self.get_clock().now().nanoseconds, data)
                self.counts[topic] += 1

        self.create_subscription(message_class(msgtype), topic, callback, qos, raw=True)

    def discovery_callback(self) -> None:
        """Subscribe to the topics outside INTERFACES.md once their type is known."""
        if not self.waiting:
            self.discovery_timer.cancel()
            return
        types = dict(self.get_topic_names_and_types())
        for topic in list(self.waiting):
            if topic in types and types[topic]:
                infos = self.get_publishers_info_by_topic(topic)
                best_effort = any(i.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT
                                  for i in infos)
                qos = sensor_qos(QUEUE_DEPTH) if best_effort else reliable_qos(QUEUE_DEPTH)
                self.waiting.remove(topic)
                try:
                    self.record(topic, types[topic][0], qos)
                except (BagWriteError, ImportError, AttributeError, ValueError) as exc:
                    self.get_logger().error(f'not recording {topic} ({types[topic][0]}): {exc}')

    def close(self) -> None:
        """Flush and close the bag (idempotent)."""
        if self.writer is not None:
            self.writer.close()
            self.writer = None
            total = sum(self.counts.values())
            self.get_logger().info(f'closed {self.output}: {total} messages')


def drain(executor, node: BagRecorder, quiet_s: float = 0.2) -> None:
    """Take what is already queued: spin until no message arrives for ``quiet_s``."""
    while True:
        before = sum(node.counts.values())
        executor.spin_once(timeout_sec=quiet_s)
        if sum(node.counts.values()) == before:
            return


def main(args=None) -> int:
    # On SIGINT/SIGTERM: drain the queues and close the bag while the context is still valid.
    return run_node('bag_recorder', __doc__.splitlines()[0], SPECS, args, BagRecorder,
                    finish=drain, cleanup=BagRecorder.close)


if __name__ == '__main__':
    sys.exit(main())
