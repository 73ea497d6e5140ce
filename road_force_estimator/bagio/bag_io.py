"""Bag I/O: rosbag2 folders with MCAP storage, the only module that imports rosbags.

Bags are written as Jazzy's rosbag2 writes them: a folder with ``metadata.yaml`` (version 9,
storage ``mcap``, offered QoS profiles as YAML lists, RIHS01 type hashes, a ``custom_data``
map) and ``<folder>_0.mcap`` (profile ``ros2``, ``ros2msg`` schemas, little-endian CDR
messages in CRC-checked chunks, message and chunk indexes, the ``rosbag2`` metadata record),
so that ``ros2 bag info/play``, the ``mcap`` / ``mcap-ros2-support`` libraries and rosbags read
them. Message definitions, type hashes and the serialization of arbitrary messages come from
the rosbags typestore for ROS 2 Jazzy (:data:`TYPESTORE`, chosen explicitly, never LATEST).

Speed. Serialising a message object with rosbags and writing it record by record costs
about 15 microseconds; the topics of INTERFACES.md have a fixed byte layout (a fixed frame
id, names and array lengths), so they are encoded and decoded here a whole column at a time:
one message is serialised by rosbags as a template, its layout (the offset of every number,
the bytes of every length and string) is found by walking the CDR stream, and all numbers
are then written into, or read out of, an (n, size) byte array with numpy; the MCAP records
around them are laid out with numpy too (the container itself, records, chunks, indexes and
CRCs: :mod:`bagio.mcap_file`). A received message whose lengths or strings differ
from the template is parsed on its own, so the fast path never misreads one (test_bag_io
checks the bytes against rosbags' ``serialize_cdr`` and rclpy's ``serialize_message``, and
bench/bag_io_speed.py measures both paths).

Robustness. Reading walks each MCAP file record by record from its start, so a bag whose
recording was cut (no summary, a truncated chunk, a missing ``metadata.yaml``) or that is
corrupt yields every message it can trust and one line per break: a chunk that fails its CRC
is skipped and reading goes on; a cut or corrupt record outside chunks ends the file. The
column readers take a chunk whose message index accounts for every record in it (checked
record by record, with numpy) through that index, about five times faster than the walk and
with the same result; any other chunk is walked (bench/bag_read_speed.py).
Messages come in file order, which is log-time order for the bags rosbag2, the bag_recorder
node and this module write. The ``read_*`` functions reject and count what cannot be trusted
(undecodable, non-finite, a JointState without a required name or with arrays of the wrong
length, duplicate or backward stamps) and keep going.

Stamps are integer nanoseconds since the epoch throughout (``stamp_ns``); the header stamp of
a message is the time of the sample it carries, the log time is when it was recorded.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math
from pathlib import Path
import shutil
import struct
from typing import Any, Collection, Iterable, Iterator, Mapping, Sequence

import numpy as np
from rosbags.interfaces import (
    Nodetype,
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
import yaml

from road_force_estimator.bagio.mcap_file import (
    _HEAD,
    _LEAD,
    _Block,
    _Channel,
    _McapFile,
    _McapScan,
)

__all__ = [
    'TYPESTORE', 'ROSBAG2_VERSION', 'DEFAULT_START_STAMP_NS', 'DEFAULT_SURVEY_SPEED_MPS',
    'DEFAULT_TRACK_WIDTH_M',
    'TOPIC_DEFLECTIONS', 'TOPIC_TWIST', 'TOPIC_TRUE_LOAD', 'TOPIC_TRUE_ROAD', 'TOPIC_FIX',
    'TOPIC_LOAD', 'TOPIC_ROAD', 'TOPIC_LTR', 'TOPIC_STATES', 'TOPIC_DIAGNOSTICS', 'TOPIC_LPA',
    'MSGTYPES', 'DEFLECTION_NAMES', 'STATE_NAMES', 'FRAME_BASE', 'FRAME_ROAD', 'WHEEL_FRAMES',
    'SENSOR_DATA_QOS', 'RELIABLE_QOS',
    'BagReadError', 'BagWriteError', 'CdrLayout', 'cdr_layout', 'encode_columns',
    'decode_columns', 'stamps_to_ns', 'ns_to_stamps',
    'BagWriter', 'BagInfo', 'bag_info', 'iter_messages', 'TopicColumns', 'read_topic_columns',
    'write_lpa_bag', 'read_lpa_bag', 'GroundTruth', 'Fixes', 'Drive', 'write_drive_bag',
    'read_drive_bag', 'write_estimate_bag', 'diagnostic_array', 'ESTIMATE_FIELDS',
]

#: The message definitions and hashes of ROS 2 Jazzy (never ``Stores.LATEST``).
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
#: metadata.yaml version written by Jazzy's rosbag2.
ROSBAG2_VERSION = 9
#: Default first stamp of a written bag: 2024-01-01T00:00:00Z (deterministic output).
DEFAULT_START_STAMP_NS = 1_704_067_200 * 1_000_000_000
#: Default survey speed of an LPA profile bag (m/s).
DEFAULT_SURVEY_SPEED_MPS = 20.0
#: Default track width, the lateral distance between the two wheel paths (m).
DEFAULT_TRACK_WIDTH_M = 2.0

# Topics of INTERFACES.md; per-side topics are (left, right).
TOPIC_DEFLECTIONS = '/suspension/deflections'
TOPIC_TWIST = '/vehicle/twist'
TOPIC_TRUE_LOAD = ('/ground_truth/wheel_load/left', '/ground_truth/wheel_load/right')
TOPIC_TRUE_ROAD = ('/ground_truth/road_profile/left', '/ground_truth/road_profile/right')
TOPIC_FIX = '/fix'
TOPIC_LOAD = ('/wheel_load/left', '/wheel_load/right')
TOPIC_ROAD = ('/road_profile/left', '/road_profile/right')
TOPIC_LTR = '/load_transfer_ratio'
TOPIC_STATES = '/observer/states'
TOPIC_DIAGNOSTICS = '/diagnostics'
TOPIC_LPA = ('/lpa/left', '/lpa/right')

_JOINT_STATE = 'sensor_msgs/msg/JointState'
_POINT = 'geometry_msgs/msg/PointStamped'
_WRENCH = 'geometry_msgs/msg/WrenchStamped'
_TWIST = 'geometry_msgs/msg/TwistStamped'
_FLOAT64 = 'std_msgs/msg/Float64'
_NAVSATFIX = 'sensor_msgs/msg/NavSatFix'
_DIAGNOSTICS = 'diagnostic_msgs/msg/DiagnosticArray'

#: Message type of every topic of INTERFACES.md.
MSGTYPES: dict[str, str] = {
    TOPIC_DEFLECTIONS: _JOINT_STATE,
    TOPIC_TWIST: _TWIST,
    **{t: _WRENCH for t in TOPIC_TRUE_LOAD + TOPIC_LOAD},
    **{t: _POINT for t in TOPIC_TRUE_ROAD + TOPIC_ROAD + TOPIC_LPA},
    TOPIC_FIX: _NAVSATFIX,
    TOPIC_LTR: _FLOAT64,
    TOPIC_STATES: _JOINT_STATE,
    TOPIC_DIAGNOSTICS: _DIAGNOSTICS,
}

#: JointState names of /suspension/deflections: q_1, q_2 (m), phi (rad).
DEFLECTION_NAMES = ('left_suspension', 'right_suspension', 'roll')
#: JointState names of /observer/states.
STATE_NAMES = ('left_suspension', 'right_suspension', 'roll', 'body_heave',
               'left_wheel_heave', 'right_wheel_heave')
FRAME_BASE = 'base_link'
FRAME_ROAD = 'road'
WHEEL_FRAMES = ('front_left_wheel', 'front_right_wheel')

_INFINITE = QosTime(9223372036, 854775807)   # RMW_DURATION_INFINITE, as rosbag2 records it
#: Sensor-data QoS (best effort, keep last 5), as rclpy's qos_profile_sensor_data.
SENSOR_DATA_QOS = Qos(QosHistory.KEEP_LAST, 5, QosReliability.BEST_EFFORT,
                      QosDurability.VOLATILE, _INFINITE, _INFINITE, QosLiveliness.AUTOMATIC,
                      _INFINITE, False)
#: Reliable QoS (keep last 10), the rclpy default: ground truth, estimates, profiles.
RELIABLE_QOS = Qos(QosHistory.KEEP_LAST, 10, QosReliability.RELIABLE, QosDurability.VOLATILE,
                   _INFINITE, _INFINITE, QosLiveliness.AUTOMATIC, _INFINITE, False)
_QOS_BY_NAME = {'sensor_data': SENSOR_DATA_QOS, 'reliable': RELIABLE_QOS}
_TOPIC_QOS = {TOPIC_DEFLECTIONS: SENSOR_DATA_QOS, TOPIC_TWIST: SENSOR_DATA_QOS,
              TOPIC_FIX: SENSOR_DATA_QOS}

_NS = 1_000_000_000


class BagReadError(Exception):
    """A bag that cannot be read at all (missing, not a bag, no usable message)."""


class BagWriteError(Exception):
    """A bag that cannot be written (the folder exists, bad stamps, unknown topic)."""


# --------------------------------------------------------------------------------------------
# Stamps

def stamps_to_ns(sec: np.ndarray, nanosec: np.ndarray) -> np.ndarray:
    """Integer nanoseconds from ``builtin_interfaces/Time`` fields (arrays)."""
    return np.asarray(sec, dtype=np.int64) * _NS + np.asarray(nanosec, dtype=np.int64)


def ns_to_stamps(stamps_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(sec int32, nanosec uint32)`` of integer-nanosecond stamps.

    Raises
    ------
    BagWriteError
        A stamp that does not fit a ROS time (negative, or past 2038 for int32 seconds).
    """
    ns = np.asarray(stamps_ns)
    if ns.size and not np.issubdtype(ns.dtype, np.integer):
        raise BagWriteError(f'stamps must be integer nanoseconds, got dtype {ns.dtype}')
    ns = ns.astype(np.int64)
    if ns.size and (ns.min() < 0 or ns.max() >= (2**31) * _NS):
        raise BagWriteError(f'stamp range [{ns.min()}, {ns.max()}] ns does not fit a ROS time '
                            f'(0 <= stamp < 2^31 s)')
    return (ns // _NS).astype(np.int32), (ns % _NS).astype(np.uint32)


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
    return _ColumnRows(msgtype, template, n, columns).array()


class _Lazy:
    """Column values for :class:`_ColumnRows` read from their sources only a block at a time:
    ``parts`` (each (N,) or (N, w)) side by side along the columns, rows ``index`` (n,) of
    them (all N rows when None). Spares an (n, count) copy of whole columns."""

    def __init__(self, parts: Sequence[np.ndarray], index: np.ndarray | None = None) -> None:
        self.parts = [np.asarray(p) for p in parts]
        self.index = index


class _ColumnRows:
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
                 columns: Mapping[str, np.ndarray | _Lazy]) -> None:
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
            if isinstance(values, _Lazy):
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
              values: _Lazy) -> None:
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
class _DecodedGroup:
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

    def group(self) -> _DecodedGroup:
        if len(self.index) == 1:
            return _DecodedGroup(self.index[0], self.layout, self.columns[0])
        return _DecodedGroup(np.concatenate(self.index), self.layout, {
            path: np.concatenate([c[path] for c in self.columns]) for path in self.columns[0]})


class _ColumnDecoder:
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
        self.singles: list[_DecodedGroup] = []
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
                    self.singles.append(_DecodedGroup(index[:1].copy(), layout, _group_columns(
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

    def result(self) -> tuple[list[_DecodedGroup], np.ndarray]:
        groups = [parts.group() for size in sorted(self.layouts)
                  for parts in self.layouts[size] if parts.index]
        return groups + self.singles, np.asarray(sorted(self.bad), dtype=np.int64)


def decode_columns(msgtype: str, datas: Sequence[bytes], *,
                   typestore=None) -> tuple[list[_DecodedGroup], np.ndarray]:
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
    decoder = _ColumnDecoder(msgtype, typestore)
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


# --------------------------------------------------------------------------------------------
# Message templates of INTERFACES.md

def _msg(name: str):
    return TYPESTORE.types[name]


def _header(frame_id: str):
    return _msg('std_msgs/msg/Header')(stamp=_msg('builtin_interfaces/msg/Time')(sec=0,
                                                                                 nanosec=0),
                                       frame_id=frame_id)


def _vector3():
    return _msg('geometry_msgs/msg/Vector3')(x=0.0, y=0.0, z=0.0)


def _template(msgtype: str, frame_id: str = '', names: Sequence[str] = (),
              velocity: bool = False):
    if msgtype == _POINT:
        return _msg(_POINT)(header=_header(frame_id),
                            point=_msg('geometry_msgs/msg/Point')(x=0.0, y=0.0, z=0.0))
    if msgtype == _WRENCH:
        return _msg(_WRENCH)(header=_header(frame_id), wrench=_msg('geometry_msgs/msg/Wrench')(
            force=_vector3(), torque=_vector3()))
    if msgtype == _TWIST:
        return _msg(_TWIST)(header=_header(frame_id), twist=_msg('geometry_msgs/msg/Twist')(
            linear=_vector3(), angular=_vector3()))
    if msgtype == _FLOAT64:
        return _msg(_FLOAT64)(data=0.0)
    if msgtype == _JOINT_STATE:
        k = len(names)
        return _msg(_JOINT_STATE)(header=_header(frame_id), name=list(names),
                                  position=np.zeros(k), velocity=np.zeros(k if velocity else 0),
                                  effort=np.zeros(0))
    if msgtype == _NAVSATFIX:
        status = _msg('sensor_msgs/msg/NavSatStatus')(status=0, service=0)
        return _msg(_NAVSATFIX)(header=_header(frame_id), status=status, latitude=0.0,
                                longitude=0.0, altitude=0.0, position_covariance=np.zeros(9),
                                position_covariance_type=0)
    raise ValueError(f'no template for {msgtype}')


def _stamp_columns(stamps_ns: np.ndarray) -> dict[str, np.ndarray]:
    sec, nanosec = ns_to_stamps(stamps_ns)
    return {'header.stamp.sec': sec, 'header.stamp.nanosec': nanosec}


# --------------------------------------------------------------------------------------------
# Writing

def _qos(qos) -> Qos:
    if qos is None:
        return RELIABLE_QOS
    if isinstance(qos, Qos):
        return qos
    if isinstance(qos, str):
        try:
            return _QOS_BY_NAME[qos]
        except KeyError:
            raise ValueError(f'qos = {qos!r}: one of {sorted(_QOS_BY_NAME)}, a mapping or '
                             'a rosbags Qos') from None
    if isinstance(qos, Mapping):
        base = RELIABLE_QOS._asdict()
        enums = {'history': QosHistory, 'reliability': QosReliability,
                 'durability': QosDurability, 'liveliness': QosLiveliness}
        for key, value in qos.items():
            if key not in base:
                raise ValueError(f'qos key {key!r}: one of {sorted(base)}')
            if key in enums and isinstance(value, str):
                value = enums[key][value.upper()]
            elif key in ('deadline', 'lifespan', 'liveliness_lease_duration'):
                value = QosTime(int(value['sec']), int(value['nsec'])) \
                    if isinstance(value, Mapping) else QosTime(*value)
            base[key] = value
        return Qos(**base)
    raise ValueError(f'qos = {qos!r}: one of {sorted(_QOS_BY_NAME)}, a mapping or a Qos')


def _prepare_folder(path: Path, overwrite: bool) -> None:
    if not path.exists():
        return
    if not overwrite:
        raise BagWriteError(f'{path} exists already (replace it with --force or '
                            'overwrite=True)')
    if not path.is_dir():
        raise BagWriteError(f'{path} exists and is not a folder: not overwriting it')
    entries = list(path.iterdir())
    if any(e.is_dir() or e.suffix not in ('.mcap', '.yaml', '.db3', '.zstd')
           for e in entries):
        raise BagWriteError(f'{path} holds more than a bag: not overwriting it')
    shutil.rmtree(path)


def _qos_dict(qos: Qos) -> dict[str, Any]:
    """One offered QoS profile as rosbag2 (metadata version 9) writes it."""
    def time(t: QosTime) -> dict[str, int]:
        return {'sec': int(t.sec), 'nsec': int(t.nsec)}
    return {
        'history': qos.history.name.lower(), 'depth': int(qos.depth),
        'reliability': qos.reliability.name.lower(),
        'durability': qos.durability.name.lower(), 'deadline': time(qos.deadline),
        'lifespan': time(qos.lifespan), 'liveliness': qos.liveliness.name.lower(),
        'liveliness_lease_duration': time(qos.liveliness_lease_duration),
        'avoid_ros_namespace_conventions': bool(qos.avoid_ros_namespace_conventions),
    }


def _yaml(data: Any) -> str:
    return yaml.safe_dump(data, sort_keys=False, default_flow_style=False, width=1000)


class BagWriter:
    """Write a rosbag2 folder with MCAP storage, as Jazzy's rosbag2 does.

    ``metadata.yaml`` (version 9) and ``<folder>_0.mcap`` (profile ``ros2``, ``ros2msg``
    schemas from the Jazzy typestore, CDR messages, CRC-checked chunks, summary and the
    ``rosbag2`` metadata record). Use as a context manager; after an exception the chunks
    written so far are kept, without index or metadata.yaml (the readers here read them).
    Not thread-safe.

    Parameters
    ----------
    path : str or Path
        Bag folder to create (must not exist, unless ``overwrite`` and it holds only a bag).
    storage : str
        ``'mcap'`` (the only one offered).
    overwrite : bool
        Replace an existing bag folder.
    custom_data : mapping, optional
        ``str -> str`` pairs stored in metadata.yaml ``custom_data``.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> folder = pathlib.Path(tempfile.mkdtemp()) / 'bag'
    >>> with BagWriter(folder) as bag:
    ...     bag.add_topic('/load_transfer_ratio', 'std_msgs/msg/Float64')
    ...     bag.write('/load_transfer_ratio', 5, TYPESTORE.types['std_msgs/msg/Float64'](0.1))
    >>> sorted(p.name for p in folder.iterdir())
    ['bag_0.mcap', 'metadata.yaml']
    """

    #: Messages laid out per numpy block by :meth:`write_rows` when no streams are aligned
    #: (bounds the temporary memory).
    BLOCK_MESSAGES = 65536
    #: Bytes of aligned rows laid out per block by :meth:`write_rows`: the block buffer is
    #: reused, so it stays in the cache and its constant bytes are written once.
    BLOCK_BYTES = 1 << 22

    def __init__(self, path: str | Path, *, storage: str = 'mcap', overwrite: bool = False,
                 custom_data: Mapping[str, str] | None = None) -> None:
        if storage != 'mcap':
            raise ValueError(f"storage = {storage!r}: only 'mcap' is written")
        self.path = Path(path)
        self._overwrite = overwrite
        self._file: _McapFile | None = None
        # A map, never null (yaml-cpp in rosbag2 refuses a null custom_data), with a tag
        # that tells where the bag came from.
        self._custom: dict[str, str] = {'road_force_estimator.writer': 'bag_io'}
        for key, value in (custom_data or {}).items():
            self.set_custom_data(key, value)
        self._channels: dict[str, int] = {}
        self._types: dict[str, str] = {}
        self._qos: dict[str, Qos] = {}
        self._schemas: dict[str, int] = {}
        self._layouts: dict[str, dict[int, CdrLayout]] = {}

    @property
    def message_count(self) -> int:
        """Messages written so far."""
        return self._file.message_count if self._file is not None else 0

    def set_custom_data(self, key: str, value: str) -> None:
        """Store ``key: value`` (strings) in metadata.yaml ``custom_data``."""
        if not isinstance(key, str) or not isinstance(value, str):
            raise ValueError(f'custom_data {key!r}: {value!r}: keys and values must be str')
        self._custom[key] = value

    def open(self) -> None:
        """Create the folder and the .mcap file."""
        _prepare_folder(self.path, self._overwrite)
        try:
            self.path.mkdir(parents=True)
            self._file = _McapFile(self.path / f'{self.path.name}_0.mcap')
        except OSError as err:
            raise BagWriteError(f'{self.path}: cannot create the bag ({err.strerror})') \
                from None

    def _metadata(self) -> dict[str, Any]:
        f = self._file
        count = f.message_count
        start = f.start_ns if count else 0
        duration = (f.end_ns - f.start_ns) if count else 0
        return {
            'version': ROSBAG2_VERSION,
            'storage_identifier': 'mcap',
            'duration': {'nanoseconds': int(duration)},
            'starting_time': {'nanoseconds_since_epoch': int(start)},
            'message_count': int(count),
            'topics_with_message_count': [
                {'topic_metadata': {
                    'name': topic, 'type': self._types[topic], 'serialization_format': 'cdr',
                    'offered_qos_profiles': [_qos_dict(self._qos[topic])],
                    'type_description_hash': TYPESTORE.hash_rihs01(self._types[topic])},
                 'message_count': int(f.counts[cid])}
                for topic, cid in self._channels.items()],
            'compression_format': '',
            'compression_mode': '',
            'relative_file_paths': [f.path.name],
            'files': [{'path': f.path.name,
                       'starting_time': {'nanoseconds_since_epoch': int(start)},
                       'duration': {'nanoseconds': int(duration)},
                       'message_count': int(count)}],
            'custom_data': dict(self._custom),
            'ros_distro': 'jazzy',
        }

    def close(self) -> None:
        """Write the summary, the index and metadata.yaml."""
        if self._file is None:
            return
        f, info = self._file, None
        f.flush_chunk()
        info = self._metadata()
        f.close(_yaml(info))
        self._file = None
        tmp = self.path / 'metadata.yaml.tmp'
        tmp.write_text(_yaml({'rosbag2_bagfile_information': info}), 'utf-8')
        tmp.replace(self.path / 'metadata.yaml')

    def __enter__(self) -> BagWriter:
        self.open()
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is None:
            self.close()
        elif self._file is not None:
            self._file.abort()
            self._file = None
        return False

    @property
    def topics(self) -> dict[str, str]:
        """``topic -> msgtype`` of the topics added so far."""
        return dict(self._types)

    def add_topic(self, topic: str, msgtype: str, qos=None) -> None:
        """Declare a topic.

        Parameters
        ----------
        topic : str
            e.g. ``'/suspension/deflections'``.
        msgtype : str
            e.g. ``'sensor_msgs/msg/JointState'`` (``pkg/Type`` is accepted too).
        qos : str, mapping or rosbags Qos, optional
            Offered QoS recorded in the metadata: ``'sensor_data'`` (best effort, keep last
            5), ``'reliable'`` (keep last 10, the default), or a mapping with the keys of
            metadata.yaml (``{'reliability': 'best_effort', 'depth': 5}``).
        """
        if self._file is None:
            raise BagWriteError('the bag is not open: use BagWriter as a context manager')
        if '/msg/' not in msgtype and msgtype.count('/') == 1:
            msgtype = msgtype.replace('/', '/msg/')
        if msgtype not in TYPESTORE.types:
            raise BagWriteError(f'topic {topic}: unknown message type {msgtype!r} '
                                '(not in the ROS 2 Jazzy typestore)')
        if topic in self._types:
            if self._types[topic] != msgtype:
                raise BagWriteError(f'topic {topic} already added as {self._types[topic]}')
            return
        profile = _qos(qos)
        if msgtype not in self._schemas:
            text, _ = TYPESTORE.generate_msgdef(msgtype, ros_version=2)
            self._schemas[msgtype] = self._file.add_schema(msgtype, 'ros2msg', text)
        self._channels[topic] = self._file.add_channel(
            self._schemas[msgtype], topic, 'cdr',
            {'offered_qos_profiles': _yaml([_qos_dict(profile)]),
             'topic_type_hash': TYPESTORE.hash_rihs01(msgtype)})
        self._types[topic] = msgtype
        self._qos[topic] = profile

    def _channel(self, topic: str) -> int:
        try:
            return self._channels[topic]
        except KeyError:
            raise BagWriteError(f'topic {topic} was not added (add_topic first)') from None

    def write(self, topic: str, stamp_ns: int, msg) -> None:
        """Serialize ``msg`` (a rosbags message of the topic's type) and write it.

        ``stamp_ns`` is the log time (int ns); the message keeps its own header stamp.
        """
        data = TYPESTORE.serialize_cdr(msg, self._types.get(topic) or msg.__msgtype__)
        self.write_raw(topic, stamp_ns, data)

    def write_raw(self, topic: str, stamp_ns: int, data: bytes | memoryview) -> None:
        """Write an already serialized (CDR) message, e.g. as rclpy delivers it.

        Spare bytes that rmw's serializer may leave after the last field (it sizes empty
        sequences as if aligned) are dropped, since rosbags refuses them; the fields are
        written unchanged. A message that does not parse is written as it is.
        """
        cid = self._channel(topic)
        if not isinstance(stamp_ns, (int, np.integer)) or not 0 <= stamp_ns < 2**63:
            raise BagWriteError(f'stamp_ns = {stamp_ns!r}: a non-negative integer (ns)')
        self._file.write(cid, int(stamp_ns), self._trim(topic, bytes(data)))

    def _trim(self, topic: str, data: bytes) -> bytes:
        layouts = self._layouts.setdefault(topic, {})
        layout = layouts.get(len(data))
        if layout is None or not layout.matches(data):
            try:
                layout = cdr_layout(self._types[topic], data)
            except ValueError:
                return data
            layouts[len(data)] = layout
        # CDR keeps up to 3 bytes of final padding: rosbags accepts those.
        return data if len(data) - layout.end <= 3 else data[:layout.end]

    def write_rows(self, streams: Sequence[tuple[str, np.ndarray, Any]]) -> None:
        """Write several topics' serialized messages, interleaved by stamp.

        Parameters
        ----------
        streams : sequence of (topic, stamps_ns (n,), rows)
            ``rows`` is an (n, size) uint8 array as :func:`encode_columns` makes it (or the
            template and columns it is made of, ``_ColumnRows``), or a sequence of n
            bytes-like messages. Messages are written by stamp; at equal stamps the streams
            keep the order given (and each stream its own order). Stamps are the log times
            (ns).

        Notes
        -----
        The largest set of fixed-size streams that share strictly increasing stamps (a drive:
        every topic at every sample) is laid out as one 2-D array, row after row, a block of
        rows at a time in a reused buffer; the other messages (diagnostics, GNSS fixes) are
        spliced in between at their places. Complete chunks go to the file straight from
        the block.
        """
        prepared = []
        for topic, stamp_ns, rows in streams:
            cid = self._channel(topic)
            stamp_ns = np.asarray(stamp_ns, dtype=np.int64).reshape(-1)
            if isinstance(rows, np.ndarray):
                rows = np.ascontiguousarray(rows, dtype=np.uint8)
                if rows.ndim != 2:
                    raise BagWriteError(f'{topic}: rows of shape {rows.shape}: need (n, size)')
            elif not isinstance(rows, _ColumnRows):
                rows = [bytes(r) for r in rows]
            if len(rows) != stamp_ns.size:
                raise BagWriteError(f'{topic}: {stamp_ns.size} stamps for {len(rows)} messages')
            if stamp_ns.size and (stamp_ns.min() < 0):
                raise BagWriteError(f'{topic}: negative stamp {stamp_ns.min()} ns')
            prepared.append((cid, stamp_ns, rows))
        prepared = [p for p in prepared if p[1].size]
        if prepared:
            self._write_spliced(prepared, self._aligned(prepared))

    @staticmethod
    def _aligned(prepared) -> list[int]:
        """Positions of the streams laid out as one 2-D block, row after row: the largest set
        of fixed-size streams, each with a channel of its own, that share strictly increasing
        stamps."""
        cids = [cid for cid, _, _ in prepared]
        free = [j for j, (cid, s, rows) in enumerate(prepared)
                if not isinstance(rows, list) and cids.count(cid) == 1
                and bool(np.all(s[1:] > s[:-1]))]
        best: list[int] = []
        while free:
            s = prepared[free[0]][1]
            group = [j for j in free
                     if prepared[j][1].size == s.size and np.array_equal(prepared[j][1], s)]
            if len(group) * s.size > len(best) * (prepared[best[0]][1].size if best else 0):
                best = group
            free = [j for j in free if j not in group]
        return best

    def _write_spliced(self, prepared, aligned: list[int]) -> None:
        """Write the ``aligned`` streams row after row and the others in between, in stamp
        order (then stream order, then position)."""
        f = self._file
        k = len(aligned)
        stamps = prepared[aligned[0]][1] if k else np.zeros(0, dtype=np.int64)
        n = stamps.size
        # The other messages in write order, with their sequence numbers and record sizes.
        others = [j for j in range(len(prepared)) if j not in aligned]
        empty = [np.zeros(0, dtype=np.int64)]
        o_stamp = np.concatenate(empty + [prepared[j][1] for j in others])
        o_which = np.concatenate(empty + [np.full(prepared[j][1].size, j) for j in others])
        o_index = np.concatenate(empty + [np.arange(prepared[j][1].size) for j in others])
        order = np.lexsort((o_index, o_which, o_stamp))
        o_stamp, o_which, o_index = o_stamp[order], o_which[order], o_index[order]
        o_cid = np.array([cid for cid, _, _ in prepared], dtype=np.int64)[o_which]
        o_seq = f.sequences(o_cid)
        o_data: dict[int, Any] = {}
        o_size = np.zeros(o_stamp.size, dtype=np.int64)
        for j in others:
            rows = prepared[j][2]
            rows = rows.array() if isinstance(rows, _ColumnRows) else rows
            o_data[j] = rows
            mine = o_which == j
            if isinstance(rows, list):
                lengths = np.fromiter(map(len, rows), dtype=np.int64, count=len(rows))
                o_size[mine] = 31 + lengths[o_index[mine]]
            else:
                o_size[mine] = 31 + rows.shape[1]
        o_all = (o_data, o_which, o_index, o_cid, o_seq, o_stamp, o_size)
        if not k:
            for i0 in range(0, o_stamp.size, self.BLOCK_MESSAGES):
                i1 = min(o_stamp.size, i0 + self.BLOCK_MESSAGES)
                records, cum = self._other_records(*(a[i0:i1] if i else a
                                                     for i, a in enumerate(o_all)))
                f.add_block([records], self._other_entries(o_cid[i0:i1], cum[:-1],
                                                           o_stamp[i0:i1]))
            return
        # Where each other message goes: before aligned message (row, stream) number `ins`.
        at = np.searchsorted(stamps, o_stamp)
        same = at < n
        same[same] = stamps[at[same]] == o_stamp[same]
        o_ins = at * k + np.where(same, np.searchsorted(np.array(aligned), o_which), 0)
        # One reused block of rows: record headers and template bytes are written once, then
        # only the numbers of each block.
        sizes = [prepared[j][2].shape[1] for j in aligned]
        pre = np.cumsum([0] + [31 + size for size in sizes])
        width, pre = int(pre[-1]), pre[:-1]
        step = max(1, min(n, self.BLOCK_BYTES // width))
        rec = np.zeros((step, width), dtype=np.uint8)
        cids = [prepared[j][0] for j in aligned]
        seq0 = [f.counts[cid] for cid in cids]
        # Streams whose records agree from the sequence number to the header stamp (the same
        # first sequence number, encapsulation and stamp columns) get those 32 bytes from one
        # array per block.
        leads: dict[tuple, list[int]] = {}
        for q, j in enumerate(aligned):
            rows = prepared[j][2]
            stamp = rows.stamp_pieces() if isinstance(rows, _ColumnRows) else None
            if stamp is not None:
                leads.setdefault((seq0[q], rows.raw[:4].tobytes()) + tuple(
                    rows.values(i, 0, 0).__array_interface__['data'][0] for i in stamp),
                                 []).append(q)
        groups = [qs for qs in leads.values() if len(qs) > 1]
        lead_of = {q: g for g, qs in enumerate(groups) for q in qs}
        lead = np.zeros((len(groups), step), dtype=_LEAD)
        lead_bytes = lead.view('V32')
        lead_stamps = []
        for g, qs in enumerate(groups):
            rows = prepared[aligned[qs[0]]][2]
            lead[g].view(np.uint8).reshape(step, 32)[:, 20:24] = rows.raw[:4]
            lead_stamps.append([lambda r0, r1, rows=rows, i=i: rows.values(i, r0, r1)
                                for i in rows.stamp_pieces()])
        names, formats, offsets, sources = [], [], [], []
        for q, j in enumerate(aligned):
            cid, _, rows = prepared[j]
            at_q = int(pre[q])
            rec[:, at_q:at_q + 11] = np.frombuffer(struct.pack('<BQH', 0x05, 22 + sizes[q], cid),
                                                   dtype=np.uint8)
            fields: list = [('V20', 11, q)]             # sequence, log and publish times
            skip: tuple[int, ...] = ()
            if q in lead_of:                             # ... up to the header stamp
                fields = [('V32', 11, (lead_of[q],))]
                skip = rows.stamp_pieces()
            if isinstance(rows, _ColumnRows):
                rec[:, at_q + 31:at_q + 31 + sizes[q]] = rows.raw
                fields += [(f'V{nbytes}', 31 + offset,
                            lambda r0, r1, rows=rows, i=i: rows.values(i, r0, r1))
                           for i, (offset, nbytes) in enumerate(rows.pieces) if i not in skip]
            elif sizes[q]:
                whole = rows.view(f'V{sizes[q]}').reshape(n)
                fields.append((f'V{sizes[q]}', 31, lambda r0, r1, whole=whole: whole[r0:r1]))
            for fmt, offset, source in fields:
                names.append(f'f{len(names)}')
                formats.append(fmt)
                offsets.append(at_q + offset)
                sources.append(source)
        view = rec.reshape(-1).view(np.dtype({'names': names, 'formats': formats,
                                               'offsets': offsets, 'itemsize': width}))
        head = np.zeros(step, dtype=[('seq', '<u4'), ('log', '<u8'), ('pub', '<u8')])
        head_bytes = head.view('V20')
        ramp = np.arange(step, dtype=np.int64)
        for r0 in range(0, n, step):
            r1 = min(n, r0 + step)
            b = r1 - r0
            s = stamps[r0:r1]
            head['log'][:b] = s
            head['pub'][:b] = s
            for g, qs in enumerate(groups):
                lead[g, :b]['seq'] = (seq0[qs[0]] + r0 + ramp[:b]) % 2**32
                lead[g, :b]['log'] = s
                lead[g, :b]['pub'] = s
                lead[g, :b]['sec'] = lead_stamps[g][0](r0, r1)
                lead[g, :b]['nsec'] = lead_stamps[g][1](r0, r1)
            block = view[:b]
            for name, source in zip(names, sources):
                if isinstance(source, int):
                    head['seq'][:b] = (seq0[source] + r0 + ramp[:b]) % 2**32
                    block[name] = head_bytes[:b]
                elif isinstance(source, tuple):
                    block[name] = lead_bytes[source[0], :b]
                else:
                    block[name] = source(r0, r1)
            flat = rec[:b].reshape(-1)
            at = pre[:, None] + ramp[:b] * width         # (k, b) record starts in `flat`
            i0 = int(o_ins.searchsorted(r0 * k))
            i1 = o_stamp.size if r1 == n else int(o_ins.searchsorted(r1 * k))
            if i0 == i1:
                f.add_block([flat], [(cid, at[q], s) for q, cid in enumerate(cids)],
                            at.T.reshape(-1))
                continue
            records, cum = self._other_records(*(a[i0:i1] if i else a
                                                 for i, a in enumerate(o_all)))
            ins = o_ins[i0:i1] - r0 * k
            points, first = np.unique(ins, return_index=True)
            after = np.append(first[1:], ins.size)
            # Aligned records move by the bytes of the others spliced in before them.
            at = at + np.repeat(np.append(cum[0], cum[after]), np.diff(
                np.concatenate([[0], points, [b * k]]))).reshape(b, k).T
            pos = ins // k * width + pre[ins % k]       # byte in `flat` they go before
            starts = pos + cum[:-1]
            entries = [(cid, at[q], s) for q, cid in enumerate(cids)]
            entries += self._other_entries(o_cid[i0:i1], starts, o_stamp[i0:i1])
            segments, done = [], 0
            for p, a, z in zip(pos[first].tolist(), first.tolist(), after.tolist()):
                if p > done:
                    segments.append(flat[done:p])
                    done = p
                segments.append(records[cum[a]:cum[z]])
            if done < flat.size:
                segments.append(flat[done:])
            f.add_block(segments, entries, np.insert(at.T.reshape(-1), ins, starts))
        for cid in cids:
            f.counts[cid] += n

    @staticmethod
    def _other_records(data, which, index, cids, seq, stamps, sizes):
        """Records of messages not in the aligned block (the given slice of them, in write
        order), back to back, and their byte positions (m + 1,)."""
        m = stamps.size
        cum = np.zeros(m + 1, dtype=np.int64)
        np.cumsum(sizes, out=cum[1:])
        out = np.empty(int(cum[-1]), dtype=np.uint8)
        head = np.zeros(m, dtype=_HEAD)
        head['op'] = 0x05
        head['length'] = sizes - 9
        head['cid'] = cids
        head['seq'] = seq
        head['log'] = stamps
        head['pub'] = stamps
        out[cum[:-1, None] + np.arange(31)] = head.view(np.uint8).reshape(m, 31)
        for j in np.unique(which).tolist():
            mine = np.flatnonzero(which == j)
            rows = data[j]
            if isinstance(rows, list):
                for i, at in zip(index[mine].tolist(), (cum[mine] + 31).tolist()):
                    out[at:at + len(rows[i])] = np.frombuffer(rows[i], dtype=np.uint8)
                continue
            width = rows.shape[1]
            many = max(1, (1 << 20) // max(width, 1))     # bounds the index arrays
            for g in range(0, mine.size, many):
                pick = mine[g:g + many]
                out[(cum[pick] + 31)[:, None] + np.arange(width)] = rows[index[pick]]
        return out, cum

    @staticmethod
    def _other_entries(cids: np.ndarray, starts: np.ndarray, stamps: np.ndarray) -> list:
        """(cid, record starts, log times) per channel, for :meth:`_McapFile.add_block`."""
        entries = []
        for cid in np.unique(cids).tolist():
            mine = cids == cid
            entries.append((cid, starts[mine], stamps[mine]))
        return entries


#: Read a chunk through the message index records that follow it when they account for
#: every record in it (:meth:`_McapScan._indexed_chunk`); False walks every record (the
#: reference path; tests switch it off to compare).
_USE_MESSAGE_INDEX = True


#: libyaml's safe loader when PyYAML has it (ten times faster on a metadata.yaml).
_YAML_LOADER = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)


def _bag_files(path: Path) -> tuple[list[Path], dict[str, Any], list[str]]:
    """The storage files of a bag folder (or a single .mcap), its metadata and issues."""
    issues: list[str] = []
    if not path.exists():
        raise BagReadError(f'{path}: no such bag folder or file')
    if path.is_file():
        if path.suffix != '.mcap':
            raise BagReadError(f'{path}: not a bag folder or an .mcap file')
        return [path], {}, issues
    meta_path = path / 'metadata.yaml'
    info: dict[str, Any] = {}
    if meta_path.is_file():
        try:
            info = (yaml.load(meta_path.read_text('utf-8'), Loader=_YAML_LOADER) or {}).get(
                'rosbag2_bagfile_information', {}) or {}
        except (yaml.YAMLError, UnicodeDecodeError, AttributeError) as err:
            issues.append(f'metadata.yaml cannot be parsed ({type(err).__name__}): '
                          'reading the .mcap files directly')
            info = {}
    storage = info.get('storage_identifier', 'mcap')
    if storage != 'mcap':
        raise BagReadError(f'{path}: storage {storage!r}: only MCAP bags are read here')
    files = [path / name for name in info.get('relative_file_paths') or []]
    missing = [f for f in files if not f.is_file()]
    for f in missing:
        issues.append(f'{f.name}: listed in metadata.yaml but missing')
    files = [f for f in files if f.is_file()]
    if not files:
        files = sorted(path.glob('*.mcap'))
        if files and not info:
            issues.append('no metadata.yaml: reading the .mcap files found in the folder')
    if not files:
        raise BagReadError(f'{path}: no metadata.yaml and no .mcap file: not an MCAP bag')
    return files, info, issues


def _raw_batches(path: Path, topics: Iterable[str] | None, issues: list[str],
                 channels_seen: dict[str, _Channel] | None = None, *, indexed: bool = False,
                 ) -> Iterator[list]:
    """Lists of wanted ``(channel, log_ns, payload)`` of every file of a bag, file order
    (``indexed``: or lists of :class:`_Block`, see :class:`_McapScan`)."""
    wanted = None if topics is None else set(topics)
    files, _, file_issues = _bag_files(path)
    issues.extend(file_issues)

    def want(channel: _Channel) -> bool:
        if channels_seen is not None:
            channels_seen.setdefault(channel.topic, channel)
        return wanted is None or channel.topic in wanted

    for f in files:
        scan = _McapScan(f, want, indexed=indexed)
        yield from scan.batches()
        issues.extend(scan.issues)
        if scan.unknown_channel:
            issues.append(f'{f.name}: {scan.unknown_channel} messages on undeclared channels '
                          'skipped')


def _raw_messages(path: Path, topics: Iterable[str] | None, issues: list[str],
                  channels_seen: dict[str, _Channel] | None = None,
                  ) -> Iterator[tuple[_Channel, int, bytes]]:
    for batch in _raw_batches(path, topics, issues, channels_seen):
        yield from batch


@dataclass(frozen=True)
class BagInfo:
    """What a bag holds: ``topics`` (topic -> msgtype), ``counts`` (topic -> messages read),
    ``custom_data`` (metadata.yaml), ``issues`` (breaks found while reading)."""

    topics: dict[str, str]
    counts: dict[str, int]
    custom_data: dict[str, str]
    issues: tuple[str, ...]


def bag_info(path: str | Path) -> BagInfo:
    """Topics, types and message counts of a bag, read from its records (not trusted from
    metadata.yaml, so a cut recording is described as it is)."""
    path = Path(path)
    issues: list[str] = []
    seen: dict[str, _Channel] = {}
    counts: dict[str, int] = {}
    for channel, _, _ in _raw_messages(path, None, issues, seen):
        counts[channel.topic] = counts.get(channel.topic, 0) + 1
    return BagInfo({t: c.msgtype for t, c in seen.items()},
                   {t: counts.get(t, 0) for t in seen}, _custom_data(path), tuple(issues))


def _custom_data(path: Path) -> dict[str, str]:
    try:
        _, info, _ = _bag_files(path)
    except BagReadError:
        return {}
    data = info.get('custom_data') or {}
    return {str(k): str(v) for k, v in data.items()} if isinstance(data, Mapping) else {}


def _deserializer(channel: _Channel, stores: dict[str, Any]):
    """Typestore able to deserialize the channel's type (registered from its schema if the
    Jazzy store lacks it), or None."""
    if channel.msgtype in TYPESTORE.types:
        return TYPESTORE
    if channel.msgtype in stores:
        return stores[channel.msgtype]
    store = None
    if channel.schema_encoding == 'ros2msg' and channel.schema:
        try:
            store = get_typestore(Stores.EMPTY)
            store.register(_types_from_schema(channel.msgtype, channel.schema))
        except Exception:  # noqa: BLE001 - an unparseable schema: no deserializer
            store = None
    stores[channel.msgtype] = store
    return store


def _types_from_schema(msgtype: str, schema: str) -> dict:
    """rosbags type definitions from a concatenated ros2msg schema."""
    sep = '=' * 80 + '\n'
    parts = schema.split(sep)
    types = dict(get_types_from_msg(parts[0], msgtype))
    for part in parts[1:]:
        head, _, body = part.partition('\n')
        name = head.removeprefix('MSG: ').strip()
        if '/msg/' not in name:
            name = name.replace('/', '/msg/')
        types.update(get_types_from_msg(body, name))
    return types


def _deserialize(store, data: bytes, msgtype: str):
    """rosbags deserialization that tolerates the spare trailing bytes rmw may leave."""
    if len(data) >= 4 and data[:2] == b'\x00\x01':
        msgdef = store.get_msgdef(msgtype)
        message, pos = msgdef.deserialize_cdr_le(data[4:], 0, msgdef.cls, store)
        if 4 + pos <= len(data):
            return message
        raise ValueError(f'{msgtype}: message shorter than its fields')
    return store.deserialize_cdr(data, msgtype)


def iter_messages(path: str | Path, topics: Iterable[str] | None = None, *,
                  issues: list[str] | None = None) -> Iterator[tuple[str, int, Any]]:
    """Every message of a bag as ``(topic, log_stamp_ns, msg)``, in file order.

    Parameters
    ----------
    path : str or Path
        Bag folder (or one .mcap file).
    topics : iterable of str, optional
        Only these topics.
    issues : list, optional
        Receives one line per problem: a truncated or corrupt file (everything before the
        break is yielded), a message that does not deserialize (skipped), a missing file.

    Yields
    ------
    topic : str
    log_stamp_ns : int
        Log (recording) time; the message's ``header.stamp`` is the sample time.
    msg : rosbags message object

    Raises
    ------
    BagReadError
        Not a bag at all.
    """
    sink = issues if issues is not None else []
    stores: dict[str, Any] = {}
    failed: dict[str, int] = {}
    for channel, log_ns, data in _raw_messages(Path(path), topics, sink):
        store = _deserializer(channel, stores)
        try:
            if store is None:
                raise ValueError('unknown type')
            msg = _deserialize(store, data, channel.msgtype)
        except Exception:  # noqa: BLE001 - skip and count any undecodable message
            failed[channel.topic] = failed.get(channel.topic, 0) + 1
            continue
        yield channel.topic, log_ns, msg
    for topic, count in failed.items():
        sink.append(f'{topic}: {count} messages could not be deserialized and were skipped')


@dataclass
class TopicColumns:
    """The messages of one topic, decoded a column at a time (file order).

    ``msgtype``; ``log_ns`` (n,) int64; ``groups`` (see :func:`decode_columns`);
    ``undecodable`` indices; ``wrong_type`` True when the topic's type is not the expected
    one (then nothing is decoded).
    """

    topic: str
    msgtype: str
    log_ns: np.ndarray
    groups: list[_DecodedGroup]
    undecodable: np.ndarray
    wrong_type: bool = False

    @property
    def count(self) -> int:
        return int(self.log_ns.size)

    def column(self, path: str, width: int | None = None,
               dtype: Any = float) -> tuple[np.ndarray, np.ndarray]:
        """``(values, present)``: a field for every message (file order).

        Scalars give shape (n,), arrays (n, width) (groups of another length are absent);
        ``present`` marks the messages that have it (NaN / 0 elsewhere). ``values`` may be
        the group's own column (one group of the right dtype): copy it to change it.
        """
        shape = (self.count,) if width is None else (self.count, width)
        if len(self.groups) == 1 and self.groups[0].index.size == self.count:
            # One layout for every message: its index is 0..n-1 in order.
            values = self.groups[0].columns.get(path)
            if values is not None and values.shape == shape:
                return values.astype(dtype, copy=False), np.ones(self.count, dtype=bool)
        fill = np.nan if np.dtype(dtype).kind == 'f' else 0
        out = np.full(shape, fill, dtype=dtype)
        present = np.zeros(self.count, dtype=bool)
        for g in self.groups:
            values = g.columns.get(path)
            if values is None or (width is not None and values.shape[1:] != (width,)):
                continue
            out[g.index] = values
            present[g.index] = True
        return out, present

    def stamps_ns(self) -> tuple[np.ndarray, np.ndarray]:
        """``(header stamps ns, valid)``: invalid when absent or nanosec >= 1e9."""
        sec, ok1 = self.column('header.stamp.sec', dtype=np.int64)
        nsec, ok2 = self.column('header.stamp.nanosec', dtype=np.int64)
        valid = ok1 & ok2 & (nsec < _NS) & (nsec >= 0)
        return stamps_to_ns(sec, nsec), valid


class _TopicReader:
    """Gathers one topic's messages (file order) and decodes them as they come."""

    def __init__(self, expected: str, recorded: str,
                 paths: Collection[str] | None = None) -> None:
        self.msgtype = recorded
        self.decoder = _ColumnDecoder(expected, paths=paths) if recorded == expected else None
        self.logs: list[np.ndarray] = []
        self.count = 0

    def add_block(self, block: _Block) -> None:
        if self.decoder is not None:
            for where, records in block.parts:
                index = np.arange(records.shape[0]) if where is None else where
                self.decoder.add_rows(records, index + self.count)
        self.logs.append(block.log_ns)
        self.count += block.count

    def add_messages(self, logs: list[int], datas: list[bytes]) -> None:
        if self.decoder is not None:
            self.decoder.add_datas(datas, self.count)
        self.logs.append(np.asarray(logs, dtype=np.int64))
        self.count += len(datas)

    def columns(self, topic: str) -> TopicColumns:
        log = np.concatenate(self.logs) if self.logs else np.zeros(0, dtype=np.int64)
        if self.decoder is None:
            return TopicColumns(topic, self.msgtype, log, [], np.arange(log.size),
                                wrong_type=True)
        groups, bad = self.decoder.result()
        return TopicColumns(topic, self.msgtype, log, groups, bad)


def read_topic_columns(path: str | Path, topics: Mapping[str, str], *,
                       issues: list[str] | None = None,
                       fields: Mapping[str, Collection[str]] | None = None,
                       ) -> dict[str, TopicColumns]:
    """Decode whole topics a column at a time.

    Parameters
    ----------
    path : str or Path
        Bag folder or .mcap file.
    topics : mapping
        ``topic -> expected msgtype``; a topic recorded with another type is marked
        ``wrong_type``; a topic absent from the bag is absent from the result.
    issues : list, optional
        Receives one line per break (truncated or corrupt file).
    fields : mapping, optional
        ``topic -> paths``: decode only these number fields of that topic (e.g.
        ``{'/vehicle/twist': ['header.stamp.sec', 'header.stamp.nanosec',
        'twist.linear.x']}``); default every field.

    Notes
    -----
    Chunks are read through their message indexes when these account for every record
    (:class:`_McapScan`), and decoded a chunk at a time while it is in the cache.
    """
    sink = issues if issues is not None else []
    seen: dict[str, _Channel] = {}
    readers: dict[str, _TopicReader] = {}

    def reader(topic: str) -> _TopicReader:
        found = readers.get(topic)
        if found is None:
            found = readers[topic] = _TopicReader(topics[topic], seen[topic].msgtype,
                                                  (fields or {}).get(topic))
        return found

    for batch in _raw_batches(Path(path), topics, sink, seen, indexed=_USE_MESSAGE_INDEX):
        if isinstance(batch[0], _Block):
            for block in batch:
                reader(block.topic).add_block(block)
            continue
        logs: dict[str, list[int]] = {}
        datas: dict[str, list[bytes]] = {}
        for channel, log_ns, data in batch:
            if channel.topic not in logs:
                logs[channel.topic], datas[channel.topic] = [], []
            logs[channel.topic].append(log_ns)
            datas[channel.topic].append(data)
        for topic, log in logs.items():
            reader(topic).add_messages(log, datas[topic])
    return {topic: reader(topic).columns(topic) for topic in topics if topic in seen}


# --------------------------------------------------------------------------------------------
# Validation shared by the readers

class _Rejects:
    """Counts of rejected messages: topic -> reason -> count."""

    def __init__(self) -> None:
        self.counts: dict[str, dict[str, int]] = {}

    def add(self, topic: str, reason: str, count: int) -> None:
        if count:
            per = self.counts.setdefault(topic, {})
            per[reason] = per.get(reason, 0) + int(count)


def _accept_in_order(stamps: np.ndarray, ok: np.ndarray, topic: str,
                     rejects: _Rejects) -> np.ndarray:
    """Keep the messages (file order) whose stamp exceeds every earlier accepted one.

    A stamp equal to the latest accepted is a duplicate, a smaller one goes backwards; both
    are dropped and counted. Returns the mask of accepted messages.
    """
    if ok.all() and bool(np.all(stamps[1:] > stamps[:-1])):
        return ok.copy()                        # the usual case: nothing to drop
    idx = np.flatnonzero(ok)
    s = stamps[idx]
    if s.size == 0:
        return np.zeros_like(ok)
    prev = np.maximum.accumulate(s)
    before = np.concatenate([[np.iinfo(np.int64).min], prev[:-1]])
    keep = s > before
    rejects.add(topic, 'duplicate_stamp', np.count_nonzero(s == before))
    rejects.add(topic, 'backwards_stamp', np.count_nonzero(s < before))
    mask = np.zeros_like(ok)
    mask[idx[keep]] = True
    return mask


def _basic_checks(cols: TopicColumns, rejects: _Rejects) -> tuple[np.ndarray, np.ndarray]:
    """(stamps, ok) after the undecodable / wrong-type / bad-stamp checks."""
    if cols.wrong_type:
        rejects.add(cols.topic, f'wrong_type ({cols.msgtype})', cols.count)
        return np.zeros(cols.count, np.int64), np.zeros(cols.count, bool)
    rejects.add(cols.topic, 'undecodable', cols.undecodable.size)
    stamps, ok = cols.stamps_ns()
    if not ok.all():
        decoded = np.zeros(cols.count, bool)
        for g in cols.groups:
            decoded[g.index] = True
        rejects.add(cols.topic, 'bad_stamp', np.count_nonzero(decoded & ~ok))
    return stamps, ok


def _finite_rows(values: np.ndarray) -> np.ndarray:
    v = values.reshape(values.shape[0], -1)
    ok = np.ones(v.shape[0], dtype=bool)
    for j in range(v.shape[1]):                 # column by column: faster than axis=1
        ok &= np.isfinite(v[:, j])
    return ok


def _read_points(cols: TopicColumns, rejects: _Rejects):
    """(stamps, x, y, z) of the accepted PointStamped messages, file order."""
    stamps, ok = _basic_checks(cols, rejects)
    xyz = np.column_stack([cols.column(f'point.{a}')[0] for a in 'xyz']) if cols.count \
        else np.zeros((0, 3))
    finite = _finite_rows(xyz)
    rejects.add(cols.topic, 'nonfinite', np.count_nonzero(ok & ~finite))
    keep = _accept_in_order(stamps, ok & finite, cols.topic, rejects)
    if not keep.all():
        stamps, xyz = stamps[keep], xyz[keep]
    return stamps, xyz[:, 0], xyz[:, 1], xyz[:, 2]


def _read_scalar(cols: TopicColumns, path: str, rejects: _Rejects):
    stamps, ok = _basic_checks(cols, rejects)
    values, _ = cols.column(path)
    finite = np.isfinite(values)
    rejects.add(cols.topic, 'nonfinite', np.count_nonzero(ok & ~finite))
    keep = _accept_in_order(stamps, ok & finite, cols.topic, rejects)
    if keep.all():
        return stamps, values
    return stamps[keep], values[keep]


def _read_joint_state(cols: TopicColumns, names: Sequence[str], rejects: _Rejects,
                      *, velocity: bool = False):
    """(stamps, position (m, k)[, velocity]) of accepted JointStates, mapped by name."""
    stamps, ok = _basic_checks(cols, rejects)
    k = len(names)
    n = cols.count
    # One group of every message (index 0..n-1 in order): its columns are taken as they are.
    whole = len(cols.groups) == 1 and cols.groups[0].index.size == n
    pos = vel = None
    mapped = np.zeros(n, bool)
    for g in cols.groups:
        have = list(g.layout.strings.get('name', ()))
        p = g.columns['position']
        v = g.columns['velocity']
        e = g.columns['effort']
        n_names = len(have)
        if p.shape[1] != n_names or v.shape[1] not in (0, n_names) \
                or e.shape[1] not in (0, n_names) or (velocity and v.shape[1] == 0):
            rejects.add(cols.topic, 'length_mismatch', g.index.size)
            continue
        if len(set(have)) != n_names:
            rejects.add(cols.topic, 'duplicate_name', g.index.size)
            continue
        if any(name not in have for name in names):
            rejects.add(cols.topic, 'missing_name', g.index.size)
            continue
        columns = [have.index(name) for name in names]
        if whole:
            if columns != list(range(p.shape[1])):       # else: the columns as they are
                p, v = p[:, columns], v[:, columns] if velocity else v
            pos, vel, mapped = p, v if velocity else None, ~mapped
            continue
        if pos is None:
            pos = np.full((n, k), np.nan)
            vel = np.full((n, k), np.nan) if velocity else None
        pos[g.index] = p[:, columns]
        if velocity:
            vel[g.index] = v[:, columns]
        mapped[g.index] = True
    if pos is None:
        pos = np.full((n, k), np.nan)
    if velocity and vel is None:
        vel = np.full((n, k), np.nan)
    ok &= mapped
    finite = _finite_rows(pos) & (_finite_rows(vel) if velocity else True)
    rejects.add(cols.topic, 'nonfinite', np.count_nonzero(ok & ~finite))
    keep = _accept_in_order(stamps, ok & finite, cols.topic, rejects)
    if keep.all():
        return (stamps, pos, vel) if velocity else (stamps, pos)
    if velocity:
        return stamps[keep], pos[keep], vel[keep]
    return stamps[keep], pos[keep]


# --------------------------------------------------------------------------------------------
# LPA profile bags

def _points_rows(stamps_ns, x, y, z, frame_id: str,
                 stamp_columns: dict[str, np.ndarray] | None = None) -> _ColumnRows:
    n = len(stamps_ns)
    cols = dict(stamp_columns) if stamp_columns is not None else _stamp_columns(stamps_ns)
    cols.update({'point.x': x if isinstance(x, _Lazy) else np.asarray(x, float),
                 'point.y': np.broadcast_to(np.asarray(y, float), (n,)),
                 'point.z': z if isinstance(z, _Lazy) else np.asarray(z, float)})
    return _ColumnRows(_POINT, _template(_POINT, frame_id), n, cols)


def _check_finite(name: str, values: np.ndarray) -> None:
    bad = np.count_nonzero(~np.isfinite(np.asarray(values, dtype=float)))
    if bad:
        raise ValueError(f'{name}: {bad} non-finite value(s); a bag never carries NaN or inf')


def write_lpa_bag(path: str | Path, profile, *,
                  survey_speed_mps: float = DEFAULT_SURVEY_SPEED_MPS,
                  track_width_m: float = DEFAULT_TRACK_WIDTH_M,
                  start_stamp_ns: int = DEFAULT_START_STAMP_NS,
                  overwrite: bool = False) -> None:
    """Write a measured (or synthetic) road profile as an LPA bag.

    Topics ``/lpa/left`` and ``/lpa/right`` (geometry_msgs/PointStamped, frame ``road``):
    ``x`` = distance along the road (m), ``y`` = +T/2 (left) / -T/2 (right), ``z`` =
    elevation (m); stamps as if surveyed at ``survey_speed_mps`` from ``start_stamp_ns``.
    The profile's name, the survey speed and the track width go to ``custom_data``.

    Parameters
    ----------
    path : str or Path
        Bag folder to create.
    profile : RoadProfile
        ``distance_m`` (n,) strictly increasing, ``elevation_m`` (n, 2) or (n,), ``name``.
    survey_speed_mps : float
        Survey speed (m/s), > 0; sets the stamps only.
    track_width_m : float
        Lateral distance between the wheel paths T (m), > 0.
    start_stamp_ns : int
        Stamp of the first sample (ns).
    overwrite : bool
        Replace an existing bag folder.
    """
    if not (survey_speed_mps > 0.0 and math.isfinite(survey_speed_mps)):
        raise ValueError(f'survey_speed_mps = {survey_speed_mps!r} m/s: must be > 0')
    if not (track_width_m > 0.0 and math.isfinite(track_width_m)):
        raise ValueError(f'track_width_m = {track_width_m!r} m: must be > 0')
    x = np.asarray(profile.distance_m, dtype=float)
    z = np.asarray(profile.elevation_m, dtype=float)
    if z.ndim == 1:
        z = np.column_stack([z, z])
    if x.ndim != 1 or z.shape != (x.size, 2) or x.size < 2:
        raise ValueError(f'profile shapes {x.shape}, {z.shape}: need (n,) and (n, 2), n >= 2')
    _check_finite('profile distance', x)
    _check_finite('profile elevation', z)
    if np.any(np.diff(x) <= 0.0):
        raise ValueError('profile distance_m must be strictly increasing')
    stamps = int(start_stamp_ns) + np.round((x - x[0]) / survey_speed_mps * _NS).astype(
        np.int64)
    if np.any(np.diff(stamps) <= 0):
        raise ValueError(f'survey_speed_mps = {survey_speed_mps!r} m/s: two samples get the '
                         'same stamp (ns); use a lower speed')
    custom = {'road_force_estimator.kind': 'lpa_profile',
              'road_force_estimator.profile_name': str(getattr(profile, 'name', '') or ''),
              'road_force_estimator.survey_speed_mps': repr(float(survey_speed_mps)),
              'road_force_estimator.track_width_m': repr(float(track_width_m))}
    half = 0.5 * track_width_m
    with BagWriter(path, overwrite=overwrite, custom_data=custom) as bag:
        streams = []
        for side, topic in enumerate(TOPIC_LPA):
            bag.add_topic(topic, _POINT, 'reliable')
            streams.append((topic, stamps, _points_rows(stamps, x, half if side == 0 else -half,
                                                        z[:, side], FRAME_ROAD)))
        bag.write_rows(streams)


def read_lpa_bag(path: str | Path, *, issues: list[str] | None = None):
    """Read an LPA bag back into a :class:`road_force_estimator.core.road.RoadProfile`.

    Samples are kept in file order while their distance increases; a NaN, undecodable,
    duplicate or backward sample is dropped and counted in ``issues``. The two tracks are
    joined on equal distances (a bag with one track uses it for both wheel paths).

    Raises
    ------
    BagReadError
        No ``/lpa/left`` nor ``/lpa/right`` topic, or fewer than 2 usable samples.
    """
    from road_force_estimator.core.road import RoadProfile   # the core, imported lazily

    path = Path(path)
    sink = issues if issues is not None else []
    cols = read_topic_columns(path, {t: _POINT for t in TOPIC_LPA}, issues=sink)
    if not cols:
        raise BagReadError(f'{path}: no {TOPIC_LPA[0]} or {TOPIC_LPA[1]} topic: not an LPA bag')
    rejects = _Rejects()
    tracks = {}
    for topic, c in cols.items():
        _, x, _, z = _read_points(c, rejects)
        # Distance must increase along the file: drop what does not, as for stamps.
        keep = _accept_in_order(x, np.ones(x.size, bool), topic + ' (distance)', rejects)
        tracks[topic] = (x[keep], z[keep])
    for topic, reasons in rejects.counts.items():
        for reason, count in reasons.items():
            sink.append(f'{topic}: {count} samples dropped ({reason})')
    if len(tracks) == 1:
        (topic, (x, z)), = tracks.items()
        sink.append(f'only {topic} in the bag: used for both wheel paths')
        elevation = np.column_stack([z, z])
    else:
        (xl, zl), (xr, zr) = tracks[TOPIC_LPA[0]], tracks[TOPIC_LPA[1]]
        if xl.size == xr.size and np.array_equal(xl, xr):
            x, elevation = xl, np.column_stack([zl, zr])
        else:
            x, il, ir = np.intersect1d(xl, xr, assume_unique=True, return_indices=True)
            sink.append(f'left and right tracks differ in distance: kept the {x.size} common '
                        f'samples ({xl.size - x.size} left and {xr.size - x.size} right '
                        'dropped)')
            elevation = np.column_stack([zl[il], zr[ir]])
    if x.size < 2:
        raise BagReadError(f'{path}: fewer than 2 usable profile samples')
    name = _custom_data(path).get('road_force_estimator.profile_name') or path.name
    return RoadProfile(distance_m=x, elevation_m=elevation, name=name, notes=tuple(sink))


# --------------------------------------------------------------------------------------------
# Drive bags: measurements and ground truth

@dataclass(frozen=True)
class GroundTruth:
    """Ground truth of a simulated drive, on the union of its stamps (NaN where a topic has
    no sample at that stamp).

    Attributes: ``stamps_ns`` (m,) int64 increasing; ``wheel_load_n`` (m, 2) true vertical
    loads [left, right] (N); ``road_m`` (m, 2) true road elevation under each tire (m);
    ``distance_m`` (m,) distance travelled (m, from the road points).
    """

    stamps_ns: np.ndarray
    wheel_load_n: np.ndarray
    road_m: np.ndarray
    distance_m: np.ndarray

    def at(self, stamps_ns: np.ndarray) -> GroundTruth:
        """The truth at the given stamps (NaN where it has no sample at exactly that stamp)."""
        want = np.asarray(stamps_ns, dtype=np.int64)
        hit = np.zeros(want.size, bool)
        pos = np.zeros(want.size, np.int64)
        if self.stamps_ns.size:
            pos = np.minimum(np.searchsorted(self.stamps_ns, want), self.stamps_ns.size - 1)
            hit = self.stamps_ns[pos] == want

        def pick(a: np.ndarray) -> np.ndarray:
            out = np.full((want.size,) + a.shape[1:], np.nan)
            out[hit] = a[pos[hit]]
            return out
        return GroundTruth(want.copy(), pick(self.wheel_load_n), pick(self.road_m),
                           pick(self.distance_m))


@dataclass(frozen=True)
class Fixes:
    """GNSS fixes: ``stamps_ns`` (k,), ``latitude_deg``, ``longitude_deg`` (WGS84),
    ``altitude_m`` (NaN allowed: NavSatFix's "unknown")."""

    stamps_ns: np.ndarray
    latitude_deg: np.ndarray
    longitude_deg: np.ndarray
    altitude_m: np.ndarray


@dataclass(frozen=True)
class Drive:
    """A drive read from a bag: the estimator's inputs, the truth if any, what was rejected.

    Attributes
    ----------
    stamps_ns : ndarray (n,) int64
        Header stamps of the accepted ``/suspension/deflections``, strictly increasing.
    q_m : ndarray (n, 2)
        Suspension deflections [q_1 left, q_2 right] (m), mapped by joint name.
    roll_rad : ndarray (n,)
        Roll angle phi (rad), > 0 when the left side is up.
    speed_mps : ndarray (n,)
        Speed held from the latest accepted ``/vehicle/twist`` stamped at or before each
        sample (m/s); NaN before the first one.
    twist_stamps_ns, twist_speed_mps : ndarray (k,)
        The accepted twist messages.
    truth : GroundTruth or None
    fixes : Fixes or None
    messages : dict
        ``topic -> messages read``.
    rejected : dict
        ``topic -> {reason -> count}``: reasons ``undecodable``, ``wrong_type (...)``,
        ``bad_stamp``, ``missing_name``, ``duplicate_name``, ``length_mismatch``,
        ``nonfinite``, ``no_fix``, ``duplicate_stamp``, ``backwards_stamp``.
    issues : tuple of str
        Breaks: a truncated or corrupt file (read up to the break), missing files.
    custom_data : dict
        metadata.yaml ``custom_data``.
    """

    stamps_ns: np.ndarray
    q_m: np.ndarray
    roll_rad: np.ndarray
    speed_mps: np.ndarray
    twist_stamps_ns: np.ndarray
    twist_speed_mps: np.ndarray
    truth: GroundTruth | None
    fixes: Fixes | None
    messages: dict[str, int] = field(default_factory=dict)
    rejected: dict[str, dict[str, int]] = field(default_factory=dict)
    issues: tuple[str, ...] = ()
    custom_data: dict[str, str] = field(default_factory=dict)

    @property
    def rejected_total(self) -> int:
        """Messages rejected over all topics."""
        return sum(sum(r.values()) for r in self.rejected.values())

    def summary_lines(self) -> list[str]:
        """Human-readable lines: messages per topic, rejections and breaks."""
        lines = [f'{topic}: {count} messages' for topic, count in sorted(self.messages.items())]
        for topic, reasons in sorted(self.rejected.items()):
            for reason, count in sorted(reasons.items()):
                lines.append(f'{topic}: {count} rejected ({reason})')
        lines.extend(self.issues)
        return lines


def _trajectory_stamps(trajectory, start_stamp_ns: int) -> np.ndarray:
    if hasattr(trajectory, 'stamps_ns'):
        return np.asarray(trajectory.stamps_ns, dtype=np.int64)
    t = np.asarray(trajectory.t_s, dtype=float)
    _check_finite('trajectory.t_s', t)
    return int(start_stamp_ns) + np.round(t * _NS).astype(np.int64)


def _fix_arrays(fixes, start_stamp_ns: int):
    if hasattr(fixes, 'stamps_ns'):
        stamps = np.asarray(fixes.stamps_ns, dtype=np.int64)
    else:
        stamps = int(start_stamp_ns) + np.round(np.asarray(fixes.time_s, float) * _NS).astype(
            np.int64)
    lat = np.asarray(fixes.latitude_deg, dtype=float)
    lon = np.asarray(fixes.longitude_deg, dtype=float)
    alt = np.asarray(getattr(fixes, 'altitude_m', np.zeros(lat.shape)), dtype=float)
    _check_finite('fix latitude', lat)
    _check_finite('fix longitude', lon)
    _check_finite('fix altitude', alt)
    return stamps, lat, lon, np.broadcast_to(alt, lat.shape)


def write_drive_bag(path: str | Path, trajectory, q_meas: np.ndarray, roll_meas: np.ndarray,
                    *, fixes=None, speed_mps: float | np.ndarray | None = None,
                    track_width_m: float = DEFAULT_TRACK_WIDTH_M,
                    start_stamp_ns: int = DEFAULT_START_STAMP_NS, ground_truth: bool = True,
                    custom_data: Mapping[str, str] | None = None,
                    overwrite: bool = False) -> int:
    """Write a (simulated) drive: measurements, ground truth, optional GNSS fixes.

    Topics (INTERFACES.md): ``/suspension/deflections`` (JointState ``[left_suspension,
    right_suspension, roll]``, frame ``base_link``, sensor-data QoS), ``/vehicle/twist``
    (``twist.linear.x`` = speed), and with ``ground_truth`` ``/ground_truth/wheel_load/left``,
    ``.../right`` (``wrench.force.z``, frames ``front_left_wheel`` / ``front_right_wheel``),
    ``/ground_truth/road_profile/left``, ``.../right`` (x = distance, y = +-T/2, z = road
    elevation, frame ``road``); ``/fix`` (NavSatFix) when ``fixes`` is given. Every sample's
    messages share its stamp (header stamp = log time); at equal stamps the twist is written
    before the deflections, so a replay delivers the speed first.

    Parameters
    ----------
    path : str or Path
        Bag folder to create.
    trajectory : Trajectory
        From ``plant.simulate``: ``t_s`` (n,) (s from the start; or ``stamps_ns``),
        ``distance_m`` (n,), ``wheel_load_n`` (n, 2), ``road_m`` (n, 2), and ``speed_mps``
        (n,) if it has one.
    q_meas : array (n, 2)
        Measured deflections [left, right] (m).
    roll_meas : array (n,)
        Measured roll angle (rad).
    fixes : object, optional
        ``stamps_ns`` or ``time_s``, ``latitude_deg``, ``longitude_deg`` [, ``altitude_m``,
        default 0] (e.g. ``gnss.GnssRoute``); written as NavSatFix with status FIX, frame
        ``gnss``, covariance type unknown, as the plant_simulator node publishes them.
    speed_mps : float or array (n,), optional
        Speed (m/s); default the trajectory's ``speed_mps``, else d(distance)/dt.
    track_width_m : float
        T (m): the road points' lateral positions +-T/2.
    start_stamp_ns : int
        Stamp of t = 0 (ns).
    ground_truth : bool
        Write the ground-truth topics.
    custom_data : mapping, optional
        Extra ``custom_data`` (e.g. the parameters used).
    overwrite : bool
        Replace an existing bag folder.

    Returns
    -------
    int
        Messages written.
    """
    stamps = _trajectory_stamps(trajectory, start_stamp_ns)
    n = stamps.size
    if n == 0:
        raise ValueError('trajectory has no sample')
    if np.any(np.diff(stamps) <= 0):
        raise ValueError('trajectory stamps must be strictly increasing')
    q = np.asarray(q_meas, dtype=float).reshape(n, 2)
    roll = np.asarray(roll_meas, dtype=float).reshape(n)
    if speed_mps is None:
        speed_mps = getattr(trajectory, 'speed_mps', None)
    if speed_mps is None:
        t = (stamps - stamps[0]) / _NS
        speed = np.gradient(np.asarray(trajectory.distance_m, float), t) if n > 1 \
            else np.zeros(1)
    else:
        speed = np.broadcast_to(np.asarray(speed_mps, dtype=float), (n,))
    for name, values in (('q_meas', q), ('roll_meas', roll), ('speed', speed)):
        _check_finite(name, values)
    custom = {'road_force_estimator.kind': 'drive',
              'road_force_estimator.track_width_m': repr(float(track_width_m))}
    custom.update(custom_data or {})
    streams = []
    stamp_cols = _stamp_columns(stamps)
    with BagWriter(path, overwrite=overwrite, custom_data=custom) as bag:
        bag.add_topic(TOPIC_TWIST, _TWIST, 'sensor_data')
        cols = dict(stamp_cols, **{'twist.linear.x': speed})
        streams.append((TOPIC_TWIST, stamps,
                        _ColumnRows(_TWIST, _template(_TWIST, FRAME_BASE), n, cols)))
        bag.add_topic(TOPIC_DEFLECTIONS, _JOINT_STATE, 'sensor_data')
        cols = dict(stamp_cols, position=np.column_stack([q, roll]))
        streams.append((TOPIC_DEFLECTIONS, stamps, _ColumnRows(
            _JOINT_STATE, _template(_JOINT_STATE, FRAME_BASE, DEFLECTION_NAMES), n, cols)))
        if ground_truth:
            load = np.asarray(trajectory.wheel_load_n, dtype=float).reshape(n, 2)
            road = np.asarray(trajectory.road_m, dtype=float).reshape(n, 2)
            x = np.asarray(trajectory.distance_m, dtype=float).reshape(n)
            for name, values in (('wheel_load_n', load), ('road_m', road), ('distance_m', x)):
                _check_finite('trajectory.' + name, values)
            half = 0.5 * float(track_width_m)
            for side in (0, 1):
                bag.add_topic(TOPIC_TRUE_LOAD[side], _WRENCH, 'reliable')
                cols = dict(stamp_cols, **{'wrench.force.z': load[:, side]})
                streams.append((TOPIC_TRUE_LOAD[side], stamps, _ColumnRows(
                    _WRENCH, _template(_WRENCH, WHEEL_FRAMES[side]), n, cols)))
            for side in (0, 1):
                bag.add_topic(TOPIC_TRUE_ROAD[side], _POINT, 'reliable')
                streams.append((TOPIC_TRUE_ROAD[side], stamps, _points_rows(
                    stamps, x, half if side == 0 else -half, road[:, side], FRAME_ROAD,
                    stamp_cols)))
        if fixes is not None:
            fs, lat, lon, alt = _fix_arrays(fixes, start_stamp_ns)
            bag.add_topic(TOPIC_FIX, _NAVSATFIX, 'sensor_data')
            cols = _stamp_columns(fs)
            cols.update({'latitude': lat, 'longitude': lon, 'altitude': alt})
            streams.append((TOPIC_FIX, fs, _ColumnRows(
                _NAVSATFIX, _template(_NAVSATFIX, 'gnss'), fs.size, cols)))
        bag.write_rows(streams)
        return bag.message_count


def _union_truth(parts: dict[str, tuple[np.ndarray, np.ndarray]]) -> GroundTruth | None:
    if not parts:
        return None
    first = next(iter(parts.values()))[0]
    if all(s is first or np.array_equal(s, first) for s, _ in parts.values()):
        stamps = first          # every topic at every stamp (a simulated drive)
    else:
        stamps = np.sort(np.concatenate([s for s, _ in parts.values()]))
        stamps = stamps[np.concatenate([[True], stamps[1:] != stamps[:-1]])]
    m = stamps.size

    def place(key: str) -> np.ndarray:
        if key not in parts:
            return np.full(m, np.nan)
        s, v = parts[key]
        if s is stamps or s.size == m:          # every stamp (parts' stamps are unique)
            return np.array(v, dtype=float)
        out = np.full(m, np.nan)
        out[np.searchsorted(stamps, s)] = v
        return out
    load = np.column_stack([place('load_l'), place('load_r')])
    road = np.column_stack([place('road_l'), place('road_r')])
    dist = place('x_l')
    dist = np.where(np.isnan(dist), place('x_r'), dist)
    return GroundTruth(stamps, load, road, dist)


_STAMP = ('header.stamp.sec', 'header.stamp.nanosec')
#: The number fields read_drive_bag uses (and checks) of each topic.
_DRIVE_FIELDS = {
    TOPIC_DEFLECTIONS: _STAMP + ('position', 'velocity', 'effort'),
    TOPIC_TWIST: _STAMP + ('twist.linear.x',),
    TOPIC_FIX: _STAMP + ('latitude', 'longitude', 'altitude', 'status.status'),
    **{t: _STAMP + ('wrench.force.z',) for t in TOPIC_TRUE_LOAD},
    **{t: _STAMP + ('point.x', 'point.y', 'point.z') for t in TOPIC_TRUE_ROAD},
}


def read_drive_bag(path: str | Path) -> Drive:
    """Read a drive: measurements, speed, ground truth and fixes, rejecting what is bad.

    JointStates are mapped by name (a missing name or an array of another length than
    ``name`` rejects the message); non-finite values, undecodable messages and invalid
    stamps are rejected; per topic, in file order, a stamp equal to the latest accepted one
    (duplicate) or before it (backwards) is dropped. Every rejection is counted by topic and
    reason in :attr:`Drive.rejected`. A truncated or corrupt file is read up to the break,
    which is described in :attr:`Drive.issues`.

    Raises
    ------
    BagReadError
        Not a bag, or no ``/suspension/deflections`` topic.
    """
    path = Path(path)
    issues: list[str] = []
    wanted = {TOPIC_DEFLECTIONS: _JOINT_STATE, TOPIC_TWIST: _TWIST, TOPIC_FIX: _NAVSATFIX}
    wanted.update({t: _WRENCH for t in TOPIC_TRUE_LOAD})
    wanted.update({t: _POINT for t in TOPIC_TRUE_ROAD})
    cols = read_topic_columns(path, wanted, issues=issues, fields=_DRIVE_FIELDS)
    if TOPIC_DEFLECTIONS not in cols:
        raise BagReadError(f'{path}: no {TOPIC_DEFLECTIONS} topic'
                           + (f' ({issues[0]})' if issues else ''))
    rejects = _Rejects()
    stamps, pos = _read_joint_state(cols[TOPIC_DEFLECTIONS], DEFLECTION_NAMES, rejects)
    if TOPIC_TWIST in cols:
        twist_ns, twist_v = _read_scalar(cols[TOPIC_TWIST], 'twist.linear.x', rejects)
    else:
        twist_ns, twist_v = np.zeros(0, np.int64), np.zeros(0)
    if np.array_equal(twist_ns, stamps):        # a twist with every sample
        speed = twist_v.copy()
    else:
        held = np.searchsorted(twist_ns, stamps, side='right') - 1
        speed = np.where(held >= 0, twist_v[np.clip(held, 0, None)] if twist_v.size
                         else np.nan, np.nan)
    parts = {}
    for side, key in ((0, 'l'), (1, 'r')):
        if TOPIC_TRUE_LOAD[side] in cols:
            parts['load_' + key] = _read_scalar(cols[TOPIC_TRUE_LOAD[side]], 'wrench.force.z',
                                                rejects)
        if TOPIC_TRUE_ROAD[side] in cols:
            s, x, _, z = _read_points(cols[TOPIC_TRUE_ROAD[side]], rejects)
            parts['road_' + key] = (s, z)
            parts['x_' + key] = (s, x)
    fixes = None
    if TOPIC_FIX in cols:
        c = cols[TOPIC_FIX]
        s, ok = _basic_checks(c, rejects)
        lat, _ = c.column('latitude')
        lon, _ = c.column('longitude')
        alt, _ = c.column('altitude')
        status, _ = c.column('status.status', dtype=np.int64)
        finite = np.isfinite(lat) & np.isfinite(lon)
        rejects.add(TOPIC_FIX, 'nonfinite', np.count_nonzero(ok & ~finite))
        nofix = ok & finite & (status < 0)
        rejects.add(TOPIC_FIX, 'no_fix', np.count_nonzero(nofix))
        keep = _accept_in_order(s, ok & finite & ~nofix, TOPIC_FIX, rejects)
        fixes = Fixes(s[keep], lat[keep], lon[keep], alt[keep])
    return Drive(
        stamps_ns=stamps, q_m=pos[:, :2].copy(), roll_rad=pos[:, 2].copy(), speed_mps=speed,
        twist_stamps_ns=twist_ns, twist_speed_mps=twist_v, truth=_union_truth(parts),
        fixes=fixes, messages={t: c.count for t, c in cols.items()}, rejected=rejects.counts,
        issues=tuple(issues), custom_data=_custom_data(path))


# --------------------------------------------------------------------------------------------
# Estimate bags: the observer's topics

#: Estimate attributes used by :func:`write_estimate_bag` (INTERFACES.md topic in brackets).
ESTIMATE_FIELDS = {
    'stamps_ns': 'header stamps (n,) int64 [every topic]; or stamp_ns',
    'wheel_load_n': '(n, 2) [/wheel_load/left|right wrench.force.z]',
    'distance_m': '(n,) [/road_profile/* point.x]',
    'road_m': '(n, 2) band-passed road [/road_profile/* point.z]',
    'ltr': '(n,) [/load_transfer_ratio]',
    'q_m, roll_rad, body_heave_m, wheel_heave_m (n, 2)': '[/observer/states position]',
    'dq, droll, body_heave_rate, wheel_heave_rate (n, 2)': '[/observer/states velocity]',
    'valid': '(n,) bool, optional: rows to write',
}


def _first_attr(obj, *names: str):
    for name in names:
        value = getattr(obj, name, None)
        if value is not None:
            return value
    raise AttributeError(f'estimates have none of the attributes {names}')


def diagnostic_array(stamp_ns: int, statuses: Iterable[Mapping[str, Any]]):
    """A diagnostic_msgs/DiagnosticArray (rosbags object) from plain dicts.

    Each status: ``name`` (str), ``level`` (0 OK, 1 WARN, 2 ERROR, 3 STALE), ``message``
    (str), optional ``hardware_id`` (str) and ``values`` (mapping, values shown with str()).
    """
    status_type = _msg('diagnostic_msgs/msg/DiagnosticStatus')
    key_value = _msg('diagnostic_msgs/msg/KeyValue')
    out = []
    for st in statuses:
        level = int(st.get('level', 0))
        if level not in (0, 1, 2, 3):
            raise ValueError(f'diagnostic level = {level!r}: one of 0 (OK), 1 (WARN), '
                             '2 (ERROR), 3 (STALE)')
        out.append(status_type(level=level, name=str(st['name']),
                               message=str(st.get('message', '')),
                               hardware_id=str(st.get('hardware_id', '')),
                               values=[key_value(key=str(k), value=str(v))
                                       for k, v in dict(st.get('values', {})).items()]))
    return _msg(_DIAGNOSTICS)(header=_stamped_header(int(stamp_ns), ''), status=out)


def _stamped_header(stamp_ns: int, frame_id: str):
    sec, nanosec = ns_to_stamps(np.array([stamp_ns]))
    return _msg('std_msgs/msg/Header')(stamp=_msg('builtin_interfaces/msg/Time')(
        sec=int(sec[0]), nanosec=int(nanosec[0])), frame_id=frame_id)


def write_estimate_bag(path: str | Path, estimates, *,
                       track_width_m: float = DEFAULT_TRACK_WIDTH_M,
                       diagnostics: Iterable[tuple[int, Any]] = (),
                       custom_data: Mapping[str, str] | None = None,
                       overwrite: bool = False) -> dict[str, int]:
    """Write the observer's output topics for a batch of estimates.

    Topics (INTERFACES.md): ``/wheel_load/left|right`` (WrenchStamped, ``force.z``, frames
    ``front_left_wheel`` / ``front_right_wheel``), ``/road_profile/left|right`` (PointStamped,
    x = distance, y = +-T/2, z = estimated band-passed road, frame ``road``),
    ``/load_transfer_ratio`` (Float64), ``/observer/states`` (JointState, names
    :data:`STATE_NAMES`, position and velocity), and ``/diagnostics`` for the given
    ``(stamp_ns, DiagnosticArray)`` pairs. Header stamp = log time = the measurement's stamp.

    Parameters
    ----------
    path : str or Path
        Bag folder to create.
    estimates : EstimateArrays or any object with the attributes of :data:`ESTIMATE_FIELDS`
        Rows where ``valid`` is False are not written; neither is a row with a non-finite
        value (nothing non-finite is published), which is counted in the result.
    track_width_m : float
        T (m) for the road points' y.
    diagnostics : iterable of (stamp_ns, DiagnosticArray or list of status dicts)
        Optional; a list of dicts is converted by :func:`diagnostic_array`.
    custom_data : mapping, optional
        Extra ``custom_data``.
    overwrite : bool
        Replace an existing bag folder.

    Returns
    -------
    dict
        ``{'written': rows written, 'invalid': rows not valid, 'nonfinite': rows with a
        non-finite value}``.
    """
    e = estimates
    stamps = np.asarray(_first_attr(e, 'stamps_ns', 'stamp_ns'), dtype=np.int64).reshape(-1)
    n = stamps.size

    def arr(*names: str, width: int | None = None) -> np.ndarray:
        a = np.asarray(_first_attr(e, *names), dtype=float)
        return a.reshape(n, width) if width else a.reshape(n)

    load = arr('wheel_load_n', width=2)
    road = arr('road_m', 'road_profile_m', width=2)
    dist = arr('distance_m')
    ltr = arr('ltr')
    position = [arr('q_m', width=2), arr('roll_rad', 'roll'), arr('body_heave_m', 'body_heave'),
                arr('wheel_heave_m', 'wheel_heave', width=2)]
    velocity = [arr('dq', 'dq_mps', width=2), arr('droll', 'droll_radps'),
                arr('body_heave_rate', 'body_heave_rate_mps'),
                arr('wheel_heave_rate', 'wheel_heave_rate_mps', width=2)]
    valid = np.asarray(getattr(e, 'valid', np.ones(n, bool)), dtype=bool).reshape(n)
    finite = np.ones(n, dtype=bool)
    for values in [load, road, dist, ltr] + position + velocity:
        for column in (values.T if values.ndim == 2 else [values]):
            finite &= np.isfinite(column)
    rows = valid & finite
    # The rows written are read a block at a time by the writer (no copies of whole columns).
    index = None if rows.all() else np.flatnonzero(rows)
    s = stamps if index is None else stamps[index]
    if s.size and np.any(np.diff(s) <= 0):
        raise ValueError('estimate stamps must be strictly increasing')
    m = s.size
    custom = {'road_force_estimator.kind': 'estimates',
              'road_force_estimator.track_width_m': repr(float(track_width_m))}
    custom.update(custom_data or {})
    half = 0.5 * float(track_width_m)
    stamp_cols = _stamp_columns(s)
    with BagWriter(path, overwrite=overwrite, custom_data=custom) as bag:
        streams = []
        for side in (0, 1):
            bag.add_topic(TOPIC_LOAD[side], _WRENCH, 'reliable')
            cols = dict(stamp_cols, **{'wrench.force.z': _Lazy([load[:, side]], index)})
            streams.append((TOPIC_LOAD[side], s, _ColumnRows(
                _WRENCH, _template(_WRENCH, WHEEL_FRAMES[side]), m, cols)))
        for side in (0, 1):
            bag.add_topic(TOPIC_ROAD[side], _POINT, 'reliable')
            streams.append((TOPIC_ROAD[side], s, _points_rows(
                s, _Lazy([dist], index), half if side == 0 else -half,
                _Lazy([road[:, side]], index), FRAME_ROAD, stamp_cols)))
        bag.add_topic(TOPIC_LTR, _FLOAT64, 'reliable')
        streams.append((TOPIC_LTR, s, _ColumnRows(_FLOAT64, _template(_FLOAT64), m,
                                                  {'data': _Lazy([ltr], index)})))
        bag.add_topic(TOPIC_STATES, _JOINT_STATE, 'reliable')
        cols = dict(stamp_cols, position=_Lazy(position, index),
                    velocity=_Lazy(velocity, index))
        streams.append((TOPIC_STATES, s, _ColumnRows(
            _JOINT_STATE, _template(_JOINT_STATE, FRAME_BASE, STATE_NAMES, velocity=True), m,
            cols)))
        diagnostics = list(diagnostics)
        if diagnostics:
            bag.add_topic(TOPIC_DIAGNOSTICS, _DIAGNOSTICS, 'reliable')
            msgs = [d[1] if hasattr(d[1], '__msgtype__') else diagnostic_array(d[0], d[1])
                    for d in diagnostics]
            streams.append((TOPIC_DIAGNOSTICS, [int(d[0]) for d in diagnostics],
                            [TYPESTORE.serialize_cdr(m, _DIAGNOSTICS) for m in msgs]))
        bag.write_rows(streams)
    return {'written': int(m), 'invalid': int(np.count_nonzero(~valid)),
            'nonfinite': int(np.count_nonzero(valid & ~finite))}
