"""Benchmark of bag_recorder: what a kill, a stop and a load cost a recording, in seconds.

Run from the repository root::

    .venv/bin/python -m bench.probes.recorder_loss [--rate 1000] [--runs 10] [--seconds 6]
        [--topics two|all] [--signals KILL,INT,TERM] [--load N] [--quiet-stop]
        [--recorder FILE] [--json FILE]

A talker in this process publishes ``--topics`` (``two``: ``/suspension/deflections`` and
``/vehicle/twist``; ``all``: the 19 topics of INTERFACES.md) at ``--rate`` each, every message
numbered (its header stamp, or the value of a Float64, carries its number; the bytes are
serialized once and the number patched in). ``bag_recorder`` runs in its own process; after
a random moment (1 s to ``--seconds``) it gets the signal, while the talker goes on for 0.5 s.
The bag is then read with the ``mcap`` library's stream reader, record by record (it needs no
summary: a killed recording has none).

Per run: ``lost_s``, the time between the signal and the publication of the first message sent
before the signal that is not in the bag (0 when none is missing); ``missing``, how many such
messages; ``stop_s`` (SIGINT, SIGTERM), the time from the signal to the recorder's exit;
``recorder_says_missed``, what the recorder itself counted as missed (from the publishers'
sequence numbers: its closing line and ``/diagnostics``). ``--load N`` runs N processes that
keep a core busy each meanwhile (loss under load: ``--signals INT --quiet-stop``: every
message sent should be in the bag). The machine is shared (other work may run): figures vary
between runs.
"""
from __future__ import annotations

import argparse
import json
import os
import pathlib
import random
import re
import signal
import struct
import subprocess
import sys
import tempfile
import threading
import time

REPO = pathlib.Path(__file__).resolve().parents[2]
os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

TWO = ('/suspension/deflections', '/vehicle/twist')
_STAMP = struct.Struct('<iI')       # header.stamp after the 4-byte CDR encapsulation header
_DOUBLE = struct.Struct('<d')


def _template(msgtype: str) -> tuple[bytes, bool]:
    """The CDR bytes of a default message of ``msgtype`` and whether it starts with a
    header (else it is a Float64 whose value carries the number)."""
    from rclpy.serialization import serialize_message

    from road_force_estimator.ros.bag_recorder import message_class
    cls = message_class(msgtype)
    msg = cls()
    if hasattr(msg, 'name') and hasattr(msg, 'position'):       # a JointState
        msg.name = ['left_suspension', 'right_suspension', 'roll']
        msg.position = [0.0, 0.0, 0.0]
    return bytes(serialize_message(msg)), hasattr(msg, 'header')


def number_of(data: bytes, headed: bool) -> int:
    """The number a talker message carries."""
    if headed:
        sec, nsec = _STAMP.unpack_from(data, 4)
        return sec * 1000 + nsec // 1_000_000
    return int(_DOUBLE.unpack_from(data, 4)[0])


class Talker:
    """Publishes every topic of ``topics`` ({name: type}) ``rate`` times a second from a
    thread, message k numbered k; :attr:`sent` holds each topic's publication times (ns,
    the system clock)."""

    def __init__(self, node, topics: dict[str, str], rate: float) -> None:
        from road_force_estimator.ros.bag_recorder import message_class
        from road_force_estimator.ros.messages import topic_qos
        self.node, self.rate = node, rate
        self.pubs = {t: node.create_publisher(message_class(m), t, topic_qos(t, 1000))
                     for t, m in topics.items()}
        self.templates = {t: _template(m) for t, m in topics.items()}
        self.sent: dict[str, list[int]] = {t: [] for t in topics}
        self.stopping = threading.Event()
        self.thread = None

    def matched(self) -> bool:
        return all(p.get_subscription_count() > 0 for p in self.pubs.values())

    def start(self) -> None:
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        period = 1.0 / self.rate
        start = time.monotonic()
        k = 0
        bufs = {t: bytearray(b) for t, (b, _) in self.templates.items()}
        while not self.stopping.is_set():
            due = start + k * period
            left = due - time.monotonic()
            if left > 0:
                time.sleep(left)
            for topic, pub in self.pubs.items():
                buf = bufs[topic]
                if self.templates[topic][1]:
                    _STAMP.pack_into(buf, 4, k // 1000, (k % 1000) * 1_000_000)
                else:
                    _DOUBLE.pack_into(buf, 4, float(k))
                self.sent[topic].append(time.time_ns())
                pub.publish(bytes(buf))
            k += 1

    def stop(self) -> None:
        self.stopping.set()
        if self.thread is not None:
            self.thread.join(timeout=5.0)


def bag_numbers(folder: pathlib.Path, templates: dict) -> tuple[dict[str, set[int]], str]:
    """The numbers of the talker's messages in the bag, per topic (the mcap library's
    streaming reader; a recording cut by a kill ends where it was cut), and how it ended."""
    from mcap.records import Channel, Message
    from mcap.stream_reader import StreamReader

    got: dict[str, set[int]] = {t: set() for t in templates}
    ending = 'complete'
    for path in sorted(folder.glob('*.mcap')):
        channels: dict[int, str] = {}
        with path.open('rb') as f:
            try:
                for record in StreamReader(f, validate_crcs=True).records:
                    if isinstance(record, Channel):
                        channels[record.id] = record.topic
                    elif isinstance(record, Message):
                        topic = channels.get(record.channel_id)
                        if topic in templates:
                            got[topic].add(number_of(record.data, templates[topic][1]))
            except Exception as exc:  # noqa: BLE001 - a cut file: what came before counts
                ending = f'cut ({type(exc).__name__})'
    return got, ending


def loss(talker: Talker, got: dict[str, set[int]], at_ns: int,
         per_topic: dict | None = None) -> tuple[float, int]:
    """(seconds between ``at_ns`` and the first message sent before it that the bag lacks,
    how many such messages) over every topic (``per_topic``: filled with each topic's)."""
    first, missing = None, 0
    for topic, times in talker.sent.items():
        have = got.get(topic, set())
        for k, t in enumerate(times):
            if t >= at_ns:
                break
            if k not in have:
                missing += 1
                first = t if first is None else min(first, t)
                if per_topic is not None:
                    per_topic[topic] = per_topic.get(topic, 0) + 1
    return (0.0 if first is None else (at_ns - first) * 1e-9), missing


def record_once(context, topics: dict[str, str], rate: float, sig: int, moment_s: float,
                folder: pathlib.Path, after_s: float = 0.5, recorder: str | None = None,
                quiet_stop: bool = False) -> dict:
    """One recording: the recorder started (``recorder``: the path of another version of
    the node's module, e.g. one taken from git history, to compare), the talker publishing,
    ``sig`` after ``moment_s`` s (``quiet_stop``: the talker stopped 0.5 s before it, so
    that a recorder that stops only when the data stop does); the loss and the stop time."""
    from rclpy.node import Node

    out = folder / 'bag'
    names = ', '.join(topics)
    env = dict(os.environ, PYTHONUNBUFFERED='1')
    command = [recorder] if recorder else ['-m', 'road_force_estimator.ros.bag_recorder']
    process = subprocess.Popen(
        [sys.executable, *command, '--ros-args', '-p',
         f'output:={out}', '-p', f'topics:=[{names}]'], cwd=REPO, env=env,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    node = Node('recorder_loss_talker', context=context)
    talker = Talker(node, topics, rate)
    try:
        deadline = time.monotonic() + 60.0
        while not talker.matched():
            if time.monotonic() > deadline or process.poll() is not None:
                raise RuntimeError(f'the recorder never subscribed: {process.stderr.read()}')
            time.sleep(0.05)
        time.sleep(0.5)                        # the subscribers' side of the discovery
        talker.start()
        time.sleep(moment_s)
        if quiet_stop:
            talker.stop()
            time.sleep(0.5)
        at = time.time_ns()
        t0 = time.monotonic()
        process.send_signal(sig)
        stop_s = None
        if sig != signal.SIGKILL:
            try:
                process.wait(timeout=30.0)
                stop_s = time.monotonic() - t0
            except subprocess.TimeoutExpired:
                stop_s = None
        time.sleep(max(0.0, after_s - (time.monotonic() - t0)))
    finally:
        talker.stop()
        if process.poll() is None:
            process.kill()
        _, err = process.communicate()
        node.destroy_node()
    got, ending = bag_numbers(out, talker.templates)
    per_topic: dict[str, int] = {}
    lost_s, missing = loss(talker, got, at, per_topic)
    said = re.search(r'\((\d+) missed on the way\)', err)
    return {'signal': signal.Signals(sig).name, 'moment_s': round(moment_s, 3),
            'lost_s': round(lost_s, 4), 'missing': missing,
            'recorded': sum(len(v) for v in got.values()),
            'sent_before': sum(sum(1 for t in v if t < at) for v in talker.sent.values()),
            'stop_s': None if stop_s is None else round(stop_s, 3), 'exit': process.returncode,
            'bag': ending, 'metadata': (out / 'metadata.yaml').is_file(),
            'recorder_says_missed': int(said.group(1)) if said else 0,
            'missing_by_topic': per_topic,
            'stderr_lines': len(err.strip().splitlines())}


class Load:
    """``n`` processes that keep a core busy each (``nice`` 0, as the recorder), for
    ``with``."""

    def __init__(self, n: int) -> None:
        self.n, self.procs = n, []

    def __enter__(self) -> 'Load':
        self.procs = [subprocess.Popen([sys.executable, '-c', 'while True: pass'])
                      for _ in range(self.n)]
        return self

    def __exit__(self, *exc) -> None:
        for p in self.procs:
            p.kill()
            p.wait()


def main(argv=None) -> int:
    import rclpy
    from rclpy.context import Context

    from road_force_estimator.interfaces import TOPIC_TYPES
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--rate', type=float, default=1000.0)
    p.add_argument('--runs', type=int, default=10)
    p.add_argument('--seconds', type=float, default=6.0)
    p.add_argument('--topics', choices=('two', 'all'), default='two')
    p.add_argument('--signals', default='KILL,INT,TERM')
    p.add_argument('--seed', type=int, default=1)
    p.add_argument('--load', type=int, default=0,
                   help='processes that keep a core busy each during the runs')
    p.add_argument('--quiet-stop', action='store_true',
                   help='stop the talker 0.5 s before the signal (for a recorder that stops '
                        'only when the data stop)')
    p.add_argument('--recorder', metavar='FILE',
                   help="another version of the node's module to run (e.g. `git show "
                        "REV:road_force_estimator/ros/bag_recorder.py > old.py`)")
    p.add_argument('--json', metavar='FILE')
    args = p.parse_args(argv)
    topics = {t: TOPIC_TYPES[t] for t in (TWO if args.topics == 'two' else TOPIC_TYPES)}
    rng = random.Random(args.seed)
    context = Context()
    rclpy.init(context=context)
    results = {}
    try:
        for name in args.signals.split(','):
            sig = getattr(signal, f'SIG{name}')
            runs = []
            for _ in range(args.runs if sig == signal.SIGKILL else max(1, args.runs // 3)):
                with tempfile.TemporaryDirectory() as tmp, Load(args.load):
                    run = record_once(context, topics, args.rate, sig,
                                      rng.uniform(1.0, args.seconds), pathlib.Path(tmp),
                                      recorder=args.recorder, quiet_stop=args.quiet_stop)
                runs.append(run)
                print(json.dumps(run), flush=True)
            results[name] = {'runs': runs, 'worst_lost_s': max(r['lost_s'] for r in runs),
                             'worst_stop_s': max((r['stop_s'] or 0.0) for r in runs)}
    finally:
        rclpy.try_shutdown(context=context)
    summary = {'rate_hz': args.rate, 'topics': len(topics), 'results': results}
    print(json.dumps({k: {'worst_lost_s': v['worst_lost_s'], 'worst_stop_s': v['worst_stop_s']}
                      for k, v in results.items()}))
    if args.json:
        pathlib.Path(args.json).write_text(json.dumps(summary, indent=1) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
