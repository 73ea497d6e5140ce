"""Little-endian CDR (ROS 2 serialization), a whole column of messages at a time.

Serialising a message object with rosbags and writing it record by record costs about 15
microseconds; the topics of INTERFACES.md have a fixed byte layout (a fixed frame id, names and
array lengths), so they are encoded and decoded here a whole column at a time: one message is
serialised by rosbags as a template, its layout (:class:`CdrLayout`: the offset of every
number, the bytes of every length and string) is found by walking the CDR stream, and all
numbers are then written into, or read out of, an (n, size) byte array with numpy. A received
message whose lengths or strings differ from the template is parsed on its own, so the fast path
never misreads one (test_cdr checks the bytes against rosbags' ``serialize_cdr`` and rclpy's
``serialize_message``; bench/probes/bag_io_speed.py measures both paths).

Message definitions, type hashes and the serialization of arbitrary messages come from the
rosbags typestore for ROS 2 Jazzy (:data:`TYPESTORE`, chosen explicitly, never LATEST). Stamps
are integer nanoseconds since the epoch throughout (``stamp_ns``).
"""
from __future__ import annotations

from dataclasses import dataclass
import struct
from typing import Any, Collection, Mapping, Sequence

import numpy as np
from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_typestore

from road_force_estimator.serde.errors import SerdeError

__all__ = [
    'TYPESTORE', 'NS_PER_S', 'stamps_to_ns', 'ns_to_stamps', 'CdrLayout', 'cdr_layout',
    'encode_columns', 'LazyColumns', 'ColumnRows', 'DecodedGroup', 'ColumnDecoder',
    'decode_columns',
]

#: The message definitions and hashes of ROS 2 Jazzy (never ``Stores.LATEST``).
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
#: Nanoseconds per second.
NS_PER_S = 1_000_000_000

# --------------------------------------------------------------------------------------------
# Stamps

def stamps_to_ns(sec: np.ndarray, nanosec: np.ndarray) -> np.ndarray:
    """Integer nanoseconds from ``builtin_interfaces/Time`` fields (arrays)."""
    return np.asarray(sec, dtype=np.int64) * NS_PER_S + np.asarray(nanosec, dtype=np.int64)


def ns_to_stamps(stamps_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(sec int32, nanosec uint32)`` of integer-nanosecond stamps.

    Raises
    ------
    SerdeError
        A stamp that does not fit a ROS time (negative, or past 2038 for int32 seconds).
    """
    ns = np.asarray(stamps_ns)
    if ns.size and not np.issubdtype(ns.dtype, np.integer):
        raise SerdeError(f'stamps must be integer nanoseconds, got dtype {ns.dtype}')
    ns = ns.astype(np.int64)
    if ns.size and (ns.min() < 0 or ns.max() >= (2**31) * NS_PER_S):
        raise SerdeError(f'stamp range [{ns.min()}, {ns.max()}] ns does not fit a ROS time '
                         f'(0 <= stamp < 2^31 s)')
    return (ns // NS_PER_S).astype(np.int32), (ns % NS_PER_S).astype(np.uint32)


# --------------------------------------------------------------------------------------------
# CDR layouts: the byte position of every number in one serialized message

_PRIMITIVES = {
    'bool': np.dtype('u1'), 'byte': np.dtype('u1'), 'char': np.dtype('u1'),
    'int8': np.dtype('i1'), 'uint8': np.dtype('u1'), 'int16': np.dtype('<i2'),
    'uint16': np.dtype('<u2'), 'int32': np.dtype('<i4'), 'uint32': np.dtype('<u4'),
    'int64': np.dtype('<i8'), 'uint64': np.dtype('<u8'), 'float32': np.dtype('<f4'),
    'float64': np.dtype('<f8'),
}
_U32 = struct.Struct('<I')


class _CdrError(Exception):
    """A CDR stream that does not match its message definition."""


@dataclass(frozen=True)
class CdrLayout:
    """Byte layout of one serialized (little-endian CDR) message.

    Attributes
    ----------
    msgtype : str
        e.g. ``'geometry_msgs/msg/PointStamped'``.
    size : int
        Bytes in the message, 4-byte encapsulation header included.
    fields : dict
        ``path -> (offset, dtype, count)`` for every number; ``path`` is dotted
        (``'header.stamp.sec'``, ``'point.x'``, ``'position'``); ``count`` is None for a
        scalar, else the array or sequence length.
    strings : dict
        ``path -> str`` (or tuple of str for a string array or sequence).
    skeleton : ndarray of int
        Byte indices that must be identical in every message of this layout: the
        encapsulation kind, sequence lengths and strings (alignment padding is excluded:
        rmw leaves it uninitialised).
    skeleton_bytes : ndarray of uint8
        Their values.
    end : int
        Bytes actually used by the fields (``size`` minus any trailing padding).
    """

    msgtype: str
    size: int
    fields: dict[str, tuple[int, np.dtype, int | None]]
    strings: dict[str, Any]
    skeleton: np.ndarray
    skeleton_bytes: np.ndarray
    end: int = 0

    def matches(self, data: bytes) -> bool:
        """True when ``data`` has this layout (same size, lengths and strings)."""
        return len(data) == self.size and bool(np.array_equal(
            np.frombuffer(data, dtype=np.uint8)[self.skeleton], self.skeleton_bytes))


def _align(pos: int, size: int) -> int:
    """Align ``pos`` (absolute, 4-byte encapsulation header first) to ``size`` in CDR."""
    rel = pos - 4
    return 4 + (rel + size - 1) // size * size


class _Walker:
    """Walk a CDR stream along a message definition, recording the layout."""

    def __init__(self, typestore, data: bytes) -> None:
        self.typestore = typestore
        self.data = data
        self.fields: dict[str, tuple[int, np.dtype, int | None]] = {}
        self.strings: dict[str, Any] = {}
        self.skeleton: list[range] = [range(0, 2)]
        self.sequences = 0

    def u32(self, pos: int) -> int:
        if pos + 4 > len(self.data):
            raise _CdrError(f'stream ends at byte {len(self.data)} before a length at {pos}')
        return _U32.unpack_from(self.data, pos)[0]

    def string(self, pos: int) -> tuple[str, int]:
        pos = _align(pos, 4)
        n = self.u32(pos)
        end = pos + 4 + n
        if n == 0 or end > len(self.data) or self.data[end - 1] != 0:
            raise _CdrError(f'bad string of {n} bytes at byte {pos}')
        self.skeleton.append(range(pos, end))
        try:
            return self.data[pos + 4:end - 1].decode('utf-8'), end
        except UnicodeDecodeError as err:
            raise _CdrError(f'string at byte {pos} is not UTF-8') from err

    def message(self, msgtype: str, pos: int, prefix: str) -> int:
        try:
            fields = self.typestore.fielddefs[msgtype][1]
        except KeyError as err:
            raise _CdrError(f'unknown message type {msgtype}') from err
        for name, desc in fields:
            pos = self.desc(desc, pos, prefix + name)
        return pos

    def desc(self, desc, pos: int, path: str) -> int:
        kind, arg = desc
        if kind == Nodetype.BASE:
            typ = arg[0]
            if typ == 'string':
                self.strings[path], pos = self.string(pos)
                return pos
            dtype = self.primitive(typ)
            pos = _align(pos, dtype.itemsize)
            self.fields[path] = (pos, dtype, None)
            return pos + dtype.itemsize
        if kind == Nodetype.NAME:
            return self.message(arg, pos, path + '.')
        if kind not in (Nodetype.ARRAY, Nodetype.SEQUENCE):
            raise _CdrError(f'unsupported field kind {kind!r} at {path}')
        sub, count = arg
        if kind == Nodetype.SEQUENCE:
            pos = _align(pos, 4)
            count = self.u32(pos)
            self.skeleton.append(range(pos, pos + 4))
            self.sequences += 1
            pos += 4
        if sub[0] == Nodetype.BASE and sub[1][0] == 'string':
            values = []
            for _ in range(count):
                value, pos = self.string(pos)
                values.append(value)
            self.strings[path] = tuple(values)
            return pos
        if sub[0] == Nodetype.BASE:
            dtype = self.primitive(sub[1][0])
            if count:
                pos = _align(pos, dtype.itemsize)
            end = pos + count * dtype.itemsize
            if end > len(self.data):
                raise _CdrError(f'{path}: {count} values run past the end of the stream')
            self.fields[path] = (pos, dtype, count)
            return end
        if count > len(self.data):
            raise _CdrError(f'{path}: implausible length {count}')
        for i in range(count):
            pos = self.desc(sub, pos, f'{path}[{i}]')
        return pos

    @staticmethod
    def primitive(typ: str) -> np.dtype:
        try:
            return _PRIMITIVES[typ]
        except KeyError as err:
            raise _CdrError(f'unsupported primitive {typ}') from err


def cdr_layout(msgtype: str, data: bytes, *, typestore=None) -> CdrLayout:
    """Layout of one little-endian CDR message of type ``msgtype``.

    Raises
    ------
    ValueError
        The bytes are not a little-endian CDR message of that type (a length or string
        runs past the end, more trailing bytes than alignment explains, big-endian).
    """
    data = bytes(data)
    if len(data) < 4 or data[0] != 0 or data[1] != 1:
        raise ValueError(f'{msgtype}: not a little-endian CDR message '
                         f'(header {data[:4].hex() or "empty"})')
    walker = _Walker(typestore or TYPESTORE, data)
    try:
        end = walker.message(msgtype, 4, '')
    except (_CdrError, IndexError, struct.error) as err:
        raise ValueError(f'{msgtype}: {err}') from None
    # rmw (Fast-CDR) sizes a message as if empty sequences were aligned: up to 4 spare bytes
    # each, plus final padding, may follow the data.
    if end > len(data) or len(data) - end > 7 + 4 * walker.sequences:
        raise ValueError(f'{msgtype}: walked to byte {end} of a {len(data)}-byte message')
    skeleton = np.fromiter((i for r in walker.skeleton for i in r), dtype=np.int64)
    raw = np.frombuffer(data, dtype=np.uint8)
    return CdrLayout(msgtype, len(data), walker.fields, walker.strings, skeleton,
                     raw[skeleton].copy(), end)


def _template_layout(msgtype: str, template) -> tuple[CdrLayout, np.ndarray]:
    data = bytes(TYPESTORE.serialize_cdr(template, msgtype))
    return cdr_layout(msgtype, data), np.frombuffer(data, dtype=np.uint8)


def encode_columns(msgtype: str, template, n: int,
                   columns: Mapping[str, np.ndarray]) -> np.ndarray:
    """Serialize ``n`` messages that differ from ``template`` only in numbers.

    Parameters
    ----------
    msgtype : str
        Message type, e.g. ``'geometry_msgs/msg/PointStamped'``.
    template : rosbags message
        Fixes the strings and array lengths (and any number not given in ``columns``).
    n : int
        Number of messages.
    columns : mapping
        ``path -> values``: shape (n,) for a scalar, (n, count) for an array (see
        :class:`CdrLayout` for the paths).

    Returns
    -------
    ndarray (n, size) of uint8
        Row i is exactly ``TYPESTORE.serialize_cdr`` of the template with row i's numbers.
    """
    return ColumnRows(msgtype, template, n, columns).array()


class LazyColumns:
    """Column values for :class:`ColumnRows` read from their sources only a block at a time:
    ``parts`` (each (N,) or (N, w)) side by side along the columns, rows ``index`` (n,) of
    them (all N rows when None). Spares an (n, count) copy of whole columns."""

    def __init__(self, parts: Sequence[np.ndarray], index: np.ndarray | None = None) -> None:
        self.parts = [np.asarray(p) for p in parts]
        self.index = index


class ColumnRows:
    """``n`` messages of one fixed layout, kept as the template's bytes and columns of numbers.

    :func:`encode_columns` lays them all out; :meth:`BagWriter.write_rows` writes them straight
    into its record blocks, a block of rows at a time, without an (n, size) copy. A column with
    the same numbers in every row (a broadcast scalar) is written into the template once.

    Attributes
    ----------
    shape : tuple
        ``(n, size)``: messages and bytes per message.
    raw : ndarray (size,) of uint8
        The template's bytes, constant columns included.
    pieces : list of (offset, nbytes)
        Byte offset and width of every other piece of a column in a message; :meth:`values`
        gives its numbers.
    """

    def __init__(self, msgtype: str, template, n: int,
                 columns: Mapping[str, np.ndarray | LazyColumns]) -> None:
        layout, raw = _template_layout(msgtype, template)
        self.shape = (n, layout.size)
        self.raw = raw.copy()
        self.pieces: list[tuple[int, int]] = []
        self._sources: list[tuple[np.dtype, np.ndarray, np.ndarray | None, bool]] = []
        for path, values in columns.items():
            try:
                offset, dtype, count = layout.fields[path]
            except KeyError:
                raise KeyError(f'{msgtype} has no numeric field {path!r} of fixed length; '
                               f'fields: {sorted(layout.fields)}') from None
            width = count if count is not None else 1
            if isinstance(values, LazyColumns):
                self._lazy(msgtype, path, offset, dtype, width, values)
                continue
            array = np.asarray(values)
            if array.dtype.kind == 'f' and dtype.kind in 'iu':
                raise TypeError(f'{msgtype}.{path}: integer field given floats')
            if array.ndim == 0:
                array = np.broadcast_to(array, (n,))
            array = array.reshape(n, width)
            nbytes = width * dtype.itemsize
            if nbytes == 0:
                continue
            if n >= 1 and (n == 1 or array.strides[0] == 0):
                self.raw[offset:offset + nbytes] = np.ascontiguousarray(
                    array[:1], dtype=dtype).view(np.uint8).reshape(nbytes)
                continue
            array = np.ascontiguousarray(array, dtype=dtype)
            self.pieces.append((offset, nbytes))
            self._sources.append((dtype, array.view(f'V{nbytes}').reshape(n), None, True))

    def _lazy(self, msgtype: str, path: str, offset: int, dtype: np.dtype, width: int,
              values: LazyColumns) -> None:
        n = self.shape[0]
        widths = [1 if p.ndim == 1 else p.shape[1] for p in values.parts]
        rows = {len(p) for p in values.parts}
        if sum(widths) != width or len(rows) > 1 or any(p.ndim not in (1, 2)
                                                         for p in values.parts):
            raise ValueError(f'{msgtype}.{path}: parts of widths {widths} and rows '
                             f'{sorted(rows)} for {width} numbers per message')
        if values.index is None and rows != {n} or values.index is not None \
                and len(values.index) != n:
            raise ValueError(f'{msgtype}.{path}: {sorted(rows)} rows for {n} messages')
        for part, w in zip(values.parts, widths):
            if part.dtype.kind == 'f' and dtype.kind in 'iu':
                raise TypeError(f'{msgtype}.{path}: integer field given floats')
            if n:
                self.pieces.append((offset, w * dtype.itemsize))
                self._sources.append((dtype, part.reshape(len(part), w), values.index, False))
            offset += w * dtype.itemsize

    def __len__(self) -> int:
        return self.shape[0]

    def stamp_pieces(self) -> tuple[int, int] | None:
        """The pieces of ``header.stamp.sec`` and ``.nanosec`` (message bytes 4 to 12, the
        header first) when both are whole columns of their own, else None."""
        found = {}
        for i, (offset, nbytes) in enumerate(self.pieces):
            if nbytes == 4 and offset in (4, 8) and self._sources[i][3]:
                found[offset] = i
        return (found[4], found[8]) if len(found) == 2 else None

    def values(self, piece: int, r0: int, r1: int) -> np.ndarray:
        """Piece ``piece`` of messages ``r0:r1``: one ``V<nbytes>`` item per message."""
        dtype, source, index, ready = self._sources[piece]
        if ready:
            return source[r0:r1]
        if index is None:
            rows = source[r0:r1]
        elif source.flags.c_contiguous:
            rows = source.take(index[r0:r1], axis=0, mode='clip')
        else:
            rows = source[index[r0:r1]]
        return np.ascontiguousarray(rows, dtype=dtype).view(
            f'V{self.pieces[piece][1]}').reshape(r1 - r0)

    def array(self) -> np.ndarray:
        """All messages, an (n, size) uint8 array."""
        n, size = self.shape
        rows = np.empty((n, size), dtype=np.uint8)
        rows[:] = self.raw
        for i, (offset, nbytes) in enumerate(self.pieces):
            rows[:, offset:offset + nbytes] = self.values(i, 0, n).view(np.uint8).reshape(
                n, nbytes)
        return rows

@dataclass
class DecodedGroup:
    """Messages (indices into the decoded list) that share one layout, and their numbers."""

    index: np.ndarray
    layout: CdrLayout
    columns: dict[str, np.ndarray]


def _group_columns(layout: CdrLayout, rows: np.ndarray,
                   paths: Collection[str] | None = None) -> dict[str, np.ndarray]:
    """Number fields (all, or ``paths``) of messages of one layout, ``rows`` (m, size) uint8
    (each row contiguous). The arrays returned are new, never views of ``rows``."""
    out = {}
    m = rows.shape[0]
    for path, (offset, dtype, count) in layout.fields.items():
        if paths is not None and path not in paths:
            continue
        width = count if count is not None else 1
        if m == 0 or width == 0:
            values = np.zeros((m, width), dtype=dtype.newbyteorder('='))
        else:
            values = rows[:, offset:offset + width * dtype.itemsize].view(dtype).astype(
                dtype.newbyteorder('='))
        out[path] = values[:, 0] if count is None else values
    return out


class _LayoutParts:
    """One layout met while decoding a topic, and the messages decoded with it so far."""

    def __init__(self, layout: CdrLayout, first: np.ndarray,
                 paths: Collection[str] | None) -> None:
        self.layout = layout
        self.paths = paths
        self.mask = np.zeros(layout.size, dtype=np.uint8)
        self.mask[layout.skeleton] = 0xFF
        self.template = first & self.mask
        self.index: list[np.ndarray] = []
        self.columns: list[dict[str, np.ndarray]] = []

    def match(self, rows: np.ndarray) -> np.ndarray | None:
        """None when every message (row) has this layout's skeleton bytes, else the mask of
        those that have."""
        diff = np.bitwise_and(rows, self.mask)
        diff ^= self.template
        if not diff.any():
            return None
        return ~diff.any(axis=1)

    def add(self, index: np.ndarray, rows: np.ndarray) -> None:
        self.index.append(index)
        self.columns.append(_group_columns(self.layout, rows, self.paths))

    def group(self) -> DecodedGroup:
        if len(self.index) == 1:
            return DecodedGroup(self.index[0], self.layout, self.columns[0])
        return DecodedGroup(np.concatenate(self.index), self.layout, {
            path: np.concatenate([c[path] for c in self.columns]) for path in self.columns[0]})


class ColumnDecoder:
    """Decode the messages of one topic a column at a time, a batch (e.g. a chunk) after
    another, while they are in the cache; :meth:`result` is what :func:`decode_columns`
    returns for all of them (only the number fields ``paths``, when given).

    The layouts met are kept per message length: a message whose skeleton bytes (lengths,
    strings) equal a known layout's is decoded with it (walking it would give the same
    layout), the others are walked in turn, so the result does not depend on how the
    messages are cut into batches.
    """

    def __init__(self, msgtype: str, typestore=None,
                 paths: Collection[str] | None = None) -> None:
        self.msgtype = msgtype
        self.typestore = typestore or TYPESTORE
        self.paths = None if paths is None else frozenset(paths)
        self.layouts: dict[int, list[_LayoutParts]] = {}
        self.singles: list[DecodedGroup] = []
        self.bad: list[int] = []

    def add_rows(self, rows: np.ndarray, index: np.ndarray) -> None:
        """Decode messages of one length: ``rows`` (m, size) uint8 (each row contiguous),
        ``index`` (m,) int64 their positions in the topic."""
        known = self.layouts.setdefault(rows.shape[1], [])
        for parts in known:
            if not index.size:
                return
            match = parts.match(rows)
            if match is None:
                parts.add(index, rows)
                return
            if match.any():
                parts.add(index[match], rows[match])
                rows, index = rows[~match], index[~match]
        while index.size:
            data = rows[0].tobytes()
            try:
                layout = cdr_layout(self.msgtype, data, typestore=self.typestore)
            except ValueError:
                converted = _convert_endianness(self.msgtype, data, self.typestore)
                if converted is None:
                    self.bad.append(int(index[0]))
                else:
                    layout = cdr_layout(self.msgtype, converted, typestore=self.typestore)
                    one = np.frombuffer(converted, dtype=np.uint8).reshape(1, -1)
                    self.singles.append(DecodedGroup(index[:1].copy(), layout, _group_columns(
                        layout, one, self.paths)))
                rows, index = rows[1:], index[1:]
                continue
            parts = _LayoutParts(layout, rows[0], self.paths)
            known.append(parts)
            match = parts.match(rows)
            if match is None:
                parts.add(index, rows)
                return
            parts.add(index[match], rows[match])
            rows, index = rows[~match], index[~match]

    def add_datas(self, datas: Sequence[bytes], start: int = 0) -> None:
        """Decode serialized messages at positions ``start``, ``start + 1``, ..."""
        n = len(datas)
        if n == 0:
            return
        lengths = np.fromiter(map(len, datas), dtype=np.int64, count=n)
        if np.all(lengths == lengths[0]):
            groups = [np.arange(n)]
        else:
            order = np.argsort(lengths, kind='stable')
            groups = np.split(order, np.flatnonzero(np.diff(lengths[order])) + 1)
        for idx in groups:
            size = int(lengths[idx[0]])
            rows = np.frombuffer(b''.join([datas[i] for i in idx.tolist()]), dtype=np.uint8)
            self.add_rows(rows.reshape(idx.size, size), idx + start)

    def result(self) -> tuple[list[DecodedGroup], np.ndarray]:
        """``(groups, undecodable positions)`` as :func:`decode_columns` returns them."""
        groups = [parts.group() for size in sorted(self.layouts)
                  for parts in self.layouts[size] if parts.index]
        return groups + self.singles, np.asarray(sorted(self.bad), dtype=np.int64)


def decode_columns(msgtype: str, datas: Sequence[bytes], *,
                   typestore=None) -> tuple[list[DecodedGroup], np.ndarray]:
    """Decode serialized messages a column at a time.

    Returns
    -------
    groups : list
        Each has ``index`` (positions in ``datas``), ``layout`` (:class:`CdrLayout`: its
        strings, e.g. the JointState names) and ``columns`` (``path -> ndarray``, scalars
        (m,), arrays (m, count)).
    undecodable : ndarray of int
        Positions of messages that are not a valid CDR message of that type.

    Notes
    -----
    Messages are grouped by length; in each group the first message is walked, and every
    message whose skeleton bytes (lengths, strings) equal its skeleton shares its layout and is
    decoded by numpy; the others are walked in turn. A big-endian message is converted by
    rosbags first.
    """
    decoder = ColumnDecoder(msgtype, typestore)
    decoder.add_datas(datas)
    return decoder.result()


def _convert_endianness(msgtype: str, data: bytes, typestore) -> bytes | None:
    """Little-endian re-serialization of a big-endian message, or None if undecodable."""
    if len(data) < 4 or data[1] != 0:
        return None
    try:
        msg = typestore.deserialize_cdr(data, msgtype)
        return bytes(typestore.serialize_cdr(msg, msgtype))
    except Exception:  # noqa: BLE001 - any failure means: not a message of this type
        return None
