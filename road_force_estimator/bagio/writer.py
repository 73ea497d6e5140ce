"""Writing rosbag2 folders with MCAP storage, as Jazzy's rosbag2 writes them.

A folder with ``metadata.yaml`` (version 9, storage ``mcap``, offered QoS profiles as YAML
lists, RIHS01 type hashes, a ``custom_data`` map) and ``<folder>_0.mcap`` (profile ``ros2``,
``ros2msg`` schemas, little-endian CDR messages in CRC-checked chunks, message and chunk
indexes, the ``rosbag2`` metadata record), so that ``ros2 bag info/play``, the ``mcap`` /
``mcap-ros2-support`` libraries and rosbags read them. The container is :mod:`.mcap_file`;
blocks of rows are laid out by :mod:`.row_blocks`.
"""
from __future__ import annotations

from pathlib import Path
import shutil
from typing import Any, Mapping, Sequence

import numpy as np
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
import yaml

from road_force_estimator.serde.cdr import TYPESTORE, CdrLayout, ColumnRows, cdr_layout
from road_force_estimator.bagio.errors import BagWriteError
from road_force_estimator.bagio.mcap_file import McapFile
from road_force_estimator.bagio.row_blocks import write_interleaved
from road_force_estimator.interfaces import RELIABLE, SENSOR_DATA

__all__ = ['ROSBAG2_VERSION', 'SENSOR_DATA_QOS', 'RELIABLE_QOS', 'RESERVE_NAME', 'BagWriter']

#: The file that holds space for the end of a recording (its summary and metadata.yaml) while
#: it runs (``reserve_bytes``): removed when the bag is closed; found in a bag, it says the
#: recording did not end (the recorder was killed).
RESERVE_NAME = '.recording'

#: metadata.yaml version written by Jazzy's rosbag2.
ROSBAG2_VERSION = 9

_INFINITE = QosTime(9223372036, 854775807)   # RMW_DURATION_INFINITE, as rosbag2 records it
#: Sensor-data QoS (best effort, keep last 5), as rclpy's qos_profile_sensor_data.
SENSOR_DATA_QOS = Qos(QosHistory.KEEP_LAST, 5, QosReliability.BEST_EFFORT,
                      QosDurability.VOLATILE, _INFINITE, _INFINITE, QosLiveliness.AUTOMATIC,
                      _INFINITE, False)
#: Reliable QoS (keep last 10), the rclpy default: ground truth, estimates, profiles.
RELIABLE_QOS = Qos(QosHistory.KEEP_LAST, 10, QosReliability.RELIABLE, QosDurability.VOLATILE,
                   _INFINITE, _INFINITE, QosLiveliness.AUTOMATIC, _INFINITE, False)
#: The rosbags profile of each QoS kind of :mod:`road_force_estimator.interfaces`.
_QOS_BY_NAME = {SENSOR_DATA: SENSOR_DATA_QOS, RELIABLE: RELIABLE_QOS}


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
        raise BagWriteError(f'{path} exists already (use --force to replace it)')
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


def _reason(err: OSError) -> str:
    """The OS reason of a failed write: 'out of space (...)' for ENOSPC / EDQUOT."""
    import errno
    text = err.strerror or str(err)
    return f'out of space ({text})' if err.errno in (errno.ENOSPC, errno.EDQUOT) else text


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
    chunk_age_s : float, optional
        Close a chunk once its first message is this old (s; a recorder: what a SIGKILL can
        lose), besides by size (:class:`.McapFile`); :meth:`flush_due` checks it between
        messages.
    reserve_bytes : int
        Space (bytes) held in :data:`RESERVE_NAME` while the bag is open and given back to
        write its end: a disk that fills during a recording still gets the summary and
        ``metadata.yaml`` (:meth:`salvage`).

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
                 custom_data: Mapping[str, str] | None = None, chunk_age_s: float | None = None,
                 reserve_bytes: int = 0) -> None:
        if storage != 'mcap':
            raise ValueError(f"storage = {storage!r}: only 'mcap' is written")
        self.path = Path(path)
        self._overwrite = overwrite
        self._chunk_age_s = chunk_age_s
        self._reserve_bytes = int(reserve_bytes)
        self._file: McapFile | None = None
        # A map, never null (yaml-cpp in rosbag2 refuses a null custom_data), with a tag
        # that tells where the bag came from ('bag_io', the writer's name when the tag was
        # set: kept, so that the bags stay byte for byte what they were).
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
            if self._reserve_bytes:
                with (self.path / RESERVE_NAME).open('xb') as f:
                    f.write(bytes(self._reserve_bytes))
            self._file = McapFile(self.path / f'{self.path.name}_0.mcap', self._chunk_age_s)
        except OSError as err:
            shutil.rmtree(self.path, ignore_errors=True)
            raise BagWriteError(f'{self.path}: cannot create the bag ({_reason(err)})') \
                from None

    def flush_due(self) -> None:
        """Close the pending chunk if it is ``chunk_age_s`` old (a recorder's timer).

        Raises
        ------
        OSError
            The write failed (out of space): see :meth:`salvage`.
        """
        if self._file is not None:
            self._file.flush_due()

    def _release_reserve(self) -> None:
        try:
            (self.path / RESERVE_NAME).unlink()
        except FileNotFoundError:
            pass

    def salvage(self) -> str:
        """After a write that failed (out of space): end the bag with what was written
        whole (the messages of the chunk that failed are lost), with the space held back
        given to its summary and ``metadata.yaml``; what was kept, one phrase.

        Raises
        ------
        BagWriteError
            Not even ``metadata.yaml`` could be written (the .mcap file stays readable).
        """
        f, self._file = self._file, None
        if f is None:
            return 'nothing was open'
        self._release_reserve()
        summary = f.salvage(_yaml(self._metadata(f)))
        try:
            self._write_metadata(self._metadata(f))
        except OSError as err:
            raise BagWriteError(f'{self.path}: metadata.yaml not written ({_reason(err)}); '
                                f'{f.message_count} messages kept in {f.path.name}, readable '
                                'without it') from None
        return (f'{f.message_count} messages kept in {f.path.name}, readable, with '
                + ('its summary' if summary else 'no summary (read from its start)')
                + ' and metadata.yaml')

    def _metadata(self, f: McapFile | None = None) -> dict[str, Any]:
        f = self._file if f is None else f
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
        """Write the summary, the index and metadata.yaml.

        Raises
        ------
        BagWriteError
            Out of space (or another OS error) on the way: the bag is ended by
            :meth:`salvage` first, the message says what was kept.
        """
        if self._file is None:
            return
        f, info = self._file, None
        try:
            f.flush_chunk()
            self._release_reserve()
            info = self._metadata()
            f.close(_yaml(info))
        except OSError as err:
            kept = self.salvage()
            raise BagWriteError(f'{self.path}: {_reason(err)} while closing: {kept}') from None
        except BaseException:
            self._file = None
            try:                # no file descriptor left open on the bag
                f.file.close()
            except OSError:
                pass
            raise
        self._file = None
        self._write_metadata(info)

    def _write_metadata(self, info: dict[str, Any]) -> None:
        tmp = self.path / 'metadata.yaml.tmp'
        try:
            tmp.write_text(_yaml({'rosbag2_bagfile_information': info}), 'utf-8')
            tmp.replace(self.path / 'metadata.yaml')
        except OSError:
            tmp.unlink(missing_ok=True)
            raise

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
            template and columns it is made of, ``ColumnRows``), or a sequence of n
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
            elif not isinstance(rows, ColumnRows):
                rows = [bytes(r) for r in rows]
            if len(rows) != stamp_ns.size:
                raise BagWriteError(f'{topic}: {stamp_ns.size} stamps for {len(rows)} messages')
            if stamp_ns.size and (stamp_ns.min() < 0):
                raise BagWriteError(f'{topic}: negative stamp {stamp_ns.min()} ns')
            prepared.append((cid, stamp_ns, rows))
        prepared = [p for p in prepared if p[1].size]
        if prepared:
            write_interleaved(self._file, prepared, block_bytes=self.BLOCK_BYTES,
                              block_messages=self.BLOCK_MESSAGES)
