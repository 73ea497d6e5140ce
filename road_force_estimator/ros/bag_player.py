"""``bag_player`` node: plays a rosbag2 MCAP bag into ROS 2 at its recorded timing.

    bag_player BAG [--rate R] [--loop] [--start-offset S] [--topics T...]
               [--remap FROM:=TO...] [--clock [HZ]] [--delay S] [--wait S]
               [--wait-for NODE...] [--wait-count N] [--ros-args ...]

What ``ros2 bag play`` does on a full ROS install, for a machine with rclpy alone (INTERFACES.md,
"Executables"). Any writer's bag (ours, ``rosbags``', the ``mcap`` library's with zstd or lz4
chunks) is read by :mod:`road_force_estimator.bagio.playback`, streaming. Each message is
published as its serialized bytes (no deserialize-serialize round trip) at its scheduled wall
time, ``start + (log_time - first log_time) / rate`` (a sleep until that time, never a fixed
period), each topic with the QoS recorded in the bag (INTERFACES.md's kind when the bag has
none; the queue at least :data:`MIN_DEPTH` deep, so that a burst is not dropped on our side).
A type that cannot be imported is skipped with one warning naming the topic.

Before it starts it waits, at most ``--wait`` seconds (default 30; 0 = not at all), for the
subscribers that matter (:mod:`.start_gate`): on each played topic the nodes of
``--wait-for NODE...`` (default: the package's node that reads it, ``observer`` for the
measurements and ``plant_simulator`` for ``/lpa/*``; any one subscriber on a topic no node of
the package reads), or with ``--wait-count N`` N subscribers on each, then ``--delay``.
``/diagnostics`` (status ``bag_player: playback``) says the stamp of the first message played
on each of those topics (``first_stamp_ns:<topic>``), so that a late observer counts what it
missed. ``--clock [HZ]`` publishes ``/clock`` (rosgraph_msgs/Clock, the bag's time; HZ default
100, at most :data:`MAX_CLOCK_HZ`; a tick that falls late is not published in a burst with the
others: the latest due is) so that nodes with ``use_sim_time`` follow the bag. ``--loop``: each
pass starts one mean message spacing after the last message of the one before
(:data:`LOOP_SINGLE_S` for a bag of one message), in bounded memory. The files of a split bag
play in time order; a file that ``metadata.yaml`` lists but that is missing is one warning (as
``estimate_bag`` gives), and so is a recorded QoS depth beyond :data:`MAX_DEPTH`; ``--remap``
to a name that is not a valid topic name is a bad command line. At the end of the bag (of the
last loop) it waits for the subscribers' acknowledgements and exits 0; SIGINT/SIGTERM stop it
cleanly (exit 0). A bag cut short plays up to the break and says so. Bad input (no such bag,
not MCAP, ``--rate 0``): one line on stderr, exit 1 (2 for a bad command line).
"""
from __future__ import annotations

import argparse
from collections import deque
import importlib
import math
import queue
import struct
import sys
import threading
import time

from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from diagnostic_msgs.msg import DiagnosticArray

from road_force_estimator.bagio.playback import PlaybackError, open_playback
from road_force_estimator.estimation import diagnostics
from road_force_estimator.interfaces import DIAGNOSTICS, READERS
from road_force_estimator.ros.messages import diagnostic_status, reliable_qos
from road_force_estimator.ros.node_runner import run_node
from road_force_estimator.ros.start_gate import SETTLE_S, SubscriberGate, first_stamp_values

PROG = 'bag_player'
#: Queue depth of every played topic at least (messages), whatever the bag recorded.
MIN_DEPTH = 1000
#: ... and at most (a recorded depth beyond it, e.g. 1e11 in a hand-edited metadata.yaml,
#: is played with this one, said so): DDS allocates the history it is given.
MAX_DEPTH = 100_000
#: The fastest /clock (Hz): a publication takes tens of microseconds, a faster clock would
#: slow the playback down (1 MHz played 7.5 times slower than asked) or stop it.
MAX_CLOCK_HZ = 10_000.0
#: Lateness values kept for bench/probes/bag_player_timing.py (the newest; older ones dropped, so
#: that --loop runs for ever in bounded memory).
LATENESS_KEPT = 20_000
#: A loop of a bag lasts its span plus its mean spacing between messages (bag time), so the
#: first message follows the last one as the others follow each other; a bag of one
#: message (no spacing) plays it every LOOP_SINGLE_S of bag time.
LOOP_SINGLE_S = 1.0
#: Messages read ahead of the schedule by the reading thread (bounds the memory).
READ_AHEAD = 20000
CLOCK_TOPIC = '/clock'


def read_ahead(messages, stopping: threading.Event, size: int = READ_AHEAD):
    """``messages`` (an iterator) read by a thread of its own, ``size`` items ahead.

    Reading and decompressing a chunk takes tens of milliseconds: done here, it never delays
    the publications, which wait only for their scheduled time.
    """
    buffer: queue.Queue = queue.Queue(maxsize=size)
    end = object()

    def put(item) -> bool:
        while not stopping.is_set():
            try:
                buffer.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def fill() -> None:
        try:
            for item in messages:
                if not put(item):
                    return
        except Exception as exc:  # raised again in the consumer
            put(exc)
        put(end)

    threading.Thread(target=fill, name='bag_reader', daemon=True).start()
    while True:
        try:
            item = buffer.get(timeout=0.1)
        except queue.Empty:          # the reader stops without a last item when stopped
            if stopping.is_set():
                return
            continue
        if item is end:
            return
        if isinstance(item, Exception):
            raise item
        yield item


class UsageError(Exception):
    """A bad command line (exit status 2)."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, no usage dump
        raise UsageError(message)


def _positive(text: str) -> float:
    value = float(text)
    if not (math.isfinite(value) and value > 0.0):
        raise argparse.ArgumentTypeError(f'{text} must be a number > 0')
    return value


def _non_negative(text: str) -> float:
    value = float(text)
    if not (math.isfinite(value) and value >= 0.0):
        raise argparse.ArgumentTypeError(f'{text} must be a number >= 0')
    return value


def _remap(text: str) -> tuple[str, str]:
    from rclpy.exceptions import InvalidTopicNameException
    from rclpy.validate_full_topic_name import validate_full_topic_name

    old, sep, new = text.partition(':=')
    if not sep or not old.startswith('/') or not new.startswith('/'):
        raise argparse.ArgumentTypeError(f'{text!r} is not FROM:=TO (two absolute topic names)')
    try:
        validate_full_topic_name(new)
    except InvalidTopicNameException as exc:
        reason = str(exc).splitlines()[0].split(': ', 1)[-1].rstrip(':')
        raise argparse.ArgumentTypeError(f'{text!r}: {new!r} is not a valid topic name '
                                         f'({reason})') from None
    return old, new


def _clock(text: str) -> float:
    value = _positive(text)
    if value > MAX_CLOCK_HZ:
        raise argparse.ArgumentTypeError(f'{text} Hz: at most {MAX_CLOCK_HZ:g} Hz (a faster '
                                         '/clock would slow the playback down)')
    return value


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``bag_player`` (the part before ``--ros-args``)."""
    p = _Parser(prog=PROG, description=__doc__.splitlines()[0].replace('``', ''))
    p.add_argument('bag', metavar='BAG', help='bag folder (metadata.yaml and .mcap files) or '
                                             'one .mcap file')
    p.add_argument('--rate', type=_positive, default=1.0, metavar='R',
                   help='playback speed: bag seconds per wall-clock second (default 1)')
    p.add_argument('--loop', action='store_true', help='play again from the start, forever')
    p.add_argument('--start-offset', type=_non_negative, default=0.0, metavar='S',
                   help='start S seconds after the first message of the bag')
    p.add_argument('--topics', nargs='+', metavar='T', help='play only these topics')
    p.add_argument('--remap', nargs='+', type=_remap, default=[], metavar='FROM:=TO',
                   help='publish topic FROM of the bag on TO')
    p.add_argument('--clock', nargs='?', type=_clock, const=100.0, default=None,
                   metavar='HZ', help='publish /clock at HZ (default 100, at most '
                                      f'{MAX_CLOCK_HZ:g}) with the bag time')
    p.add_argument('--delay', type=_non_negative, default=0.0, metavar='S',
                   help='wait S seconds before playing')
    p.add_argument('--wait', type=_non_negative, default=30.0, metavar='S',
                   help='wait at most S seconds for the subscribers that matter (default 30)')
    p.add_argument('--wait-for', nargs='+', metavar='NODE',
                   help='nodes that must subscribe to every played topic first (default: the '
                        "package's reader of each topic: observer for the measurements, "
                        'plant_simulator for /lpa/*; any subscriber on the others)')
    p.add_argument('--wait-count', type=int, default=0, metavar='N',
                   help='instead: wait until every played topic has N subscribers')
    return p


def message_class(msgtype: str):
    """The Python class of ``'pkg/msg/Name'``."""
    package, _, name = msgtype.split('/')
    return getattr(importlib.import_module(f'{package}.msg'), name)


def qos_profile(qos) -> QoSProfile:
    """rclpy's profile of a :class:`bagio.playback.TopicQoS` (depth between
    :data:`MIN_DEPTH` and :data:`MAX_DEPTH`)."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=min(max(qos.depth, MIN_DEPTH), MAX_DEPTH),
        reliability=(ReliabilityPolicy.BEST_EFFORT if qos.reliability == 'best_effort'
                     else ReliabilityPolicy.RELIABLE),
        durability=(DurabilityPolicy.TRANSIENT_LOCAL if qos.durability == 'transient_local'
                    else DurabilityPolicy.VOLATILE))


class BagPlayer(Node):
    """Publishes a :class:`bagio.playback.Playback` from a thread of its own.

    :attr:`done` turns true at the end (or on :meth:`stop`); :attr:`published` counts the
    messages published per output topic; :attr:`lateness_s` (and :attr:`clock_lateness_s`)
    hold, per message (per /clock tick), how late it was published against its schedule (s),
    and :attr:`schedule` the schedule's origin, for bench/probes/bag_player_timing.py.
    """

    def __init__(self, playback, options, **kwargs):
        super().__init__(PROG, **kwargs)
        self.playback = playback
        self.options = options
        self.remap = dict(options.remap)
        self.stopping = threading.Event()
        self.done = False
        self.published: dict[str, int] = {}
        self.lateness_s: deque[float] = deque(maxlen=LATENESS_KEPT)
        self.clock_lateness_s: deque[float] = deque(maxlen=LATENESS_KEPT)
        self.schedule: tuple[float, int] | None = None  # (monotonic start, first log time ns)
        self.clock_ticks = 0
        self.pubs: dict[str, object] = {}
        self.skipped: set[str] = set()
        self.first_stamps: dict[str, int] = {}    # first header stamp played, per topic (ns)
        self.reported_wall = time.monotonic()
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, DIAGNOSTICS,
                                                     reliable_qos(10))
        self.clock_pub = None
        if options.clock is not None:
            from rosgraph_msgs.msg import Clock
            self.clock_msg = Clock
            self.clock_pub = self.create_publisher(Clock, CLOCK_TOPIC, QoSProfile(
                depth=1, reliability=ReliabilityPolicy.BEST_EFFORT))
        for issue in playback.issues:       # a file missing, files out of order: as estimate_bag
            self.get_logger().warning(f'{playback.path}: {issue}')
        wanted = options.topics or list(playback.topics)
        missing = [t for t in wanted if t not in playback.topics]
        if missing and playback.topics and options.topics:
            self.get_logger().warning(f'not in the bag: {", ".join(missing)}')
        for name in wanted:
            if name in playback.topics:
                self.publisher_for(name)
        self.thread = threading.Thread(target=self.run, name='bag_player', daemon=True)
        self.thread.start()

    def publisher_for(self, topic: str):
        """The publisher of a bag topic (created on first use), None for a skipped one."""
        if topic in self.pubs or topic in self.skipped:
            return self.pubs.get(topic)
        info = self.playback.topics[topic]
        try:
            if info.encoding != 'cdr':
                raise ValueError(f'{info.encoding!r} messages (CDR only)')
            cls = message_class(info.type)
        except (ImportError, AttributeError, ValueError) as exc:
            self.skipped.add(topic)
            self.get_logger().warning(f'skipping {topic}: cannot publish type '
                                      f'{info.type or "(none)"!r} ({exc})')
            return None
        out = self.remap.get(topic, topic)
        if info.qos.depth > MAX_DEPTH:
            self.get_logger().warning(f'{topic}: the recorded QoS depth {info.qos.depth} is '
                                      f'more than {MAX_DEPTH}: played with {MAX_DEPTH}')
        self.pubs[topic] = self.create_publisher(cls, out, qos_profile(info.qos))
        self.published.setdefault(out, 0)
        return self.pubs[topic]

    # ----------------------------------------------------------------------------------------

    def run(self) -> None:
        try:
            if self.wait_for_subscribers() and self.sleep(self.options.delay):
                self.play_all()
        except Exception as exc:  # never a traceback from the playing thread
            self.get_logger().error(f'playback stopped: {type(exc).__name__}: {exc}')
        finally:
            self.done = True

    def sleep(self, seconds: float) -> bool:
        """Sleep unless stopped; False when stopped."""
        return not self.stopping.wait(seconds) if seconds > 0 else not self.stopping.is_set()

    def wait_for_subscribers(self) -> bool:
        pubs = dict(self.pubs)
        if not pubs or self.options.wait <= 0:
            return not self.stopping.is_set()
        outs = [self.remap.get(t, t) for t in pubs]
        given = tuple(self.options.wait_for or ())
        gate = SubscriberGate(self, {t: given or ((READERS[t],) if t in READERS else ())
                                     for t in outs}, max(self.options.wait_count, 0))
        self.get_logger().info(f'waiting up to {self.options.wait:g} s for {gate.describe()}')
        deadline = time.monotonic() + self.options.wait
        while True:
            missing = gate.missing()
            if not missing:
                return self.sleep(SETTLE_S)
            if time.monotonic() >= deadline:
                self.get_logger().warning(f'no {", ".join(missing)} after '
                                          f'{self.options.wait:g} s: playing anyway')
                return not self.stopping.is_set()
            if not self.sleep(0.02):
                return False

    def note_first(self, out: str, data: bytes) -> None:
        """Keep the header stamp of the first message played on a topic a package node reads
        (its CDR: encapsulation, then the header's sec and nanosec), and say it at once."""
        if out in self.first_stamps or out not in READERS or len(data) < 12:
            return
        sec, nanosec = struct.unpack('<iI' if data[1] == 1 else '>iI', data[4:12])
        self.first_stamps[out] = sec * 1_000_000_000 + nanosec
        self.report()

    def report(self) -> None:
        """``/diagnostics``: what was played, and the first stamps (see the module notes)."""
        values = {f'published:{t}': n for t, n in self.published.items()}
        values.update(first_stamp_values(self.first_stamps))
        msg = DiagnosticArray(status=[diagnostic_status(diagnostics.status(
            'bag_player: playback', self.get_name(), 'done' if self.done else 'playing',
            values))])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.diagnostics_pub.publish(msg)
        self.reported_wall = time.monotonic()

    def play_all(self) -> None:
        opts = self.options
        loops = 0
        origin = None          # (wall time, bag time ns) the next pass is scheduled from
        while not self.stopping.is_set():
            count, origin = self.play_once(origin)
            loops += 1
            broken = self.playback.broken
            if broken:
                self.get_logger().warning(broken)
            if count == 0:
                self.get_logger().warning(f'{self.playback.path}: no message to play')
                return
            if not opts.loop or broken:
                break
        self.report()
        total = sum(self.published.values())
        self.get_logger().info(f'played {total} messages from {self.playback.path}'
                               + (f' ({loops} loops)' if loops > 1 else ''))
        for pub in self.pubs.values():
            if pub.qos_profile.reliability == ReliabilityPolicy.RELIABLE:
                pub.wait_for_all_acked(Duration(seconds=2.0))

    def play_once(self, origin=None) -> tuple[int, tuple[float, int] | None]:
        """One pass over the bag on its schedule, from ``origin`` (wall time, bag time ns:
        where the previous pass said the next one starts) or now; the number of messages
        published, and the origin of a next pass (:data:`LOOP_SINGLE_S`)."""
        opts = self.options
        start_wall = first_ns = last_ns = None
        period_s = 1.0 / opts.clock if opts.clock else math.inf
        next_clock = math.inf
        count = 0
        messages = self.playback.messages(opts.topics,
                                          start_offset_ns=round(opts.start_offset * 1e9))
        for t_ns, topic, _, data in read_ahead(messages, self.stopping):
            if topic not in self.playback.topics:
                continue
            pub = self.publisher_for(topic)
            if pub is None:
                continue
            if start_wall is None:
                start_wall, first_ns = time.monotonic(), t_ns
                if origin is not None:
                    start_wall = max(origin[0], start_wall - 1.0)   # (a slow reader: late)
                self.schedule = (start_wall, first_ns)
                next_clock = start_wall if self.clock_pub else math.inf
            due = start_wall + (t_ns - first_ns) * 1e-9 / opts.rate
            if next_clock <= due:
                next_clock = self.tick_clock(next_clock, due, period_s, start_wall, first_ns)
                if next_clock is None:
                    return count, None
            if not self.wait_until(due):
                return count, None
            pub.publish(data)
            self.lateness_s.append(time.monotonic() - due)
            out = self.remap.get(topic, topic)
            self.published[out] += 1
            count += 1
            self.note_first(out, data)
            if time.monotonic() - self.reported_wall >= 1.0:
                self.report()
            last_ns = t_ns
        if start_wall is None:
            return count, None
        span = last_ns - first_ns
        gap_ns = span / (count - 1) if count > 1 and span > 0 else LOOP_SINGLE_S * 1e9
        return count, (start_wall + (span + gap_ns) * 1e-9 / opts.rate, first_ns)

    def tick_clock(self, next_clock: float, due: float, period_s: float, start_wall: float,
                   first_ns: int) -> float | None:
        """Publish the /clock ticks due before the message due at ``due`` (monotonic s); the
        next tick's time, None when stopped. Ticks that are already late are not published
        one by one: the latest of them is, and the schedule goes on from there."""
        opts = self.options
        while next_clock <= due:
            if not self.wait_until(next_clock):
                return None
            now = time.monotonic()
            if now - next_clock >= period_s:            # behind: skip to the latest tick due
                next_clock += math.floor((now - next_clock) / period_s) * period_s
            self.publish_clock(first_ns + (next_clock - start_wall) * opts.rate * 1e9)
            self.clock_lateness_s.append(time.monotonic() - next_clock)
            next_clock += period_s
        return next_clock

    def wait_until(self, wall: float) -> bool:
        """Sleep until the monotonic time ``wall``; False when stopped."""
        left = wall - time.monotonic()
        if left > 0.0:
            return not self.stopping.wait(left)
        return not self.stopping.is_set()

    def publish_clock(self, bag_ns: float) -> None:
        sec, nanosec = divmod(int(bag_ns), 1_000_000_000)
        msg = self.clock_msg()
        msg.clock.sec, msg.clock.nanosec = sec, nanosec
        self.clock_pub.publish(msg)
        self.clock_ticks += 1

    def stop(self) -> None:
        """Stop playing and wait for the thread (idempotent)."""
        self.stopping.set()
        if self.thread.is_alive():
            self.thread.join(timeout=5.0)


def main(args=None) -> int:
    argv = list(sys.argv if args is None else args)
    split = argv.index('--ros-args') if '--ros-args' in argv else len(argv)
    try:
        options = build_parser().parse_args(argv[1:split])
    except SystemExit as exc:  # --help
        return int(exc.code or 0)
    except UsageError as exc:
        print(f'{PROG}: error: {exc}', file=sys.stderr)
        return 2
    try:
        playback = open_playback(options.bag)
    except PlaybackError as exc:
        print(f'{PROG}: {exc}', file=sys.stderr)
        return 1
    return run_node(PROG, __doc__.splitlines()[0], (), [argv[0], *argv[split:]],
                    lambda: BagPlayer(playback, options), done=lambda node: node.done,
                    cleanup=BagPlayer.stop)


if __name__ == '__main__':
    sys.exit(main())
