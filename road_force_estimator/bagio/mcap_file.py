"""The MCAP container of the bags (https://mcap.dev/spec): record layouts, CRCs and the writer.

Only the container: what a message is (ROS 2 CDR, schemas, QoS, ``metadata.yaml``) is the
business of :mod:`.cdr` and :mod:`.writer`. The writer (:class:`McapFile`) lays out the ``ros2``
profile as rosbag2 does: uncompressed CRC-checked chunks of about 1 MiB, each followed by its
message index records, then the summary (schemas, channels, statistics, chunk and metadata
indexes, summary offsets) and the footer; whole blocks of fixed-size message records are laid
out with numpy. The reader is :mod:`.mcap_scan`.
"""
from __future__ import annotations

import os
from pathlib import Path
import struct
import time
from typing import Mapping, Sequence
import zlib

import numpy as np

__all__ = ['MAGIC', 'RECORD', 'U32', 'RECORD_HEAD', 'RECORD_LEAD', 'McapFile', 'crc32_combine']

#: The magic bytes that open and close an MCAP file.
MAGIC = b'\x89MCAP0\r\n'
#: Every record's head: opcode (u8) and body length (u64).
RECORD = struct.Struct('<BQ')
U32 = struct.Struct('<I')

def _mcap_string(text: str) -> bytes:
    raw = text.encode('utf-8')
    return U32.pack(len(raw)) + raw


def _mcap_map(items: Mapping[str, str]) -> bytes:
    body = b''.join(_mcap_string(k) + _mcap_string(v) for k, v in items.items())
    return U32.pack(len(body)) + body


_SINGLE = struct.Struct('<BQHIQQ')
#: A message record from the sequence number to the header stamp (20 + 12 bytes).
RECORD_LEAD = np.dtype([('seq', '<u4'), ('log', '<u8'), ('pub', '<u8'), ('encapsulation', 'V4'),
                  ('sec', 'V4'), ('nsec', 'V4')])
#: A message record's head: opcode, length, channel, sequence, log and publish times.
RECORD_HEAD = np.dtype([('op', 'u1'), ('length', '<u8'), ('cid', '<u2'), ('seq', '<u4'),
                  ('log', '<u8'), ('pub', '<u8')])


def _mcap_record(op: int, body: bytes) -> bytes:
    return RECORD.pack(op, len(body)) + body


_CRC32_POLY = 0xEDB88320      # CRC-32 (zlib), bit-reflected


def _crc32_multiply(a: int, b: int) -> int:
    """``a * b`` modulo the CRC-32 polynomial, bit-reflected (zlib's ``multmodp``)."""
    p = 0
    for bit in range(31, -1, -1):
        if a >> bit & 1:
            p ^= b
        b = (b >> 1) ^ _CRC32_POLY if b & 1 else b >> 1
    return p


def _crc32_powers() -> list[int]:
    """``x^(2^k)`` modulo the polynomial, k = 0..31 (zlib's ``x2n_table``)."""
    powers = [1 << 30]
    for _ in range(31):
        powers.append(_crc32_multiply(powers[-1], powers[-1]))
    return powers


_CRC32_X2N = _crc32_powers()
_CRC32_SHIFTS: dict[int, int] = {}


def crc32_combine(crc1: int, crc2: int, length2: int) -> int:
    """``zlib.crc32(a + b)`` from ``crc1 = zlib.crc32(a)``, ``crc2 = zlib.crc32(b)`` and
    ``length2 = len(b)``, without reading the bytes again (zlib's ``crc32_combine``)."""
    shift = _CRC32_SHIFTS.get(length2)
    if shift is None:
        shift, n, k = 1 << 31, length2, 3        # x^(8 length2): bytes are 8 bits
        while n:
            if n & 1:
                shift = _crc32_multiply(_CRC32_X2N[k & 31], shift)
            n >>= 1
            k += 1
        if len(_CRC32_SHIFTS) > 4096:
            _CRC32_SHIFTS.clear()
        _CRC32_SHIFTS[length2] = shift
    return _crc32_multiply(shift, crc1) ^ crc2


class McapFile:
    """MCAP writer for the ``ros2`` profile: chunked, CRC-checked, indexed.

    Messages go into uncompressed chunks of about 1 MiB, each followed by its message index
    records; ``close`` writes the rosbag2 metadata record, the summary (schemas, channels,
    statistics, chunk and metadata indexes, summary offsets) and the footer. Blocks of records
    laid out with numpy (:meth:`add_block`) go to the file straight from the writer's buffer,
    a system call per chunk; each byte is read once for the CRCs (the data section CRC is
    combined from the chunk's), so a long drive costs well under a microsecond per row of
    six messages. After a crash the chunks already flushed stay readable.

    ``chunk_age_s``: a chunk is also closed once its first message is that old (s, wall
    time; checked at each message and by :meth:`flush_due`), so that a recorder killed
    (SIGKILL) loses at most that much whatever the rates; None: by size only. The file is
    written unbuffered, each record whole or not at all from the readers' view: a write that
    fails (out of space) leaves the file cut back at the last complete record
    (:attr:`good_offset`), and :meth:`salvage` then ends it with its summary when it can.
    """

    CHUNK_BYTES = 1 << 20

    def __init__(self, path: Path, chunk_age_s: float | None = None) -> None:
        self.path = path
        self.file = path.open('xb', buffering=0)
        self.chunk_age_s = chunk_age_s
        self.pending_since = 0.0       # time.monotonic() of the pending chunk's first message
        self.good_offset = 0           # bytes of complete records in the file
        self.crc = 0
        self.offset = 0
        self._put(MAGIC)
        # The header's library string names the writer as it was then (bags stay byte-identical).
        self._put(_mcap_record(0x01, _mcap_string('ros2') + _mcap_string(
            'road_force_estimator bag_io (rosbags typestore ros2_jazzy)')))
        self.good_offset = self.offset
        self.schemas: list[bytes] = []
        self.channels: list[bytes] = []
        self.counts: dict[int, int] = {}
        self.committed: dict[int, int] = {}     # messages per channel in complete chunks
        self.chunk_indexes: list[bytes] = []
        self.pending = bytearray()
        self.pending_index: dict[int, list[tuple[np.ndarray, np.ndarray]]] = {}
        self.pending_start = 2**64 - 1
        self.pending_end = 0
        self.start_ns = 2**64 - 1
        self.end_ns = 0
        self.message_count = 0

    def _write_all(self, data) -> None:
        """Write every byte of ``data`` (an unbuffered file may take part of it)."""
        view = memoryview(data).cast('B')
        while view:
            done = self.file.write(view)
            if done is None:             # (a non-blocking file: never for a regular one)
                continue
            view = view[done:]

    def _put(self, data: bytes | bytearray) -> None:
        self._write_all(data)
        self.crc = zlib.crc32(data, self.crc)
        self.offset += len(data)

    def add_schema(self, name: str, encoding: str, text: str) -> int:
        """Write a schema record; its id."""
        sid = len(self.schemas) + 1
        record = _mcap_record(0x03, struct.pack('<H', sid) + _mcap_string(name)
                              + _mcap_string(encoding) + _mcap_string(text))
        self.schemas.append(record)
        self._put(record)
        self.good_offset = self.offset
        return sid

    def add_channel(self, sid: int, topic: str, encoding: str,
                    metadata: Mapping[str, str]) -> int:
        """Write a channel record of schema ``sid``; its id."""
        cid = len(self.channels) + 1
        record = _mcap_record(0x04, struct.pack('<HH', cid, sid) + _mcap_string(topic)
                              + _mcap_string(encoding) + _mcap_map(metadata))
        self.channels.append(record)
        self.counts[cid] = 0
        self.committed[cid] = 0
        self._put(record)
        self.good_offset = self.offset
        return cid

    def sequences(self, cids: np.ndarray) -> np.ndarray:
        """Per-channel sequence numbers for messages about to be written in this order."""
        seq = np.zeros(cids.size, dtype=np.uint32)
        for cid in np.unique(cids).tolist():
            mine = cids == cid
            count = int(np.count_nonzero(mine))
            seq[mine] = (self.counts[cid] + np.arange(count)) % 2**32
            self.counts[cid] += count
        return seq

    def add_block(self, segments: Sequence[np.ndarray],
                  entries: Sequence[tuple[int, np.ndarray, np.ndarray]],
                  bounds: np.ndarray | None = None) -> None:
        """Append complete message records laid out back to back.

        Parameters
        ----------
        segments : sequence of ndarray of uint8
            The records' bytes, in write order, cut anywhere (no empty piece).
        entries : sequence of (cid, starts, logs)
            Every record once: channel, byte positions of its records counted from the
            start of the first segment (int64, increasing) and their log times (int64 ns,
            not decreasing).
        bounds : ndarray of int64, optional
            All the starts, sorted (made from ``entries`` when not given).

        Notes
        -----
        As :meth:`write` message by message, a chunk is closed after the record that brings
        it to ``CHUNK_BYTES`` or more; complete chunks go to the file straight from
        ``segments``, the rest waits in ``pending``.
        """
        total = sum(len(s) for s in segments)
        if bounds is None:
            bounds = np.sort(np.concatenate([starts for _, starts, _ in entries]))
        # Chunk ends: the first record start at or past the chunk's size, else the block end.
        ends, cs, room = [], 0, self.CHUNK_BYTES - len(self.pending)
        while cs < total:
            target = cs + room
            i = int(bounds.searchsorted(target)) if target < total else bounds.size
            cs = int(bounds[i]) if i < bounds.size else total
            ends.append(cs)
            room = self.CHUNK_BYTES
        last = [0] * len(entries)
        his = [starts.searchsorted(ends) for _, starts, _ in entries]
        seg, seg_start, cs = 0, 0, 0
        for c, ce in enumerate(ends):
            base = len(self.pending)
            for e, (cid, starts, logs) in enumerate(entries):
                lo, hi = last[e], int(his[e][c])
                if hi > lo:
                    part = np.empty((hi - lo, 2), dtype='<u8')
                    part[:, 0] = logs[lo:hi]
                    part[:, 1] = starts[lo:hi] - (cs - base)
                    self._index(cid).append(part)
                    self.pending_start = min(self.pending_start, int(logs[lo]))
                    self.pending_end = max(self.pending_end, int(logs[hi - 1]))
                    self.message_count += hi - lo
                    last[e] = hi
            length = base + ce - cs
            pieces = []
            while cs < ce:
                piece = segments[seg][cs - seg_start:ce - seg_start]
                pieces.append(piece)
                cs += len(piece)
                if cs == seg_start + len(segments[seg]):
                    seg_start += len(segments[seg])
                    seg += 1
            if length >= self.CHUNK_BYTES:
                self._emit_chunk(([self.pending] if base else []) + pieces, length)
            else:
                for piece in pieces:
                    self.pending += memoryview(piece)

    def _index(self, cid: int) -> list:
        return self.pending_index.setdefault(cid, [])

    def write(self, cid: int, log_ns: int, data: bytes) -> None:
        """Append one message (the per-message path, e.g. for a recorder)."""
        seq = self.counts[cid] % 2**32
        self.counts[cid] += 1
        offset = len(self.pending)
        self.pending += _SINGLE.pack(0x05, 22 + len(data), cid, seq, log_ns, log_ns)
        self.pending += data
        self._index(cid).append((log_ns, offset))
        self.pending_start = min(self.pending_start, log_ns)
        self.pending_end = max(self.pending_end, log_ns)
        self.message_count += 1
        if offset == 0:
            self.pending_since = time.monotonic()
        if len(self.pending) >= self.CHUNK_BYTES or (
                self.chunk_age_s is not None
                and time.monotonic() - self.pending_since >= self.chunk_age_s):
            self.flush_chunk()

    def flush_chunk(self) -> None:
        """Write the pending messages as a chunk (if any)."""
        if self.pending:
            self._emit_chunk([self.pending], len(self.pending))

    def flush_due(self) -> bool:
        """Close the pending chunk if it is ``chunk_age_s`` old; whether it was."""
        if self.pending and self.chunk_age_s is not None and \
                time.monotonic() - self.pending_since >= self.chunk_age_s:
            self.flush_chunk()
            return True
        return False

    @staticmethod
    def _index_pairs(parts: list) -> np.ndarray:
        """(log, offset) pairs ('<u8', (m, 2)) of one channel's records in the pending chunk,
        ordered by log time then offset. Parts, in write order: (m, 2) arrays of ascending log
        times (:meth:`add_block`) or single (log, offset) tuples (:meth:`write`)."""
        arrays, singles, ordered = [], [], True
        for part in parts + [None]:
            if isinstance(part, tuple):
                singles.append(part)
                continue
            if singles:
                run = np.array(singles, dtype='<u8').reshape(-1, 2)
                ordered = ordered and not bool(np.any(run[1:, 0] < run[:-1, 0]))
                arrays.append(run)
                singles = []
            if part is not None:
                arrays.append(part)
        ordered = ordered and all(int(a[-1, 0]) <= int(b[0, 0])
                                  for a, b in zip(arrays, arrays[1:]))
        pairs = arrays[0] if len(arrays) == 1 else np.concatenate(arrays)
        if not ordered:
            pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]
        return pairs

    def _write_pieces(self, pieces: Sequence) -> None:
        """Write bytes-like ``pieces`` in order, a system call per 512 (not per piece)."""
        for i in range(0, len(pieces), 512):
            group = pieces[i:i + 512]
            done = os.writev(self.file.fileno(), group)
            for piece in group:                 # a short write: the rest the usual way
                if done < len(piece):
                    self._write_all(memoryview(piece)[done:])
                done = max(0, done - len(piece))

    def _emit_chunk(self, pieces: Sequence, length: int) -> None:
        """Write the pending chunk: its records are ``pieces`` (bytes-like, ``length`` bytes
        in all), then the message indexes; note its chunk index; reset ``pending``."""
        chunk_start, crc_before = self.offset, self.crc
        try:
            self._emit(pieces, length)
        except BaseException:
            # a failed write (out of space): back to the last complete record
            self.offset, self.crc = chunk_start, crc_before
            self.good_offset = chunk_start
            self.cut_back()
            raise

    def cut_back(self) -> None:
        """Cut the file at :attr:`good_offset` (what a failed write left beyond it goes)."""
        try:
            os.ftruncate(self.file.fileno(), self.good_offset)
            os.lseek(self.file.fileno(), self.good_offset, os.SEEK_SET)
        except OSError:
            pass

    def _emit(self, pieces: Sequence, length: int) -> None:
        crc = 0
        for piece in pieces:
            crc = zlib.crc32(piece, crc)
        chunk_start = self.offset
        self._put(RECORD.pack(0x06, 40 + length) + struct.pack(
            '<QQQI', self.pending_start, self.pending_end, length, crc) + _mcap_string('')
            + struct.pack('<Q', length))
        self._write_pieces(pieces)
        self.crc = crc32_combine(self.crc, crc, length)
        self.offset += length
        chunk_length = self.offset - chunk_start
        index_offsets, index, index_length = {}, [], 0
        done = []
        for cid, parts in sorted(self.pending_index.items()):
            pairs = self._index_pairs(parts)
            done.append((cid, pairs.shape[0]))
            index_offsets[cid] = self.offset + index_length
            index += [RECORD.pack(0x07, 6 + pairs.nbytes), struct.pack('<HI', cid, pairs.nbytes),
                      pairs.tobytes()]
            index_length += 15 + pairs.nbytes
        self._put(b''.join(index))
        for cid, n in done:                     # the chunk is whole in the file from here
            self.committed[cid] = self.committed.get(cid, 0) + n
        offsets_map = b''.join(struct.pack('<HQ', c, o) for c, o in index_offsets.items())
        self.chunk_indexes.append(_mcap_record(0x08, struct.pack(
            '<QQQQ', self.pending_start, self.pending_end, chunk_start, chunk_length)
            + U32.pack(len(offsets_map)) + offsets_map + struct.pack('<Q', index_length)
            + _mcap_string('') + struct.pack('<QQ', length, length)))
        self.start_ns = min(self.start_ns, self.pending_start)
        self.end_ns = max(self.end_ns, self.pending_end)
        self.pending = bytearray()
        self.pending_index = {}
        self.pending_start, self.pending_end = 2**64 - 1, 0
        self.good_offset = self.offset

    def close(self, metadata_yaml: str) -> None:
        """Flush, write the rosbag2 metadata record, the summary and the footer."""
        self.flush_chunk()
        metadata_start = self.offset
        self._put(_mcap_record(0x0C, _mcap_string('rosbag2') + _mcap_map(
            {'serialized_metadata': metadata_yaml})))
        metadata_length = self.offset - metadata_start
        self._put(_mcap_record(0x0F, U32.pack(self.crc)))     # data section CRC
        summary_start = self.offset
        self.crc = 0
        groups = []
        for op, records in ((0x03, self.schemas), (0x04, self.channels),
                            (0x08, self.chunk_indexes)):
            if records:
                start = self.offset
                for record in records:
                    self._put(record)
                groups.append((op, start, self.offset - start))
        start = self.offset
        self._put(_mcap_record(0x0D, struct.pack('<QQ', metadata_start, metadata_length)
                               + _mcap_string('rosbag2')))
        groups.append((0x0D, start, self.offset - start))
        start = self.offset
        counts = b''.join(struct.pack('<HQ', c, n) for c, n in sorted(self.counts.items()))
        empty = self.message_count == 0
        self._put(_mcap_record(0x0B, struct.pack(
            '<QHIIIIQQ', self.message_count, len(self.schemas), len(self.channels), 0, 1,
            len(self.chunk_indexes), 0 if empty else self.start_ns, self.end_ns)
            + U32.pack(len(counts)) + counts))
        groups.append((0x0B, start, self.offset - start))
        offsets_start = self.offset
        for op, start, length in groups:
            self._put(_mcap_record(0x0E, struct.pack('<BQQ', op, start, length)))
        footer = RECORD.pack(0x02, 20) + struct.pack('<QQ', summary_start, offsets_start)
        self._put(footer)
        self._write_all(U32.pack(self.crc))
        self._write_all(MAGIC)
        self.file.close()

    def abort(self) -> None:
        """Keep what was written (flush the pending chunk), without index or summary."""
        try:
            self.flush_chunk()
        finally:
            self.file.close()

    def salvage(self, metadata_yaml: str) -> bool:
        """After a failed write: end the file with the summary of the chunks written (the
        pending messages are dropped) if the space allows, else leave it cut at its last
        complete record; True when the summary was written. The file is closed."""
        self.pending = bytearray()
        self.pending_index = {}
        self.pending_start, self.pending_end = 2**64 - 1, 0
        self.counts = dict(self.committed)
        self.message_count = sum(self.committed.values())
        good, crc = self.good_offset, self.crc
        self.offset = good
        self.cut_back()
        try:
            self.close(metadata_yaml)
            return True
        except OSError:
            self.good_offset, self.offset, self.crc = good, good, crc
            self.cut_back()
            try:
                self.file.close()
            except OSError:
                pass
            return False
