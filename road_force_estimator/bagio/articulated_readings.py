"""The articulated observer's inputs from a drive bag (``vehicle.model: articulated``, issue 32):
the readings of ``/suspension/deflections`` in the observer's channel order and the speed of
``/vehicle/twist`` held at each sample, as :func:`.drive.read_drive_bag` takes the front
axle's.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from road_force_estimator.bagio.checks import Rejects, read_joint_state, read_scalar
from road_force_estimator.bagio.errors import BagReadError
from road_force_estimator.bagio.reader import read_topic_columns
from road_force_estimator.interfaces import DEFLECTIONS, JOINT_STATE, TWIST, TWIST_STAMPED

__all__ = ['ArticulatedReadings', 'read_articulated_readings']


@dataclass(frozen=True)
class ArticulatedReadings:
    """``stamps_ns`` (m,), ``readings`` (m, C) of ``names`` (m, rad), ``speed_mps`` (m,; the
    twist's last speed at or before each sample, NaN before the first), ``rejected`` (topic ->
    reason -> count)."""

    stamps_ns: np.ndarray
    readings: np.ndarray
    names: tuple[str, ...]
    speed_mps: np.ndarray
    rejected: dict


def read_articulated_readings(path: str | Path, names: Sequence[str]) -> ArticulatedReadings:
    """The readings of the joints ``names`` (the observer's channels,
    :func:`road_force_estimator.estimation.models.articulated.channel_names`) and the speed.

    Raises
    ------
    BagReadError
        No ``/suspension/deflections`` topic.
    """
    cols = read_topic_columns(path, {DEFLECTIONS: JOINT_STATE, TWIST: TWIST_STAMPED})
    if DEFLECTIONS not in cols:
        raise BagReadError(f'{path}: no {DEFLECTIONS} topic')
    rejects = Rejects()
    stamps, pos = read_joint_state(cols[DEFLECTIONS], list(names), rejects)
    if TWIST in cols:
        twist_ns, twist_v = read_scalar(cols[TWIST], 'twist.linear.x', rejects)
    else:
        twist_ns, twist_v = np.zeros(0, np.int64), np.zeros(0)
    held = np.searchsorted(twist_ns, stamps, side='right') - 1
    speed = np.full(stamps.size, np.nan)
    if twist_v.size:
        speed[held >= 0] = twist_v[held[held >= 0]]
    return ArticulatedReadings(stamps, np.asarray(pos, float), tuple(names), speed,
                               rejects.counts)
