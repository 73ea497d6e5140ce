"""Drive bags (bagio.drive): round trips, what rosbag2 and mcap see, bad messages (NaN,
wrong names, duplicate / backward stamps) rejected and counted by topic and reason."""
from types import SimpleNamespace

from mcap_ros2.reader import read_ros2_messages
import numpy as np
import yaml

from bag_samples import BASE_NS, T, header, joint_state, make_trajectory, twist
from road_force_estimator import bagio, interfaces
from road_force_estimator.bagio import BagWriter
from road_force_estimator.serde import TYPESTORE


class TestDriveBag:
    def test_round_trip_and_other_readers(self, tmp_path):
        trajectory, q, roll = make_trajectory()
        fixes = SimpleNamespace(time_s=np.arange(0.0, 2.0, 0.1),
                                latitude_deg=48.1 + 1e-5 * np.arange(20),
                                longitude_deg=17.1 + 2e-5 * np.arange(20))
        count = bagio.write_drive_bag(tmp_path / 'd', trajectory, q, roll, fixes=fixes,
                                       track_width_m=2.2)
        assert count == 6 * 400 + 20
        d = bagio.read_drive_bag(tmp_path / 'd')
        stamps = BASE_NS + np.round(trajectory.t_s * 1e9).astype(np.int64)
        np.testing.assert_array_equal(d.stamps_ns, stamps)
        np.testing.assert_array_equal(d.q_m, q)
        np.testing.assert_array_equal(d.roll_rad, roll)
        assert np.all(d.speed_mps == 15.0)
        np.testing.assert_array_equal(d.truth.stamps_ns, stamps)
        np.testing.assert_array_equal(d.truth.wheel_load_n, trajectory.wheel_load_n)
        np.testing.assert_array_equal(d.truth.road_m, trajectory.road_m)
        np.testing.assert_array_equal(d.truth.distance_m, trajectory.distance_m)
        np.testing.assert_array_equal(d.fixes.latitude_deg, fixes.latitude_deg)
        assert (d.fixes.altitude_m == 0.0).all()
        assert d.rejected == {} and d.issues == () and d.rejected_total == 0
        assert d.custom_data['road_force_estimator.kind'] == 'drive'

        # mcap + mcap-ros2-support decode the same values with the bag's own schemas.
        (mcap_file,) = (tmp_path / 'd').glob('*.mcap')
        seen = {}
        for m in read_ros2_messages(str(mcap_file)):
            seen.setdefault(m.channel.topic, []).append(m)
        js = seen['/suspension/deflections']
        assert [x.ros_msg.name for x in js[:1]] == [list(interfaces.DEFLECTION_JOINTS)]
        assert js[0].schema.encoding == 'ros2msg' and js[0].channel.message_encoding == 'cdr'
        np.testing.assert_array_equal([x.ros_msg.position for x in js],
                                      np.column_stack([q, roll]))
        np.testing.assert_array_equal([x.log_time_ns for x in js], stamps)
        load = seen['/ground_truth/wheel_load/right']
        assert load[0].ros_msg.header.frame_id == 'front_right_wheel'
        np.testing.assert_array_equal([x.ros_msg.wrench.force.z for x in load],
                                      trajectory.wheel_load_n[:, 1])
        road = seen['/ground_truth/road_profile/left']
        assert {x.ros_msg.point.y for x in road} == {1.1}
        assert [x.ros_msg.twist.linear.x for x in seen['/vehicle/twist']] == [15.0] * 400
        qos = yaml.safe_load(js[0].channel.metadata['offered_qos_profiles'])
        assert qos[0]['reliability'] == 'best_effort'
        assert js[0].channel.metadata['offered_qos_profiles'] != ''

        # rosbags' own reader (indexed access, log-time order) agrees.
        from rosbags.highlevel import AnyReader
        with AnyReader([tmp_path / 'd'], default_typestore=TYPESTORE) as reader:
            conns = [c for c in reader.connections if c.topic == '/fix']
            lats = [reader.deserialize(raw, c.msgtype).latitude
                    for c, _, raw in reader.messages(connections=conns)]
        np.testing.assert_array_equal(lats, fixes.latitude_deg)

    def test_speed_is_held_from_the_latest_twist(self, tmp_path):
        with BagWriter(tmp_path / 'b') as bag:
            bag.add_topic('/suspension/deflections', 'sensor_msgs/msg/JointState')
            bag.add_topic('/vehicle/twist', 'geometry_msgs/msg/TwistStamped')
            for k in range(6):
                if k in (2, 4):
                    bag.write('/vehicle/twist', 10 * k, twist(10 * k, float(k)))
                bag.write('/suspension/deflections', 10 * k,
                          joint_state(10 * k, interfaces.DEFLECTION_JOINTS, [0.0, 0.0, 0.0]))
        d = bagio.read_drive_bag(tmp_path / 'b')
        np.testing.assert_array_equal(d.speed_mps, [np.nan, np.nan, 2.0, 2.0, 4.0, 4.0])
        assert d.truth is None and d.fixes is None

    def test_bad_messages_are_rejected_by_name_and_counted(self, tmp_path):
        names = list(interfaces.DEFLECTION_JOINTS)
        deflections = [   # (stamp, names, position, velocity) in file order
            (1, names, [0.01, 0.02, 0.001], []),
            (2, ['roll', 'right_suspension', 'left_suspension'], [0.003, 0.04, 0.03], []),
            (3, names, [np.nan, 0.0, 0.0], []),                 # nonfinite
            (3, names, [0.05, 0.06, 0.005], []),                # accepted (3 is new)
            (3, names, [0.07, 0.08, 0.007], []),                # duplicate
            (2, names, [0.09, 0.10, 0.009], []),                # backwards
            (4, names[:2], [0.1, 0.2], []),                     # missing name
            (5, names, [0.1, 0.2], []),                         # length mismatch
            (6, names + ['steering'], [0.11, 0.12, 0.011, 0.5], []),   # extra name: fine
            (7, names, [0.1, 0.2, 0.3], [1.0, 2.0]),            # velocity length mismatch
            (8, names, [0.1, np.inf, 0.3], []),                 # nonfinite
            (9, names, [0.13, 0.14, 0.013], []),
        ]
        with BagWriter(tmp_path / 'b') as bag:
            bag.add_topic('/suspension/deflections', 'sensor_msgs/msg/JointState',
                          'sensor_data')
            bag.add_topic('/vehicle/twist', 'geometry_msgs/msg/TwistStamped', 'sensor_data')
            bag.add_topic('/ground_truth/wheel_load/left', 'std_msgs/msg/Float64')
            for s, v in ((1, 10.0), (1, 11.0), (5, np.nan), (6, 12.0)):
                bag.write('/vehicle/twist', s, twist(s, v))
            bag.write_raw('/vehicle/twist', 6, b'\x00\x01\x00\x00\x01\x02')   # undecodable
            for s, n, p, v in deflections:
                bag.write('/suspension/deflections', s, joint_state(s, n, p, v))
            bag.write('/ground_truth/wheel_load/left', 3, T['std_msgs/msg/Float64'](data=1.0))
        d = bagio.read_drive_bag(tmp_path / 'b')
        assert d.stamps_ns.tolist() == [1, 2, 3, 6, 9]
        np.testing.assert_array_equal(d.q_m, [[0.01, 0.02], [0.03, 0.04], [0.05, 0.06],
                                              [0.11, 0.12], [0.13, 0.14]])
        np.testing.assert_array_equal(d.roll_rad, [0.001, 0.003, 0.005, 0.011, 0.013])
        np.testing.assert_array_equal(d.speed_mps, [10.0, 10.0, 10.0, 12.0, 12.0])
        assert d.rejected['/suspension/deflections'] == {
            'nonfinite': 2, 'duplicate_stamp': 1, 'backwards_stamp': 1, 'missing_name': 1,
            'length_mismatch': 2}
        assert d.rejected['/vehicle/twist'] == {'duplicate_stamp': 1, 'nonfinite': 1,
                                                'undecodable': 1}
        assert d.rejected['/ground_truth/wheel_load/left'] == {
            'wrong_type (std_msgs/msg/Float64)': 1}
        assert d.rejected_total == 11
        assert d.messages['/suspension/deflections'] == 12
        assert any('12 messages' in line for line in d.summary_lines())


def navsatfix(stamp_ns, status, lat, lon):
    return T['sensor_msgs/msg/NavSatFix'](
        header=header(stamp_ns, 'gnss'),
        status=T['sensor_msgs/msg/NavSatStatus'](status=status, service=1),
        latitude=lat, longitude=lon, altitude=0.0, position_covariance=np.zeros(9),
        position_covariance_type=0)


def test_a_fix_of_unknown_status_is_kept_and_counted(tmp_path):
    """NavSatStatus -2 (STATUS_UNKNOWN, Jazzy) with a finite position is a fix of unknown
    quality: kept and counted; -1 (NO_FIX) and non-finite positions are rejected (issue 17).
    Before: every status < 0 was rejected as no_fix."""
    from road_force_estimator.interfaces import DEFLECTION_JOINTS
    statuses = [0, -2, -1, 2, -2, -2, 1]
    lats = [48.0, 48.1, 48.2, 48.3, float('nan'), 48.5, 48.6]
    with bagio.BagWriter(tmp_path / 'd') as bag:
        bag.add_topic('/suspension/deflections', 'sensor_msgs/msg/JointState')
        bag.add_topic('/fix', 'sensor_msgs/msg/NavSatFix')
        for i, (status, lat) in enumerate(zip(statuses, lats)):
            stamp = BASE_NS + i * 10**8
            bag.write('/suspension/deflections', stamp,
                      joint_state(stamp, DEFLECTION_JOINTS, [0.0, 0.0, 0.0]))
            bag.write('/fix', stamp, navsatfix(stamp, status, lat, 17.0))
    d = bagio.read_drive_bag(tmp_path / 'd')
    np.testing.assert_array_equal(d.fixes.latitude_deg, [48.0, 48.1, 48.3, 48.5, 48.6])
    assert d.rejected['/fix'] == {'nonfinite': 1, 'no_fix': 1}
    assert d.noted == {'/fix': {'fix_status_unknown': 2}}
    assert '/fix: 2 kept (fix_status_unknown)' in d.summary_lines()
