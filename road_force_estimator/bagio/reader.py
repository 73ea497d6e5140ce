"""Reading rosbag2 folders with MCAP storage: messages one by one, or whole topics in columns.

Reading walks each MCAP file record by record from its start (:mod:`.mcap_scan`), so a bag
whose recording was cut (no summary, a truncated chunk, a missing ``metadata.yaml``) or that is
corrupt yields every message it can trust and one line per break: a chunk that fails its CRC is
skipped and reading goes on; a cut or corrupt record outside chunks ends the file. The column
readers take a chunk whose message index accounts for every record in it through that index,
about five times faster than the walk and with the same result; any other chunk is walked
(bench/probes/bag_read_speed.py). Messages come in file order, which is log-time order for the bags
rosbag2, the bag_recorder node and this package write; the files of a split bag in the order of
their first messages, whatever order ``metadata.yaml`` lists them in (an issue says so). Only
regular files inside the bag folder are read (a FIFO, a device, or a ``metadata.yaml`` entry
such as ``../x.mcap`` or an absolute path is refused and named); a file that changes while it
is read is a :class:`BagReadError`.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path, PurePath
import stat
from typing import Any, Collection, Iterable, Iterator, Mapping

import numpy as np
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
import yaml

from road_force_estimator.serde.cdr import (
    NS_PER_S,
    TYPESTORE,
    ColumnDecoder,
    DecodedGroup,
    stamps_to_ns,
)
from road_force_estimator.bagio.errors import BagReadError
from road_force_estimator.bagio.writer import RESERVE_NAME
from road_force_estimator.bagio.mcap_scan import Block, Channel, McapScan
from road_force_estimator.bagio.mcap_source import (
    FileChanged, McapSource, NotRegular, first_log_time)

__all__ = [
    'USE_MESSAGE_INDEX', 'BagInfo', 'bag_info', 'bag_custom_data', 'iter_messages',
    'TopicColumns', 'read_topic_columns',
]
#: Read a chunk through the message index records that follow it when they account for
#: every record in it (``McapScan._indexed_chunk``); False walks every record (the
#: reference path; tests switch it off to compare).
USE_MESSAGE_INDEX = True


#: libyaml's safe loader when PyYAML has it (ten times faster on a metadata.yaml).
_YAML_LOADER = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)


def _not_regular(path: Path) -> str | None:
    """What ``path`` is when it is neither a regular file nor a folder (a FIFO, a device)."""
    try:
        mode = path.stat().st_mode
    except OSError:
        return None
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return None
    return NOT_REGULAR_KINDS.get(stat.S_IFMT(mode), 'not a regular file')


NOT_REGULAR_KINDS = {stat.S_IFIFO: 'a FIFO', stat.S_IFCHR: 'a character device',
                     stat.S_IFBLK: 'a block device', stat.S_IFSOCK: 'a socket'}


def _metadata(meta_path: Path, issues: list[str]) -> dict[str, Any]:
    """``rosbag2_bagfile_information`` of a metadata.yaml (empty, with an issue, when it
    cannot be parsed or has the wrong shape)."""
    if not meta_path.is_file():
        return {}
    try:
        doc = yaml.load(meta_path.read_text('utf-8'), Loader=_YAML_LOADER)
    except (yaml.YAMLError, UnicodeDecodeError) as err:
        issues.append(f'metadata.yaml cannot be parsed ({type(err).__name__}): '
                      'reading the .mcap files directly')
        return {}
    info = doc.get('rosbag2_bagfile_information') if isinstance(doc, Mapping) else doc
    if info is None:
        return {}
    if not isinstance(info, Mapping):
        issues.append('metadata.yaml: rosbag2_bagfile_information is not a mapping '
                      f'({type(info).__name__}): reading the .mcap files directly')
        return {}
    return dict(info)


def _listed_files(path: Path, info: Mapping[str, Any], issues: list[str]) -> list[Path]:
    """The files metadata.yaml lists that are inside the bag folder and regular files."""
    names = info.get('relative_file_paths') or []
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        issues.append('metadata.yaml: relative_file_paths is not a list of file names: '
                      'reading the .mcap files found in the folder')
        return []
    files = []
    for name in names:
        rel = PurePath(name)
        if rel.is_absolute() or '..' in rel.parts or not rel.parts:
            issues.append(f'{name}: outside the bag folder (listed in metadata.yaml): not read')
            continue
        f = path / rel
        kind = _not_regular(f)
        if kind:
            issues.append(f'{name}: {kind}, not a regular file (listed in metadata.yaml): '
                          'not read')
        elif not f.is_file():
            issues.append(f'{f.name}: listed in metadata.yaml but missing')
        else:
            files.append(f)
    return files


def bag_files(path: Path) -> tuple[list[Path], dict[str, Any], list[str]]:
    """The storage files of a bag folder (or a single .mcap), its metadata (the
    ``rosbag2_bagfile_information`` mapping, or {}) and issues: regular files inside the folder
    only (metadata.yaml naming a file outside it, a FIFO or a device: refused, named).

    Raises
    ------
    BagReadError
        No such folder or file, not MCAP storage, no readable .mcap file.
    """
    issues: list[str] = []
    if not path.exists():
        raise BagReadError(f'{path}: no such bag folder or file')
    kind = _not_regular(path)
    if kind:
        raise BagReadError(f'{path}: {kind}, not a regular file or a bag folder: not read')
    if path.is_file():
        if path.suffix != '.mcap':
            raise BagReadError(f'{path}: not a bag folder or an .mcap file')
        return [path], {}, issues
    info = _metadata(path / 'metadata.yaml', issues)
    if (path / RESERVE_NAME).exists():
        issues.append('the recording did not end (the recorder was stopped without closing '
                      'the bag, e.g. killed): read as far as it was written')
    storage = info.get('storage_identifier', 'mcap')
    if storage != 'mcap':
        raise BagReadError(f'{path}: storage {storage!r}: only MCAP bags are read here')
    files = _listed_files(path, info, issues)
    if not files:
        files = sorted(path.glob('*.mcap'))
        if files and not info:
            issues.append('no metadata.yaml: reading the .mcap files found in the folder')
        for f in files:
            kind = _not_regular(f)
            if kind:
                issues.append(f'{f.name}: {kind}, not a regular file: not read')
        files = [f for f in files if f.is_file()]
        if not files and issues:
            raise BagReadError(f'{path}: no readable .mcap file ({"; ".join(issues)})')
    if not files:
        raise BagReadError(f'{path}: no metadata.yaml and no .mcap file: not an MCAP bag')
    return _in_time_order(files, issues), info, issues


def _in_time_order(files: list[Path], issues: list[str]) -> list[Path]:
    """The files of a split bag in the order of their first messages (a file without one
    last, in the given order), whatever order metadata.yaml lists them in (said so when it
    is another)."""
    if len(files) < 2:
        return files
    starts = []
    for f in files:
        try:
            src = McapSource(f)
        except (OSError, NotRegular):
            starts.append(None)
            continue
        try:
            starts.append(first_log_time(src))
        except (OSError, FileChanged):
            starts.append(None)
        finally:
            src.close()
    order = sorted(range(len(files)), key=lambda i: (starts[i] is None, starts[i] or 0, i))
    if order != list(range(len(files))):
        issues.append('the files are not listed in time order: read in the order of their '
                      f'first messages ({", ".join(files[i].name for i in order)})')
    return [files[i] for i in order]


def raw_batches(path: Path, topics: Iterable[str] | None, issues: list[str],
                 channels_seen: dict[str, Channel] | None = None, *, indexed: bool = False,
                 ) -> Iterator[list]:
    """Lists of wanted ``(channel, log_ns, payload)`` of every file of a bag, file order
    (``indexed``: or lists of :class:`Block`, see :class:`McapScan`)."""
    wanted = None if topics is None else set(topics)
    files, _, file_issues = bag_files(path)
    issues.extend(file_issues)

    def want(channel: Channel) -> bool:
        if channels_seen is not None:
            channels_seen.setdefault(channel.topic, channel)
        return wanted is None or channel.topic in wanted

    for f in files:
        scan = McapScan(f, want, indexed=indexed)
        yield from scan.batches()
        issues.extend(scan.issues)
        if scan.unknown_channel:
            issues.append(f'{f.name}: {scan.unknown_channel} messages on undeclared channels '
                          'skipped')


def _raw_messages(path: Path, topics: Iterable[str] | None, issues: list[str],
                  channels_seen: dict[str, Channel] | None = None,
                  ) -> Iterator[tuple[Channel, int, bytes]]:
    for batch in raw_batches(path, topics, issues, channels_seen):
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
    seen: dict[str, Channel] = {}
    counts: dict[str, int] = {}
    for channel, _, _ in _raw_messages(path, None, issues, seen):
        counts[channel.topic] = counts.get(channel.topic, 0) + 1
    return BagInfo({t: c.msgtype for t, c in seen.items()},
                   {t: counts.get(t, 0) for t in seen}, bag_custom_data(path), tuple(issues))


def bag_custom_data(path: str | Path) -> dict[str, str]:
    """metadata.yaml ``custom_data`` of a bag (empty when it has none or is no bag)."""
    try:
        _, info, _ = bag_files(Path(path))
    except BagReadError:
        return {}
    data = info.get('custom_data') or {}
    return {str(k): str(v) for k, v in data.items()} if isinstance(data, Mapping) else {}


def _deserializer(channel: Channel, stores: dict[str, Any]):
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
    groups: list[DecodedGroup]
    undecodable: np.ndarray
    wrong_type: bool = False

    @property
    def count(self) -> int:
        """Messages of the topic."""
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
        valid = ok1 & ok2 & (nsec < NS_PER_S) & (nsec >= 0)
        return stamps_to_ns(sec, nsec), valid


class TopicReader:
    """Gathers one topic's messages (file order) and decodes them as they come."""

    def __init__(self, expected: str, recorded: str,
                 paths: Collection[str] | None = None) -> None:
        self.msgtype = recorded
        self.decoder = ColumnDecoder(expected, paths=paths) if recorded == expected else None
        self.logs: list[np.ndarray] = []
        self.count = 0

    def add_block(self, block: Block) -> None:
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
    (:class:`McapScan`), and decoded a chunk at a time while it is in the cache.
    """
    sink = issues if issues is not None else []
    seen: dict[str, Channel] = {}
    readers: dict[str, TopicReader] = {}

    def reader(topic: str) -> TopicReader:
        found = readers.get(topic)
        if found is None:
            found = readers[topic] = TopicReader(topics[topic], seen[topic].msgtype,
                                                  (fields or {}).get(topic))
        return found

    for batch in raw_batches(Path(path), topics, sink, seen, indexed=USE_MESSAGE_INDEX):
        if isinstance(batch[0], Block):
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
