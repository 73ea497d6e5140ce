"""Reading the MCAP container (https://mcap.dev/spec) of a bag, record by record.

:class:`McapScan` walks a file from its start so that a cut or corrupt file yields every
message it can trust (a chunk failing its CRC is skipped; a cut record ends the file), and
takes a chunk through its message index when that index accounts for every record in it
(checked with numpy), which is several times faster than the walk. The record layouts and the
writer are :mod:`.mcap_file`.
"""
from __future__ import annotations

from dataclasses import dataclass
import mmap
from pathlib import Path
import struct
from typing import Callable, Iterator
import zlib

import numpy as np

from road_force_estimator.bagio.mcap_file import MAGIC, RECORD, U32

__all__ = ['Channel', 'Block', 'McapScan']

_MESSAGE = struct.Struct('<HIQQ')
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


def _decompress(data: bytes, compression: str, size: int | None) -> bytes:
    if compression == '':
        return bytes(data)
    if compression == 'zstd':
        try:
            import zstandard
            return zstandard.ZstdDecompressor().decompress(data, max_output_size=size or 0)
        except ImportError:
            from backports import zstd  # rosbags' own dependency
            return zstd.decompress(data)
    if compression == 'lz4':
        import lz4.frame
        return lz4.frame.decompress(data)
    raise _Truncated(f'unsupported chunk compression {compression!r}')


def _decompress_partial(data: bytes, compression: str) -> bytes:
    """As much as can be decompressed of a chunk cut short."""
    try:
        if compression == '':
            return bytes(data)
        if compression == 'zstd':
            import zstandard
            return zstandard.ZstdDecompressor().decompressobj().decompress(data)
        if compression == 'lz4':
            import lz4.frame
            return lz4.frame.LZ4FrameDecompressor().decompress(data)
    except Exception:  # noqa: BLE001 - nothing recoverable
        return b''
    return b''


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


def _open_buffer(path: Path):
    """The bytes of a file: a read-only memory map (no copy, pages read on demand), or the
    bytes read when it cannot be mapped (an empty file)."""
    with path.open('rb') as f:
        try:
            return mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
        except (ValueError, OSError):
            return f.read()


def _take_records(raw: np.ndarray, starts: np.ndarray, size: int) -> np.ndarray:
    """The ``size`` bytes from each of ``starts`` in ``raw`` (uint8): an (m, size) copy."""
    if size == 0:
        return np.zeros((starts.size, 0), dtype=np.uint8)
    view = np.ndarray((raw.size - size + 1,), dtype=f'V{size}', buffer=raw, strides=(1,))
    return view[starts].view(np.uint8).reshape(starts.size, size)


class McapScan:
    """Sequential reader of one MCAP file that keeps going past what it can skip safely.

    A chunk that fails its CRC or does not decompress is skipped whole (its length is
    known); a chunk whose records break is read up to the break; a record that runs past
    the end of the file (a cut recording) or a corrupt record outside chunks ends the file.
    Every such event is one line in :attr:`issues`.

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
        self.blocks: list[Block] = []

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
            buf = _open_buffer(self.path)
        except OSError as err:
            self._note(f'cannot be read ({err.strerror})')
            return
        try:
            yield from self._batches(buf)
        finally:
            if isinstance(buf, mmap.mmap):
                try:
                    buf.close()
                except BufferError:      # a view is still alive: closed when collected
                    pass

    def _batches(self, buf) -> Iterator[list]:
        if len(buf) < len(MAGIC) or buf[:len(MAGIC)] != MAGIC:
            self._note('not an MCAP file (bad magic)')
            return
        out: list[tuple[Channel, int, bytes]] = []
        pos, end = len(MAGIC), len(buf)
        try:
            while pos < end:
                pos = self._parse(buf, pos, end, out, top=True)
                if out:
                    self.messages += len(out)
                    yield out
                    out = []
                if self.blocks:
                    blocks, self.blocks = self.blocks, []
                    self.messages += sum(block.count for block in blocks)
                    yield blocks
                if pos < 0:                      # end-of-data record reached
                    return
        except _Truncated as err:
            if out:
                self.messages += len(out)
                yield out
            self._note(f'{err.args[0]}; read {self.messages} messages before it')
            return
        self._note(f'ends at byte {len(buf)} without the MCAP end-of-data record '
                   f'(recording cut short?); read {self.messages} messages')

    def _parse(self, buf, start: int, end: int, out: list, *, top: bool) -> int:
        """Append the wanted messages of the records in ``buf[start:end]`` to ``out``.

        At the top level it returns after each chunk (the position to go on from), or -1 at
        the end-of-data record; inside a chunk it parses all of it.
        """
        pos = start
        unpack_record, unpack_message = RECORD.unpack_from, _MESSAGE.unpack_from
        keep, channels = self.keep, self.channels
        append = out.append
        where = 'file' if top else 'chunk'
        while pos < end:
            if end - pos < 9:
                raise _Truncated(f'{where} ends inside a record header at byte {pos}')
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
            elif op == 0x06 and top:
                self._chunk(buf, pos, body, min(nxt, end), out, complete=nxt <= end)
                return nxt
            elif nxt > end:
                raise _Truncated(f'{where} ends inside a record (op 0x{op:02x}) at byte '
                                 f'{pos}: {nxt - end} bytes missing')
            elif op == 0x03:
                self._schema(buf, body, nxt, pos)
            elif op == 0x04:
                self._channel(buf, body, nxt, pos)
            elif op in (0x0F, 0x02) and top:
                return -1
            elif op == 0x00 or 0x0F < op < 0x80:   # 0x80-0xFF: private records, skipped
                raise _Truncated(f'corrupt record (op 0x{op:02x}) at byte {pos}')
            pos = nxt
        return pos

    def _chunk(self, buf, pos: int, body: int, end: int, out: list, *,
               complete: bool) -> None:
        try:
            _, _, size, crc = _CHUNK.unpack_from(buf, body)
            compression, rpos = _string(buf, body + 28)
            (rlen,) = struct.unpack_from('<Q', buf, rpos)
        except (struct.error, UnicodeDecodeError):
            raise _Truncated(f'chunk at byte {pos} has a corrupt header') from None
        rstart = rpos + 8
        if not (complete and rstart + rlen <= end):
            # The file ends inside this chunk: recover its complete records, then stop.
            data = _decompress_partial(buf[rstart:end], compression)
            inner = self._records_in_chunk(data, out)
            raise _Truncated(f'file ends inside the chunk at byte {pos} '
                             f'({rstart + rlen - end} bytes missing'
                             + (f'; {inner}' if inner else '') + ')')
        try:
            if compression == '':
                data = memoryview(buf)[rstart:rstart + rlen]      # no copy
            else:
                data = _decompress(buf[rstart:rstart + rlen], compression, size)
        except Exception as err:  # noqa: BLE001 - zstd/lz4 raise their own types
            self._note(f'chunk at byte {pos} does not decompress ({err}): skipped')
            return
        if len(data) != size:
            self._note(f'chunk at byte {pos} decompresses to {len(data)} bytes, not {size}: '
                       'skipped')
            return
        if crc and zlib.crc32(data) != crc:
            self._note(f'chunk at byte {pos} fails its CRC check (corrupt): its messages '
                       'are skipped')
            return
        if self.indexed and self._indexed_chunk(data, buf, end):
            self.indexed_chunks += 1
            return
        self.walked_chunks += 1
        inner = self._records_in_chunk(bytes(data), out)
        if inner is not None:
            self._note(f'{inner} in the chunk at byte {pos}: the rest of that chunk is '
                       'skipped')

    def _records_in_chunk(self, data: bytes, out: list) -> str | None:
        """Parse a chunk's records into ``out``; the break, if any (positions inside the
        chunk's records)."""
        try:
            self._parse(data, 0, len(data), out, top=False)
        except _Truncated as err:
            return err.args[0]
        return None

    @staticmethod
    def _message_index(buf, pos: int) -> list[tuple[int, np.ndarray]]:
        """``(channel id, record offsets)`` of the message index records from ``pos`` on."""
        index = []
        end = len(buf)
        while pos + 15 <= end and buf[pos] == 0x07:
            (length,) = struct.unpack_from('<Q', buf, pos + 1)
            cid, nbytes = struct.unpack_from('<HI', buf, pos + 9)
            if length < 6 or pos + 9 + length > end or nbytes > length - 6 or nbytes % 16:
                break
            pairs = np.frombuffer(buf, dtype='<u8', count=nbytes // 8, offset=pos + 15)
            index.append((cid, pairs[1::2]))          # (log time, offset) pairs
            pos += 9 + length
        return index

    def _indexed_chunk(self, data, buf, at: int) -> bool:
        """Read a chunk's records ``data`` through the message index records that follow the
        chunk at byte ``at`` of ``buf``, into :attr:`blocks`.

        Only when the indexed records tile ``data`` exactly (the first at 0, each starting
        where the one before ends, the last ending at its end) and every one is a message
        record (op, length, channel id checked in its own bytes) of a declared channel: then
        no record (a schema or channel inside the chunk, an unindexed message, a message of
        an undeclared channel) is missed and the walk would read the same. Otherwise
        returns False having read nothing.
        """
        size = len(data)
        index = self._message_index(buf, at)
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
