"""The bytes of an MCAP file, read with bounded copies, and its summary section.

:class:`McapSource` reads regular files only (a FIFO or a device named ``.mcap`` is refused
without blocking) with ``pread``, never a memory map: a file cut or changed by another process
while it is read raises :class:`FileChanged` instead of killing the process with SIGBUS.
:func:`read_summary` takes the summary section's schemas, channels and chunk index (the
offsets to resynchronise on after a corrupt record) when the footer is intact;
:func:`find_chunk` finds the next chunk by its head in a file without one; :func:`decompress`
gives a chunk's records, never more bytes than asked (a decompression bomb stops there). The
record layouts are :mod:`.mcap_file`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import os
from pathlib import Path
import stat
import struct
import zlib

from road_force_estimator.bagio.mcap_file import MAGIC, RECORD

__all__ = ['FileChanged', 'NotRegular', 'McapSource', 'Summary', 'read_summary', 'find_chunk',
           'first_log_time', 'decompress', 'decompress_partial', 'MAX_SUMMARY_BYTES']

#: The largest summary section read (bytes): a chunk index is about 100 bytes a chunk.
MAX_SUMMARY_BYTES = 64 << 20
_CACHE = 1 << 16          # bytes read ahead for small reads
_FOOTER = struct.Struct('<BQQQI')          # op, length, summary start, offsets start, CRC
_CHUNK_INDEX = struct.Struct('<QQQQ')      # start and end times, chunk start, chunk length


class FileChanged(Exception):
    """The file became shorter (or otherwise changed) while it was read (text in args[0])."""


class NotRegular(Exception):
    """Not a regular file (a FIFO, a device, a socket): not read (its kind in args[0])."""


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISFIFO, 'a FIFO'), (stat.S_ISCHR, 'a character device'),
                       (stat.S_ISBLK, 'a block device'), (stat.S_ISSOCK, 'a socket'),
                       (stat.S_ISDIR, 'a directory')):
        if test(mode):
            return name
    return 'not a regular file'


class McapSource:
    """A regular file opened for reading, its size fixed at opening.

    :meth:`read` copies a byte range (``pread``); fewer bytes than the size promised means
    the file was cut under the reader (:class:`FileChanged`). :meth:`check` compares size
    and modification time with those at opening.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        flags = os.O_RDONLY | getattr(os, 'O_NONBLOCK', 0) | getattr(os, 'O_CLOEXEC', 0)
        self.fd = os.open(path, flags)        # O_NONBLOCK: a FIFO does not block the open
        st = os.fstat(self.fd)
        if not stat.S_ISREG(st.st_mode):
            os.close(self.fd)
            raise NotRegular(_kind(st.st_mode))
        self.size = st.st_size
        self._stamp = (st.st_size, st.st_mtime_ns, st.st_ino)
        self._cache, self._cache_at = b'', 0

    def read(self, pos: int, n: int) -> bytes:
        """``n`` bytes from ``pos`` (fewer only where the file, at its opening size, ends).

        Small reads are served from a window of :data:`_CACHE` bytes read ahead (record heads,
        the records of a file without chunks, small chunks)."""
        n = max(0, min(n, self.size - pos))
        if n > _CACHE // 4:
            return self._pread(pos, n)
        off = pos - self._cache_at
        if not (0 <= off and off + n <= len(self._cache)):
            self._cache, self._cache_at, off = self._pread(pos, _CACHE), pos, 0
        return self._cache[off:off + n]

    def window(self, pos: int) -> tuple[bytes, int]:
        """``(buffer, offset)``: the read-ahead window holding the bytes from ``pos`` (at
        least a quarter of it, unless the file ends first) at ``buffer[offset:]``."""
        off = pos - self._cache_at
        if not (0 <= off and len(self._cache) - off >= min(_CACHE // 4, self.size - pos)):
            self._cache, self._cache_at, off = self._pread(pos, _CACHE), pos, 0
        return self._cache, off

    def _pread(self, pos: int, n: int) -> bytes:
        n = max(0, min(n, self.size - pos))
        parts, got = [], 0
        while got < n:
            part = os.pread(self.fd, n - got, pos + got)
            if not part:
                self._changed(f'{self.size - pos - got} bytes vanished at byte {pos + got}')
            parts.append(part)
            got += len(part)
        return parts[0] if len(parts) == 1 else b''.join(parts)

    def check(self) -> None:
        """Raise :class:`FileChanged` if the file is no longer as it was opened."""
        st = os.fstat(self.fd)
        if (st.st_size, st.st_mtime_ns, st.st_ino) != self._stamp:
            self._changed('modified')

    def _changed(self, what: str) -> None:
        now = os.fstat(self.fd).st_size
        raise FileChanged(f'changed while being read ({what}; {self.size} bytes when opened, '
                          f'{now} now)')

    def close(self) -> None:
        """Close the file."""
        os.close(self.fd)


@dataclass
class Summary:
    """What the summary section holds: ``records`` ``(op, body, at)`` of its schemas (0x03)
    and channels (0x04), ``chunks`` chunk start -> chunk record length (bytes, head
    included), ``trusted`` False when it fails its CRC check (the ``mcap`` library reads it
    all the same: a hint, not a fact), ``issue`` why it was not (all) used, or None."""

    records: list[tuple[int, bytes, int]] = field(default_factory=list)
    chunks: dict[int, int] = field(default_factory=dict)
    trusted: bool = True
    issue: str | None = None


def read_summary(src: McapSource) -> Summary:
    """The summary section of a file whose footer is intact (CRC-checked when the footer
    has a CRC: not ``trusted`` when it fails); an empty :class:`Summary` when there is none
    (a cut file has no footer)."""
    out = Summary()
    tail = _FOOTER.size + len(MAGIC)
    if src.size < len(MAGIC) + tail:
        return out
    footer = src.read(src.size - tail, tail)
    if footer[-len(MAGIC):] != MAGIC or footer[0] != 0x02:
        return out
    op, length, start, _, crc = _FOOTER.unpack_from(footer)
    if start == 0:
        return out
    end = src.size - tail
    if length != _FOOTER.size - RECORD.size or not len(MAGIC) <= start < end \
            or end - start > MAX_SUMMARY_BYTES:
        out.issue = 'the footer is corrupt: the summary section is not used'
        return out
    data = src.read(start, end - start)
    if crc and zlib.crc32(footer[:_FOOTER.size - 4], zlib.crc32(data)) != crc:
        out.trusted = False
        out.issue = 'the summary section fails its CRC check: used only where the data lack'
    pos = 0
    while pos + RECORD.size <= len(data):
        op, length = RECORD.unpack_from(data, pos)
        body, nxt = pos + RECORD.size, pos + RECORD.size + length
        if nxt > len(data):
            out.issue = f'the summary section is corrupt at byte {start + pos}: read up to it'
            break
        if op in (0x03, 0x04):
            out.records.append((op, data[body:nxt], start + pos))
        elif op == 0x08 and length >= _CHUNK_INDEX.size:
            _, _, chunk_start, chunk_length = _CHUNK_INDEX.unpack_from(data, body)
            if len(MAGIC) <= chunk_start < start and chunk_length <= start - chunk_start:
                out.chunks[chunk_start] = chunk_length
        pos = nxt
    return out


def first_log_time(src: McapSource, records: int = 4096) -> int | None:
    """The log time (ns) of a file's first message: its first chunk's start time, or its
    first message outside chunks, walking at most ``records`` top-level records (schemas and
    channels come first); None when there is none (no message, a cut or corrupt head)."""
    pos = len(MAGIC)
    for _ in range(records):
        head = src.read(pos, RECORD.size + 8) if pos + RECORD.size + 8 <= src.size else b''
        if len(head) < RECORD.size + 8:
            return None
        op, length = RECORD.unpack_from(head)
        if op == 0x06 and length >= 32:
            return int(struct.unpack_from('<Q', head, RECORD.size)[0])
        if op == 0x05 and length >= 14:
            return int(struct.unpack_from('<Q', src.read(pos + RECORD.size + 6, 8))[0])
        if op in (0x0F, 0x02) or pos + RECORD.size + length > src.size:
            return None
        pos += RECORD.size + length
    return None


_CHUNK_HEAD = struct.Struct('<BQQQQII')   # op, length, times, size, CRC, compression length
_COMPRESSIONS = (b'', b'zstd', b'lz4')
#: Bytes searched at a time by :func:`find_chunk`.
_WINDOW = 1 << 20


def find_chunk(src: McapSource, pos: int) -> int | None:
    """The first byte from ``pos`` on where a chunk record starts, judged by its head alone:
    op 0x06, a known compression, and a length equal to its header plus its records' length
    (a false match in other bytes is all but impossible; the chunk's CRC checks the rest).
    None when there is none (the resynchronisation of a file without a summary)."""
    while pos < src.size:
        window = src.read(pos, _WINDOW + _CHUNK_HEAD.size + 16)
        i = window.find(b'\x06')
        while 0 <= i < min(len(window), _WINDOW):
            if _is_chunk_head(window, i):
                return pos + i
            i = window.find(b'\x06', i + 1)
        pos += _WINDOW
    return None


def _is_chunk_head(buf: bytes, i: int) -> bool:
    if i + _CHUNK_HEAD.size > len(buf):
        return False
    _, length, _, _, _, _, n = _CHUNK_HEAD.unpack_from(buf, i)
    start = i + _CHUNK_HEAD.size
    if n > 4 or start + n + 8 > len(buf) or buf[start:start + n] not in _COMPRESSIONS:
        return False
    (records,) = struct.unpack_from('<Q', buf, start + n)
    return length == 8 + 8 + 8 + 4 + 4 + n + 8 + records


def decompress(data: bytes, compression: str, size: int) -> bytes:
    """A chunk's records: at most ``size + 1`` bytes are produced, whatever the compressed
    stream holds (a decompression bomb stops there)."""
    if compression == '':
        return bytes(data)
    if compression == 'zstd':
        try:
            import zstandard
        except ImportError:
            from backports import zstd  # rosbags' own dependency
            return zstd.ZstdDecompressor().decompress(data, max_length=size + 1)
        parts, got = [], 0
        with zstandard.ZstdDecompressor().stream_reader(data) as stream:
            while got <= size:
                part = stream.read(size + 1 - got)
                if not part:
                    break
                parts.append(part)
                got += len(part)
        return b''.join(parts)
    if compression == 'lz4':
        import lz4.frame
        return lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=size + 1)
    raise ValueError(f'unsupported chunk compression {compression!r}')


def decompress_partial(data: bytes, compression: str, limit: int) -> bytes:
    """As much as can be decompressed of a chunk cut short (at most ``limit`` bytes)."""
    try:
        if compression == '':
            return bytes(data)
        if compression == 'zstd':
            import zstandard
            parts, got = [], 0
            for part in zstandard.ZstdDecompressor().read_to_iter(data):
                parts.append(part)
                got += len(part)
                if got > limit:
                    break
            return b''.join(parts)[:limit]
        if compression == 'lz4':
            import lz4.frame
            return lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=limit)
    except Exception:  # noqa: BLE001 - nothing recoverable
        return b''
    return b''
