"""A drive bag read block by block: the estimator's inputs in bounded memory (issue 21).

:func:`read_drive_bag` holds the whole drive; :class:`DriveBlocks` yields it in blocks of
about ``block_samples`` accepted ``/suspension/deflections`` samples with their speed, and
ends with the counts that :class:`.Drive` carries. The same checks, in the same order, give
the same samples, speeds and counts (test_drive_blocks):

- each block's messages go through :func:`.checks.read_joint_state` /
  :func:`.checks.read_scalar` with the latest stamp accepted before it as the floor, so that a
  duplicate or backward stamp across blocks is dropped and counted as in one piece;
- a sample's speed is that of the latest accepted twist stamped at or before it; a sample is
  handed out once a twist stamped at or after it has been accepted (no later twist can then
  change it), the rest at the end; samples before the first twist take its speed (as
  ``estimate_bag`` does: :func:`~road_force_estimator.tools.estimate_bag.drive_speed`) and
  are counted (:attr:`DriveBlocks.early`);
- ``/fix`` (a few per second) is gathered whole and read as :func:`read_drive_bag` does;
- the ground truth (wheel loads, road points) is checked as the deflections are (its own
  floor per topic) and handed out with the samples, at their stamps
  (:attr:`InputBlock.truth`: :meth:`.GroundTruth.at` of the whole drive's truth, NaN where
  a topic has no sample at that stamp); while a truth topic the bag lists has not reached a
  sample's stamp, the sample waits.

The whole vehicle's inputs (``joints``: the articulated observer's channels, as
:func:`.articulated_readings.read_articulated_readings` reads them; ``imu``: with
``/imu/tractor``) come the same way: :attr:`InputBlock.readings` every channel, the samples
before the first twist the speed of the first sample that holds one (that reader's caller's
rule, :func:`road_force_estimator.pipeline.whole_vehicle.estimate`: they wait for it), with
the IMU each sample's a_y and code by :func:`~road_force_estimator.estimation.imu_hold.
pair_imu` (a sample waits until an IMU message at or after it while the bag's metadata
lists more of them, always without usable metadata: such a bag is read as one block);
only those topics are read and counted (no fixes, no truth).
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from pathlib import Path
from typing import Any, Iterator, Sequence

import numpy as np

from road_force_estimator.bagio.checks import (
    Rejects, read_joint_state, read_points, read_scalar)
from road_force_estimator.bagio.drive import GroundTruth
from road_force_estimator.bagio.vehicle_layout import front_axle_joints
from road_force_estimator.bagio.errors import BagReadError
from road_force_estimator.bagio.mcap_scan import Block
from road_force_estimator.bagio.reader import (
    USE_MESSAGE_INDEX, raw_batches, TopicReader, bag_custom_data, bag_files)
from road_force_estimator.interfaces import (
    DEFLECTIONS, FIX, IMU, IMU_MSG, JOINT_STATE, NAVSATFIX, POINT, TRUE_LOAD, TRUE_ROAD,
    TWIST, TWIST_STAMPED, WRENCH)

__all__ = ['BLOCK_SAMPLES', 'InputBlock', 'DriveRecord', 'DriveBlocks', 'listed_messages',
           'streamable']

#: Default samples per block (deflection messages gathered before a block is decoded).
BLOCK_SAMPLES = 1 << 16

_STAMP = ('header.stamp.sec', 'header.stamp.nanosec')
_TRUTH = {**{t: WRENCH for t in TRUE_LOAD}, **{t: POINT for t in TRUE_ROAD}}
_WANTED = {DEFLECTIONS: JOINT_STATE, TWIST: TWIST_STAMPED, FIX: NAVSATFIX, **_TRUTH}
_FIELDS = {DEFLECTIONS: _STAMP + ('position', 'velocity', 'effort'),
           TWIST: _STAMP + ('twist.linear.x',),
           FIX: _STAMP + ('latitude', 'longitude', 'altitude', 'status.status'),
           **{t: _STAMP + ('wrench.force.z',) for t in TRUE_LOAD},
           **{t: _STAMP + ('point.x', 'point.y', 'point.z') for t in TRUE_ROAD},
           IMU: _STAMP + ('linear_acceleration.y',)}
#: The truth's columns by topic: (key, value column) as :func:`.drive.read_drive_bag` keys them.
_TRUTH_KEYS = {TRUE_LOAD[0]: ('load_l',), TRUE_LOAD[1]: ('load_r',),
               TRUE_ROAD[0]: ('road_l', 'x_l'), TRUE_ROAD[1]: ('road_r', 'x_r')}


@dataclass
class InputBlock:
    """Accepted samples in order: stamps (ns), q (m, (k, 2)), roll (rad), speed (m/s; before
    the first twist its speed) and ``early`` (those samples: :attr:`.Drive.speed_mps` has NaN
    there)."""

    stamps_ns: np.ndarray
    q_m: np.ndarray
    roll_rad: np.ndarray
    speed_mps: np.ndarray
    early: np.ndarray | None = None
    #: the ground truth at the samples' stamps (None: the bag has none)
    truth: GroundTruth | None = None
    #: the whole vehicle's readings (k, channels; m, rad) of :class:`DriveBlocks` ``joints``
    #: (then ``q_m`` and ``roll_rad`` are empty), else None
    readings: np.ndarray | None = None
    #: with ``imu``: each sample's a_y (m/s^2) and pairing code (:mod:`.estimation.imu_hold`)
    imu_ay_mps2: np.ndarray | None = None
    imu_codes: np.ndarray | None = None


@dataclass(frozen=True)
class DriveRecord:
    """What a drive read block by block says of itself, without its arrays: the fields of
    :class:`.Drive` of the same names (messages per topic, rejections, breaks, fixes,
    ``custom_data``, kept-with-a-caveat counts, what the reader took)."""

    messages: dict[str, int]
    rejected: dict[str, dict[str, int]]
    issues: tuple[str, ...]
    fixes: Any
    custom_data: dict[str, str]
    noted: dict[str, dict[str, int]]
    notes: tuple[str, ...] = ()

    @property
    def rejected_total(self) -> int:
        """Messages rejected over all topics."""
        return sum(sum(r.values()) for r in self.rejected.values())


def listed_messages(path: str | Path) -> dict[str, int]:
    """``topic -> message count`` as metadata.yaml lists them; empty without usable
    metadata (then a drive is read whole)."""
    try:
        _, info, issues = bag_files(Path(path))
    except BagReadError:
        return {}
    if issues or not isinstance(info, dict):
        return {}
    counts: dict[str, int] = {}
    for entry in info.get('topics_with_message_count') or []:
        name = ((entry or {}).get('topic_metadata') or {}).get('name')
        if name:
            counts[str(name)] = int((entry or {}).get('message_count') or 0)
    return counts


def streamable(path: str | Path) -> int:
    """The ``/suspension/deflections`` messages metadata.yaml lists; 0 without usable
    metadata (then read it whole)."""
    return listed_messages(path).get(DEFLECTIONS, 0)


class DriveBlocks:
    """Iterate over a drive bag's accepted samples, block by block (see the module notes).

    After the iteration: :attr:`messages`, :attr:`rejected` (as :class:`.Drive`),
    :attr:`issues`, :attr:`custom_data`, :attr:`fixes`, :attr:`noted`, :attr:`twists`
    (accepted twists), :attr:`first_speed` and :attr:`early`. ``joints``, ``imu``: the whole
    vehicle's inputs (module notes).
    """

    def __init__(self, path: str | Path, block_samples: int = BLOCK_SAMPLES, *,
                 joints: Sequence[str] | None = None, imu: bool = False) -> None:
        self.path = Path(path)
        self.block_samples = int(block_samples)
        self.whole = joints is not None
        self.imu = bool(imu)
        self._wanted = ({DEFLECTIONS: JOINT_STATE, TWIST: TWIST_STAMPED,
                         **({IMU: IMU_MSG} if imu else {})} if self.whole else _WANTED)
        self._imu_ns = np.zeros(0, np.int64)          # the IMU messages a sample may need
        self._imu_ay = np.zeros(0)
        self.rejects = Rejects()
        self.issues: list[str] = []
        self.messages: dict[str, int] = {}
        self.fixes = None
        self.noted: dict = {}
        self.custom_data = bag_custom_data(self.path)
        #: the deflection joints read and what the reader says of them (.vehicle_layout)
        self.joints: tuple | None = None if joints is None else tuple(joints)
        self.notes: tuple[str, ...] = ()
        self.twists = 0
        self.first_speed: float | None = None
        self.early = 0
        self.seen_deflections = False
        self._last = {DEFLECTIONS: None, TWIST: None}
        self._twist_ns = np.zeros(0, np.int64)      # the twists a pending sample may need
        self._twist_v = np.zeros(0)
        self._pending: list[InputBlock] = []
        #: the truth topics the bag lists with messages (a sample waits until each has
        #: reached its stamp or has given every message listed)
        self._listed = listed_messages(self.path)
        self._truth_topics = (set() if self.whole else
                              {t for t, c in self._listed.items() if c} & set(_TRUTH))
        self._truth_last: dict[str, int | None] = {t: None for t in _TRUTH}
        if self.imu:
            self._truth_last[IMU] = None
        #: the samples wait for the IMU (notes): while the bag lists more of its messages,
        #: always without a usable metadata.yaml (then a bag without it is one block)
        self._imu_wait = self.imu and (bool(self._listed.get(IMU)) or not self._listed)
        self._truth: dict[str, tuple[np.ndarray, np.ndarray]] = {}

    @property
    def rejected(self) -> dict[str, dict[str, int]]:
        return self.rejects.counts

    def record(self) -> DriveRecord:
        """What was read (after the iteration), as :class:`DriveRecord`."""
        return DriveRecord(self.messages, self.rejected, tuple(self.issues), self.fixes,
                           self.custom_data, self.noted, self.notes)

    @property
    def rejected_total(self) -> int:
        return sum(sum(r.values()) for r in self.rejected.values())

    def __iter__(self) -> Iterator[InputBlock]:
        from road_force_estimator.bagio.drive import read_fixes

        seen: dict = {}
        readers: dict[str, TopicReader] = {}
        fix_reader = None
        for batch in raw_batches(self.path, self._wanted, self.issues, seen,
                                  indexed=USE_MESSAGE_INDEX):
            for topic, add in self._parts(batch):
                if topic == FIX:
                    if fix_reader is None:
                        fix_reader = TopicReader(NAVSATFIX, seen[FIX].msgtype, _FIELDS[FIX])
                    add(fix_reader)
                    continue
                if topic not in readers:
                    readers[topic] = TopicReader(self._wanted[topic], seen[topic].msgtype,
                                                  _FIELDS[topic])
                add(readers[topic])
            deflections = readers.get(DEFLECTIONS)
            if deflections is not None and deflections.count >= self.block_samples:
                block = self._decode(readers, seen)
                readers = {}
                if block is not None:
                    yield block
        if readers:
            block = self._decode(readers, seen)
            if block is not None:
                yield block
        if DEFLECTIONS not in seen:
            raise BagReadError(f'{self.path}: no {DEFLECTIONS} topic'
                               + (f' ({self.issues[0]})' if self.issues else ''))
        if fix_reader is not None:
            self.messages[FIX] = fix_reader.count
            self.fixes, self.noted = read_fixes(fix_reader.columns(FIX), self.rejects)
        rest = self._release(final=True)
        if rest is not None:
            yield rest

    @staticmethod
    def _parts(batch: list):
        """``(topic, add(reader))`` of one batch of the scan (blocks or messages)."""
        if isinstance(batch[0], Block):
            for block in batch:
                yield block.topic, (lambda r, b=block: r.add_block(b))
            return
        logs: dict[str, list] = {}
        datas: dict[str, list] = {}
        for channel, log_ns, data in batch:
            logs.setdefault(channel.topic, []).append(log_ns)
            datas.setdefault(channel.topic, []).append(data)
        for topic, log in logs.items():
            yield topic, (lambda r, a=log, d=datas[topic]: r.add_messages(a, d))

    def _decode(self, readers: dict, seen: dict) -> InputBlock | None:
        """Check one block's messages; the samples whose speed is known now (or None)."""
        for topic, reader in readers.items():
            self.messages[topic] = self.messages.get(topic, 0) + reader.count
        if TWIST in readers:
            s, v = read_scalar(readers[TWIST].columns(TWIST), 'twist.linear.x', self.rejects,
                               self._last[TWIST])
            if s.size:
                self._last[TWIST] = int(s[-1])
                if self.first_speed is None:
                    self.first_speed = float(v[0])
                self.twists += int(s.size)
                self._twist_ns = np.concatenate([self._twist_ns, s])
                self._twist_v = np.concatenate([self._twist_v, v])
        for topic in set(readers) & set(_TRUTH):
            self._truth_topics.add(topic)
            self._add_truth(topic, readers[topic].columns(topic))
        if IMU in readers:
            s, a = read_scalar(readers[IMU].columns(IMU), 'linear_acceleration.y',
                               self.rejects, self._truth_last[IMU])
            if s.size:
                self._truth_last[IMU] = int(s[-1])
                self._imu_ns = np.concatenate([self._imu_ns, s])
                self._imu_ay = np.concatenate([self._imu_ay, a])
        if DEFLECTIONS in readers:
            self.seen_deflections = True
            columns = readers[DEFLECTIONS].columns(DEFLECTIONS)
            if self.joints is None:         # an articulated drive: its front axle
                groups = columns.groups
                self.joints, note = front_axle_joints(
                    self.custom_data, groups[0].layout.strings.get('name') if groups else None)
                self.notes = (note,) if note else ()
            s, pos = read_joint_state(columns, self.joints, self.rejects,
                                      floor=self._last[DEFLECTIONS])
            if s.size and self.whole:
                self._last[DEFLECTIONS] = int(s[-1])
                self._pending.append(InputBlock(s, pos[:, :0], pos[:, 0][:0], np.zeros(0),
                                                readings=np.asarray(pos, float)))
            elif s.size:
                self._last[DEFLECTIONS] = int(s[-1])
                self._pending.append(InputBlock(s, pos[:, :2].copy(), pos[:, 2].copy(),
                                                np.zeros(0)))
        return self._release(final=False)

    def _release(self, final: bool) -> InputBlock | None:
        """The pending samples stamped at or before the latest twist (all when ``final``),
        with their held speed; None when there are none."""
        if not self._pending:
            return None
        stamps = np.concatenate([b.stamps_ns for b in self._pending])
        lasts = [self._last[TWIST]] + [self._truth_last[t] for t in self._truth_topics
                                       if self.messages.get(t, 0) < self._listed.get(t, 1)]
        if self._imu_wait and self.messages.get(IMU, 0) < self._listed.get(IMU, math.inf):
            lasts.append(self._truth_last[IMU])
        if final:
            k = stamps.size
        elif any(last is None for last in lasts):
            k = 0
        else:
            k = int(np.searchsorted(stamps, min(lasts), side='right'))
        if k and self.whole and not final and not self._twist_ns.size or (
                k and self.whole and not final and stamps[k - 1] < self._twist_ns[0]):
            k = 0                         # only early samples: they wait for a held speed
        if k == 0:
            return None
        q = np.concatenate([b.q_m for b in self._pending])
        roll = np.concatenate([b.roll_rad for b in self._pending])
        y = (np.concatenate([b.readings for b in self._pending]) if self.whole else None)
        self._pending = ([InputBlock(stamps[k:], q[k:], roll[k:], np.zeros(0),
                                     readings=None if y is None else y[k:])]
                         if k < stamps.size else [])
        s = stamps[:k]
        held = np.searchsorted(self._twist_ns, s, side='right') - 1
        if self._twist_v.size:
            speed = np.where(held >= 0, self._twist_v[np.clip(held, 0, None)], np.nan)
        else:
            speed = np.full(k, np.nan)
        early = ~np.isfinite(speed)
        if self.whole and early.any() and not early.all():
            speed[early] = speed[np.argmax(~early)]     # the first held speed (notes)
            self.early += int(np.count_nonzero(early))
        elif not self.whole and self.first_speed is not None and early.any():
            speed[early] = self.first_speed
            self.early += int(np.count_nonzero(early))
        # keep only the twists a later sample may still need (the last one at or before it)
        nxt = stamps[k] if k < stamps.size else s[-1]
        keep = max(0, int(np.searchsorted(self._twist_ns, nxt, side='right')) - 1)
        self._twist_ns, self._twist_v = self._twist_ns[keep:], self._twist_v[keep:]
        if self.whole:
            return InputBlock(s, q[:k], roll[:k], speed, early, None, y[:k],
                              *self._imu_at(s, nxt))
        return InputBlock(s, q[:k], roll[:k], speed, early, self._truth_at(s))

    def _imu_at(self, s: np.ndarray, nxt: int) -> tuple:
        """With the IMU: the samples' a_y and codes (:func:`.imu_hold.pair_imu` over the
        messages kept), the messages no later sample needs dropped; else (None, None)."""
        if not self.imu:
            return None, None
        from road_force_estimator.estimation.imu_hold import pair_imu

        ay, codes = pair_imu(s, self._imu_ns, self._imu_ay)
        keep = max(0, int(np.searchsorted(self._imu_ns, nxt, side='right')) - 1)
        self._imu_ns, self._imu_ay = self._imu_ns[keep:], self._imu_ay[keep:]
        return ay, codes

    def _add_truth(self, topic: str, columns) -> None:
        """One batch of a truth topic, checked (its own floor) into the waiting columns."""
        if topic in TRUE_LOAD:
            s, v = read_scalar(columns, 'wrench.force.z', self.rejects, self._truth_last[topic])
            values = (v,)
        else:
            s, x, _, z = read_points(columns, self.rejects, self._truth_last[topic])
            values = (z, x)
        if s.size:
            self._truth_last[topic] = int(s[-1])
        for key, v in zip(_TRUTH_KEYS[topic], values):
            old = self._truth.get(key)
            self._truth[key] = ((s, v) if old is None else
                                (np.concatenate([old[0], s]), np.concatenate([old[1], v])))

    def _truth_at(self, s: np.ndarray) -> GroundTruth | None:
        """The truth at the released stamps ``s`` (NaN where a topic has none there); the
        waiting truth up to ``s[-1]`` dropped."""
        if not self._truth_topics:
            return None
        k = s.size

        def place(key: str) -> np.ndarray:
            out = np.full(k, np.nan)
            if key not in self._truth:
                return out
            ts, tv = self._truth[key]
            pos = np.minimum(np.searchsorted(ts, s), max(ts.size - 1, 0))
            hit = (ts[pos] == s) if ts.size else np.zeros(k, bool)
            out[hit] = tv[pos[hit]]
            drop = int(np.searchsorted(ts, s[-1], side='right'))
            self._truth[key] = (ts[drop:], tv[drop:])
            return out
        load = np.column_stack([place('load_l'), place('load_r')])
        road = np.column_stack([place('road_l'), place('road_r')])
        x_l, x_r = place('x_l'), place('x_r')
        return GroundTruth(s.copy(), load, road, np.where(np.isnan(x_l), x_r, x_l))
