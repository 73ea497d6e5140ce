"""``bag_recorder`` node: records topics, as received (serialized), to a rosbag2 MCAP bag.

Parameters (node-local): ``topics`` (default: every topic of INTERFACES.md) and ``output`` (the
bag folder; default ``rosbag2_<date>-<time>`` as ``ros2 bag record`` names it; an existing
folder is refused, never overwritten). Messages are taken raw (CDR bytes, no deserialization)
by a thread of their own (:class:`.take_loop.TakeLoop`: every queued message at once, with
its message info) and written through :class:`road_force_estimator.bagio.BagWriter` with
their receive time as log time (the node clock with ``use_sim_time``).

QoS: the topics of INTERFACES.md with the QoS their publishers use (sensor-data best effort for
the sensor streams, reliable for the others), :data:`QUEUE_DEPTH` deep; a topic not in
INTERFACES.md is subscribed once a publisher appears, with its type and its publishers'
reliability.

What a recording can lose, and what it does about it:

- a SIGKILL (or a power cut): at most the chunk being filled, and a chunk is closed by age,
  :data:`CHUNK_AGE_S`, as well as by size; the bag (no summary, no metadata.yaml, a
  ``.recording`` file left in it) is read from its start by the readers here and by the
  ``mcap`` library;
- SIGINT / SIGTERM: what was received before the signal, and what comes within
  :data:`GRACE_S` (on its way), is taken from the queues and written (within :data:`DRAIN_S`
  however fast the data come), then the bag is closed: summary, index, ``metadata.yaml``;
- a full disk: one error line; the bag is ended with what was written whole (the space held
  back, :data:`RESERVE_BYTES`, goes to its summary and ``metadata.yaml``) and the node exits
  with status 1;
- messages sent but not received (lost in the transport, or dropped from a queue when the
  recorder falls behind): counted per topic from the publishers' sequence numbers
  (:mod:`.sources`) and published on ``/diagnostics`` every second (``missed``), with what was
  received and written.
"""
from __future__ import annotations

from datetime import datetime
import errno
import importlib
import os
import sys
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.qos import ReliabilityPolicy

from road_force_estimator.bagio import BagWriteError, BagWriter
from road_force_estimator.estimation import diagnostics
from road_force_estimator.interfaces import DIAGNOSTICS, TOPIC_TYPES
from road_force_estimator.ros.messages import (
    bounded, diagnostic_status, reliable_qos, sensor_qos, topic_qos)
from road_force_estimator.ros.node_runner import run_node
from road_force_estimator.ros.ros_parameters import ParameterError, ParameterGuard, local_spec
from road_force_estimator.ros.sources import Sources
from road_force_estimator.ros.take_loop import TakeLoop

#: Messages per topic held by DDS between two takes (10 s at 1 kHz): a recorder that falls
#: behind a burst for a moment loses nothing.
QUEUE_DEPTH = 10_000
#: A chunk is closed once its first message is this old (s): what a SIGKILL can lose.
CHUNK_AGE_S = 0.5
#: At SIGINT / SIGTERM: what comes this long after the signal is still written (s: the
#: messages on their way, late on a loaded machine; a topic still flowing shows its first
#: later message at once and is done), and the longest time taken to empty the queues (s).
GRACE_S = 0.25
DRAIN_S = 0.5
#: Space held back for the end of the bag (bytes).
RESERVE_BYTES = 4 << 20
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
        self.writer = BagWriter(output, chunk_age_s=CHUNK_AGE_S, reserve_bytes=RESERVE_BYTES)
        try:
            self.writer.open()
        except (BagWriteError, OSError) as exc:
            raise ParameterError(f'bag_recorder: refused output = {output!r}: {exc}') from None
        self.lock = threading.Lock()            # the writer: the take thread, then the stop
        self.exit_status = 0
        self.failed = ''
        self.names: list[str] = []              # topic of each subscription of the loop
        self.counts: dict[str, int] = {topic: 0 for topic in topics}
        self.sources: dict[str, Sources] = {}
        self.sim_time = bool(self.get_parameter('use_sim_time').value)
        self.loop = TakeLoop(self.get_name(), self.context)
        self.waiting = [t for t in topics if t not in TOPIC_TYPES]
        for topic in topics:
            if topic in TOPIC_TYPES:
                self.record(topic, TOPIC_TYPES[topic], topic_qos(topic, QUEUE_DEPTH))
        self.loop.start(self.write_batch, idle=self.flush_due)
        self.discovery_timer = self.create_timer(0.5, self.discovery_callback)
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, DIAGNOSTICS,
                                                     reliable_qos(10))
        self.create_timer(1.0, self.diagnostics_callback)
        self.get_logger().info(f'recording {len(topics)} topics to {output}')

    def record(self, topic: str, msgtype: str, qos) -> None:
        best_effort = qos.reliability == ReliabilityPolicy.BEST_EFFORT
        with self.lock:
            self.writer.add_topic(topic, msgtype, qos='sensor_data' if best_effort else
                                  'reliable')
        self.sources[topic] = Sources()
        self.counts.setdefault(topic, 0)
        self.names.append(topic)
        self.loop.add(message_class(msgtype), topic, qos)

    # -- the take thread ------------------------------------------------------------------
    def write_batch(self, batch) -> None:
        """Write a round of messages (the take thread, or the drain at a stop)."""
        clock_ns = self.get_clock().now().nanoseconds if self.sim_time else None
        now = time.monotonic()
        with self.lock:
            if self.writer is None:
                return
            try:
                for m in batch:
                    topic = self.names[m.index]
                    stamp = clock_ns if clock_ns is not None else (m.received_ns
                                                                   or time.time_ns())
                    self.writer.write_raw(topic, stamp, m.data)
                    self.counts[topic] += 1
                    self.sources[topic].add(m.sequence, now)
            except OSError as err:
                self.write_failed(err)

    def flush_due(self) -> None:
        with self.lock:
            if self.writer is None:
                return
            try:
                self.writer.flush_due()
            except OSError as err:
                self.write_failed(err)

    def write_failed(self, err: OSError) -> None:
        """A write failed (out of space): end the bag with what it holds, one line, stop."""
        writer, self.writer = self.writer, None
        try:
            kept = writer.salvage()
        except BagWriteError as exc:
            kept = str(exc)
        reason = f'out of space ({err.strerror})' if err.errno in (
            errno.ENOSPC, errno.EDQUOT) else (err.strerror or str(err))
        self.failed = f'cannot write {self.output}: {reason}: recording stopped; {kept}'
        self.get_logger().error(self.failed)
        self.exit_status = 1
        self.loop.request_stop()

    # -- the executor's side ---------------------------------------------------------------
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

    def check_loop(self) -> None:
        """A take thread that died (a bug): said once, and the recording stops."""
        error = self.loop.error
        if error is not None and not self.failed:
            self.failed = bounded(f'the recording thread stopped: {type(error).__name__}: '
                                  f'{error}')
            self.get_logger().error(self.failed)
            self.exit_status = 1

    def diagnostics_callback(self) -> None:
        """The recording's status: messages received and missed per topic (totals)."""
        self.check_loop()
        values: dict[str, object] = {'output': self.output}
        missed = 0
        for topic in sorted(self.sources):
            src = self.sources[topic]
            values[f'{topic}.received'] = self.counts[topic]
            values[f'{topic}.missed'] = src.missed
            if len(src.sources) > 1:
                values[f'{topic}.sources'] = len(src.sources)
            missed += src.missed
        values['received'] = sum(self.counts.values())
        values['missed'] = missed
        if self.failed:
            message, level = self.failed, diagnostics.ERROR
        elif missed:
            message, level = f'{missed} messages missed', diagnostics.WARN
        else:
            message, level = 'recording', diagnostics.OK
        msg = DiagnosticArray(status=[diagnostic_status(diagnostics.status(
            'bag_recorder', self.get_name(), message, values, level=level))])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.diagnostics_pub.publish(msg)

    def stop(self) -> None:
        """Stop taking; write what was received before now and what comes within
        :data:`GRACE_S` (the messages on their way when the signal came): every topic read up
        to its first later message, or until nothing more comes (at most :data:`DRAIN_S`);
        close the bag (idempotent)."""
        self.loop.stop()
        self.check_loop()
        until = time.time_ns() + int(GRACE_S * 1e9)
        start = time.monotonic()
        done: set[int] = set()             # topics that showed a message after `until`
        while self.writer is not None and time.monotonic() - start < DRAIN_S:
            batch = self.loop.take_all(until_ns=until)
            self.write_batch([m for m in batch if m.received_ns <= until])
            done.update(m.index for m in batch if m.received_ns > until)
            if len(done) == len(self.names):
                break
            if not batch:
                if time.time_ns() > until:
                    break
                time.sleep(0.002)
        self.close()

    def close(self) -> None:
        """Flush and close the bag (idempotent)."""
        with self.lock:
            writer, self.writer = self.writer, None
        if writer is not None:
            try:
                writer.close()
            except BagWriteError as exc:
                self.failed = str(exc)
                self.exit_status = 1
                self.get_logger().error(self.failed)
                return
            total = sum(self.counts.values())
            missed = sum(s.missed for s in self.sources.values())
            self.get_logger().info(f'closed {self.output}: {total} messages'
                                   + (f' ({missed} missed on the way)' if missed else ''))

    def destroy_node(self):
        self.loop.destroy()
        super().destroy_node()


def main(args=None) -> int:
    # On SIGINT/SIGTERM: drain the queues and close the bag while the context is still valid.
    return run_node('bag_recorder', __doc__.splitlines()[0], SPECS, args, BagRecorder,
                    done=lambda node: node.exit_status != 0,
                    finish=lambda executor, node: node.stop(), cleanup=BagRecorder.close)


if __name__ == '__main__':
    sys.exit(main())
