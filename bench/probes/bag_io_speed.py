"""Messages per second of bag writing and reading: rosbags' generic path against bagio's
column-at-a-time CDR (encode_columns / decode_columns) over road_force_estimator.bagio.mcap_file's
container (chunks taken through their message index, or walked record by record when the index
does not check out; bench/probes/bag_read_speed.py times both).

    .venv/bin/python -m bench.probes.bag_io_speed [--samples N]

A drive of N samples has 6 messages per sample (deflections, twist, 2 loads, 2 road points).
Prints one line per path: messages, seconds, messages/s.
"""
from __future__ import annotations

import argparse
from pathlib import Path
import tempfile
import time
from types import SimpleNamespace

import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer

from road_force_estimator import bagio, interfaces
from road_force_estimator.serde import TYPESTORE


def fake_drive(n: int, rate_hz: float = 500.0, speed: float = 20.0):
    rng = np.random.default_rng(1)
    t = np.arange(n) / rate_hz
    trajectory = SimpleNamespace(t_s=t, distance_m=speed * t, speed_mps=speed,
                                 wheel_load_n=rng.normal(25000.0, 800.0, (n, 2)),
                                 road_m=rng.normal(0.0, 0.004, (n, 2)))
    return trajectory, rng.normal(0.0, 0.01, (n, 2)), rng.normal(0.0, 0.002, n)


def generic_write(path: Path, trajectory, q, roll) -> int:
    """The same drive bag through rosbags message objects and serialize_cdr, one by one."""
    types = TYPESTORE.types
    time_ = types['builtin_interfaces/msg/Time']
    header = types['std_msgs/msg/Header']
    v3 = types['geometry_msgs/msg/Vector3']
    stamps = bagio.DEFAULT_START_STAMP_NS + np.round(trajectory.t_s * 1e9).astype(np.int64)
    count = 0
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = {}
        for topic in (interfaces.TWIST, interfaces.DEFLECTIONS) + interfaces.TRUE_LOAD \
                + interfaces.TRUE_ROAD:
            conns[topic] = writer.add_connection(topic, interfaces.TOPIC_TYPES[topic],
                                                 typestore=TYPESTORE)
        for i, s in enumerate(stamps.tolist()):
            h = header(stamp=time_(sec=s // 10**9, nanosec=s % 10**9), frame_id='base_link')
            tw = types['geometry_msgs/msg/TwistStamped'](
                header=h, twist=types['geometry_msgs/msg/Twist'](
                    linear=v3(x=20.0, y=0.0, z=0.0), angular=v3(x=0.0, y=0.0, z=0.0)))
            js = types['sensor_msgs/msg/JointState'](
                header=h, name=list(interfaces.DEFLECTION_JOINTS),
                position=np.array([q[i, 0], q[i, 1], roll[i]]), velocity=np.zeros(0),
                effort=np.zeros(0))
            msgs = [(interfaces.TWIST, tw), (interfaces.DEFLECTIONS, js)]
            for side in (0, 1):
                wrench = types['geometry_msgs/msg/WrenchStamped'](
                    header=h, wrench=types['geometry_msgs/msg/Wrench'](
                        force=v3(x=0.0, y=0.0, z=trajectory.wheel_load_n[i, side]),
                        torque=v3(x=0.0, y=0.0, z=0.0)))
                point = types['geometry_msgs/msg/PointStamped'](
                    header=h, point=types['geometry_msgs/msg/Point'](
                        x=trajectory.distance_m[i], y=1.0, z=trajectory.road_m[i, side]))
                msgs += [(interfaces.TRUE_LOAD[side], wrench),
                         (interfaces.TRUE_ROAD[side], point)]
            for topic, msg in msgs:
                writer.write(conns[topic], s,
                             TYPESTORE.serialize_cdr(msg, interfaces.TOPIC_TYPES[topic]))
                count += 1
    return count


def generic_read(path: Path) -> int:
    count = 0
    with AnyReader([path], default_typestore=TYPESTORE) as reader:
        for conn, _, raw in reader.messages():
            reader.deserialize(raw, conn.msgtype)
            count += 1
    return count


def timed(label: str, func) -> None:
    start = time.perf_counter()
    count = func()
    elapsed = time.perf_counter() - start
    print(f'{label:<46s} {count:>9d} msgs {elapsed:8.2f} s {count / elapsed:>12,.0f} msgs/s')


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--samples', type=int, default=100_000,
                        help='samples of the drive (6 messages each), default 100000')
    args = parser.parse_args(argv)
    trajectory, q, roll = fake_drive(args.samples)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        timed('write: rosbags objects + serialize_cdr', lambda: generic_write(
            tmp / 'generic', trajectory, q, roll))
        timed('write: bagio.write_drive_bag (columns)', lambda: bagio.write_drive_bag(
            tmp / 'columns', trajectory, q, roll))
        timed('read: rosbags AnyReader + deserialize', lambda: generic_read(tmp / 'columns'))
        timed('read: bagio.iter_messages (objects)', lambda: sum(
            1 for _ in bagio.iter_messages(tmp / 'columns')))
        timed('read: bagio.read_drive_bag (columns)', lambda: sum(
            bagio.read_drive_bag(tmp / 'columns').messages.values()))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
