"""Reading the MCAP container (https://mcap.dev/spec) of a bag, record by record.

:class:`McapScan` walks a file from its start so that a cut or corrupt file yields every
message it can trust: a chunk failing its CRC, not decompressing or declaring more than
:data:`MAX_CHUNK_BYTES` is skipped; after a corrupt record the read resumes at the next chunk
of the summary's chunk index (whose lengths also overrule a chunk's own, and whose schemas and
channels stand in for those of a damaged chunk); a cut record ends the file. A chunk is taken
through its message index when that index accounts for every record in it (checked with
numpy), which is several times faster than the walk. The bytes come through
:class:`.mcap_source.McapSource` (regular files only, copies, no memory map); the record
layouts and the writer are :mod:`.mcap_file`.
"""
from __future__ import annotations

from dataclasses import dataclass
import bisect
from pathlib import Path
import struct
from typing import Callable, Iterator
import zlib

import numpy as np

from road_force_estimator.bagio.errors import BagReadError
from road_force_estimator.bagio.mcap_file import MAGIC, RECORD, U32, McapFile
from road_force_estimator.bagio.mcap_source import (
    FileChanged,
    McapSource,
    NotRegular,
    decompress,
    decompress_partial,
    find_chunk,
    read_summary,
)

__all__ = ['MAX_CHUNK_BYTES', 'Channel', 'Block', 'McapScan']

#: The largest uncompressed chunk read (bytes): the writer's chunk size times a margin (the
#: ``mcap`` library and rosbag2 write chunks of about 1-4 MiB). A chunk declaring more (a
#: decompression bomb, a corrupt header) is skipped and counted; change it for bags written
#: with larger chunks.
MAX_CHUNK_BYTES = 64 * McapFile.CHUNK_BYTES

_MESSAGE = struct.Struct('<HIQQ')
_INDEX_WINDOW = 1 << 18           # bytes of message index records read at a time
_CHUNK = struct.Struct('<QQQI')


@dataclass
class Channel:
    """A channel record: topic, message type (its schema's name), message and schema
    encodings, schema text and metadata (e.g. the offered QoS profiles)."""

    topic: str
    msgtype: str
    encoding: str
    schema_encoding: str
    schema: str
    metadata: dict[str, str]


class _Truncated(Exception):
    """The record stream breaks here (message in ``args[0]``)."""


def _string(buf, pos: int) -> tuple[str, int]:
    (n,) = U32.unpack_from(buf, pos)
    end = pos + 4 + n
    if end > len(buf):
        raise struct.error('string runs past its record')
    return bytes(buf[pos + 4:end]).decode('utf-8'), end


@dataclass
class Block:
    """The messages of one topic in one chunk, read through the chunk's message index.

    ``log_ns`` (k,) int64 log times in file order; ``parts`` ``(positions, rows)``: ``rows``
    (m, size) uint8, serialized messages of one size, ``positions`` (m,) their places among
    the k, or None for all k in order.
    """

    topic: str
    log_ns: np.ndarray
    parts: list[tuple[np.ndarray | None, np.ndarray]]

    @property
    def count(self) -> int:
        """Messages in the block."""
        return int(self.log_ns.size)


def _take_records(raw: np.ndarray, starts: np.ndarray, size: int) -> np.ndarray:
    """The ``size`` bytes from each of ``starts`` in ``raw`` (uint8): an (m, size) copy."""
    if size == 0:
        return np.zeros((starts.size, 0), dtype=np.uint8)
    view = np.ndarray((raw.size - size + 1,), dtype=f'V{size}', buffer=raw, strides=(1,))
    return view[starts].view(np.uint8).reshape(starts.size, size)


class McapScan:
    """Sequential reader of one MCAP file that keeps going past what it can skip safely.

    A chunk that fails its CRC, does not decompress or declares more than
    :data:`MAX_CHUNK_BYTES` is skipped whole (its length is known); a chunk whose records
    break is read up to the break; a corrupt record (a flipped length) resumes at the next
    chunk the summary's chunk index lists, whose lengths also overrule a chunk's own. A
    record that runs past the end of the file (a cut recording) ends the file. Schemas and
    channels come from the summary section too, so a damaged first chunk that held them
    loses only its own messages. Every such event is one line in :attr:`issues`; a file
    that changes while it is read raises :class:`BagReadError`.

    With ``indexed``, a chunk followed by message index records (rosbag2, the ``mcap``
    library and this module write them) that account for every record in it is read with
    numpy through them and gives :class:`Block` lists; any other chunk is walked record by
    record, with the same result.
    """

    def __init__(self, path: Path, want: Callable[[Channel], bool], *,
                 indexed: bool = False) -> None:
        self.path = path
        self.want = want
        self.indexed = indexed
        self.schemas: dict[int, tuple[str, str, str]] = {}
        self.channels: dict[int, Channel] = {}
        self.keep: dict[int, Channel] = {}
        self.issues: list[str] = []
        self.unknown_channel = 0
        self.messages = 0
        self.indexed_chunks = 0
        self.walked_chunks = 0
        self.skipped_chunks = 0          #: corrupt, undecompressable or too large
        self.resyncs = 0                 #: corrupt records passed over to the next chunk
        self.blocks: list[Block] = []
        self.chunk_at: dict[int, int] = {}
        self._starts: list[int] = []

    def _note(self, text: str) -> None:
        self.issues.append(f'{self.path.name}: {text}')

    def records(self) -> Iterator[tuple[Channel, int, bytes]]:
        """The wanted messages ``(channel, log_ns, payload)`` in file order."""
        for batch in self.batches():
            yield from batch

    def batches(self) -> Iterator[list]:
        """The wanted messages in lists of about a chunk each (cheaper than one by one):
        ``(channel, log_ns, payload)`` tuples, or (``indexed``) lists of :class:`Block`."""
        try:
            src = McapSource(self.path)
        except NotRegular as err:
            self._note(f'{err.args[0]}, not a regular file: not read')
            return
        except OSError as err:
            self._note(f'cannot be read ({err.strerror})')
            return
        try:
            yield from self._batches(src)
            src.check()
        except FileChanged as err:
            raise BagReadError(f'{self.path}: {err.args[0]}; {self.messages} messages read '
                               'before: not read further') from None
        finally:
            src.close()

    def _batches(self, src: McapSource) -> Iterator[list]:
        if src.read(0, len(MAGIC)) != MAGIC:
            self._note('not an MCAP file (bad magic)')
            return
        self._summary(src)
        out: list[tuple[Channel, int, bytes]] = []
        pos, end = len(MAGIC), src.size
        while pos < end:
            try:
                pos = self._top(src, pos, out)
            except _Truncated as err:
                pos = self._resync(src, pos, err.args[0], len(out))
            if out and (len(out) >= 4096 or self.blocks or pos in self.chunk_at or pos < 0):
                self.messages += len(out)
                yield out
                out = []
            if self.blocks:
                blocks, self.blocks = self.blocks, []
                self.messages += sum(block.count for block in blocks)
                yield blocks
            if pos < 0:                      # end-of-data record reached
                break
        if out:
            self.messages += len(out)
            yield out
        if pos == end:
            self._note(f'ends at byte {end} without the MCAP end-of-data record '
                       f'(recording cut short?); read {self.messages} messages')

    def _summary(self, src: McapSource) -> None:
        """Schemas, channels and chunk offsets of the summary section (if intact)."""
        summary = read_summary(src)
        if summary.issue:
            self._note(summary.issue)
        for op, body, at in summary.records:
            try:
                (self._schema if op == 0x03 else self._channel)(body, 0, len(body), at)
            except _Truncated:
                pass                         # the record in the data section may be good
        self.chunk_at = summary.chunks if summary.trusted else {}
        self._starts = sorted(summary.chunks)

    def _resync(self, src: McapSource, pos: int, why: str, pending: int) -> int:
        """Where to go on after a corrupt record at ``pos`` (``pending`` messages not yet
        yielded): the next chunk of the summary's chunk index, else (no summary, as in a cut
        recording) the next chunk head found in the bytes, or the end (-2) when none
        follows."""
        at = bisect.bisect_right(self._starts, pos)
        if at < len(self._starts):
            nxt, how = self._starts[at], 'from the chunk index'
        elif not self._starts and (found := find_chunk(src, pos + 1)) is not None:
            nxt, how = found, 'found by its head'
        else:
            self._note(f'{why}; read {self.messages + pending} messages before it')
            return -2
        self.resyncs += 1
        self._note(f'{why}: resuming at the next chunk (byte {nxt}, {how})')
        return nxt

    def _top(self, src: McapSource, pos: int, out: list) -> int:
        """Read the record at ``pos`` of the data section; the position of the next one, or
        -1 at the end-of-data record (or the footer)."""
        end = src.size
        if not self._starts and (run := self._message_run(src, pos, out)) > pos:
            return run
        if end - pos < RECORD.size:
            raise _Truncated(f'file ends inside a record header at byte {pos}')
        op, length = RECORD.unpack(src.read(pos, RECORD.size))
        known = self.chunk_at.get(pos)
        if known is not None and (op != 0x06 or length != known - RECORD.size):
            self._note(f'chunk at byte {pos}: its record head (op 0x{op:02x}, {length} bytes) '
                       f'disagrees with the chunk index ({known - RECORD.size} bytes): the '
                       'chunk index is used')
            op, length = 0x06, known - RECORD.size
        body = pos + RECORD.size
        nxt = body + length
        if op == 0x06:
            return self._chunk(src, pos, length, out)
        if op == 0x05 and (nxt > end or length < 22):
            raise _Truncated(f'message record at byte {pos} is cut or corrupt ({length} bytes '
                             'claimed)')
        if nxt > end:
            raise _Truncated(f'file ends inside a record (op 0x{op:02x}) at byte {pos}: '
                             f'{nxt - end} bytes missing')
        after = bisect.bisect_right(self._starts, pos)
        if after < len(self._starts) and self._starts[after] < nxt:
            raise _Truncated(f'record (op 0x{op:02x}) at byte {pos} runs over the chunk at '
                             f'byte {self._starts[after]} (a corrupt length)')
        if op in (0x03, 0x04, 0x05):
            if length > MAX_CHUNK_BYTES:
                raise _Truncated(f'corrupt record (op 0x{op:02x}, {length} bytes) at byte '
                                 f'{pos}')
            data = src.read(body, length)
            if op == 0x05:
                self._message(data, 0, length, out)
            else:
                (self._schema if op == 0x03 else self._channel)(data, 0, length, pos)
        elif op in (0x0F, 0x02):
            return -1
        elif op == 0x00 or 0x0F < op < 0x80:   # 0x80-0xFF: private records, skipped
            raise _Truncated(f'corrupt record (op 0x{op:02x}) at byte {pos}')
        return nxt

    def _message_run(self, src: McapSource, pos: int, out: list) -> int:
        """Read the message records from ``pos`` on that lie whole in the read-ahead window,
        in one loop (a file without chunks); the position after them."""
        buf, off = src.window(pos)
        start, end = off, len(buf)
        unpack_record, unpack_message = RECORD.unpack_from, _MESSAGE.unpack_from
        keep, channels, append = self.keep, self.channels, out.append
        while end - off >= RECORD.size:
            op, length = unpack_record(buf, off)
            nxt = off + RECORD.size + length
            if op != 0x05 or length < _MESSAGE.size or nxt > end:
                break
            cid, _, log_ns, _ = unpack_message(buf, off + RECORD.size)
            channel = keep.get(cid)
            if channel is not None:
                append((channel, log_ns, buf[off + RECORD.size + _MESSAGE.size:nxt]))
            elif cid not in channels:
                self.unknown_channel += 1
            off = nxt
        return pos + off - start

    def _message(self, buf, body: int, nxt: int, out: list) -> None:
        cid, _, log_ns, _ = _MESSAGE.unpack_from(buf, body)
        channel = self.keep.get(cid)
        if channel is not None:
            out.append((channel, log_ns, buf[body + 22:nxt]))
        elif cid not in self.channels:
            self.unknown_channel += 1

    def _parse(self, buf, end: int, out: list) -> None:
        """Append the wanted messages of a chunk's records ``buf[:end]`` to ``out``."""
        pos = 0
        unpack_record, unpack_message = RECORD.unpack_from, _MESSAGE.unpack_from
        keep, channels = self.keep, self.channels
        append = out.append
        while pos < end:
            if end - pos < 9:
                raise _Truncated(f'chunk ends inside a record header at byte {pos}')
            op, length = unpack_record(buf, pos)
            body = pos + 9
            nxt = body + length
            if op == 0x05:
                if nxt > end or length < 22:
                    raise _Truncated(f'message record at byte {pos} is cut or corrupt '
                                     f'({length} bytes claimed)')
                cid, _, log_ns, _ = unpack_message(buf, body)
                channel = keep.get(cid)
                if channel is not None:
                    append((channel, log_ns, buf[body + 22:nxt]))
                elif cid not in channels:
                    self.unknown_channel += 1
            elif nxt > end:
                raise _Truncated(f'chunk ends inside a record (op 0x{op:02x}) at byte '
                                 f'{pos}: {nxt - end} bytes missing')
            elif op == 0x03:
                self._schema(buf, body, nxt, pos)
            elif op == 0x04:
                self._channel(buf, body, nxt, pos)
            elif op == 0x00 or 0x0F < op < 0x80:   # 0x80-0xFF: private records, skipped
                raise _Truncated(f'corrupt record (op 0x{op:02x}) at byte {pos}')
            pos = nxt

    def _skip(self, pos: int, why: str) -> None:
        self.skipped_chunks += 1
        self._note(f'chunk at byte {pos} {why}: skipped')

    def _chunk(self, src: McapSource, pos: int, length: int, out: list) -> int:
        """Read the chunk record at ``pos`` (``length`` bytes after its head); the position
        after it."""
        nxt = pos + RECORD.size + length
        if length > 2 * MAX_CHUNK_BYTES:
            if nxt > src.size:
                raise _Truncated(f'chunk at byte {pos} is corrupt ({length} bytes claimed, '
                                 f'{nxt - src.size} past the end of the file)')
            self._skip(pos, f'is {length} bytes long, more than twice MAX_CHUNK_BYTES')
            return nxt
        rec = src.read(pos, nxt - pos)
        try:
            _, _, size, crc = _CHUNK.unpack_from(rec, RECORD.size)
            compression, rpos = _string(rec, RECORD.size + 28)
            (rlen,) = struct.unpack_from('<Q', rec, rpos)
        except (struct.error, UnicodeDecodeError):
            raise _Truncated(f'chunk at byte {pos} has a corrupt header') from None
        rstart = rpos + 8
        limit = min(size, MAX_CHUNK_BYTES)
        if nxt > src.size and pos + rstart + rlen <= src.size:
            self._note(f'chunk at byte {pos}: its length field ({length} bytes) runs past the '
                       f'end of the file, its records end at byte {pos + rstart + rlen}: used')
            nxt = pos + rstart + rlen
            rec = rec[:rstart + rlen]
        if nxt > src.size:
            # The file ends inside this chunk: recover its complete records, then stop.
            data = decompress_partial(rec[rstart:rstart + rlen], compression, MAX_CHUNK_BYTES)
            inner = self._records_in_chunk(data, out)
            raise _Truncated(f'file ends inside the chunk at byte {pos} '
                             f'({nxt - src.size} bytes missing'
                             + (f'; {inner}' if inner else '') + ')')
        if rstart + rlen > len(rec):
            if not crc:
                self._skip(pos, f'is corrupt (its records run {rstart + rlen - len(rec)} '
                           'bytes past its end)')
                return nxt
            self._note(f'chunk at byte {pos}: its records length field ({rlen} bytes) runs '
                       'past its end: the rest of the record is taken (its CRC checks it)')
            rlen = len(rec) - rstart
        return nxt + self._chunk_records(src, pos, rec, rstart, rlen, compression,
                                         (size, limit), crc, out)

    def _chunk_records(self, src: McapSource, pos: int, rec: bytes, rstart: int, rlen: int,
                       compression: str, sizes: tuple[int, int], crc: int, out: list) -> int:
        """Decompress (``sizes``: declared, at most that many bytes) and check a complete
        chunk's records, then read them; the bytes of message index records after the chunk
        read with it (0 when none was read)."""
        size, limit = sizes
        try:
            if compression == '':
                data = memoryview(rec)[rstart:rstart + rlen]      # no copy
            else:
                data = decompress(rec[rstart:rstart + rlen], compression, limit)
        except Exception as err:  # noqa: BLE001 - zstd/lz4 raise their own types
            self._skip(pos, f'does not decompress ({err})')
            return 0
        if compression and len(data) > MAX_CHUNK_BYTES:
            self._skip(pos, f'declares {size} bytes uncompressed and holds more than '
                       f'MAX_CHUNK_BYTES ({MAX_CHUNK_BYTES})')
            return 0
        if crc and zlib.crc32(data) != crc:
            self._skip(pos, 'fails its CRC check (corrupt)')
            return 0
        if len(data) != size:
            if not crc or len(data) > size:
                self._skip(pos, f'decompresses to {len(data)} bytes, not {size}')
                return 0
            self._note(f'chunk at byte {pos} declares {size} bytes uncompressed but holds '
                       f'{len(data)} (its CRC is good): read')
        index = b''
        if self.indexed:
            index = self._index_records(src, pos + len(rec), len(rec))
            if self._indexed_chunk(data, index):
                self.indexed_chunks += 1
                return len(index)
        self.walked_chunks += 1
        inner = self._records_in_chunk(bytes(data), out)
        if inner is not None:
            self._note(f'{inner} in the chunk at byte {pos}: the rest of that chunk is '
                       'skipped')
        return len(index)

    def _records_in_chunk(self, data: bytes, out: list) -> str | None:
        """Parse a chunk's records into ``out``; the break, if any (positions inside the
        chunk's records)."""
        try:
            self._parse(data, len(data), out)
        except _Truncated as err:
            return err.args[0]
        return None

    def _index_records(self, src: McapSource, pos: int, chunk: int) -> bytes:
        """The message index records that follow a chunk of ``chunk`` bytes ending at
        ``pos`` (up to the next chunk of the chunk index), read a window at a time (one read
        for most chunks: an index is less than half its chunk)."""
        at = bisect.bisect_left(self._starts, pos)
        stop = self._starts[at] if at < len(self._starts) else src.size
        window = min(_INDEX_WINDOW, chunk // 2 + 4096, stop - pos)
        buf, end = src.read(pos, window), 0
        while True:
            if len(buf) - end < RECORD.size:
                more = src.read(pos + len(buf), min(window, stop - pos - len(buf)))
                if not more:
                    break
                buf += more
                continue
            if buf[end] != 0x07:
                break
            (length,) = struct.unpack_from('<Q', buf, end + 1)
            nxt = end + RECORD.size + length
            if length > MAX_CHUNK_BYTES or pos + nxt > stop:
                break
            if nxt > len(buf):
                buf += src.read(pos + len(buf), nxt - len(buf))
            end = nxt
        return buf[:end]

    @staticmethod
    def _message_index(buf) -> list[tuple[int, np.ndarray]]:
        """``(channel id, record offsets)`` of the message index records in ``buf``."""
        index = []
        pos, end = 0, len(buf)
        while pos + 15 <= end and buf[pos] == 0x07:
            (length,) = struct.unpack_from('<Q', buf, pos + 1)
            cid, nbytes = struct.unpack_from('<HI', buf, pos + 9)
            if length < 6 or pos + 9 + length > end or nbytes > length - 6 or nbytes % 16:
                break
            pairs = np.frombuffer(buf, dtype='<u8', count=nbytes // 8, offset=pos + 15)
            index.append((cid, pairs[1::2]))          # (log time, offset) pairs
            pos += 9 + length
        return index

    def _indexed_chunk(self, data, index_records: bytes) -> bool:
        """Read a chunk's records ``data`` through the message index records that follow the
        chunk (``index_records``), into :attr:`blocks`.

        Only when the indexed records tile ``data`` exactly (the first at 0, each starting
        where the one before ends, the last ending at its end) and every one is a message
        record (op, length, channel id checked in its own bytes) of a declared channel: then
        no record (a schema or channel inside the chunk, an unindexed message, a message of
        an undeclared channel) is missed and the walk would read the same. Otherwise
        returns False having read nothing.
        """
        size = len(data)
        index = self._message_index(index_records)
        if not index or any(cid not in self.channels for cid, _ in index):
            return size == 0 and not index
        offsets = np.concatenate([o for _, o in index]).view(np.int64)
        n = offsets.size
        if n == 0:
            return size == 0
        order = np.argsort(offsets, kind='stable')
        starts = offsets[order]
        ends = np.empty(n, dtype=np.int64)
        ends[:-1] = starts[1:]
        ends[-1] = size
        body = ends - starts - RECORD.size            # each record's length field
        if starts[0] != 0 or body.min() < _MESSAGE.size:
            return False
        # Every record's head in file order: op, length, channel id, sequence, log time.
        raw = np.frombuffer(data, dtype=np.uint8)
        heads = _take_records(raw, starts, RECORD.size + 14)
        width = heads.shape[1]
        length = np.ndarray((n,), dtype='<u8', buffer=heads, offset=1, strides=(width,))
        cid = np.ndarray((n,), dtype='<u2', buffer=heads, offset=9, strides=(width,))
        labels = np.repeat(np.array([c for c, _ in index], dtype=np.uint16),
                           [o.size for _, o in index])
        if not (np.all(heads[:, 0] == 0x05) and np.all(length == body.astype(np.uint64))
                and np.all(cid == labels[order])):
            return False
        logs = np.empty(n, dtype=np.int64)            # back in index order, as offsets
        logs[order] = np.ndarray((n,), dtype='<u8', buffer=heads, offset=15,
                                 strides=(width,)).astype(np.int64)
        sizes = np.empty(n, dtype=np.int64)
        sizes[order] = body - _MESSAGE.size
        topics: dict[str, list[slice]] = {}
        first = 0
        for cid, offs in index:
            if cid in self.keep and offs.size:
                topics.setdefault(self.keep[cid].topic, []).append(
                    slice(first, first + offs.size))
            first += offs.size
        payload = offsets + (RECORD.size + _MESSAGE.size)
        self.blocks = [self._topic_block(raw, payload, sizes, logs, topic, parts)
                       for topic, parts in topics.items()]
        return True

    @staticmethod
    def _topic_block(raw: np.ndarray, starts: np.ndarray, sizes: np.ndarray, logs: np.ndarray,
                     topic: str, parts: list[slice]) -> Block:
        """The :class:`Block` of one topic's messages (``parts`` of the index entries: the
        messages' starts and sizes in ``raw``, their log times)."""
        if len(parts) == 1:
            starts, sizes, logs = starts[parts[0]], sizes[parts[0]], logs[parts[0]]
        else:
            starts, sizes, logs = (np.concatenate([a[p] for p in parts])
                                   for a in (starts, sizes, logs))
        if starts.size > 1 and not np.all(starts[1:] > starts[:-1]):   # log-time order
            order = np.argsort(starts, kind='stable')
            starts, sizes, logs = starts[order], sizes[order], logs[order]
        if sizes.min() == sizes.max():
            return Block(topic, logs, [(None, _take_records(raw, starts, int(sizes[0])))])
        out = []
        for size in np.unique(sizes).tolist():
            where = np.flatnonzero(sizes == size)
            out.append((where, _take_records(raw, starts[where], size)))
        return Block(topic, logs, out)

    def _schema(self, buf, body: int, end: int, at: int) -> None:
        try:
            (sid,) = struct.unpack_from('<H', buf, body)
            name, p = _string(buf, body + 2)
            encoding, p = _string(buf, p)
            (n,) = U32.unpack_from(buf, p)
            text = bytes(buf[p + 4:p + 4 + n]).decode('utf-8')
        except (struct.error, UnicodeDecodeError):
            raise _Truncated(f'corrupt schema record at byte {at}') from None
        self.schemas[sid] = (name, encoding, text)

    def _channel(self, buf, body: int, end: int, at: int) -> None:
        try:
            cid, sid = struct.unpack_from('<HH', buf, body)
            topic, p = _string(buf, body + 4)
            encoding, p = _string(buf, p)
            (n,) = U32.unpack_from(buf, p)
            meta, stop, p = {}, p + 4 + n, p + 4
            while p < stop:
                key, p = _string(buf, p)
                meta[key], p = _string(buf, p)
        except (struct.error, UnicodeDecodeError):
            raise _Truncated(f'corrupt channel record at byte {at}') from None
        name, schema_encoding, text = self.schemas.get(sid, ('', '', ''))
        channel = Channel(topic, name, encoding, schema_encoding, text, meta)
        self.channels[cid] = channel
        if self.want(channel):
            self.keep[cid] = channel
