"""Reading chunks through their message indexes (bagio.reader's fast path): the same columns as
the record-by-record walk (the reference path, forced with ``reader.USE_MESSAGE_INDEX = False``)
and as
the ``mcap`` library's own reader, on bags of this module's writer and of the ``mcap`` writer
(compressed chunks, schemas and channels inside chunks, several channels on one topic,
messages of varying size), and a fallback to the walk for every chunk whose index is missing,
wrong or incomplete."""
import dataclasses
from pathlib import Path
import struct
from types import SimpleNamespace
import zlib

from mcap.reader import make_reader
from mcap_walk import top_level_records
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest

from road_force_estimator import bagio, interfaces
from road_force_estimator.bagio import BagWriter, mcap_scan
from road_force_estimator.serde import TYPESTORE
from road_force_estimator.bagio import reader as bag_reader

T = TYPESTORE.types
BASE_NS = bagio.DEFAULT_START_STAMP_NS
ALL_TOPICS = {t: interfaces.TOPIC_TYPES[t] for t in (
    (interfaces.DEFLECTIONS, interfaces.TWIST, interfaces.FIX)
    + interfaces.TRUE_LOAD + interfaces.TRUE_ROAD)}


def header(stamp_ns, frame):
    return T['std_msgs/msg/Header'](
        stamp=T['builtin_interfaces/msg/Time'](sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9),
        frame_id=frame)


def joint_state(stamp_ns, names, position, velocity=()):
    return T['sensor_msgs/msg/JointState'](
        header=header(stamp_ns, 'base_link'), name=list(names),
        position=np.asarray(position, float), velocity=np.asarray(velocity, float),
        effort=np.zeros(0))


def point(stamp_ns, x, y, z):
    return T['geometry_msgs/msg/PointStamped'](
        header=header(stamp_ns, 'road'), point=T['geometry_msgs/msg/Point'](x=x, y=y, z=z))


def write_drive(folder, n=12000, seed=3):
    """A drive of n samples at 1 kHz with ground truth and 10 Hz fixes (several chunks)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 1000.0
    trajectory = SimpleNamespace(t_s=t, distance_m=20.0 * t, speed_mps=20.0,
                                 wheel_load_n=rng.normal(25000.0, 800.0, (n, 2)),
                                 road_m=rng.normal(0.0, 0.004, (n, 2)))
    fixes = SimpleNamespace(time_s=t[::100], latitude_deg=48.1 + 1e-6 * np.arange(t[::100].size),
                            longitude_deg=np.full(t[::100].size, 17.1))
    bagio.write_drive_bag(folder, trajectory, rng.normal(0.0, 0.01, (n, 2)),
                           rng.normal(0.0, 0.002, n), fixes=fixes)
    (mcap,) = Path(folder).glob('*.mcap')
    return mcap


def read_columns(path, topics, *, indexed, monkeypatch):
    monkeypatch.setattr(bag_reader, 'USE_MESSAGE_INDEX', indexed)
    issues = []
    cols = bagio.read_topic_columns(path, topics, issues=issues)
    return cols, issues


def read_drive(path, *, indexed, monkeypatch):
    monkeypatch.setattr(bag_reader, 'USE_MESSAGE_INDEX', indexed)
    return bagio.read_drive_bag(path)


def scan_counts(mcap):
    """(chunks read through their index, chunks walked) of one .mcap file."""
    scan = mcap_scan.McapScan(Path(mcap), lambda channel: True, indexed=True)
    for _ in scan.batches():
        pass
    return scan.indexed_chunks, scan.walked_chunks


def assert_same_columns(a, b):
    assert a.keys() == b.keys()
    for topic in a:
        x, y = a[topic], b[topic]
        assert (x.msgtype, x.wrong_type) == (y.msgtype, y.wrong_type), topic
        np.testing.assert_array_equal(x.log_ns, y.log_ns)
        np.testing.assert_array_equal(x.undecodable, y.undecodable)
        gx = sorted(x.groups, key=lambda g: int(g.index[0]))
        gy = sorted(y.groups, key=lambda g: int(g.index[0]))
        assert len(gx) == len(gy), topic
        for p, q in zip(gx, gy):
            np.testing.assert_array_equal(p.index, q.index)
            assert p.layout.strings == q.layout.strings and p.columns.keys() == q.columns.keys()
            for path in p.columns:
                assert p.columns[path].dtype == q.columns[path].dtype, (topic, path)
                np.testing.assert_array_equal(p.columns[path], q.columns[path])


def assert_same_drive(a, b, where='drive'):
    if dataclasses.is_dataclass(a):
        assert type(a) is type(b), where
        for f in dataclasses.fields(a):
            assert_same_drive(getattr(a, f.name), getattr(b, f.name), f'{where}.{f.name}')
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape, where
        np.testing.assert_array_equal(a, b, err_msg=where)
    else:
        assert a == b, where


def chunk_layout(data, at):
    """(records start, records length, crc field position) of the uncompressed chunk at
    byte ``at``, and the (offset, length) of the message index records after it."""
    body = at + 9
    (n,) = struct.unpack_from('<I', data, body + 28)
    assert n == 0                                    # uncompressed
    (rlen,) = struct.unpack_from('<Q', data, body + 32)
    rstart = body + 40
    pos = rstart + rlen
    index = []
    while data[pos] == 0x07:
        (length,) = struct.unpack_from('<Q', data, pos + 1)
        index.append((pos, length))
        pos += 9 + length
    return rstart, rlen, body + 24, index


class TestOwnBags:
    @pytest.fixture(scope='class')
    def drive(self, tmp_path_factory):
        folder = tmp_path_factory.mktemp('fast') / 'drive'
        mcap = write_drive(folder)
        return folder, mcap

    def test_index_and_walk_read_the_same(self, drive, monkeypatch):
        folder, mcap = drive
        fast, issues_fast = read_columns(folder, ALL_TOPICS, indexed=True,
                                         monkeypatch=monkeypatch)
        walk, issues_walk = read_columns(folder, ALL_TOPICS, indexed=False,
                                         monkeypatch=monkeypatch)
        assert_same_columns(fast, walk)
        assert issues_fast == issues_walk == []
        assert_same_drive(read_drive(folder, indexed=True, monkeypatch=monkeypatch),
                          read_drive(folder, indexed=False, monkeypatch=monkeypatch))
        chunks = sum(1 for op, _, _ in top_level_records(mcap.read_bytes()) if op == 0x06)
        assert chunks >= 4 and scan_counts(mcap) == (chunks, 0)
        # The mcap library's reader (file order) finds the same messages and log times.
        logs = {}
        with mcap.open('rb') as f:
            for _, channel, message in make_reader(f).iter_messages(log_time_order=False):
                logs.setdefault(channel.topic, []).append(message.log_time)
        assert {t: len(v) for t, v in logs.items()} == {t: c.count for t, c in fast.items()}
        for topic, c in fast.items():
            np.testing.assert_array_equal(c.log_ns, logs[topic])

    def test_fields_selects_the_numbers_decoded(self, drive):
        folder, _ = drive
        want = ['header.stamp.sec', 'twist.linear.x']
        topics = {interfaces.TWIST: interfaces.TOPIC_TYPES[interfaces.TWIST]}
        some = bagio.read_topic_columns(folder, topics, fields={interfaces.TWIST: want})
        full = bagio.read_topic_columns(folder, topics)
        (g,), (h,) = some[interfaces.TWIST].groups, full[interfaces.TWIST].groups
        assert sorted(g.columns) == sorted(want) and len(h.columns) == 8
        for path in want:
            np.testing.assert_array_equal(g.columns[path], h.columns[path])

    def test_bad_messages_are_read_the_same(self, tmp_path, monkeypatch):
        """Undecodable, big-endian, other names and lengths, NaN, repeated stamps, in every
        chunk: the same columns and rejections through the index as by the walk."""
        names = list(interfaces.DEFLECTION_JOINTS)
        rng = np.random.default_rng(5)
        with BagWriter(tmp_path / 'b') as bag:
            bag.add_topic(interfaces.DEFLECTIONS, 'sensor_msgs/msg/JointState')
            bag.add_topic(interfaces.TWIST, 'geometry_msgs/msg/TwistStamped')
            bag.add_topic(interfaces.TRUE_LOAD[0], 'std_msgs/msg/Float64')   # wrong type
            v3 = T['geometry_msgs/msg/Vector3']
            for i in range(6000):
                s = BASE_NS + 1000 * i - (2500 if i % 501 == 0 and i else 0)   # backwards
                kind = i % 97           # 1 to 7: a bad or odd message, 62 of each
                if kind in (1, 7):      # undecodable: cut, empty
                    bag.write_raw(interfaces.DEFLECTIONS, s,
                                  b'\x00\x01\x00\x00\x07' if kind == 1 else b'')
                    continue
                msg = joint_state(s, names if kind != 2 else names[::-1],
                                  rng.normal(size=3) if kind != 3 else [np.nan, 0.0, 0.0],
                                  () if kind != 4 else [1.0, 2.0])
                if kind == 5:
                    msg = joint_state(s, names[:2], [0.1, 0.2])
                if kind == 6:
                    bag.write_raw(interfaces.DEFLECTIONS, s, bytes(TYPESTORE.serialize_cdr(
                        msg, 'sensor_msgs/msg/JointState', little_endian=False)))
                else:
                    bag.write(interfaces.DEFLECTIONS, s, msg)
                if i % 3 == 0:
                    tw = T['geometry_msgs/msg/TwistStamped'](
                        header=header(s, 'base_link'), twist=T['geometry_msgs/msg/Twist'](
                            linear=v3(x=float(i), y=0.0, z=0.0), angular=v3(x=0.0, y=0.0,
                                                                            z=0.0)))
                    bag.write(interfaces.TWIST, s, tw)
                if i % 1000 == 0:
                    bag.write(interfaces.TRUE_LOAD[0], s, T['std_msgs/msg/Float64'](data=1.0))
        (mcap,) = (tmp_path / 'b').glob('*.mcap')
        indexed, walked = scan_counts(mcap)
        assert indexed >= 2 and walked == 0
        fast, _ = read_columns(tmp_path / 'b', ALL_TOPICS, indexed=True, monkeypatch=monkeypatch)
        walk, _ = read_columns(tmp_path / 'b', ALL_TOPICS, indexed=False,
                               monkeypatch=monkeypatch)
        assert_same_columns(fast, walk)
        a = read_drive(tmp_path / 'b', indexed=True, monkeypatch=monkeypatch)
        b = read_drive(tmp_path / 'b', indexed=False, monkeypatch=monkeypatch)
        assert_same_drive(a, b)
        assert a.rejected[interfaces.DEFLECTIONS] == {
            'undecodable': 124, 'nonfinite': 62, 'length_mismatch': 62, 'missing_name': 62,
            'backwards_stamp': 11}
        assert a.rejected[interfaces.TRUE_LOAD[0]] == {'wrong_type (std_msgs/msg/Float64)': 6}
        # Big-endian messages are converted (kind 6), reversed names mapped (kind 2).
        big = fast[interfaces.DEFLECTIONS]
        assert sum(g.index.size == 1 for g in big.groups) == 62

    @staticmethod
    def broken(data, how, chunk):
        """A copy of the file's bytes with the message index of chunk number ``chunk`` (or
        one of its records) broken in one way."""
        data = bytearray(data)
        at = [a for op, a, _ in top_level_records(bytes(data)) if op == 0x06][chunk]
        rstart, rlen, crc_at, index = chunk_layout(data, at)
        cids = [struct.unpack_from('<H', data, pos + 9)[0] for pos, _ in index]
        if how == 'missing':                 # index records turned into private records
            for pos, _ in index:
                data[pos] = 0x80
        elif how == 'offset':                # one offset one byte off
            pos, _ = index[1]
            (off,) = struct.unpack_from('<Q', data, pos + 15 + 16 * 5 + 8)
            struct.pack_into('<Q', data, pos + 15 + 16 * 5 + 8, off + 1)
        elif how == 'swapped_channels':      # the same offsets, under the wrong channels
            twist, deflections = (cids.index(c) for c in (1, 2))
            struct.pack_into('<H', data, index[twist][0] + 9, 2)
            struct.pack_into('<H', data, index[deflections][0] + 9, 1)
        elif how == 'dropped_entry':         # one message left out of its channel's index
            pos, _ = index[cids.index(2)]
            (nbytes,) = struct.unpack_from('<I', data, pos + 11)
            last = pos + 15 + nbytes - 16
            data[pos + 15 + 16 * 7:pos + 15 + 16 * 8] = data[last:last + 16]
            struct.pack_into('<I', data, pos + 11, nbytes - 16)
        elif how == 'not_a_message':         # an indexed record turned private (CRC fixed)
            pos, _ = index[cids.index(2)]
            (off,) = struct.unpack_from('<Q', data, pos + 15 + 16 * 9 + 8)
            assert data[rstart + off] == 0x05
            data[rstart + off] = 0x80
            struct.pack_into('<I', data, crc_at, zlib.crc32(data[rstart:rstart + rlen]))
        return bytes(data)

    @pytest.mark.parametrize('how', ['missing', 'offset', 'swapped_channels', 'dropped_entry',
                                     'not_a_message'])
    def test_a_broken_index_falls_back_to_the_walk(self, drive, tmp_path, monkeypatch, how):
        folder, mcap = drive
        good = read_drive(folder, indexed=True, monkeypatch=monkeypatch)
        copy = tmp_path / 'copy'
        copy.mkdir()
        (copy / mcap.name).write_bytes(self.broken(mcap.read_bytes(), how, chunk=2))
        (copy / 'metadata.yaml').write_bytes((folder / 'metadata.yaml').read_bytes())
        chunks = sum(1 for op, _, _ in top_level_records(mcap.read_bytes()) if op == 0x06)
        assert scan_counts(copy / mcap.name) == (chunks - 1, 1)
        fast = read_drive(copy, indexed=True, monkeypatch=monkeypatch)
        walk = read_drive(copy, indexed=False, monkeypatch=monkeypatch)
        assert_same_drive(fast, walk)
        assert fast.issues == ()
        if how == 'not_a_message':           # the walk skips the private record
            assert fast.messages[interfaces.DEFLECTIONS] == \
                good.messages[interfaces.DEFLECTIONS] - 1
        else:
            assert_same_drive(fast, good)

    def test_cut_files_read_the_same(self, drive, tmp_path, monkeypatch):
        folder, mcap = drive
        data = mcap.read_bytes()
        chunks = [a for op, a, _ in top_level_records(data) if op == 0x06]
        copy = tmp_path / 'cut'
        copy.mkdir()
        # Inside a chunk, inside the message index after a chunk, at a chunk's start.
        for cut in (chunks[2] + 5000, chunks[3] - 100, chunks[3]):
            (copy / mcap.name).write_bytes(data[:cut])
            fast = read_drive(copy, indexed=True, monkeypatch=monkeypatch)
            walk = read_drive(copy, indexed=False, monkeypatch=monkeypatch)
            assert_same_drive(fast, walk)
            assert len(fast.issues) == 2 and 'read ' in fast.issues[1], fast.issues


class TestMcapLibraryBags:
    @staticmethod
    def write(path, compression):
        """Three topics interleaved, /p on two channels (the second declared mid-way, inside
        a chunk), JointStates of 1 to 3 joints, small chunks."""
        from mcap.writer import CompressionType, Writer

        msgdef = {t: TYPESTORE.generate_msgdef(t, ros_version=2)[0].encode() for t in (
            'geometry_msgs/msg/PointStamped', 'sensor_msgs/msg/JointState',
            'std_msgs/msg/Float64')}
        rng = np.random.default_rng(7)
        with path.open('wb') as f:
            writer = Writer(f, compression=CompressionType[compression.upper()],
                            chunk_size=16 * 1024)
            writer.start(profile='ros2', library='test')
            sids = {t: writer.register_schema(t, 'ros2msg', d) for t, d in msgdef.items()}
            cp = writer.register_channel('/p', 'cdr', sids['geometry_msgs/msg/PointStamped'])
            cj = writer.register_channel('/j', 'cdr', sids['sensor_msgs/msg/JointState'])
            cf = writer.register_channel('/f', 'cdr', sids['std_msgs/msg/Float64'])
            cp2 = None
            for i in range(3000):
                s = BASE_NS + 1000 * i
                if i == 1500:
                    cp2 = writer.register_channel('/p', 'cdr',
                                                  sids['geometry_msgs/msg/PointStamped'])
                writer.add_message(cp, s, bytes(TYPESTORE.serialize_cdr(
                    point(s, 0.1 * i, 1.0, rng.normal()), 'geometry_msgs/msg/PointStamped')), s)
                k = 1 + i % 3
                names = [f'joint_{j}' * (1 + (i // 7) % 2) for j in range(k)]
                writer.add_message(cj, s, bytes(TYPESTORE.serialize_cdr(
                    joint_state(s, names, rng.normal(size=k)), 'sensor_msgs/msg/JointState')), s)
                if cp2 is not None and i % 2:
                    writer.add_message(cp2, s + 1, bytes(TYPESTORE.serialize_cdr(
                        point(s + 1, -0.1 * i, -1.0, rng.normal()),
                        'geometry_msgs/msg/PointStamped')), s + 1)
                if i % 7 == 0:
                    writer.add_message(cf, s, bytes(TYPESTORE.serialize_cdr(
                        T['std_msgs/msg/Float64'](data=float(i)), 'std_msgs/msg/Float64')), s)
            writer.finish()

    @pytest.mark.parametrize('compression', ['none', 'zstd', 'lz4'])
    def test_same_as_the_mcap_reader(self, tmp_path, monkeypatch, compression):
        path = tmp_path / 'm.mcap'
        self.write(path, compression)
        topics = {'/p': 'geometry_msgs/msg/PointStamped', '/j': 'sensor_msgs/msg/JointState',
                  '/f': 'std_msgs/msg/Float64'}
        fast, issues = read_columns(path, topics, indexed=True, monkeypatch=monkeypatch)
        walk, _ = read_columns(path, topics, indexed=False, monkeypatch=monkeypatch)
        assert_same_columns(fast, walk)
        assert issues == []
        indexed, walked = scan_counts(path)
        assert indexed >= 10 and walked >= 2     # chunks with schemas or channels: walked
        # The mcap library with mcap-ros2-support: every message in file order.
        ref = {}
        with path.open('rb') as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            for _, channel, message, msg in reader.iter_decoded_messages(
                    log_time_order=False):
                ref.setdefault(channel.topic, []).append((message.log_time, msg))
        assert {t: c.count for t, c in fast.items()} == {t: len(v) for t, v in ref.items()}
        for topic, c in fast.items():
            np.testing.assert_array_equal(c.log_ns, [t for t, _ in ref[topic]])
            assert c.undecodable.size == 0
        p = fast['/p']
        for axis in 'xyz':
            values, present = p.column(f'point.{axis}')
            assert present.all()
            np.testing.assert_array_equal(values, [getattr(m.point, axis) for _, m in ref['/p']])
        stamps, valid = p.stamps_ns()
        assert valid.all()
        np.testing.assert_array_equal(
            stamps, [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for _, m in ref['/p']])
        np.testing.assert_array_equal(fast['/f'].column('data')[0],
                                      [m.data for _, m in ref['/f']])
        j = fast['/j']
        assert len(j.groups) == 6                # 1 to 3 joints, two name lengths
        seen = 0
        for g in j.groups:
            for i, position in zip(g.index.tolist(), g.columns['position']):
                msg = ref['/j'][i][1]
                assert list(g.layout.strings['name']) == list(msg.name)
                np.testing.assert_array_equal(position, msg.position)
                seen += 1
        assert seen == 3000
