"""What the bag readers reject, and how they count it: shared by the drive and LPA readers.

Every message that cannot be trusted (undecodable, of the wrong type, with a bad stamp, a
non-finite value, a JointState without a required name or with arrays of the wrong length, a
duplicate or backward stamp) is dropped and counted by topic and reason; reading goes on.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from road_force_estimator.bagio.reader import TopicColumns

__all__ = ['Rejects', 'accept_in_order', 'increasing_run', 'basic_checks', 'read_points',
           'read_scalar', 'read_joint_state']

class Rejects:
    """Counts of rejected messages: topic -> reason -> count."""

    def __init__(self) -> None:
        self.counts: dict[str, dict[str, int]] = {}

    def add(self, topic: str, reason: str, count: int) -> None:
        """Count ``count`` more messages of ``topic`` rejected for ``reason``."""
        if count:
            per = self.counts.setdefault(topic, {})
            per[reason] = per.get(reason, 0) + int(count)


def accept_in_order(stamps: np.ndarray, ok: np.ndarray, topic: str,
                     rejects: Rejects, floor: int | None = None) -> np.ndarray:
    """Keep the messages (file order) that form the longest run of increasing stamps.

    The usual case (every stamp later than the one before) keeps them all. Otherwise the
    longest strictly increasing subsequence of the stamps is kept (:func:`increasing_run`):
    any number of outlier stamps, ahead of the stream or behind it, costs those messages
    only, where keeping every stamp above the latest one kept lost the rest of the drive to
    one stamp in the future. A dropped stamp is counted as a ``duplicate_stamp`` (equal to
    the one kept before it), an ``outlier_stamp`` (later than the one kept after it) or a
    ``backwards_stamp``. ``floor``: the latest stamp accepted before these messages (a bag
    read block by block, :mod:`.drive_blocks`): a stamp not after it is dropped (an outlier
    that is a block's last message can so cost the next block the messages before its
    stamp). Returns the mask of accepted messages.
    """
    if ok.all() and bool(np.all(stamps[1:] > stamps[:-1])) and (
            floor is None or stamps.size == 0 or stamps[0] > floor):
        return ok.copy()                        # the usual case: nothing to drop
    idx = np.flatnonzero(ok)
    s = stamps[idx]
    mask = np.zeros_like(ok)
    if s.size == 0:
        return mask
    start = np.iinfo(np.int64).min if floor is None else int(floor)
    above = s > start
    rejects.add(topic, 'duplicate_stamp', np.count_nonzero(s == start))
    rejects.add(topic, 'backwards_stamp', np.count_nonzero(s < start))
    idx, s = idx[above], s[above]
    keep = increasing_run(s)
    kept = s[keep]
    dropped = s[~keep]
    # the kept stamps around each dropped one: before (equal: a duplicate), after (smaller:
    # it was ahead of the stream)
    pos = np.searchsorted(np.flatnonzero(keep), np.flatnonzero(~keep))
    prev = np.where(pos > 0, kept[np.maximum(pos - 1, 0)], start) if kept.size else \
        np.full(dropped.size, start)
    nxt = kept[np.minimum(pos, kept.size - 1)] if kept.size else dropped
    duplicate = dropped == prev
    ahead = ~duplicate & (pos < kept.size) & (dropped > nxt)
    rejects.add(topic, 'duplicate_stamp', np.count_nonzero(duplicate))
    rejects.add(topic, 'outlier_stamp', np.count_nonzero(ahead))
    rejects.add(topic, 'backwards_stamp', np.count_nonzero(~duplicate & ~ahead))
    mask[idx[keep]] = True
    return mask


def increasing_run(values: np.ndarray) -> np.ndarray:
    """Mask of a longest strictly increasing subsequence of ``values`` (int64); of the
    longest, the one that keeps the earliest messages (``[10, 20, 15, 40]`` keeps 20, which
    came first, and drops 15). Patience sorting over the values reversed and negated (the
    longest run that ends highest, read backwards), O(n log n)."""
    import bisect

    v = [-x for x in reversed(values.tolist())]
    n = len(v)
    tails: list[int] = []        # the smallest last value of an increasing run of length j+1
    tail_at: list[int] = []      # its index
    before = [-1] * n
    for i, x in enumerate(v):
        j = bisect.bisect_left(tails, x)
        if j == len(tails):
            tails.append(x)
            tail_at.append(i)
        else:                    # (equal: the later here, the earlier message, replaces it)
            tails[j] = x
            tail_at[j] = i
        before[i] = tail_at[j - 1] if j else -1
    keep = np.zeros(n, dtype=bool)
    i = tail_at[-1] if tail_at else -1
    while i >= 0:
        keep[n - 1 - i] = True
        i = before[i]
    return keep


def basic_checks(cols: TopicColumns, rejects: Rejects) -> tuple[np.ndarray, np.ndarray]:
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
    if values.shape[0] == 0:
        return np.ones(0, dtype=bool)
    v = values.reshape(values.shape[0], -1)
    ok = np.ones(v.shape[0], dtype=bool)
    for j in range(v.shape[1]):                 # column by column: faster than axis=1
        ok &= np.isfinite(v[:, j])
    return ok


def read_points(cols: TopicColumns, rejects: Rejects, floor: int | None = None):
    """(stamps, x, y, z) of the accepted PointStamped messages, file order (``floor``: as
    :func:`accept_in_order`)."""
    stamps, ok = basic_checks(cols, rejects)
    xyz = np.column_stack([cols.column(f'point.{a}')[0] for a in 'xyz']) if cols.count \
        else np.zeros((0, 3))
    finite = _finite_rows(xyz)
    rejects.add(cols.topic, 'nonfinite', np.count_nonzero(ok & ~finite))
    keep = accept_in_order(stamps, ok & finite, cols.topic, rejects, floor)
    if not keep.all():
        stamps, xyz = stamps[keep], xyz[keep]
    return stamps, xyz[:, 0], xyz[:, 1], xyz[:, 2]


def read_scalar(cols: TopicColumns, path: str, rejects: Rejects, floor: int | None = None):
    """(stamps, values) of the accepted messages' number field ``path``, file order
    (``floor``: as :func:`accept_in_order`)."""
    stamps, ok = basic_checks(cols, rejects)
    values, _ = cols.column(path)
    finite = np.isfinite(values)
    rejects.add(cols.topic, 'nonfinite', np.count_nonzero(ok & ~finite))
    keep = accept_in_order(stamps, ok & finite, cols.topic, rejects, floor)
    if keep.all():
        return stamps, values
    return stamps[keep], values[keep]


def read_joint_state(cols: TopicColumns, names: Sequence[str], rejects: Rejects,
                      *, velocity: bool = False, floor: int | None = None):
    """(stamps, position (m, k)[, velocity]) of accepted JointStates, mapped by name
    (``floor``: as :func:`accept_in_order`)."""
    stamps, ok = basic_checks(cols, rejects)
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
    keep = accept_in_order(stamps, ok & finite, cols.topic, rejects, floor)
    if keep.all():
        return (stamps, pos, vel) if velocity else (stamps, pos)
    if velocity:
        return stamps[keep], pos[keep], vel[keep]
    return stamps[keep], pos[keep]
