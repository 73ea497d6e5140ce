"""The articulated observer's inputs from a drive bag (``vehicle.model: articulated``, issue 32):
the readings of ``/suspension/deflections`` in the observer's channel order and the speed of
``/vehicle/twist`` held at each sample, as :func:`.drive.read_drive_bag` takes the front
axle's; with ``imu`` the tractor IMU's messages (``/imu/tractor``: stamps and
``linear_acceleration.y``, m/s^2), paired with the samples by the estimator's rule
(:func:`road_force_estimator.estimation.imu_hold.pair_imu`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from road_force_estimator.bagio.checks import Rejects, read_joint_state, read_scalar
from road_force_estimator.bagio.errors import BagReadError
from road_force_estimator.bagio.reader import read_topic_columns
from road_force_estimator.interfaces import (
    DEFLECTIONS, IMU, IMU_MSG, JOINT_STATE, TWIST, TWIST_STAMPED)

__all__ = ['ArticulatedReadings', 'read_articulated_readings']


@dataclass(frozen=True)
class ArticulatedReadings:
    """``stamps_ns`` (m,), ``readings`` (m, C) of ``names`` (m, rad), ``speed_mps`` (m,; the
    twist's last speed at or before each sample, NaN before the first), ``rejected`` (topic ->
    reason -> count); ``imu_stamps_ns``, ``imu_ay_mps2``: the accepted ``/imu/tractor``
    messages' stamps and a_y (m/s^2; empty without ``imu`` or without the topic)."""

    stamps_ns: np.ndarray
    readings: np.ndarray
    names: tuple[str, ...]
    speed_mps: np.ndarray
    rejected: dict
    imu_stamps_ns: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    imu_ay_mps2: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: topic -> messages read (the topics above that the bag has)
    messages: dict = field(default_factory=dict)


def read_articulated_readings(path: str | Path, names: Sequence[str], imu: bool = False
                              ) -> ArticulatedReadings:
    """The readings of the joints ``names`` (the observer's deflection and roll channels,
    :func:`road_force_estimator.estimation.models.articulated.channel_names`), the speed and,
    with ``imu``, the ``/imu/tractor`` messages (out-of-order or non-finite ones rejected and
    counted, as every topic's).

    Raises
    ------
    BagReadError
        No ``/suspension/deflections`` topic.
    """
    topics = {DEFLECTIONS: JOINT_STATE, TWIST: TWIST_STAMPED}
    if imu:
        topics[IMU] = IMU_MSG
    cols = read_topic_columns(path, topics)
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
    imu_ns, imu_ay = np.zeros(0, np.int64), np.zeros(0)
    if imu and IMU in cols:
        imu_ns, imu_ay = read_scalar(cols[IMU], 'linear_acceleration.y', rejects)
    return ArticulatedReadings(stamps, np.asarray(pos, float), tuple(names), speed,
                               rejects.counts, np.asarray(imu_ns, np.int64),
                               np.asarray(imu_ay, float),
                               {t: c.count for t, c in cols.items()})
