"""Bags of one small test content written by three writers: ours, rosbags', the mcap library's.

Shared by the playback tests (test/bagio/test_playback.py) and the bag_player node tests.
"""
from __future__ import annotations

from rosbags.typesys import Stores, get_typestore

from road_force_estimator.bagio import BagWriter

STORE = get_typestore(Stores.ROS2_JAZZY)
POINT = 'geometry_msgs/msg/PointStamped'
FLOAT = 'std_msgs/msg/Float64'
BASE_NS = 1_700_000_000_000_000_000
N = 500


def point_bytes(i: int, side: int) -> bytes:
    t = STORE.types
    stamp = t['builtin_interfaces/msg/Time'](sec=BASE_NS // 10**9 + i // 1000,
                                             nanosec=(i % 1000) * 10**6)
    msg = t[POINT](header=t['std_msgs/msg/Header'](stamp=stamp, frame_id='road'),
                   point=t['geometry_msgs/msg/Point'](x=0.05 * i, y=1.0 - 2 * side, z=1e-4 * i))
    return bytes(STORE.serialize_cdr(msg, POINT))


def expected(n: int = N):
    """(log time, topic, bytes) as written: left then right at each ms, and /ratio every 10."""
    out = []
    for i in range(n):
        for side, topic in enumerate(('/lpa/left', '/lpa/right')):
            out.append((BASE_NS + i * 10**6, topic, point_bytes(i, side)))
        if i % 10 == 0:
            out.append((BASE_NS + i * 10**6, '/ratio', bytes(STORE.serialize_cdr(
                STORE.types[FLOAT](data=i / n), FLOAT))))
    return out


def write_ours(folder, items):
    with BagWriter(folder) as bag:
        bag.add_topic('/lpa/left', POINT, 'reliable')
        bag.add_topic('/lpa/right', POINT, 'reliable')
        bag.add_topic('/ratio', FLOAT, 'sensor_data')
        for t, topic, data in items:
            bag.write_raw(topic, t, data)


def write_rosbags(folder, items):
    from rosbags.rosbag2 import StoragePlugin, Writer
    with Writer(folder, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = {topic: writer.add_connection(topic, msgtype, typestore=STORE)
                 for topic, msgtype in (('/lpa/left', POINT), ('/lpa/right', POINT),
                                        ('/ratio', FLOAT))}
        for t, topic, data in items:
            writer.write(conns[topic], t, data)


def write_mcap(folder, items, compression: str):
    from mcap.writer import CompressionType, Writer
    folder.mkdir()
    with (folder / f'{folder.name}_0.mcap').open('wb') as f:
        writer = Writer(f, compression=CompressionType[compression.upper()], chunk_size=4096)
        writer.start(profile='ros2', library='test')
        ids = {}
        for topic, msgtype in (('/lpa/left', POINT), ('/lpa/right', POINT), ('/ratio', FLOAT)):
            sid = writer.register_schema(msgtype, 'ros2msg', STORE.generate_msgdef(
                msgtype, ros_version=2)[0].encode())
            ids[topic] = writer.register_channel(topic, 'cdr', sid, {})
        for t, topic, data in items:
            writer.add_message(ids[topic], t, data, t)
        writer.finish()


WRITERS = {'ours': write_ours, 'rosbags': write_rosbags,
           'mcap_zstd': lambda f, m: write_mcap(f, m, 'zstd'),
           'mcap_lz4': lambda f, m: write_mcap(f, m, 'lz4')}
