"""The messages of INTERFACES.md as templates for :class:`.cdr.ColumnRows`, and shared defaults.

A template fixes a message's strings and array lengths (frame id, joint names); the numbers of
each row are written into it a column at a time.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from road_force_estimator.serde.cdr import TYPESTORE, ColumnRows, LazyColumns, ns_to_stamps
from road_force_estimator.interfaces import (
    FLOAT64,
    IMU_MSG,
    JOINT_STATE,
    NAVSATFIX,
    POINT,
    TWIST_STAMPED,
    VECTOR3_STAMPED,
    WRENCH,
)

__all__ = [
    'DEFAULT_START_STAMP_NS', 'DEFAULT_TRACK_WIDTH_M', 'message_class', 'message_template',
    'stamp_columns', 'points_rows', 'check_finite', 'imu_template', 'IMU_PATHS',
]

#: Default first stamp of a written bag: 2024-01-01T00:00:00Z (deterministic output).
DEFAULT_START_STAMP_NS = 1_704_067_200 * 1_000_000_000
#: Default track width, the lateral distance between the two wheel paths (m).
DEFAULT_TRACK_WIDTH_M = 2.0


def message_class(msgtype: str):
    """The rosbags class of ``msgtype`` (e.g. ``'std_msgs/msg/Header'``) in the Jazzy store."""
    return TYPESTORE.types[msgtype]


def _header(frame_id: str):
    time = message_class('builtin_interfaces/msg/Time')(sec=0, nanosec=0)
    return message_class('std_msgs/msg/Header')(stamp=time, frame_id=frame_id)


def _vector3():
    return message_class('geometry_msgs/msg/Vector3')(x=0.0, y=0.0, z=0.0)


def message_template(msgtype: str, frame_id: str = '', names: Sequence[str] = (),
                     velocity: bool = False, effort: bool = False):
    """A message of ``msgtype`` with zero numbers: frame ``frame_id``; for a JointState the
    joint ``names``, positions and (``velocity``) velocities, no efforts; with ``effort``
    efforts only (``/wheel_loads``: no positions or velocities). An Imu has its orientation
    unknown (``orientation_covariance[0] = -1``, REP-145)."""
    if msgtype == POINT:
        point = message_class('geometry_msgs/msg/Point')(x=0.0, y=0.0, z=0.0)
        return message_class(POINT)(header=_header(frame_id), point=point)
    if msgtype == WRENCH:
        wrench = message_class('geometry_msgs/msg/Wrench')(force=_vector3(), torque=_vector3())
        return message_class(WRENCH)(header=_header(frame_id), wrench=wrench)
    if msgtype == TWIST_STAMPED:
        twist = message_class('geometry_msgs/msg/Twist')(linear=_vector3(), angular=_vector3())
        return message_class(TWIST_STAMPED)(header=_header(frame_id), twist=twist)
    if msgtype == FLOAT64:
        return message_class(FLOAT64)(data=0.0)
    if msgtype == VECTOR3_STAMPED:
        return message_class(VECTOR3_STAMPED)(header=_header(frame_id), vector=_vector3())
    if msgtype == JOINT_STATE and effort:
        return message_class(JOINT_STATE)(
            header=_header(frame_id), name=list(names), position=np.zeros(0),
            velocity=np.zeros(0), effort=np.zeros(len(names)))
    if msgtype == IMU_MSG:
        quaternion = message_class('geometry_msgs/msg/Quaternion')(x=0.0, y=0.0, z=0.0, w=1.0)
        unknown = np.zeros(9)
        unknown[0] = -1.0
        return message_class(IMU_MSG)(
            header=_header(frame_id), orientation=quaternion, orientation_covariance=unknown,
            angular_velocity=_vector3(), angular_velocity_covariance=np.zeros(9),
            linear_acceleration=_vector3(), linear_acceleration_covariance=np.zeros(9))
    if msgtype == JOINT_STATE:
        k = len(names)
        return message_class(JOINT_STATE)(
            header=_header(frame_id), name=list(names), position=np.zeros(k),
            velocity=np.zeros(k if velocity else 0), effort=np.zeros(0))
    if msgtype == NAVSATFIX:
        status = message_class('sensor_msgs/msg/NavSatStatus')(status=0, service=0)
        return message_class(NAVSATFIX)(
            header=_header(frame_id), status=status, latitude=0.0, longitude=0.0, altitude=0.0,
            position_covariance=np.zeros(9), position_covariance_type=0)
    raise ValueError(f'no template for {msgtype}')


#: The IMU's numbers in a message's byte order: angular rates, then linear accelerations.
IMU_PATHS = ('angular_velocity.x', 'angular_velocity.y', 'angular_velocity.z',
             'linear_acceleration.x', 'linear_acceleration.y', 'linear_acceleration.z')


def imu_template(frame_id: str, accel_std: float, rate_std: float):
    """An Imu message with the noise variances on the covariances' diagonals (m/s^2, rad/s;
    orientation unknown)."""
    template = message_template(IMU_MSG, frame_id)
    template.linear_acceleration_covariance[[0, 4, 8]] = float(accel_std) ** 2
    template.angular_velocity_covariance[[0, 4, 8]] = float(rate_std) ** 2
    return template


def stamp_columns(stamps_ns: np.ndarray) -> dict[str, np.ndarray]:
    """The header stamp columns (``sec``, ``nanosec``) of integer-nanosecond stamps."""
    sec, nanosec = ns_to_stamps(stamps_ns)
    return {'header.stamp.sec': sec, 'header.stamp.nanosec': nanosec}


def points_rows(stamps_ns, x, y, z, frame_id: str,
                columns: dict[str, np.ndarray] | None = None) -> ColumnRows:
    """PointStamped rows: point ``x``, ``y`` (one value for every row), ``z`` (arrays or
    :class:`.cdr.LazyColumns`), frame ``frame_id``; ``columns``: the stamp columns, if made."""
    n = len(stamps_ns)
    cols = dict(columns) if columns is not None else stamp_columns(stamps_ns)
    cols.update({'point.x': x if isinstance(x, LazyColumns) else np.asarray(x, float),
                 'point.y': np.broadcast_to(np.asarray(y, float), (n,)),
                 'point.z': z if isinstance(z, LazyColumns) else np.asarray(z, float)})
    return ColumnRows(POINT, message_template(POINT, frame_id), n, cols)


def check_finite(name: str, values: np.ndarray) -> None:
    """Raise ValueError when ``values`` holds a NaN or inf (a bag never carries them)."""
    bad = np.count_nonzero(~np.isfinite(np.asarray(values, dtype=float)))
    if bad:
        raise ValueError(f'{name}: {bad} non-finite value(s); a bag never carries NaN or inf')
