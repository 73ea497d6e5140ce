"""Bag I/O: byte-exact CDR against rosbags and rclpy, bags that rosbag2 (Jazzy), mcap and
rosbags read, round trips, and bad bags (NaN, wrong names, duplicate / backward stamps,
truncated and corrupt files) read without a crash and with every rejection counted."""
import json
import os
from pathlib import Path
import sys
from types import SimpleNamespace

from mcap_walk import top_level_records
from mcap_ros2.reader import read_ros2_messages
import numpy as np
import pytest
import yaml

from road_force_estimator import bagio, interfaces
from road_force_estimator.bagio import (
    BagReadError,
    BagWriteError,
    BagWriter,
    TYPESTORE,
)
from road_force_estimator.core.road import RoadProfile

T = TYPESTORE.types
BASE_NS = bagio.DEFAULT_START_STAMP_NS


def header(stamp_ns, frame):
    return T['std_msgs/msg/Header'](
        stamp=T['builtin_interfaces/msg/Time'](sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9),
        frame_id=frame)


def joint_state(stamp_ns, names, position, velocity=(), frame='base_link'):
    return T['sensor_msgs/msg/JointState'](
        header=header(stamp_ns, frame), name=list(names),
        position=np.asarray(position, float), velocity=np.asarray(velocity, float),
        effort=np.zeros(0))


def twist(stamp_ns, speed):
    v3 = T['geometry_msgs/msg/Vector3']
    return T['geometry_msgs/msg/TwistStamped'](
        header=header(stamp_ns, 'base_link'),
        twist=T['geometry_msgs/msg/Twist'](linear=v3(x=speed, y=0.0, z=0.0),
                                           angular=v3(x=0.0, y=0.0, z=0.0)))


def jazzy_type_hash(msgtype):
    """RIHS01 hash from the type description that the ROS 2 Jazzy message package installs."""
    package, _, name = msgtype.split('/')
    prefixes = [sys.prefix] + [p for p in os.environ.get('AMENT_PREFIX_PATH', '').split(':')
                               if p]
    for prefix in prefixes:
        path = Path(prefix) / 'share' / package / 'msg' / f'{name}.json'
        if path.is_file():
            hashes = json.loads(path.read_text())['type_hashes']
            return next(h['hash_string'] for h in hashes if h['type_name'] == msgtype)
    pytest.fail(f'no installed type description for {msgtype} (ROS 2 Jazzy message packages)')


def make_trajectory(n=400, rate_hz=200.0, speed=15.0, seed=1):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate_hz
    return SimpleNamespace(
        t_s=t, distance_m=speed * t, speed_mps=speed,
        wheel_load_n=rng.normal(25000.0, 800.0, (n, 2)),
        road_m=rng.normal(0.0, 0.004, (n, 2))), rng.normal(0.0, 0.01, (n, 2)), \
        rng.normal(0.0, 0.002, n)


# --------------------------------------------------------------------------------------------

class TestCdr:
    def test_encoded_rows_equal_rosbags_serialize_cdr(self):
        rng = np.random.default_rng(11)
        n = 40
        stamps = rng.integers(0, 2**31 * 10**9, n)
        cases = [
            ('geometry_msgs/msg/PointStamped', bagio.message_template(
                'geometry_msgs/msg/PointStamped', 'road'), ['point.x', 'point.y', 'point.z']),
            ('geometry_msgs/msg/WrenchStamped', bagio.message_template(
                'geometry_msgs/msg/WrenchStamped', 'front_right_wheel'),
             ['wrench.force.z', 'wrench.torque.x']),
            ('geometry_msgs/msg/TwistStamped', bagio.message_template(
                'geometry_msgs/msg/TwistStamped', 'base_link'), ['twist.linear.x']),
            ('sensor_msgs/msg/NavSatFix',
             bagio.message_template('sensor_msgs/msg/NavSatFix', 'gnss'),
             ['latitude', 'longitude', 'altitude']),
        ]
        for msgtype, template, paths in cases:
            cols = bagio.stamp_columns(stamps)
            cols.update({p: rng.normal(size=n) for p in paths})
            rows = bagio.encode_columns(msgtype, template, n, cols)
            for i in range(n):
                msg = TYPESTORE.deserialize_cdr(rows[i].tobytes(), msgtype)
                assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == stamps[i]
                assert bytes(TYPESTORE.serialize_cdr(msg, msgtype)) == rows[i].tobytes()
        for names, velocity in ((interfaces.DEFLECTION_JOINTS, False),
                                (interfaces.STATE_JOINTS, True)):
            k = len(names)
            cols = bagio.stamp_columns(stamps)
            cols['position'] = rng.normal(size=(n, k))
            if velocity:
                cols['velocity'] = rng.normal(size=(n, k))
            rows = bagio.encode_columns('sensor_msgs/msg/JointState', bagio.message_template(
                'sensor_msgs/msg/JointState', 'base_link', names, velocity), n, cols)
            for i in range(n):
                ref = joint_state(int(stamps[i]), names, cols['position'][i],
                                  cols['velocity'][i] if velocity else ())
                assert bytes(TYPESTORE.serialize_cdr(ref, 'sensor_msgs/msg/JointState')) \
                    == rows[i].tobytes()
        rows = bagio.encode_columns('std_msgs/msg/Float64', bagio.message_template(
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
        groups, bad = bagio.decode_columns('sensor_msgs/msg/JointState', datas)
        assert bad.size == 0 and sum(g.index.size for g in groups) == len(datas)
        for g in groups:
            for row, i in enumerate(g.index):
                assert list(g.layout.strings['name']) == want[i][0]
                assert g.columns['position'][row].tolist() == want[i][1]
        point = PointStamped()
        point.header.frame_id = 'road'
        point.point.x, point.point.y, point.point.z = 1.25, -1.0, 3e-3
        groups, bad = bagio.decode_columns('geometry_msgs/msg/PointStamped',
                                            [serialize_message(point)])
        cols = groups[0].columns
        assert (cols['point.x'][0], cols['point.y'][0], cols['point.z'][0]) == (1.25, -1.0,
                                                                                 3e-3)

    def test_bad_bytes_are_undecodable_and_big_endian_is_converted(self):
        good = bytes(TYPESTORE.serialize_cdr(twist(5, 12.5), 'geometry_msgs/msg/TwistStamped'))
        big = bytes(TYPESTORE.serialize_cdr(twist(6, 13.5), 'geometry_msgs/msg/TwistStamped',
                                            little_endian=False))
        assert big[1] == 0
        groups, bad = bagio.decode_columns('geometry_msgs/msg/TwistStamped',
                                            [good, good[:30], b'', big, b'\x00\x01\x00\x00'])
        assert bad.tolist() == [1, 2, 4]
        speeds = {int(i): v for g in groups
                  for i, v in zip(g.index, g.columns['twist.linear.x'])}
        assert speeds == {0: 12.5, 3: 13.5}
        with pytest.raises(ValueError, match='little-endian'):
            bagio.cdr_layout('geometry_msgs/msg/TwistStamped', big)


# --------------------------------------------------------------------------------------------

class TestLpaBag:
    def profile(self):
        rng = np.random.default_rng(5)
        x = 12.0 + 0.05 * np.arange(3001)
        return RoadProfile(x, np.cumsum(rng.normal(0.0, 3e-4, (x.size, 2)), axis=0),
                           name='test road')

    def test_round_trip_is_exact(self, tmp_path):
        p = self.profile()
        bagio.write_lpa_bag(tmp_path / 'lpa', p, survey_speed_mps=10.0, track_width_m=1.8)
        issues = []
        q = bagio.read_lpa_bag(tmp_path / 'lpa', issues=issues)
        assert issues == []
        np.testing.assert_array_equal(q.distance_m, p.distance_m)
        np.testing.assert_array_equal(q.elevation_m, p.elevation_m)
        assert q.name == 'test road'
        # Stamps at the survey speed, y = +-T/2, frame road (read with the generic reader).
        msgs = list(bagio.iter_messages(tmp_path / 'lpa', ['/lpa/right']))
        assert len(msgs) == 3001
        topic, log_ns, msg = msgs[20]
        assert log_ns == BASE_NS + 100_000_000          # 1 m at 10 m/s
        assert msg.header.frame_id == 'road' and msg.point.y == -0.9
        assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == log_ns

    def test_metadata_is_what_jazzy_rosbag2_reads(self, tmp_path):
        bagio.write_lpa_bag(tmp_path / 'lpa', self.profile())
        meta = yaml.safe_load((tmp_path / 'lpa' / 'metadata.yaml').read_text())
        info = meta['rosbag2_bagfile_information']
        assert info['version'] == 9 and info['storage_identifier'] == 'mcap'
        assert isinstance(info['custom_data'], dict)      # never null: yaml-cpp wants a map
        for name in info['relative_file_paths']:
            assert (tmp_path / 'lpa' / name).is_file() and name.endswith('.mcap')
        assert info['message_count'] == 2 * 3001
        topics = {t['topic_metadata']['name']: t for t in info['topics_with_message_count']}
        assert set(topics) == {'/lpa/left', '/lpa/right'}
        for t in topics.values():
            meta = t['topic_metadata']
            assert meta['type'] == 'geometry_msgs/msg/PointStamped'
            assert meta['serialization_format'] == 'cdr'
            assert meta['type_description_hash'] == jazzy_type_hash(meta['type'])
            (qos,) = meta['offered_qos_profiles']
            assert qos['reliability'] == 'reliable' and qos['history'] == 'keep_last'
            assert t['message_count'] == 3001
        # The mcap library validates every CRC and finds the rosbag2 metadata record, which
        # Jazzy's MCAP plugin decodes as the same bag information.
        from mcap.reader import make_reader
        (mcap,) = (tmp_path / 'lpa').glob('*.mcap')
        with mcap.open('rb') as f:
            reader = make_reader(f, validate_crcs=True)
            assert reader.get_header().profile == 'ros2'
            assert sum(1 for _ in reader.iter_messages()) == 2 * 3001
            (record,) = list(reader.iter_metadata())
            assert record.name == 'rosbag2'
            assert yaml.safe_load(record.metadata['serialized_metadata']) == info
            stats = reader.get_summary().statistics
            assert stats.message_count == 2 * 3001 and stats.chunk_count >= 1

    def test_one_track_and_dropped_samples(self, tmp_path):
        point = T['geometry_msgs/msg/PointStamped']
        with BagWriter(tmp_path / 'b') as bag:
            bag.add_topic('/lpa/left', 'geometry_msgs/msg/PointStamped')
            for i, (x, z) in enumerate([(0.0, 1.0), (1.0, 2.0), (1.0, 9.0), (0.5, 9.0),
                                        (2.0, np.nan), (3.0, 4.0)]):
                bag.write('/lpa/left', BASE_NS + i, point(
                    header=header(BASE_NS + i, 'road'),
                    point=T['geometry_msgs/msg/Point'](x=x, y=1.0, z=z)))
        issues = []
        p = bagio.read_lpa_bag(tmp_path / 'b', issues=issues)
        assert p.distance_m.tolist() == [0.0, 1.0, 3.0]
        assert p.elevation_m.tolist() == [[1.0, 1.0], [2.0, 2.0], [4.0, 4.0]]
        text = ' | '.join(issues)
        assert 'only /lpa/left' in text and '(nonfinite)' in text
        assert '1 samples dropped (duplicate_stamp)' in text          # x = 1.0 again
        assert '1 samples dropped (backwards_stamp)' in text          # x = 0.5
        with pytest.raises(BagReadError, match='not an LPA bag'):
            bagio.read_lpa_bag(self.drive_bag(tmp_path))

    def drive_bag(self, tmp_path):
        trajectory, q, roll = make_trajectory(n=10)
        bagio.write_drive_bag(tmp_path / 'drive', trajectory, q, roll)
        return tmp_path / 'drive'


# --------------------------------------------------------------------------------------------

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


# --------------------------------------------------------------------------------------------

class TestBrokenFiles:
    @pytest.fixture
    def drive(self, tmp_path):
        trajectory, q, roll = make_trajectory(n=3000)
        bagio.write_drive_bag(tmp_path / 'd', trajectory, q, roll)
        (mcap,) = (tmp_path / 'd').glob('*.mcap')
        return tmp_path / 'd', mcap, bagio.read_drive_bag(tmp_path / 'd')

    def assert_prefix(self, d, full):
        m = d.stamps_ns.size
        assert 0 < m < full.stamps_ns.size
        np.testing.assert_array_equal(d.stamps_ns, full.stamps_ns[:m])
        np.testing.assert_array_equal(d.q_m, full.q_m[:m])

    def test_truncated_file_is_read_up_to_the_break(self, drive):
        folder, mcap, full = drive
        data = mcap.read_bytes()
        assert len(data) > 2**20          # more than one chunk
        for cut in (0.3, 0.6, 0.9):                  # inside the first or second chunk
            mcap.write_bytes(data[:int(cut * len(data))])
            d = bagio.read_drive_bag(folder)
            self.assert_prefix(d, full)
            assert len(d.issues) == 1 and 'ends inside the chunk' in d.issues[0], d.issues
        mcap.write_bytes(data[:int(0.99 * len(data))])   # inside the index: every message
        d = bagio.read_drive_bag(folder)
        np.testing.assert_array_equal(d.q_m, full.q_m)
        assert len(d.issues) == 1 and 'bytes missing' in d.issues[0], d.issues
        # Cut exactly at a record boundary inside the data: no end-of-data record.
        mcap.write_bytes(data[:8 + 9 + int.from_bytes(data[9:17], 'little')])
        with pytest.raises(BagReadError, match='no /suspension/deflections'):
            bagio.read_drive_bag(folder)

    def assert_subset(self, d, full):
        keep = np.isin(full.stamps_ns, d.stamps_ns)
        assert keep.sum() == d.stamps_ns.size
        np.testing.assert_array_equal(d.q_m, full.q_m[keep])
        np.testing.assert_array_equal(d.roll_rad, full.roll_rad[keep])
        return keep

    def test_a_chunk_that_fails_its_crc_is_skipped_and_reading_goes_on(self, drive):
        folder, mcap, full = drive
        data = bytearray(mcap.read_bytes())
        chunks = [at for op, at, _ in top_level_records(bytes(data)) if op == 0x06]
        assert len(chunks) >= 2
        at = (chunks[0] + chunks[1]) // 2             # inside the first chunk's messages
        data[at:at + 300] = b'\xff' * 300
        mcap.write_bytes(bytes(data))
        d = bagio.read_drive_bag(folder)
        keep = self.assert_subset(d, full)
        assert 0 < keep.sum() < keep.size and keep[-1]   # a gap, then the rest of the drive
        assert len(d.issues) == 1 and 'CRC' in d.issues[0], d.issues

    def test_a_corrupt_record_ends_the_read_with_a_message(self, drive):
        folder, mcap, full = drive
        data = bytearray(mcap.read_bytes())
        second = [at for op, at, _ in top_level_records(bytes(data)) if op == 0x06][1]
        data[second] = 0x33                            # not an MCAP opcode
        mcap.write_bytes(bytes(data))
        d = bagio.read_drive_bag(folder)
        self.assert_prefix(d, full)
        assert len(d.issues) == 1 and 'corrupt record (op 0x33)' in d.issues[0], d.issues

    @pytest.mark.parametrize('compression', ['zstd', 'lz4'])
    def test_compressed_chunks_of_other_writers(self, tmp_path, compression):
        """A bag folder holding only an .mcap written by the mcap library with compressed
        chunks (as rosbag2's zstd presets do): read whole, then cut inside a chunk."""
        from mcap.writer import CompressionType, Writer

        folder = tmp_path / 'foreign'
        folder.mkdir()
        path = folder / 'foreign_0.mcap'
        msgtype = 'geometry_msgs/msg/PointStamped'
        point = T[msgtype]
        with path.open('wb') as f:
            writer = Writer(f, compression=CompressionType[compression.upper()],
                            chunk_size=64 * 1024)
            writer.start(profile='ros2', library='test')
            sid = writer.register_schema(msgtype, 'ros2msg', TYPESTORE.generate_msgdef(
                msgtype, ros_version=2)[0].encode())
            cids = [writer.register_channel(t, 'cdr', sid, {'offered_qos_profiles': ''})
                    for t in ('/lpa/left', '/lpa/right')]
            for i in range(4000):
                for side, cid in enumerate(cids):
                    msg = point(header=header(BASE_NS + i, 'road'),
                                point=T['geometry_msgs/msg/Point'](x=0.1 * i, y=1.0 - 2 * side,
                                                                   z=1e-3 * i + side))
                    writer.add_message(cid, BASE_NS + i, bytes(TYPESTORE.serialize_cdr(
                        msg, msgtype)), BASE_NS + i)
            writer.finish()
        issues = []
        p = bagio.read_lpa_bag(folder, issues=issues)
        assert len(p) == 4000 and p.elevation_m[-1].tolist() == [1e-3 * 3999, 1e-3 * 3999 + 1]
        assert issues == ['no metadata.yaml: reading the .mcap files found in the folder']
        data = path.read_bytes()
        path.write_bytes(data[:len(data) // 2])
        issues = []
        p = bagio.read_lpa_bag(folder, issues=issues)
        assert 100 < len(p) < 4000
        np.testing.assert_array_equal(p.distance_m, 0.1 * np.arange(len(p)))
        assert any('ends inside the chunk' in line for line in issues), issues

    def test_missing_metadata_and_missing_files(self, drive, tmp_path):
        folder, mcap, full = drive
        (folder / 'metadata.yaml').unlink()
        d = bagio.read_drive_bag(folder)
        np.testing.assert_array_equal(d.q_m, full.q_m)
        assert any('no metadata.yaml' in line for line in d.issues)
        mcap.unlink()
        with pytest.raises(BagReadError, match='not an MCAP bag'):
            bagio.read_drive_bag(folder)
        with pytest.raises(BagReadError, match='no such bag'):
            bagio.read_drive_bag(tmp_path / 'nowhere')
        (tmp_path / 'empty').mkdir()
        (tmp_path / 'empty' / 'x.mcap').write_bytes(b'')
        issues = []
        assert list(bagio.iter_messages(tmp_path / 'empty', issues=issues)) == []
        assert any('not an MCAP file' in line for line in issues), issues


# --------------------------------------------------------------------------------------------

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
        with pytest.raises(BagWriteError, match='ROS time'):
            bagio.ns_to_stamps(np.array([2**31 * 10**9]))


# --------------------------------------------------------------------------------------------

class TestEstimateBag:
    def test_observer_topics(self, tmp_path):
        rng = np.random.default_rng(2)
        n = 50
        e = SimpleNamespace(
            stamp_ns=BASE_NS + 2_000_000 * np.arange(n), valid=np.ones(n, bool),
            distance_m=0.04 * np.arange(n), q_m=rng.normal(size=(n, 2)),
            dq=rng.normal(size=(n, 2)), roll_rad=rng.normal(size=n), droll=rng.normal(size=n),
            body_heave_m=rng.normal(size=n), body_heave_rate=rng.normal(size=n),
            wheel_heave_m=rng.normal(size=(n, 2)), wheel_heave_rate=rng.normal(size=(n, 2)),
            road_m=rng.normal(size=(n, 2)), wheel_load_n=rng.normal(2e4, 1e3, (n, 2)),
            ltr=rng.normal(size=n))
        e.valid[3] = False
        e.road_m[7, 1] = np.nan
        status = T['diagnostic_msgs/msg/DiagnosticStatus'](
            level=b'\x00'[0], name='observer', message='ok', hardware_id='', values=[])
        diag = T['diagnostic_msgs/msg/DiagnosticArray'](header=header(BASE_NS, ''),
                                                       status=[status])
        plain = [{'name': 'observer', 'level': 1, 'message': 'rejects',
                  'values': {'rejected': 3}}]
        result = bagio.write_estimate_bag(tmp_path / 'e', e, diagnostics=[
            (BASE_NS, diag), (BASE_NS + 10**9, plain)])
        assert result == {'written': 48, 'invalid': 1, 'nonfinite': 1}
        keep = np.ones(n, bool)
        keep[[3, 7]] = False
        cols = bagio.read_topic_columns(tmp_path / 'e', {
            '/observer/states': 'sensor_msgs/msg/JointState',
            '/wheel_load/left': 'geometry_msgs/msg/WrenchStamped',
            '/road_profile/right': 'geometry_msgs/msg/PointStamped',
            '/load_transfer_ratio': 'std_msgs/msg/Float64'})
        (g,) = cols['/observer/states'].groups
        assert g.layout.strings['name'] == interfaces.STATE_JOINTS
        np.testing.assert_array_equal(g.columns['position'][:, 3], e.body_heave_m[keep])
        np.testing.assert_array_equal(g.columns['velocity'][:, 4:], e.wheel_heave_rate[keep])
        np.testing.assert_array_equal(g.columns['velocity'][:, 2], e.droll[keep])
        load, _ = cols['/wheel_load/left'].column('wrench.force.z')
        np.testing.assert_array_equal(load, e.wheel_load_n[keep, 0])
        y, _ = cols['/road_profile/right'].column('point.y')
        assert set(y.tolist()) == {-1.0}
        ltr, _ = cols['/load_transfer_ratio'].column('data')
        np.testing.assert_array_equal(ltr, e.ltr[keep])
        stamps, ok = cols['/wheel_load/left'].stamps_ns()
        assert ok.all()
        np.testing.assert_array_equal(stamps, e.stamp_ns[keep])
        np.testing.assert_array_equal(cols['/wheel_load/left'].log_ns, e.stamp_ns[keep])
        diags = list(bagio.iter_messages(tmp_path / 'e', ['/diagnostics']))
        assert [m.status[0].name for _, _, m in diags] == ['observer', 'observer']
        last = diags[1][2]
        assert (last.header.stamp.sec, last.status[0].level, last.status[0].values[0].value) \
            == (BASE_NS // 10**9 + 1, 1, '3')
        with pytest.raises(ValueError, match='diagnostic level'):
            bagio.diagnostic_array(0, [{'name': 'x', 'level': 7}])
