"""Live CDR: one message at a time, for a node that takes and publishes serialized bytes.

A node that builds a message object per output and lets rclpy serialise it spends tens of
microseconds per message; the topics of INTERFACES.md have a fixed byte layout, so a message is
serialised once as a template (by rosbags, as :mod:`.cdr` does for a column) and each message
after that is a copy of the template with its stamp and numbers written in with
:mod:`struct` (:class:`CdrEncoder`). A received message is read the same way when its
lengths and strings (its skeleton, :class:`.cdr.CdrLayout`) are the template's
(:class:`CdrReader`); any other is left to the caller's general path, so a message of another
layout is never misread.

The bytes are those rmw puts on the wire for the same message object: little-endian CDR,
alignment padding zero, no trailing bytes (``rclpy.serialization.serialize_message`` returns
the same numbers and strings, but its padding is uninitialised and its buffer may be longer).
"""
from __future__ import annotations

from operator import itemgetter
import struct
from typing import Sequence

import numpy as np

from road_force_estimator.serde.cdr import NS_PER_S, TYPESTORE, cdr_layout

__all__ = ['CdrEncoder', 'CdrEncoderGroup', 'CdrReader']

_STAMP = struct.Struct('<iI')
_STAMP_OFFSET = 4  # header.stamp is the first field: right after the encapsulation header


def _regions(layout, paths: Sequence[str]) -> list[tuple[struct.Struct, int, int]]:
    """``(Struct, offset, count)`` per run of numbers of ``paths`` that lie next to each other
    in the message (in ``paths``' order)."""
    regions: list[list] = []
    for path in paths:
        try:
            offset, dtype, count = layout.fields[path]
        except KeyError:
            raise KeyError(f'{layout.msgtype} has no numeric field {path!r}; fields: '
                           f'{sorted(layout.fields)}') from None
        if dtype != np.dtype('<f8'):
            raise TypeError(f'{layout.msgtype}.{path}: {dtype}, not float64')
        k = 1 if count is None else count
        if regions and regions[-1][1] + 8 * regions[-1][2] == offset:
            regions[-1][2] += k
        else:
            regions.append([None, offset, k])
    return [(struct.Struct(f'<{k}d'), offset, k) for _, offset, k in regions]


def _stamped(layout) -> bool:
    return layout.fields.get('header.stamp.sec', (None,))[0] == _STAMP_OFFSET


class CdrEncoder:
    """Serialize messages that differ from ``template`` only in the stamp and float64 fields.

    Parameters
    ----------
    msgtype : str
        e.g. ``'geometry_msgs/msg/WrenchStamped'``.
    template : rosbags message
        Fixes the strings, the sequence lengths and every number not in ``paths``.
    paths : sequence of str
        The float64 fields (:class:`.cdr.CdrLayout` paths: ``'wrench.force.z'``,
        ``'position'``) :meth:`encode` writes, in its argument order; an array field takes as
        many numbers as it holds.
    """

    def __init__(self, msgtype: str, template, paths: Sequence[str]) -> None:
        self.template = bytes(TYPESTORE.serialize_cdr(template, msgtype))
        self.layout = cdr_layout(msgtype, self.template)
        self.regions = _regions(self.layout, paths)
        self.count = sum(k for _, _, k in self.regions)
        self.stamped = _stamped(self.layout)
        self._packer, self._consts, self._order = self._plan()
        self._pick = itemgetter(*self._order)

    def _plan(self) -> tuple[struct.Struct, tuple[bytes, ...], tuple[int, ...]]:
        """One :class:`struct.Struct` for the whole message: the template's bytes between
        the numbers as ``s`` fields; ``order`` picks its arguments out of
        ``consts + (sec, nanosec) + values``."""
        numbers = [(offset, packer.format[1:], k) for packer, offset, k in self.regions]
        if self.stamped:
            numbers.insert(0, (_STAMP_OFFSET, 'iI', -2))
        fmt, consts, order, pos, value = ['<'], [], [], 0, 0
        n_consts = len(numbers) + 1
        for offset, code, k in sorted(numbers):
            if offset < pos:
                raise ValueError(f'{self.layout.msgtype}: fields overlap at byte {offset}')
            fmt.append(f'{offset - pos}s')
            order.append(len(consts))
            consts.append(self.template[pos:offset])
            fmt.append(code)
            if k == -2:
                order += [n_consts, n_consts + 1]
                pos = offset + _STAMP.size
            else:
                order += [n_consts + 2 + value + j for j in range(k)]
                value += k
                pos = offset + 8 * k
        fmt.append(f'{len(self.template) - pos}s')
        order.append(len(consts))
        consts.append(self.template[pos:])
        if value != self.count or sorted(numbers) != numbers:
            raise ValueError(f'{self.layout.msgtype}: paths must be given in byte order')
        return struct.Struct(''.join(fmt)), tuple(consts), tuple(order)

    def encode(self, stamp_ns: int | None, values: Sequence[float]) -> bytes:
        """The message with stamp ``stamp_ns`` (ns; None for a type without a header) and
        ``values`` (:attr:`count` numbers, in ``paths``' order)."""
        if len(values) != self.count:
            raise ValueError(f'{self.layout.msgtype}: {len(values)} numbers for {self.count}')
        stamp = divmod(int(stamp_ns), NS_PER_S) if self.stamped else (0, 0)
        return self._packer.pack(*self._pick(self._consts + stamp + tuple(values)))


class CdrEncoderGroup:
    """Several messages of one stamp (the encoders' messages, in order) serialized with one
    :meth:`struct.Struct.pack`: each the bytes its :meth:`CdrEncoder.encode` gives.

    Parameters
    ----------
    encoders : sequence of CdrEncoder
        The messages; :meth:`encode` takes their values one after the other.
    """

    def __init__(self, encoders: Sequence[CdrEncoder]) -> None:
        self.encoders = tuple(encoders)
        self.count = sum(e.count for e in self.encoders)
        n_consts = sum(len(e._consts) for e in self.encoders)
        fmt, order, spans, c0, v0, pos = ['<'], [], [], 0, n_consts + 2, 0
        for e in self.encoders:
            fmt.append(e._packer.format[1:])   # '<': no alignment, so formats concatenate
            k = len(e._consts)
            order += [c0 + i if i < k else n_consts + i - k if i < k + 2 else v0 + i - k - 2
                      for i in e._order]
            spans.append((pos, pos + e._packer.size))
            c0, v0, pos = c0 + k, v0 + e.count, pos + e._packer.size
        self._packer = struct.Struct(''.join(fmt))
        self._consts = tuple(c for e in self.encoders for c in e._consts)
        self._pick = itemgetter(*order)
        self.spans = tuple(spans)

    def encode(self, stamp_ns: int, values: Sequence[float]) -> list[bytes]:
        """The messages with stamp ``stamp_ns`` (ns; ignored by a type without a header) and
        ``values`` (:attr:`count` numbers: the first encoder's, then the next's, ...)."""
        if len(values) != self.count:
            raise ValueError(f'{len(values)} numbers for {self.count}')
        data = self._packer.pack(*self._pick(
            self._consts + divmod(int(stamp_ns), NS_PER_S) + tuple(values)))
        return [data[a:b] for a, b in self.spans]


class CdrReader:
    """Read the stamp and float64 fields of received messages of ``template``'s layout.

    Parameters are those of :class:`CdrEncoder`. :meth:`read` gives None for a message whose
    size, byte order, lengths or strings differ from the template's (its padding is not
    looked at: rmw may leave it uninitialised).
    """

    def __init__(self, msgtype: str, template, paths: Sequence[str]) -> None:
        data = bytes(TYPESTORE.serialize_cdr(template, msgtype))
        self.layout = cdr_layout(msgtype, data)
        self.regions = _regions(self.layout, paths)
        self.stamped = _stamped(self.layout)
        mask = np.zeros(len(data), dtype=np.uint8)
        mask[self.layout.skeleton] = 0xFF
        self.size = len(data)
        self.mask = int.from_bytes(mask.tobytes(), 'little')
        self.skeleton = int.from_bytes(data, 'little') & self.mask

    def read(self, data: bytes) -> tuple[int, tuple[float, ...]] | None:
        """``(stamp_ns, values)`` (stamp 0 for a type without a header), or None when
        ``data`` does not have the template's layout."""
        if len(data) != self.size or int.from_bytes(data, 'little') & self.mask \
                != self.skeleton:
            return None
        stamp_ns = 0
        if self.stamped:
            sec, nanosec = _STAMP.unpack_from(data, _STAMP_OFFSET)
            stamp_ns = sec * NS_PER_S + nanosec
        if len(self.regions) == 1:
            packer, offset, _ = self.regions[0]
            return stamp_ns, packer.unpack_from(data, offset)
        return stamp_ns, tuple(v for packer, offset, _ in self.regions
                               for v in packer.unpack_from(data, offset))
