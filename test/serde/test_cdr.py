"""CDR a column at a time (serde.cdr): byte-exact against rosbags and rclpy, layouts,
decoding of messages with other layouts or byte orders."""

import numpy as np
import pytest

from bag_samples import T, joint_state, twist
from road_force_estimator import interfaces
from road_force_estimator import serde
from road_force_estimator.serde import TYPESTORE


class TestCdr:
    def test_encoded_rows_equal_rosbags_serialize_cdr(self):
        rng = np.random.default_rng(11)
        n = 40
        stamps = rng.integers(0, 2**31 * 10**9, n)
        cases = [
            ('geometry_msgs/msg/PointStamped', serde.message_template(
                'geometry_msgs/msg/PointStamped', 'road'), ['point.x', 'point.y', 'point.z']),
            ('geometry_msgs/msg/WrenchStamped', serde.message_template(
                'geometry_msgs/msg/WrenchStamped', 'front_right_wheel'),
             ['wrench.force.z', 'wrench.torque.x']),
            ('geometry_msgs/msg/TwistStamped', serde.message_template(
                'geometry_msgs/msg/TwistStamped', 'base_link'), ['twist.linear.x']),
            ('sensor_msgs/msg/NavSatFix',
             serde.message_template('sensor_msgs/msg/NavSatFix', 'gnss'),
             ['latitude', 'longitude', 'altitude']),
        ]
        for msgtype, template, paths in cases:
            cols = serde.stamp_columns(stamps)
            cols.update({p: rng.normal(size=n) for p in paths})
            rows = serde.encode_columns(msgtype, template, n, cols)
            for i in range(n):
                msg = TYPESTORE.deserialize_cdr(rows[i].tobytes(), msgtype)
                assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == stamps[i]
                assert bytes(TYPESTORE.serialize_cdr(msg, msgtype)) == rows[i].tobytes()
        for names, velocity in ((interfaces.DEFLECTION_JOINTS, False),
                                (interfaces.STATE_JOINTS, True)):
            k = len(names)
            cols = serde.stamp_columns(stamps)
            cols['position'] = rng.normal(size=(n, k))
            if velocity:
                cols['velocity'] = rng.normal(size=(n, k))
            rows = serde.encode_columns('sensor_msgs/msg/JointState', serde.message_template(
                'sensor_msgs/msg/JointState', 'base_link', names, velocity), n, cols)
            for i in range(n):
                ref = joint_state(int(stamps[i]), names, cols['position'][i],
                                  cols['velocity'][i] if velocity else ())
                assert bytes(TYPESTORE.serialize_cdr(ref, 'sensor_msgs/msg/JointState')) \
                    == rows[i].tobytes()
        rows = serde.encode_columns('std_msgs/msg/Float64', serde.message_template(
            'std_msgs/msg/Float64'), 3, {'data': [1.5, -2.0, 0.25]})
        assert rows[1].tobytes() == bytes(TYPESTORE.serialize_cdr(
            T['std_msgs/msg/Float64'](data=-2.0), 'std_msgs/msg/Float64'))

    def test_decodes_rclpy_bytes_with_uninitialised_padding(self):
        from geometry_msgs.msg import PointStamped
        from rclpy.serialization import serialize_message
        from sensor_msgs.msg import JointState

        datas, want = [], []
        for i, names in enumerate([list(interfaces.DEFLECTION_JOINTS),
                                   ['roll', 'left_suspension', 'right_suspension', 'steer']]):
            for j in range(5):
                msg = JointState()
                msg.header.stamp.sec, msg.header.stamp.nanosec = 100 + j, 7 * j
                msg.header.frame_id = 'base_link'
                msg.name = names
                msg.position = [0.1 * j + k for k in range(len(names))]
                datas.append(serialize_message(msg))
                want.append((names, msg.position.tolist()))
        groups, bad = serde.decode_columns('sensor_msgs/msg/JointState', datas)
        assert bad.size == 0 and sum(g.index.size for g in groups) == len(datas)
        for g in groups:
            for row, i in enumerate(g.index):
                assert list(g.layout.strings['name']) == want[i][0]
                assert g.columns['position'][row].tolist() == want[i][1]
        point = PointStamped()
        point.header.frame_id = 'road'
        point.point.x, point.point.y, point.point.z = 1.25, -1.0, 3e-3
        groups, bad = serde.decode_columns('geometry_msgs/msg/PointStamped',
                                            [serialize_message(point)])
        cols = groups[0].columns
        assert (cols['point.x'][0], cols['point.y'][0], cols['point.z'][0]) == (1.25, -1.0,
                                                                                 3e-3)

    def test_bad_bytes_are_undecodable_and_big_endian_is_converted(self):
        good = bytes(TYPESTORE.serialize_cdr(twist(5, 12.5), 'geometry_msgs/msg/TwistStamped'))
        big = bytes(TYPESTORE.serialize_cdr(twist(6, 13.5), 'geometry_msgs/msg/TwistStamped',
                                            little_endian=False))
        assert big[1] == 0
        groups, bad = serde.decode_columns('geometry_msgs/msg/TwistStamped',
                                            [good, good[:30], b'', big, b'\x00\x01\x00\x00'])
        assert bad.tolist() == [1, 2, 4]
        speeds = {int(i): v for g in groups
                  for i, v in zip(g.index, g.columns['twist.linear.x'])}
        assert speeds == {0: 12.5, 3: 13.5}
        with pytest.raises(ValueError, match='little-endian'):
            serde.cdr_layout('geometry_msgs/msg/TwistStamped', big)
