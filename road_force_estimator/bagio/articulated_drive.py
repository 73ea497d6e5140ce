"""Drive bags of the articulated truck (``vehicle.model: articulated``, INTERFACES.md "The
whole vehicle"): written as the plant_simulator publishes them, and the truth per axle read
back.

Topics: ``/vehicle/twist``; ``/suspension/deflections`` (JointState: both sides of every
instrumented axle, ``tractor_roll``, ``trailer_roll`` where fitted); ``/imu/tractor``
(sensor_msgs/Imu) where fitted; ``/fix``; and the ground truth: the front axle's
``/ground_truth/wheel_load/left|right`` and ``/ground_truth/road_profile/left|right`` (the road
under the front wheels, ``y = +-w_front``: every axle drives these two paths), every wheel's
load in ``/ground_truth/wheel_loads`` (JointState, ``effort``), and each unit's load transfer
in ``/ground_truth/load_transfer_ratios`` (JointState: name tractor, trailer, combination;
position = LTR, velocity = quasi-static LTR). ``custom_data`` says
``road_force_estimator.vehicle_model: articulated``, names the front axle's deflection joints
(what a front-axle tool reads) and holds the static wheel loads.
"""
from __future__ import annotations

from dataclasses import dataclass
import json
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from road_force_estimator.serde.cdr import ColumnRows
from road_force_estimator.bagio.checks import (
    Rejects, accept_in_order, basic_checks, read_joint_state)
from road_force_estimator.bagio.drive import fix_stream
from road_force_estimator.serde.messages import (
    DEFAULT_START_STAMP_NS, IMU_PATHS, check_finite, imu_template, message_template,
    points_rows, stamp_columns)
from road_force_estimator.bagio.reader import bag_custom_data, read_topic_columns
from road_force_estimator.bagio.vehicle_layout import AXLES_KEY, MODEL_KEY, STATIC_KEY
from road_force_estimator.bagio.writer import BagWriter
from road_force_estimator.interfaces import (
    BASE_FRAME, DEFLECTIONS, IMU, IMU_FRAME, IMU_MSG, JOINT_STATE, ROAD_FRAME, TOPIC_TYPES,
    TRUE_LOAD, TRUE_LOAD_TRANSFER_RATIOS, TRUE_ROAD, TRUE_WHEEL_LOADS, TWIST, TWIST_STAMPED,
    UNITS, WHEEL_FRAMES, WRENCH, qos_kind)

__all__ = ['write_articulated_drive_bag', 'ArticulatedTruth', 'read_articulated_truth']


def write_articulated_drive_bag(path: str | Path, *, stamps_ns: np.ndarray,
                                speed_mps: np.ndarray, readings: np.ndarray,
                                names: Sequence[str], truth: Mapping | None,
                                imu: np.ndarray | None = None, imu_std=(0.0, 0.0),
                                fixes=None, custom_data: Mapping[str, str] | None = None,
                                start_stamp_ns: int = DEFAULT_START_STAMP_NS) -> int:
    """Write an articulated drive; the number of messages.

    Parameters
    ----------
    stamps_ns : (n,) int64, strictly increasing
    speed_mps : (n,) the twist's speed (m/s)
    readings : (n, C) the deflections (m) and rolls (rad) of ``names``
    names : the C joint names (:func:`.interfaces.articulated_deflection_joints`)
    truth : mapping or None
        ``distance_m`` (n,), ``front_road_m`` (n, 2), ``front_half_track_m``,
        ``wheel_names`` (2N), ``wheel_load_n`` (n, 2N) and ``unit_ltr`` (n, 6): the ground
        truth (None: the measurements only, as a real truck records them).
    imu : (n, 6) or None
        a_x, a_y, a_z (m/s^2), roll, pitch, yaw rates (rad/s); ``imu_std``: their noise std
        (the covariances' diagonals).
    fixes : as :func:`.write_drive_bag`'s.
    """
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    n = stamps.size
    if n == 0 or np.any(np.diff(stamps) <= 0):
        raise ValueError('articulated drive: stamps must be non-empty and strictly increasing')
    readings = np.asarray(readings, float).reshape(n, len(names))
    speed = np.broadcast_to(np.asarray(speed_mps, float), (n,))
    check_finite('readings', readings)
    check_finite('speed', speed)
    cols = stamp_columns(stamps)
    # twist first: at equal stamps a replay delivers the speed before the deflections
    streams = [(TWIST, stamps, ColumnRows(
        TWIST_STAMPED, message_template(TWIST_STAMPED, BASE_FRAME), n,
        dict(cols, **{'twist.linear.x': speed}))), (DEFLECTIONS, stamps, ColumnRows(
        JOINT_STATE, message_template(JOINT_STATE, BASE_FRAME, names), n,
        dict(cols, position=readings)))]
    if imu is not None:
        streams.append((IMU, stamps, _imu_rows(cols, n, np.asarray(imu, float), imu_std)))
    if truth is not None:
        streams += _truth_streams(stamps, cols, truth)
    if fixes is not None:
        streams.append(fix_stream(fixes, start_stamp_ns))
    custom = {'road_force_estimator.kind': 'drive', MODEL_KEY: 'articulated'}
    custom.update(custom_data or {})
    with BagWriter(path, custom_data=custom) as bag:
        for topic, _, _ in streams:
            bag.add_topic(topic, TOPIC_TYPES[topic], qos_kind(topic))
        bag.write_rows(streams)
        return bag.message_count



def _imu_rows(cols, n: int, imu: np.ndarray, std) -> ColumnRows:
    """The IMU's rows; ``imu`` columns a_x, a_y, a_z, roll, pitch, yaw rates."""
    check_finite('imu', imu)
    fields = dict(cols)
    for path, col in zip(IMU_PATHS, (3, 4, 5, 0, 1, 2)):
        fields[path] = imu[:, col]
    return ColumnRows(IMU_MSG, imu_template(IMU_FRAME, *std), n, fields)


def _truth_streams(stamps, cols, truth) -> list:
    n = stamps.size
    x = np.asarray(truth['distance_m'], float).reshape(n)
    road = np.asarray(truth['front_road_m'], float).reshape(n, 2)
    loads = np.asarray(truth['wheel_load_n'], float)
    ltr = np.asarray(truth['unit_ltr'], float).reshape(n, 6)
    for name, values in (('distance_m', x), ('front_road_m', road), ('wheel_load_n', loads),
                         ('unit_ltr', ltr)):
        check_finite('truth.' + name, values)
    half = float(truth['front_half_track_m'])
    streams = []
    for side in (0, 1):
        streams.append((TRUE_LOAD[side], stamps, ColumnRows(
            WRENCH, message_template(WRENCH, WHEEL_FRAMES[side]), n,
            dict(cols, **{'wrench.force.z': loads[:, side]}))))
    for side in (0, 1):
        streams.append((TRUE_ROAD[side], stamps, points_rows(
            stamps, x, half if side == 0 else -half, road[:, side], ROAD_FRAME, cols)))
    streams.append((TRUE_WHEEL_LOADS, stamps, ColumnRows(
        JOINT_STATE, message_template(JOINT_STATE, BASE_FRAME, truth['wheel_names'],
                                      effort=True), n, dict(cols, effort=loads))))
    streams.append((TRUE_LOAD_TRANSFER_RATIOS, stamps, ColumnRows(
        JOINT_STATE, message_template(JOINT_STATE, BASE_FRAME, UNITS, velocity=True), n,
        dict(cols, position=ltr[:, 0::2], velocity=ltr[:, 1::2]))))
    return streams


@dataclass(frozen=True)
class ArticulatedTruth:
    """The truth per axle of an articulated drive bag.

    ``wheel_names`` (2N) and ``axle_names`` (N), ``stamps_ns`` (m,), ``wheel_load_n`` (m, 2N),
    ``static_load_n`` (2N, the statics the drive used; NaN when the bag does not say),
    ``axle_bodies`` (N, 'tractor' / 'trailer' where the bag says), ``unit_ltr`` (m, 6: per
    unit LTR and quasi-static LTR; NaN where absent), ``rejected`` (topic -> reason -> count).
    """

    wheel_names: tuple[str, ...]
    axle_names: tuple[str, ...]
    stamps_ns: np.ndarray
    wheel_load_n: np.ndarray
    static_load_n: np.ndarray
    axle_bodies: tuple[str, ...]
    unit_ltr: np.ndarray
    rejected: dict


def read_articulated_truth(path: str | Path) -> ArticulatedTruth | None:
    """The truth per axle of a drive bag (None when it has no ``/ground_truth/wheel_loads``).
    Messages that cannot be trusted are dropped and counted, as :func:`.read_drive_bag` does."""
    cols = read_topic_columns(path, {TRUE_WHEEL_LOADS: JOINT_STATE,
                                     TRUE_LOAD_TRANSFER_RATIOS: JOINT_STATE})
    if TRUE_WHEEL_LOADS not in cols:
        return None
    rejects = Rejects()
    c = cols[TRUE_WHEEL_LOADS]
    stamps, ok = basic_checks(c, rejects)
    names: tuple[str, ...] = ()
    loads = np.full((c.count, 0), np.nan)
    for g in c.groups:
        have = tuple(g.layout.strings.get('name', ()))
        effort = g.columns['effort']
        if not names and effort.shape[1] == len(have) and have:
            names = have
            loads = np.full((c.count, len(names)), np.nan)
        if have == names and effort.shape[1] == len(names):
            loads[g.index] = effort
    finite = np.all(np.isfinite(loads), axis=1) if loads.shape[1] else np.zeros(c.count, bool)
    rejects.add(c.topic, 'nonfinite_or_other_names', np.count_nonzero(ok & ~finite))
    keep = accept_in_order(stamps, ok & finite, c.topic, rejects)
    stamps, loads = stamps[keep], loads[keep]
    ltr = np.full((stamps.size, 6), np.nan)
    if TRUE_LOAD_TRANSFER_RATIOS in cols:
        s, pos, vel = read_joint_state(cols[TRUE_LOAD_TRANSFER_RATIOS], UNITS, rejects,
                                       velocity=True)
        at = np.searchsorted(stamps, s)
        hit = at < stamps.size
        hit[hit] &= stamps[at[hit]] == s[hit]
        ltr[at[hit], 0::2] = pos[hit]
        ltr[at[hit], 1::2] = vel[hit]
    custom = bag_custom_data(path)
    axles = tuple(dict.fromkeys(n.rsplit('_', 2)[0] for n in names))
    try:
        static = np.asarray(json.loads(custom.get(STATIC_KEY, '[]')), float)
    except ValueError:
        static = np.zeros(0)
    if static.shape != (len(names),):
        static = np.full(len(names), np.nan)
    try:
        bodies = tuple(json.loads(custom.get(AXLES_KEY, '[]')))
    except ValueError:
        bodies = ()
    return ArticulatedTruth(names, axles, stamps, loads, static,
                            bodies if len(bodies) == len(axles) else (), ltr, rejects.counts)
