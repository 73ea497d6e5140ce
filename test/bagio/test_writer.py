"""The rosbag2 writer (bagio.writer): metadata.yaml as Jazzy writes it, QoS, raw CDR,
type errors, stamps."""

from mcap_ros2.reader import read_ros2_messages
import numpy as np
import pytest

from road_force_estimator import bagio, interfaces
from road_force_estimator import serde
from road_force_estimator.bagio import BagWriteError, BagWriter
from road_force_estimator.serde import TYPESTORE


class TestWriter:
    def test_write_raw_from_rclpy_and_generic_read(self, tmp_path):
        from rclpy.serialization import serialize_message
        from sensor_msgs.msg import JointState

        msg = JointState()
        msg.header.stamp.sec = 3
        msg.header.frame_id = 'base_link'
        msg.name = list(interfaces.DEFLECTION_JOINTS)
        msg.position = [0.01, -0.02, 0.003]
        with BagWriter(tmp_path / 'b') as bag:
            bag.add_topic('/suspension/deflections', 'sensor_msgs/JointState', 'sensor_data')
            bag.write_raw('/suspension/deflections', 3 * 10**9 + 5, serialize_message(msg))
        ((topic, log_ns, got),) = list(bagio.iter_messages(tmp_path / 'b'))
        assert (topic, log_ns) == ('/suspension/deflections', 3 * 10**9 + 5)
        assert got.name == msg.name and got.position.tolist() == [0.01, -0.02, 0.003]
        d = bagio.read_drive_bag(tmp_path / 'b')
        assert d.stamps_ns.tolist() == [3 * 10**9] and d.q_m.tolist() == [[0.01, -0.02]]
        info = bagio.bag_info(tmp_path / 'b')
        assert info.counts == {'/suspension/deflections': 1}
        # rmw leaves spare bytes after an empty sequence; rosbags refuses them, so they are
        # dropped on writing and rosbags' strict reader reads the recorded message.
        from rosbags.highlevel import AnyReader
        with AnyReader([tmp_path / 'b'], default_typestore=TYPESTORE) as reader:
            ((conn, _, raw),) = list(reader.messages())
            assert reader.deserialize(raw, conn.msgtype).position.tolist() == list(msg.position)
        (mcap,) = (tmp_path / 'b').glob('*.mcap')
        (m,) = list(read_ros2_messages(str(mcap)))
        assert m.ros_msg.position == [0.01, -0.02, 0.003]

    def test_types_outside_jazzy_are_read_from_the_bag_schema(self, tmp_path):
        from mcap.writer import Writer
        from rosbags.typesys import get_types_from_msg, get_typestore, Stores

        definition = 'float64 a\nstring b\nint32[] c\n'
        store = get_typestore(Stores.EMPTY)
        store.register(get_types_from_msg(definition, 'my_pkg/msg/Thing'))
        thing = store.types['my_pkg/msg/Thing']
        (tmp_path / 'b').mkdir()
        with (tmp_path / 'b' / 'b_0.mcap').open('wb') as f:
            writer = Writer(f)
            writer.start(profile='ros2', library='test')
            sid = writer.register_schema('my_pkg/msg/Thing', 'ros2msg', definition.encode())
            cid = writer.register_channel('/thing', 'cdr', sid, {})
            for i in range(3):
                msg = thing(a=0.5 * i, b=f's{i}', c=np.arange(i, dtype=np.int32))
                writer.add_message(cid, i, bytes(store.serialize_cdr(msg, 'my_pkg/msg/Thing')),
                                   i)
            writer.add_message(cid, 9, b'\x00\x01\x00\x00\x01', 9)      # broken
            writer.finish()
        issues = []
        got = list(bagio.iter_messages(tmp_path / 'b', issues=issues))
        assert [(m.a, m.b, m.c.tolist()) for _, _, m in got] == [(0.0, 's0', []),
                                                                  (0.5, 's1', [0]),
                                                                  (1.0, 's2', [0, 1])]
        assert any('1 messages could not be deserialized' in line for line in issues)

    def test_refusals(self, tmp_path):
        with BagWriter(tmp_path / 'b') as bag:
            bag.add_topic('/x', 'std_msgs/msg/Float64')
            with pytest.raises(BagWriteError, match='not added'):
                bag.write_raw('/y', 0, b'')
            with pytest.raises(BagWriteError, match='unknown message type'):
                bag.add_topic('/z', 'nope_msgs/msg/Nope')
            with pytest.raises(BagWriteError, match='non-negative'):
                bag.write_raw('/x', -1, b'')
            with pytest.raises(BagWriteError, match='already added'):
                bag.add_topic('/x', 'std_msgs/msg/String')
            with pytest.raises(ValueError, match='qos'):
                bag.add_topic('/q', 'std_msgs/msg/Float64', 'fast')
        with pytest.raises(BagWriteError, match='exists already'):
            BagWriter(tmp_path / 'b').open()
        with BagWriter(tmp_path / 'b', overwrite=True) as bag:
            bag.add_topic('/x', 'std_msgs/msg/Float64', {'reliability': 'best_effort',
                                                         'depth': 1})
        assert bagio.bag_info(tmp_path / 'b').topics == {'/x': 'std_msgs/msg/Float64'}
        (tmp_path / 'b' / 'notes.txt').write_text('mine')
        with pytest.raises(BagWriteError, match='more than a bag'):
            BagWriter(tmp_path / 'b', overwrite=True).open()
        with pytest.raises(serde.SerdeError, match='ROS time'):
            serde.ns_to_stamps(np.array([2**31 * 10**9]))
