"""Damaged and hostile bags for the reader tests (issue 16), crafted with the ``mcap`` library
where they must not come from our writer, and what the ``mcap`` library recovers from them.

``small_drive`` writes a drive (our writer), ``rewrite_with_mcap`` writes the same messages
again with the ``mcap`` library (small chunks, schemas and channels inside chunks);
``mcap_recovers`` counts the messages of a topic the ``mcap`` library's readers get from some
bytes, chunk by chunk, leaving out chunks whose CRC fails; ``chunk_record`` and
``with_extra_chunk`` splice a hand-made chunk into a bag; ``run_python`` runs code in a
fresh interpreter whose address space is capped.
"""
from __future__ import annotations

import io
import os
from pathlib import Path
import resource
import shutil
import struct
import subprocess
import sys
import zlib

from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Message
from mcap.stream_reader import ReadDataStream, StreamReader, breakup_chunk
from mcap.writer import CompressionType, Writer

from bag_samples import make_trajectory
from road_force_estimator import bagio
from road_force_estimator.interfaces import DEFLECTIONS

#: The fuzz's drive: samples and the mcap writer's chunk size (several chunks).
SAMPLES = 400
CHUNK = 8192
REPO = Path(__file__).resolve().parents[2]
#: Address space of a subprocess that reads a hostile bag (numpy and the decoders fit).
LIMIT_AS = 1536 << 20


def run_python(code: str, *args, limit_as: int | None = LIMIT_AS, timeout: float = 120):
    """``code`` run by a fresh interpreter (this tree and the test helpers on its path),
    its address space capped: the CompletedProcess."""
    path = [str(REPO), str(REPO / 'test'), str(REPO / 'test' / 'bagio'),
            os.environ.get('PYTHONPATH', '')]
    env = dict(os.environ, OPENBLAS_NUM_THREADS='1', OMP_NUM_THREADS='1',
               PYTHONPATH=os.pathsep.join(path))

    def cap():
        if limit_as:
            resource.setrlimit(resource.RLIMIT_AS, (limit_as, limit_as))
    return subprocess.run([sys.executable, '-c', code, *map(str, args)], env=env,
                          capture_output=True, text=True, timeout=timeout, preexec_fn=cap)


def small_drive(folder: Path, n: int = SAMPLES, seed: int = 5) -> Path:
    """A drive of ``n`` samples at 200 Hz (our writer); its .mcap file."""
    trajectory, q, roll = make_trajectory(n=n, seed=seed)
    bagio.write_drive_bag(folder, trajectory, q, roll)
    (mcap,) = Path(folder).glob('*.mcap')
    return mcap


def rewrite_with_mcap(src: Path, dst: Path, *, compression: str = 'none',
                      chunk_size: int = CHUNK, chunked: bool = True) -> Path:
    """The bag folder ``src`` written again by the ``mcap`` library into ``dst`` (same file
    name, same metadata.yaml; ``chunked`` False: every record at the top level); its .mcap
    file."""
    (mcap,) = Path(src).glob('*.mcap')
    dst.mkdir()
    shutil.copy(Path(src) / 'metadata.yaml', dst / 'metadata.yaml')
    out = dst / mcap.name
    with mcap.open('rb') as f, out.open('wb') as g:
        reader = make_reader(f)
        writer = Writer(g, compression=CompressionType[compression.upper()],
                        chunk_size=chunk_size, use_chunking=chunked)
        writer.start(profile='ros2', library='test')
        ids: dict[int, int] = {}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if channel.id not in ids:
                sid = writer.register_schema(schema.name, schema.encoding, schema.data)
                ids[channel.id] = writer.register_channel(channel.topic,
                                                          channel.message_encoding, sid,
                                                          dict(channel.metadata))
            writer.add_message(ids[channel.id], message.log_time, message.data,
                               message.publish_time, message.sequence)
        writer.finish()
    return out


def _count(records, topics: dict[int, str], topic: str) -> int:
    n = 0
    for record in records:
        if isinstance(record, Channel):
            topics[record.id] = record.topic
        elif isinstance(record, Message) and topics.get(record.channel_id) == topic:
            n += 1
    return n


def _seeking(data: bytes, topic: str) -> int:
    """Chunk by chunk through the summary's chunk index, a broken chunk skipped."""
    stream = io.BytesIO(data)
    try:
        summary = make_reader(stream).get_summary()
    except Exception:  # noqa: BLE001 - no usable summary
        return 0
    if summary is None:
        return 0
    topics = {cid: c.topic for cid, c in summary.channels.items()}
    n = 0
    for index in summary.chunk_indexes:
        try:
            stream.seek(index.chunk_start_offset + 9)
            chunk = Chunk.read(ReadDataStream(stream))
            n += _count(breakup_chunk(chunk, validate_crc=True), topics, topic)
        except Exception:  # noqa: BLE001 - this chunk is lost
            continue
    return n


def _streaming(data: bytes, topic: str) -> int:
    """Record by record from the start until a break, chunks failing their CRC skipped."""
    topics: dict[int, str] = {}
    n = 0
    try:
        for record in StreamReader(io.BytesIO(data), emit_chunks=True).records:
            if isinstance(record, Chunk):
                try:
                    n += _count(breakup_chunk(record, validate_crc=True), topics, topic)
                except Exception:  # noqa: BLE001 - a chunk failing its CRC
                    continue
            else:
                n += _count([record], topics, topic)
    except Exception:  # noqa: BLE001 - the break ends the read
        pass
    return n


def mcap_recovers(data: bytes, topic: str = DEFLECTIONS) -> int:
    """Messages of ``topic`` the ``mcap`` library's readers recover from ``data``: the better
    of its seeking reader (through the summary) and its stream reader (from the start), each
    given every chunk that passes its CRC check."""
    return max(_seeking(data, topic), _streaming(data, topic))


def chunk_record(records: bytes, *, compression: str = '', compressed: bytes | None = None,
                 declared: int | None = None) -> bytes:
    """A chunk record holding ``records`` (``compressed``: its compressed bytes;
    ``declared``: the uncompressed size it claims)."""
    payload = records if compressed is None else compressed
    size = len(records) if declared is None else declared
    name = compression.encode()
    body = (struct.pack('<QQQI', 0, 0, size, zlib.crc32(records) if compressed is None else 0)
            + struct.pack('<I', len(name)) + name + struct.pack('<Q', len(payload)) + payload)
    return struct.pack('<BQ', 0x06, len(body)) + body


def with_extra_chunk(data: bytes, chunk: bytes) -> bytes:
    """``data`` (a complete MCAP file) with ``chunk`` inserted before its end-of-data record
    and without summary (the footer says none), so every offset before stays valid."""
    reader = make_reader(io.BytesIO(data))
    summary_start = reader.get_summary() and _footer_summary_start(data)
    data_end = summary_start - 13 if summary_start else len(data) - 8 - 29 - 13
    assert data[data_end] == 0x0F, 'end-of-data record not found'
    footer = struct.pack('<BQQQI', 0x02, 20, 0, 0, 0)
    return data[:data_end] + chunk + data[data_end:data_end + 13] + footer + data[:8]


def _footer_summary_start(data: bytes) -> int:
    (start,) = struct.unpack_from('<Q', data, len(data) - 8 - 20)
    return start
