"""Playback side of a rosbag2 MCAP bag: serialized messages in log-time order, recorded QoS.

Any writer's bag (ours, ``rosbags``', the ``mcap`` library's, ``ros2 bag record``'s) is read
through the ``mcap`` library, which reads the records and decompresses zstd and lz4 chunks
(the messages of a chunk are then taken from its bytes here, without an object per message).
Reading streams: one chunk at a time is decompressed and its messages merged into the
log-time order (a bounded window: chunks as recorders write them, in time order; a file whose
chunks overlap in time is read through its chunk index, which merges them), so a bag of any
length plays in bounded memory. A bag cut short (a recorder killed, a copy interrupted) plays
up to the break: :attr:`Playback.broken` then says where.

QoS: each topic's ``offered_qos_profiles`` from ``metadata.yaml`` (rosbag2 writes a list, older
versions a YAML string), else from the MCAP channel's metadata; a topic without any (as
``rosbags`` writes them) gets the QoS kind of :func:`road_force_estimator.interfaces.qos_kind`
(reliable for topics INTERFACES.md does not list).
"""
from __future__ import annotations

from dataclasses import dataclass
import heapq
import io
from pathlib import Path
import struct
from typing import Iterator, Sequence

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import StreamReader, get_chunk_data_stream
import yaml

from road_force_estimator.bagio.errors import BagReadError
from road_force_estimator.bagio.reader import bag_files
from road_force_estimator.interfaces import SENSOR_DATA, qos_kind

__all__ = ['PlaybackError', 'TopicQoS', 'PlayedTopic', 'Playback', 'open_playback']

_RECORD_HEAD = struct.Struct('<BQ')      # opcode, length
_MESSAGE_HEAD = struct.Struct('<HIQ')    # channel id, sequence, log time (then publish time)
#: Depth of a topic's queue when the bag records none (a keep-all recording has none either).
DEFAULT_DEPTH = 100


class PlaybackError(ValueError):
    """A bag that cannot be played at all (missing, not MCAP, no messages); one line."""


@dataclass(frozen=True)
class TopicQoS:
    """The QoS to publish a topic with: ``reliability`` 'reliable' or 'best_effort',
    ``durability`` 'volatile' or 'transient_local', ``depth`` (messages, keep last)."""

    reliability: str = 'reliable'
    durability: str = 'volatile'
    depth: int = DEFAULT_DEPTH
    recorded: bool = False  #: taken from the bag (False: from interfaces.qos_kind)

    @classmethod
    def of_kind(cls, kind: str) -> TopicQoS:
        """The QoS of a kind of :mod:`road_force_estimator.interfaces`."""
        return cls('best_effort' if kind == SENSOR_DATA else 'reliable')


@dataclass(frozen=True)
class PlayedTopic:
    """A topic of the bag: name, type ('pkg/msg/Name'), encoding, QoS, message count."""

    name: str
    type: str
    encoding: str
    qos: TopicQoS
    count: int = -1  #: from metadata.yaml (-1: unknown)


def _qos_from_profiles(profiles) -> TopicQoS | None:
    """The first of rosbag2's ``offered_qos_profiles`` (list, or YAML text of a list)."""
    if isinstance(profiles, str):
        try:
            profiles = yaml.safe_load(profiles) if profiles.strip() else None
        except yaml.YAMLError:
            return None
    if not profiles or not isinstance(profiles, list) or not isinstance(profiles[0], dict):
        return None
    first = profiles[0]
    rel = str(first.get('reliability', 'reliable')).lower()
    dur = str(first.get('durability', 'volatile')).lower()
    depth = first.get('depth', DEFAULT_DEPTH)
    if rel in ('2', 'best_effort'):
        rel = 'best_effort'
    elif rel in ('1', 'reliable', '0', 'system_default'):
        rel = 'reliable'
    else:
        return None
    dur = 'transient_local' if dur in ('1', 'transient_local') else 'volatile'
    depth = int(depth) if isinstance(depth, int) and depth > 0 else DEFAULT_DEPTH
    return TopicQoS(rel, dur, depth, recorded=True)


def _chunk_messages(chunk: Chunk, schemas: dict[int, str], channel) -> list:
    """``(channel id, log time, data)`` of a chunk's messages (its schemas and channels
    registered on the way), CRC checked: the records parsed here, without an object per
    message, as a chunk of a 1 kHz drive holds tens of thousands."""
    stream, length = get_chunk_data_stream(chunk, validate_crc=True)
    buf = stream.read(length) if length else b''
    out = []
    pos, end = 0, len(buf)
    message, head = Opcode.MESSAGE, _RECORD_HEAD.unpack_from
    while pos + 9 <= end:
        op, size = head(buf, pos)
        body = pos + 9
        pos = body + size
        if pos > end:
            raise ValueError(f'record of {size} bytes overruns the chunk')
        if op == message:
            cid, _, log_time = _MESSAGE_HEAD.unpack_from(buf, body)
            out.append((cid, log_time, buf[body + 22:pos]))
        elif op == Opcode.SCHEMA:
            rec = Schema.read(ReadDataStream(io.BytesIO(buf[body:pos])))
            schemas[rec.id] = rec.name
        elif op == Opcode.CHANNEL:
            channel(Channel.read(ReadDataStream(io.BytesIO(buf[body:pos]))))
    return out


def _normal_type(name: str) -> str:
    parts = name.split('/')
    return f'{parts[0]}/msg/{parts[1]}' if len(parts) == 2 else name


class Playback:
    """A bag opened for playback (:func:`open_playback`).

    Attributes
    ----------
    path : Path
    files : list of Path
        The MCAP files, in the order of their first messages.
    topics : dict of str to PlayedTopic
        Known from metadata.yaml before reading; topics found only in the MCAP channels are
        added while :meth:`messages` reads.
    broken : str
        Empty, or what stopped the last :meth:`messages` early (a cut or damaged file).
    issues : list of str
        What the bag's folder lacks or holds out of order (a file metadata.yaml lists but
        that is missing, files listed out of time order: read in time order), as
        :func:`.reader.bag_files` says it: the player warns of each.
    """

    def __init__(self, path: Path, files: list[Path], topics: dict[str, PlayedTopic],
                 issues: list[str] | None = None):
        self.path = path
        self.files = files
        self.topics = topics
        self.issues = list(issues or [])
        self.broken = ''

    def messages(self, topics: Sequence[str] | None = None, start_offset_ns: int = 0
                 ) -> Iterator[tuple[int, str, str, bytes]]:
        """``(log_time_ns, topic, type, serialized CDR bytes)`` in log-time order.

        Parameters
        ----------
        topics : sequence of str, optional
            Only these topics (default: all).
        start_offset_ns : int
            Skip the messages logged before the bag's first message (of any topic) plus this
            (ns).
        """
        self.broken = ''
        self._first_ns = None
        wanted = None if topics is None else set(topics)
        for path in self.files:
            for t, topic, msgtype, data in self._file_messages(path, wanted):
                if t - self._first_ns >= start_offset_ns:
                    yield t, topic, msgtype, data
            if self.broken:
                return

    def _seen(self, t_ns: int) -> None:
        if self._first_ns is None or t_ns < self._first_ns:
            self._first_ns = t_ns

    def _file_messages(self, path: Path, wanted):
        """One file's messages in log-time order: read linearly, chunk by chunk
        (:meth:`_linear`), unless the chunk index shows chunks that start earlier than the
        chunk before them (then through the index, which merges overlapping chunks)."""
        with path.open('rb') as f:
            reader = SeekingReader(f, validate_crcs=True)
            try:
                summary = reader.get_summary()
            except Exception:  # cut: no footer or summary
                summary = None
            index = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset) if (
                summary is not None) else []
            starts = [c.message_start_time for c in index]
            if starts == sorted(starts):
                yield from self._linear(path, wanted)
                return
            self._seen(min(starts))
            messages = reader.iter_messages(topics=wanted, log_time_order=True)
            while True:
                try:
                    schema, channel, message = next(messages)
                except StopIteration:
                    return
                except Exception as exc:  # a damaged chunk: play what came before
                    self.broken = (f'{path.name} is damaged ({type(exc).__name__}: {exc}): '
                                   f'played up to the break')
                    return
                if channel.topic not in self.topics:
                    self._channel(channel, {channel.schema_id: schema.name if schema else ''})
                yield message.log_time, channel.topic, self.topics[channel.topic].type, \
                    message.data

    def _linear(self, path: Path, wanted):
        """A file read from the start, chunk by chunk, merged into log-time order (a chunk's
        messages wait until a later chunk starts after them); a cut or damaged file ends the
        read where the damage begins, with :attr:`broken` saying so."""
        heap: list = []
        seq = 0
        channels: dict[int, tuple[str, str] | None] = {}
        schemas: dict[int, str] = {}

        def release(upto: int):
            while heap and heap[0][0] <= upto:
                t, _, topic, msgtype, data = heapq.heappop(heap)
                yield t, topic, msgtype, data

        def channel(rec: Channel) -> None:
            name, msgtype = self._channel(rec, schemas)
            channels[rec.id] = (name, msgtype) if wanted is None or name in wanted else None

        with path.open('rb') as f:
            records = StreamReader(f, emit_chunks=True, validate_crcs=True).records
            while True:
                try:
                    record = next(records)
                except StopIteration:
                    break
                except Exception as exc:  # a cut or damaged file: play what came before
                    self.broken = (f'{path.name} is cut or damaged near byte {f.tell()} '
                                   f'({type(exc).__name__}{": " if str(exc) else ""}{exc}): '
                                   f'played up to the break')
                    break
                if isinstance(record, Chunk):
                    try:
                        inner = _chunk_messages(record, schemas, channel)
                    except Exception as exc:
                        self.broken = (f'{path.name}: a chunk near byte {f.tell()} cannot be '
                                       f'read ({exc}): played up to the break')
                        break
                    self._seen(record.message_start_time)
                    yield from release(record.message_start_time)
                elif isinstance(record, Message):
                    self._seen(record.log_time)
                    yield from release(record.log_time)
                    inner = [(record.channel_id, record.log_time, record.data)]
                else:
                    if isinstance(record, Schema):
                        schemas[record.id] = record.name
                    elif isinstance(record, Channel):
                        channel(record)
                    continue
                for cid, t, data in inner:
                    target = channels.get(cid)
                    if target is not None:
                        heapq.heappush(heap, (t, seq, *target, data))
                        seq += 1
        yield from release(float('inf'))

    def _channel(self, channel: Channel, schemas: dict[int, str]) -> tuple[str, str]:
        known = self.topics.get(channel.topic)
        if known is None:
            msgtype = _normal_type(schemas.get(channel.schema_id, ''))
            qos = _qos_from_profiles(channel.metadata.get('offered_qos_profiles', ''))
            known = PlayedTopic(channel.topic, msgtype, channel.message_encoding,
                                qos or TopicQoS.of_kind(qos_kind(channel.topic)))
            self.topics[channel.topic] = known
        return known.name, known.type


def open_playback(path: str | Path) -> Playback:
    """Open a bag folder (with or without ``metadata.yaml``) or one ``.mcap`` file.

    Raises
    ------
    PlaybackError
        No such folder or file, no MCAP file in it, a file that is not MCAP, or a
        metadata.yaml that cannot be read.
    """
    path = Path(path)
    try:
        files, info, issues = bag_files(path)   # regular files inside the folder only
    except BagReadError as exc:
        raise PlaybackError(str(exc)) from None
    topics: dict[str, PlayedTopic] = {}
    for entry in info.get('topics_with_message_count') or []:
        meta = entry.get('topic_metadata', {}) if isinstance(entry, dict) else {}
        name = meta.get('name') if isinstance(meta, dict) else None
        if not name:
            continue
        qos = _qos_from_profiles(meta.get('offered_qos_profiles'))
        topics[name] = PlayedTopic(
            name, _normal_type(str(meta.get('type', ''))),
            str(meta.get('serialization_format', 'cdr')),
            qos or TopicQoS.of_kind(qos_kind(name)), int(entry.get('message_count', -1)))
    for file in files:
        with file.open('rb') as f:
            if f.read(8) != b'\x89MCAP0\r\n':
                raise PlaybackError(f'{file}: not an MCAP file (rosbag2 MCAP storage only)')
    return Playback(path, files, topics, issues)

