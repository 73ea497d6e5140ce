"""Bag writing in blocks (bagio.BagWriter.write_rows, write_estimate_bag, write_drive_bag):
every message, its order, log and publish times and sequence number, checked by the mcap and
mcap-ros2-support readers, rosbags' AnyReader and an MCAP walk written here (chunk CRCs,
message and chunk indexes, statistics, data and summary CRCs, where chunks end), with small
chunk and block sizes so that chunks and blocks end anywhere, also inside a row."""
import os
from pathlib import Path
import struct
from types import SimpleNamespace
import zlib

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest
from rosbags.highlevel import AnyReader
import yaml

from road_force_estimator import bagio, interfaces
from road_force_estimator import serde
from road_force_estimator.bagio import BagWriter, mcap_file
from road_force_estimator.serde import TYPESTORE, cdr

T = TYPESTORE.types
BASE_NS = bagio.DEFAULT_START_STAMP_NS
MAGIC = b'\x89MCAP0\r\n'


# --------------------------------------------------------------------------------------------
# An MCAP walk of its own (the MCAP specification, uncompressed chunks)

def _string(buf, pos):
    (n,) = struct.unpack_from('<I', buf, pos)
    return buf[pos + 4:pos + 4 + n].decode(), pos + 4 + n


def _records(buf, start, end):
    pos = start
    while pos < end:
        op, length = struct.unpack_from('<BQ', buf, pos)
        yield op, pos, buf[pos + 9:pos + 9 + length]
        pos += 9 + length
    assert pos == end


def check_mcap(folder, chunk_bytes):
    """Check the structure of the folder's .mcap file; return its messages in file order as
    (cid, sequence, log_ns, publish_ns, data)."""
    (path,) = Path(folder).glob('*.mcap')
    buf = path.read_bytes()
    assert buf[:8] == MAGIC and buf[-8:] == MAGIC
    footer = len(buf) - 8 - 29
    assert struct.unpack_from('<BQ', buf, footer) == (0x02, 20)
    summary_start, offsets_start, summary_crc = struct.unpack_from('<QQI', buf, footer + 9)
    assert summary_crc == zlib.crc32(buf[summary_start:footer + 25])

    messages, chunks, index_at = [], [], {}
    top = _records(buf, 8, summary_start)
    for op, pos, body in top:
        if op == 0x0F:                                   # data end: CRC of all before it
            assert struct.unpack('<I', body) == (zlib.crc32(buf[:pos]),)
            break
        if op == 0x07:
            index_at[pos] = body
        if op != 0x06:
            continue
        start, end, size, crc = struct.unpack_from('<QQQI', body, 0)
        compression, at = _string(body, 28)
        (records_len,) = struct.unpack_from('<Q', body, at)
        records = body[at + 8:]
        assert compression == '' and size == records_len == len(records)
        assert crc == zlib.crc32(records)
        inner = []
        for rop, rpos, rbody in _records(records, 0, len(records)):
            assert rop == 0x05
            cid, seq, log, pub = struct.unpack_from('<HIQQ', rbody, 0)
            inner.append((rpos, cid, seq, log, pub, bytes(rbody[22:])))
        assert (start, end) == (min(m[3] for m in inner), max(m[3] for m in inner))
        last_record = len(records) - inner[-1][0]
        chunks.append((pos, 9 + len(body), len(records), last_record, inner))
        messages += [m[1:] for m in inner]
    else:
        pytest.fail('no data end record')
    # Every chunk but the last closes after the record that reaches chunk_bytes.
    for _, _, size, last_record, _ in chunks[:-1]:
        assert size >= chunk_bytes > size - last_record
    if chunks:
        assert chunks[-1][2] - chunks[-1][3] < chunk_bytes

    # Summary: chunk indexes point at the chunks and their message indexes, which list each
    # channel's records by log time then offset; statistics count everything.
    chunk_indexes, stats = [], None
    for op, _, body in _records(buf, summary_start, offsets_start):
        if op == 0x08:
            chunk_indexes.append(body)
        elif op == 0x0B:
            stats = body
    assert len(chunk_indexes) == len(chunks)
    for body, (pos, length, size, _, inner) in zip(chunk_indexes, chunks):
        start, end, chunk_start, chunk_length, map_len = struct.unpack_from('<QQQQI', body, 0)
        assert (chunk_start, chunk_length) == (pos, length)
        assert (start, end) == (min(m[3] for m in inner), max(m[3] for m in inner))
        offsets = dict(struct.iter_unpack('<HQ', body[36:36 + map_len]))
        (index_length,) = struct.unpack_from('<Q', body, 36 + map_len)
        assert sorted(offsets) == sorted({m[1] for m in inner}) == list(offsets)
        assert list(offsets.values()) == sorted(offsets.values())
        assert min(offsets.values()) == pos + length
        total = 0
        for cid, at in offsets.items():
            index = index_at[at]
            (icid, n_bytes) = struct.unpack_from('<HI', index, 0)
            pairs = list(struct.iter_unpack('<QQ', index[6:6 + n_bytes]))
            assert icid == cid and 6 + n_bytes == len(index)
            assert pairs == sorted((m[3], m[0]) for m in inner if m[1] == cid)
            total += 9 + len(index)
        assert total == index_length
        _, at = _string(body, 44 + map_len)
        assert struct.unpack_from('<QQ', body, at) == (size, size)
    count, _, _, _, _, n_chunks, first, last, map_len = struct.unpack_from('<QHIIIIQQI', stats)
    per_channel = dict(struct.iter_unpack('<HQ', stats[46:46 + map_len]))
    assert count == len(messages) and n_chunks == len(chunks)
    if messages:
        assert (first, last) == (min(m[2] for m in messages), max(m[2] for m in messages))
    for cid, n in per_channel.items():
        assert n == sum(1 for m in messages if m[0] == cid)
    return messages


def read_decoded(folder):
    """(topic, sequence, log_ns, publish_ns, decoded message) in file order, CRCs checked."""
    (path,) = Path(folder).glob('*.mcap')
    with path.open('rb') as f:
        reader = make_reader(f, validate_crcs=True, decoder_factories=[DecoderFactory()])
        return [(channel.topic, message.sequence, message.log_time, message.publish_time, ros)
                for _, channel, message, ros in reader.iter_decoded_messages(
                    log_time_order=False)]


def rosbags_counts(folder):
    with AnyReader([Path(folder)], default_typestore=TYPESTORE) as reader:
        counts = {}
        for connection, _, raw in reader.messages():
            reader.deserialize(raw, connection.msgtype)
            counts[connection.topic] = counts.get(connection.topic, 0) + 1
        return counts


def assert_sequences(messages):
    """Sequence numbers count each channel's messages in file order from 0."""
    seen = {}
    for cid, seq, *_ in messages:
        assert seq == seen.get(cid, 0)
        seen[cid] = seq + 1


@pytest.fixture(params=[None, (2000, 5000), (300, 900), (1, 1)],
                ids=['default', 'chunk2000_block5000', 'chunk300_block900', 'chunk1_block1'])
def sizes(request, monkeypatch):
    """Chunk and block sizes (bytes): chunks and blocks end inside rows and records."""
    if request.param is None:
        return mcap_file.McapFile.CHUNK_BYTES
    chunk, block = request.param
    monkeypatch.setattr(mcap_file.McapFile, 'CHUNK_BYTES', chunk)
    monkeypatch.setattr(BagWriter, 'BLOCK_BYTES', block)
    monkeypatch.setattr(BagWriter, 'BLOCK_MESSAGES', 7)
    return chunk


# --------------------------------------------------------------------------------------------

def estimates(n, seed):
    rng = np.random.default_rng(seed)
    stamps = BASE_NS + np.cumsum(rng.integers(1, 3, n)) * 1_000_000
    e = SimpleNamespace(
        stamp_ns=stamps, wheel_load_n=rng.normal(25000.0, 900.0, (n, 2)),
        distance_m=np.arange(n) * 0.02, road_m=rng.normal(0.0, 0.01, (n, 2)),
        ltr=rng.normal(0.0, 0.1, n), q_m=rng.normal(0.0, 0.01, (n, 2)),
        roll_rad=rng.normal(0.0, 0.01, n), body_heave_m=rng.normal(0.0, 0.01, n),
        wheel_heave_m=rng.normal(0.0, 0.01, (n, 2)), dq=rng.normal(0.0, 0.1, (n, 2)),
        droll=rng.normal(0.0, 0.1, n), body_heave_rate=rng.normal(0.0, 0.1, n),
        wheel_heave_rate=rng.normal(0.0, 0.1, (n, 2)), valid=rng.random(n) > 0.1)
    e.ltr[rng.random(n) < 0.05] = np.nan
    e.wheel_heave_rate[rng.random(n) < 0.05, 1] = -np.inf
    return e


class TestEstimateBag:
    def test_every_message_in_order_with_indexes(self, tmp_path, sizes):
        n = 120
        e = estimates(n, 3)
        ok = e.valid & np.isfinite(e.ltr) & np.isfinite(e.wheel_heave_rate[:, 1])
        rows = np.flatnonzero(ok)
        s = e.stamp_ns
        invalid = int(np.flatnonzero(~ok)[0])
        diag_stamps = [BASE_NS - 5, s[rows[0]], s[rows[0]] + 1, s[rows[3]], s[rows[3]],
                       s[invalid], s[rows[40]] + 999, s[rows[-1]], s[rows[-1]] + 10**9]
        diagnostics = [(int(t), [{'name': f'd{i}', 'level': i % 4, 'message': 'x' * (3 * i),
                                  'values': {'k': 'v' * i}}])
                       for i, t in enumerate(diag_stamps)]
        result = bagio.write_estimate_bag(tmp_path / 'e', e, diagnostics=diagnostics,
                                           track_width_m=1.6)
        assert result == {'written': rows.size, 'invalid': int(np.count_nonzero(~e.valid)),
                          'nonfinite': int(np.count_nonzero(e.valid & ~ok))}

        # What must be there, in write order: by stamp, then the topics' order, then
        # position in the stream.
        topics = [*interfaces.LOAD, *interfaces.ROAD, interfaces.LTR,
                  interfaces.STATES]
        expected = [(int(s[i]), j, i, topic) for i in rows.tolist()
                    for j, topic in enumerate(topics)]
        expected += [(t, len(topics), i, interfaces.DIAGNOSTICS)
                     for i, (t, _) in enumerate(diagnostics)]
        expected.sort()

        walked = check_mcap(tmp_path / 'e', sizes)
        assert_sequences(walked)
        got = read_decoded(tmp_path / 'e')
        assert [(g[0], g[2], g[3]) for g in got] == [(x[3], x[0], x[0]) for x in expected]
        for (_, _, i, topic), (_, _, _, _, msg) in zip(expected, got):
            if topic == interfaces.DIAGNOSTICS:
                assert msg.status[0].name == f'd{i}' and msg.status[0].message == 'x' * (3 * i)
                continue
            if topic != interfaces.LTR:
                assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == s[i]
            if topic in interfaces.LOAD:
                side = interfaces.LOAD.index(topic)
                assert msg.wrench.force.z == e.wheel_load_n[i, side]
                assert msg.header.frame_id == interfaces.WHEEL_FRAMES[side]
            elif topic in interfaces.ROAD:
                side = interfaces.ROAD.index(topic)
                assert (msg.point.x, msg.point.y, msg.point.z) == (
                    e.distance_m[i], 0.8 if side == 0 else -0.8, e.road_m[i, side])
            elif topic == interfaces.LTR:
                assert msg.data == e.ltr[i]
            else:
                assert list(msg.name) == list(interfaces.STATE_JOINTS)
                assert list(msg.position) == [*e.q_m[i], e.roll_rad[i], e.body_heave_m[i],
                                              *e.wheel_heave_m[i]]
                assert list(msg.velocity) == [*e.dq[i], e.droll[i], e.body_heave_rate[i],
                                              *e.wheel_heave_rate[i]]
        counts = rosbags_counts(tmp_path / 'e')
        assert counts == {**{t: rows.size for t in topics},
                          interfaces.DIAGNOSTICS: len(diagnostics)}

    def test_no_row_to_write_keeps_the_diagnostics(self, tmp_path):
        e = estimates(6, 4)
        e.valid[:] = False
        diagnostics = [(BASE_NS + 7, [{'name': 'only', 'level': 1, 'message': 'no rows'}])]
        result = bagio.write_estimate_bag(tmp_path / 'e', e, diagnostics=diagnostics)
        assert result == {'written': 0, 'invalid': 6, 'nonfinite': 0}
        got = read_decoded(tmp_path / 'e')
        assert [(g[0], g[2], g[4].status[0].message) for g in got] == [
            (interfaces.DIAGNOSTICS, BASE_NS + 7, 'no rows')]
        assert len(check_mcap(tmp_path / 'e', mcap_file.McapFile.CHUNK_BYTES)) == 1
        meta = yaml.safe_load((tmp_path / 'e' / 'metadata.yaml').read_text())
        counts = {t['topic_metadata']['name']: t['message_count']
                  for t in meta['rosbag2_bagfile_information']['topics_with_message_count']}
        assert counts == {**{t: 0 for t in (*interfaces.LOAD, *interfaces.ROAD,
                                            interfaces.LTR, interfaces.STATES)},
                          interfaces.DIAGNOSTICS: 1}


class TestDriveBag:
    def test_fixes_go_after_the_sample_topics_at_equal_stamps(self, tmp_path, sizes):
        n, rate = 150, 1000.0
        rng = np.random.default_rng(5)
        t = np.arange(n) / rate
        trajectory = SimpleNamespace(t_s=t, distance_m=20.0 * t, speed_mps=20.0,
                                     wheel_load_n=rng.normal(25000.0, 800.0, (n, 2)),
                                     road_m=rng.normal(0.0, 0.004, (n, 2)))
        q, roll = rng.normal(0.0, 0.01, (n, 2)), rng.normal(0.0, 0.002, n)
        fix_t = np.array([-0.5, 0.0, 0.0005, 0.010, 0.010, 0.0731, 0.149, 0.149, 0.2])
        fixes = SimpleNamespace(time_s=fix_t, latitude_deg=48.0 + np.arange(fix_t.size),
                                longitude_deg=np.full(fix_t.size, 11.0))
        count = bagio.write_drive_bag(tmp_path / 'd', trajectory, q, roll, fixes=fixes)
        assert count == 6 * n + fix_t.size

        stamps = BASE_NS + np.round(t * 1e9).astype(np.int64)
        fix_stamps = BASE_NS + np.round(fix_t * 1e9).astype(np.int64)
        topics = [interfaces.TWIST, interfaces.DEFLECTIONS, *interfaces.TRUE_LOAD,
                  *interfaces.TRUE_ROAD]
        expected = sorted([(int(stamps[i]), j, i, topic) for i in range(n)
                           for j, topic in enumerate(topics)]
                          + [(int(fix_stamps[i]), 6, i, interfaces.FIX)
                             for i in range(fix_t.size)])
        walked = check_mcap(tmp_path / 'd', sizes)
        assert_sequences(walked)
        got = read_decoded(tmp_path / 'd')
        assert [(g[0], g[2], g[3]) for g in got] == [(x[3], x[0], x[0]) for x in expected]
        for (_, _, i, topic), (_, _, _, _, msg) in zip(expected, got):
            if topic == interfaces.FIX:
                assert msg.latitude == 48.0 + i and msg.header.frame_id == 'gnss'
            elif topic == interfaces.DEFLECTIONS:
                assert list(msg.position) == [q[i, 0], q[i, 1], roll[i]]
            elif topic in interfaces.TRUE_ROAD:
                side = interfaces.TRUE_ROAD.index(topic)
                assert (msg.point.x, msg.point.z) == (trajectory.distance_m[i],
                                                      trajectory.road_m[i, side])
        assert sum(rosbags_counts(tmp_path / 'd').values()) == count


# --------------------------------------------------------------------------------------------

def float64_rows(values):
    return serde.encode_columns('std_msgs/msg/Float64',
                                serde.message_template('std_msgs/msg/Float64'), len(values),
                                {'data': np.asarray(values, dtype=float)})


def string_datas(texts):
    return [bytes(TYPESTORE.serialize_cdr(T['std_msgs/msg/String'](data=x), 'std_msgs/msg/String'))
            for x in texts]


class TestWriteRows:
    def test_any_streams_and_calls_are_merged_by_stamp(self, tmp_path, sizes):
        rng = np.random.default_rng(11)
        a = np.cumsum(rng.integers(1, 4, 300))
        b = a[::3] + rng.integers(0, 2, a[::3].size)        # some equal to a's stamps
        u = rng.integers(0, a[-1] + 5, 40)                   # not sorted, repeated
        texts = [f'u{i}' * int(rng.integers(0, 5)) for i in range(u.size)]
        calls = [
            ('msg', '/x', 10**6, 'late first'),
            ('rows', [('/a', a, float64_rows(a * 0.5)), ('/s', u, string_datas(texts)),
                      ('/c', b, float64_rows(-b)), ('/a', b[:5], float64_rows([7.0] * 5)),
                      ('/d', a, float64_rows(a + 0.25))]),
            ('msg', '/x', 3, 'early after'),
            ('rows', [('/c', [], np.zeros((0, 12), np.uint8)),
                      ('/d', a[:4], float64_rows(a[:4]))]),
            ('rows', []),
        ]
        expected = []
        with BagWriter(tmp_path / 'w') as bag:
            for topic in ('/a', '/c', '/d'):
                bag.add_topic(topic, 'std_msgs/msg/Float64')
            for topic in ('/s', '/x'):
                bag.add_topic(topic, 'std_msgs/msg/String')
            for call in calls:
                if call[0] == 'msg':
                    _, topic, stamp, text = call
                    bag.write(topic, stamp, T['std_msgs/msg/String'](data=text))
                    expected.append((topic, stamp, text))
                    continue
                merged = []
                for j, (topic, stamps, rows) in enumerate(call[1]):
                    for i, stamp in enumerate(np.asarray(stamps).tolist()):
                        value = texts[i] if topic == '/s' else \
                            float(np.frombuffer(bytes(rows[i][4:12]), '<f8')[0])
                        merged.append((stamp, j, i, topic, value))
                expected += [(m[3], m[0], m[4]) for m in sorted(merged)]
                bag.write_rows(call[1])
            assert bag.message_count == len(expected)
        walked = check_mcap(tmp_path / 'w', sizes)
        assert_sequences(walked)
        got = read_decoded(tmp_path / 'w')
        assert [(g[0], g[2], g[4].data) for g in got] == expected
        assert all(g[2] == g[3] for g in got)

    def test_short_writes_lose_nothing(self, tmp_path, monkeypatch):
        monkeypatch.setattr(mcap_file.McapFile, 'CHUNK_BYTES', 5000)
        real = os.writev

        def short(fd, pieces):
            """Write at most 1000 bytes, as a system call may."""
            data = b''.join(bytes(p) for p in pieces)[:1000]
            return real(fd, [data])

        monkeypatch.setattr(mcap_file.os, 'writev', short)
        stamps = BASE_NS + np.arange(400) * 1000
        with BagWriter(tmp_path / 'w') as bag:
            bag.add_topic('/a', 'std_msgs/msg/Float64')
            bag.add_topic('/s', 'std_msgs/msg/String')
            bag.write_rows([('/a', stamps, float64_rows(np.arange(400.0))),
                            ('/s', stamps[::7] + 1, string_datas(['z' * 20] * 58))])
        check_mcap(tmp_path / 'w', 5000)
        got = read_decoded(tmp_path / 'w')
        assert [g[4].data for g in got if g[0] == '/a'] == list(np.arange(400.0))
        assert len(got) == 458


class TestColumns:
    def test_crc32_combine_equals_zlib(self):
        rng = np.random.default_rng(2)
        for la, lb in [(0, 0), (5, 0), (0, 9), (1, 1), (1000, 1 << 20), (77, 1048599)]:
            a, b = rng.bytes(la), rng.bytes(lb)
            assert mcap_file.crc32_combine(zlib.crc32(a), zlib.crc32(b), lb) == zlib.crc32(a + b)

    def test_lazy_parts_taken_rows_and_constants_equal_serialize_cdr(self):
        rng = np.random.default_rng(4)
        n_source = 9
        take = np.array([0, 2, 3, 7, 8])
        q, roll, heave = rng.normal(size=(n_source, 2)), rng.normal(size=n_source), \
            rng.normal(size=(n_source, 3))
        stamps = BASE_NS + 10**7 * take
        cols = dict(serde.stamp_columns(stamps),
                    position=cdr.LazyColumns([q, roll, heave[:, ::2]], take),
                    velocity=np.broadcast_to(np.arange(5.0), (take.size, 5)))
        names = ('a', 'bb', 'ccc', 'dddd', 'e')
        msgtype = 'sensor_msgs/msg/JointState'
        rows = cdr.ColumnRows(msgtype, serde.message_template(msgtype, 'base_link', names, True),
                                  take.size, cols).array()
        for k, i in enumerate(take.tolist()):
            s = int(stamps[k])
            ref = T[msgtype](
                header=T['std_msgs/msg/Header'](stamp=T['builtin_interfaces/msg/Time'](
                    sec=s // 10**9, nanosec=s % 10**9), frame_id='base_link'),
                name=list(names), position=np.array([*q[i], roll[i], heave[i, 0], heave[i, 2]]),
                velocity=np.arange(5.0), effort=np.zeros(0))
            assert rows[k].tobytes() == bytes(TYPESTORE.serialize_cdr(ref, msgtype))
        empty = serde.encode_columns('std_msgs/msg/Float64', serde.message_template(
            'std_msgs/msg/Float64'), 0, {'data': np.zeros(0)})
        assert empty.shape == (0, 12)
        with pytest.raises(ValueError, match='position'):
            cdr.ColumnRows(msgtype, serde.message_template(msgtype, 'base_link', names, True), 5,
                               {'position': cdr.LazyColumns([q[:5], roll[:5]])})
