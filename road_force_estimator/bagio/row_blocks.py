"""Laying out message records in blocks: several topics' rows, interleaved by stamp.

:func:`write_interleaved` is :meth:`.writer.BagWriter.write_rows`' engine. The largest set of
fixed-size streams that share strictly increasing stamps (a drive: every topic at every sample)
is laid out as one 2-D array, row after row, a block of rows at a time in a reused buffer
(:class:`_AlignedBlock`); the other messages (diagnostics, GNSS fixes: :class:`_Others`) are
spliced in between at their places. Complete chunks go to the file straight from the block.
"""
from __future__ import annotations

import struct
from typing import Any, Sequence

import numpy as np

from road_force_estimator.serde.cdr import ColumnRows
from road_force_estimator.bagio.mcap_file import RECORD_HEAD, RECORD_LEAD, McapFile

__all__ = ['aligned_streams', 'write_interleaved']

#: Bytes of a message record before its payload: opcode, length, channel, sequence, times.
_HEAD_BYTES = 31


def aligned_streams(prepared) -> list[int]:
    """Positions of the streams laid out as one 2-D block, row after row: the largest set
    of fixed-size streams, each with a channel of its own, that share strictly increasing
    stamps. ``prepared``: ``(cid, stamps_ns, rows)`` per stream."""
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


def write_interleaved(file: McapFile, prepared: Sequence[tuple[int, np.ndarray, Any]], *,
                      block_bytes: int, block_messages: int) -> None:
    """Write every stream's messages in stamp order (then stream order, then position).

    Parameters
    ----------
    file : McapFile
        The open container.
    prepared : sequence of (cid, stamps_ns (n,) int64, rows)
        Non-empty streams: ``rows`` an (n, size) uint8 array, a :class:`.cdr.ColumnRows` or a
        list of n ``bytes``.
    block_bytes : int
        Bytes of aligned rows laid out per block (the buffer is reused).
    block_messages : int
        Other messages laid out per block when no stream is aligned.
    """
    aligned = aligned_streams(prepared)
    others = _Others(file, prepared, aligned)
    if not aligned:
        others.write_alone(block_messages)
        return
    block = _AlignedBlock(file, prepared, aligned, block_bytes)
    others.place(block.stamps, aligned)
    for r0 in range(0, block.n, block.step):
        r1 = min(block.n, r0 + block.step)
        flat, at = block.fill(r0, r1)
        _emit(file, block, others, r0, r1, flat, at)
    for cid in block.cids:
        file.counts[cid] += block.n


class _Others:
    """The messages not in the aligned block in write order (stamp, stream, position): their
    stream (``which``), position in it (``index``), channel, sequence number, stamp and record
    size; ``ins`` (after :meth:`place`): the aligned message (row * k + stream) each goes
    before."""

    def __init__(self, file: McapFile, prepared, aligned: list[int]) -> None:
        self.file = file
        others = [j for j in range(len(prepared)) if j not in aligned]
        empty = [np.zeros(0, dtype=np.int64)]
        stamp = np.concatenate(empty + [prepared[j][1] for j in others])
        which = np.concatenate(empty + [np.full(prepared[j][1].size, j) for j in others])
        index = np.concatenate(empty + [np.arange(prepared[j][1].size) for j in others])
        order = np.lexsort((index, which, stamp))
        self.stamp, self.which, self.index = stamp[order], which[order], index[order]
        self.cid = np.array([cid for cid, _, _ in prepared], dtype=np.int64)[self.which]
        self.seq = file.sequences(self.cid)
        self.data: dict[int, Any] = {}
        self.size = np.zeros(self.stamp.size, dtype=np.int64)
        for j in others:
            rows = prepared[j][2]
            rows = rows.array() if isinstance(rows, ColumnRows) else rows
            self.data[j] = rows
            mine = self.which == j
            if isinstance(rows, list):
                lengths = np.fromiter(map(len, rows), dtype=np.int64, count=len(rows))
                self.size[mine] = _HEAD_BYTES + lengths[self.index[mine]]
            else:
                self.size[mine] = _HEAD_BYTES + rows.shape[1]
        self.ins = np.zeros(0, dtype=np.int64)

    def write_alone(self, block_messages: int) -> None:
        """Write them all (no aligned block), ``block_messages`` records per block."""
        for i0 in range(0, self.stamp.size, block_messages):
            i1 = min(self.stamp.size, i0 + block_messages)
            records, cum = self.records(i0, i1)
            self.file.add_block([records], self.entries(i0, i1, cum[:-1]))

    def place(self, stamps: np.ndarray, aligned: list[int]) -> None:
        """Where each goes among the aligned rows of ``stamps``: before the first row of a later
        stamp, or at its own stamp's row before the aligned streams that follow its stream."""
        n, k = stamps.size, len(aligned)
        at = np.searchsorted(stamps, self.stamp)
        same = at < n
        same[same] = stamps[at[same]] == self.stamp[same]
        self.ins = at * k + np.where(same, np.searchsorted(np.array(aligned), self.which), 0)

    def records(self, i0: int, i1: int) -> tuple[np.ndarray, np.ndarray]:
        """Records of messages ``i0:i1`` (write order), back to back, and their byte positions
        (m + 1,)."""
        which, index, sizes = self.which[i0:i1], self.index[i0:i1], self.size[i0:i1]
        stamps = self.stamp[i0:i1]
        m = stamps.size
        cum = np.zeros(m + 1, dtype=np.int64)
        np.cumsum(sizes, out=cum[1:])
        out = np.empty(int(cum[-1]), dtype=np.uint8)
        head = np.zeros(m, dtype=RECORD_HEAD)
        head['op'] = 0x05
        head['length'] = sizes - 9
        head['cid'] = self.cid[i0:i1]
        head['seq'] = self.seq[i0:i1]
        head['log'] = stamps
        head['pub'] = stamps
        out[cum[:-1, None] + np.arange(_HEAD_BYTES)] = head.view(np.uint8).reshape(
            m, _HEAD_BYTES)
        for j in np.unique(which).tolist():
            mine = np.flatnonzero(which == j)
            rows = self.data[j]
            if isinstance(rows, list):
                for i, at in zip(index[mine].tolist(), (cum[mine] + _HEAD_BYTES).tolist()):
                    out[at:at + len(rows[i])] = np.frombuffer(rows[i], dtype=np.uint8)
                continue
            width = rows.shape[1]
            many = max(1, (1 << 20) // max(width, 1))     # bounds the index arrays
            for g in range(0, mine.size, many):
                pick = mine[g:g + many]
                out[(cum[pick] + _HEAD_BYTES)[:, None] + np.arange(width)] = rows[index[pick]]
        return out, cum

    def entries(self, i0: int, i1: int, starts: np.ndarray) -> list:
        """(cid, record starts, log times) per channel of messages ``i0:i1``, for
        :meth:`.mcap_file.McapFile.add_block`."""
        cids, stamps = self.cid[i0:i1], self.stamp[i0:i1]
        entries = []
        for cid in np.unique(cids).tolist():
            mine = cids == cid
            entries.append((cid, starts[mine], stamps[mine]))
        return entries


class _AlignedBlock:
    """The aligned streams' records, a block of ``step`` rows (one message of each of the k
    streams per row, ``width`` bytes) at a time in one reused buffer: record headers and
    template bytes are written once, then only the numbers of each block."""

    def __init__(self, file: McapFile, prepared, aligned: list[int], block_bytes: int) -> None:
        self.k = len(aligned)
        self.stamps = prepared[aligned[0]][1]
        self.n = self.stamps.size
        self.sizes = [prepared[j][2].shape[1] for j in aligned]
        pre = np.cumsum([0] + [_HEAD_BYTES + size for size in self.sizes])
        self.width, self.pre = int(pre[-1]), pre[:-1]
        self.step = max(1, min(self.n, block_bytes // self.width))
        self.rec = np.zeros((self.step, self.width), dtype=np.uint8)
        self.cids = [prepared[j][0] for j in aligned]
        self.seq0 = [file.counts[cid] for cid in self.cids]
        self.streams = [prepared[j][2] for j in aligned]
        self._shared_leads()
        self._fields()
        self.head = np.zeros(self.step, dtype=[('seq', '<u4'), ('log', '<u8'), ('pub', '<u8')])
        self.head_bytes = self.head.view('V20')
        self.ramp = np.arange(self.step, dtype=np.int64)

    def _shared_leads(self) -> None:
        """Streams whose records agree from the sequence number to the header stamp (the same
        first sequence number, encapsulation and stamp columns) get those 32 bytes from one
        array per block: ``groups`` of stream numbers, ``lead_of`` stream -> group."""
        leads: dict[tuple, list[int]] = {}
        for q, rows in enumerate(self.streams):
            stamp = rows.stamp_pieces() if isinstance(rows, ColumnRows) else None
            if stamp is not None:
                leads.setdefault((self.seq0[q], rows.raw[:4].tobytes()) + tuple(
                    rows.values(i, 0, 0).__array_interface__['data'][0] for i in stamp),
                                 []).append(q)
        self.groups = [qs for qs in leads.values() if len(qs) > 1]
        self.lead_of = {q: g for g, qs in enumerate(self.groups) for q in qs}
        self.lead = np.zeros((len(self.groups), self.step), dtype=RECORD_LEAD)
        self.lead_bytes = self.lead.view('V32')
        self.lead_stamps = []
        for g, qs in enumerate(self.groups):
            rows = self.streams[qs[0]]
            self.lead[g].view(np.uint8).reshape(self.step, 32)[:, 20:24] = rows.raw[:4]
            self.lead_stamps.append([lambda r0, r1, rows=rows, i=i: rows.values(i, r0, r1)
                                     for i in rows.stamp_pieces()])

    def _fields(self) -> None:
        """The record headers and template bytes in the buffer, and a structured view of it
        with one field per piece written each block: its ``sources`` (stream number for the
        sequence and times, ``(group,)`` for a shared lead, else a function of the rows)."""
        names, formats, offsets, self.sources = [], [], [], []
        for q, rows in enumerate(self.streams):
            at_q, size = int(self.pre[q]), self.sizes[q]
            self.rec[:, at_q:at_q + 11] = np.frombuffer(
                struct.pack('<BQH', 0x05, 22 + size, self.cids[q]), dtype=np.uint8)
            fields: list = [('V20', 11, q)]             # sequence, log and publish times
            skip: tuple[int, ...] = ()
            if q in self.lead_of:                        # ... up to the header stamp
                fields = [('V32', 11, (self.lead_of[q],))]
                skip = rows.stamp_pieces()
            if isinstance(rows, ColumnRows):
                self.rec[:, at_q + _HEAD_BYTES:at_q + _HEAD_BYTES + size] = rows.raw
                fields += [(f'V{nbytes}', _HEAD_BYTES + offset,
                            lambda r0, r1, rows=rows, i=i: rows.values(i, r0, r1))
                           for i, (offset, nbytes) in enumerate(rows.pieces) if i not in skip]
            elif size:
                whole = rows.view(f'V{size}').reshape(self.n)
                fields.append((f'V{size}', _HEAD_BYTES,
                               lambda r0, r1, whole=whole: whole[r0:r1]))
            for fmt, offset, source in fields:
                names.append(f'f{len(names)}')
                formats.append(fmt)
                offsets.append(at_q + offset)
                self.sources.append(source)
        self.names = names
        self.view = self.rec.reshape(-1).view(np.dtype(
            {'names': names, 'formats': formats, 'offsets': offsets, 'itemsize': self.width}))

    def fill(self, r0: int, r1: int) -> tuple[np.ndarray, np.ndarray]:
        """Lay out rows ``r0:r1``: their bytes (flat) and the (k, b) record starts in them."""
        b = r1 - r0
        s = self.stamps[r0:r1]
        ramp = self.ramp[:b]
        self.head['log'][:b] = s
        self.head['pub'][:b] = s
        for g, qs in enumerate(self.groups):
            lead = self.lead[g, :b]
            lead['seq'] = (self.seq0[qs[0]] + r0 + ramp) % 2**32
            lead['log'] = s
            lead['pub'] = s
            lead['sec'] = self.lead_stamps[g][0](r0, r1)
            lead['nsec'] = self.lead_stamps[g][1](r0, r1)
        block = self.view[:b]
        for name, source in zip(self.names, self.sources):
            if isinstance(source, int):
                self.head['seq'][:b] = (self.seq0[source] + r0 + ramp) % 2**32
                block[name] = self.head_bytes[:b]
            elif isinstance(source, tuple):
                block[name] = self.lead_bytes[source[0], :b]
            else:
                block[name] = source(r0, r1)
        flat = self.rec[:b].reshape(-1)
        return flat, self.pre[:, None] + ramp * self.width


def _emit(file: McapFile, block: _AlignedBlock, others: _Others, r0: int, r1: int,
          flat: np.ndarray, at: np.ndarray) -> None:
    """Add rows ``r0:r1`` (``flat``, record starts ``at``) to the file with the other messages
    that go among them spliced in at their places."""
    k, b = block.k, r1 - r0
    s = block.stamps[r0:r1]
    i0 = int(others.ins.searchsorted(r0 * k))
    i1 = others.stamp.size if r1 == block.n else int(others.ins.searchsorted(r1 * k))
    if i0 == i1:
        file.add_block([flat], [(cid, at[q], s) for q, cid in enumerate(block.cids)],
                       at.T.reshape(-1))
        return
    records, cum = others.records(i0, i1)
    ins = others.ins[i0:i1] - r0 * k
    points, first = np.unique(ins, return_index=True)
    after = np.append(first[1:], ins.size)
    # Aligned records move by the bytes of the others spliced in before them.
    at = at + np.repeat(np.append(cum[0], cum[after]), np.diff(
        np.concatenate([[0], points, [b * k]]))).reshape(b, k).T
    pos = ins // k * block.width + block.pre[ins % k]       # byte in `flat` they go before
    starts = pos + cum[:-1]
    entries = [(cid, at[q], s) for q, cid in enumerate(block.cids)]
    entries += others.entries(i0, i1, starts)
    segments, done = [], 0
    for p, a, z in zip(pos[first].tolist(), first.tolist(), after.tolist()):
        if p > done:
            segments.append(flat[done:p])
            done = p
        segments.append(records[cum[a]:cum[z]])
    if done < flat.size:
        segments.append(flat[done:])
    file.add_block(segments, entries, np.insert(at.T.reshape(-1), ins, starts))
