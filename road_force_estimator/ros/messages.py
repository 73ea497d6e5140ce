"""Messages of the nodes (INTERFACES.md "Topics"): QoS profiles and conversions.

The nodes convert at this edge and nowhere else: ROS stamps to integer nanoseconds
(``stamp_ns``), messages to plain floats and arrays for the core, core results to standard
messages (std_msgs, sensor_msgs, geometry_msgs, diagnostic_msgs). A received JointState is
mapped by joint NAME (:data:`road_force_estimator.interfaces.DEFLECTION_JOINTS`), never by
position; one that cannot be read is refused with a
:class:`MessageRejected` whose ``reason`` is a short key for the diagnostics counters.
"""
from __future__ import annotations

import math
from typing import Sequence

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from geometry_msgs.msg import PointStamped, TwistStamped, Vector3Stamped, WrenchStamped
from rclpy.qos import (
    DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy)
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from road_force_estimator.estimation.diagnostics import Status
from road_force_estimator.interfaces import (
    BASE_FRAME, DEFLECTION_JOINTS, ROAD_FRAME, SENSOR_DATA, STATE_JOINTS, qos_kind)

__all__ = [
    'sensor_qos', 'reliable_qos', 'topic_qos',
    'MessageRejected', 'stamp_to_ns', 'ns_to_stamp', 'deflections_msg', 'read_deflections',
    'twist_msg', 'read_twist', 'wrench_msg', 'road_point_msg', 'float64_msg', 'states_msg',
    'diagnostic_status',
]

def sensor_qos(depth: int = 5) -> QoSProfile:
    """Sensor-data QoS (best effort, keep last ``depth``, volatile)."""
    return QoSProfile(reliability=ReliabilityPolicy.BEST_EFFORT, history=HistoryPolicy.KEEP_LAST,
                      durability=DurabilityPolicy.VOLATILE, depth=depth)


def reliable_qos(depth: int = 100) -> QoSProfile:
    """Reliable, keep last ``depth``, volatile: ground truth, estimates, diagnostics."""
    return QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST,
                      durability=DurabilityPolicy.VOLATILE, depth=depth)


def topic_qos(topic: str, depth: int = 100) -> QoSProfile:
    """The QoS a topic of INTERFACES.md is published with (``depth`` deep): its kind in
    :data:`road_force_estimator.interfaces.TOPIC_QOS`."""
    return sensor_qos(depth) if qos_kind(topic) == SENSOR_DATA else reliable_qos(depth)


#: The longest text a rejection, a log line's detail or a diagnostic value carries (chars):
#: a message's content is quoted up to it (a JointState with 1e5 names made 1 MB lines).
MAX_TEXT = 240


def bounded(text: str, limit: int = MAX_TEXT) -> str:
    """``text`` cut to ``limit`` characters, the cut said with the length it had."""
    text = str(text)
    if len(text) <= limit:
        return text
    return f'{text[:limit - 32]}... ({len(text)} characters)'


def _names_text(names: list) -> str:
    """A list of names for a message: the first few, and how many in all."""
    shown = ', '.join(repr(n)[:40] for n in names[:5])
    return f'[{shown}{", ..." if len(names) > 5 else ""}] ({len(names)} names)'


class MessageRejected(ValueError):
    """A received message that cannot be used; ``reason`` is a short counter key; the
    message is at most :data:`MAX_TEXT` characters."""

    def __init__(self, reason: str, message: str):
        super().__init__(bounded(message))
        self.reason = reason


def stamp_to_ns(stamp: Time) -> int:
    """``builtin_interfaces/Time`` to integer nanoseconds."""
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def ns_to_stamp(stamp_ns: int) -> Time:
    """Integer nanoseconds to ``builtin_interfaces/Time`` (exact, no float on the way)."""
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return Time(sec=sec, nanosec=nanosec)


def deflections_msg(stamp_ns: int, q_m: Sequence[float], roll_rad: float) -> JointState:
    """``/suspension/deflections``: positions [q_1 (m), q_2 (m), phi (rad)] by name."""
    msg = JointState(name=list(DEFLECTION_JOINTS),
                     position=[float(q_m[0]), float(q_m[1]), float(roll_rad)])
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id = BASE_FRAME
    return msg


def front_axle_joints(names) -> tuple[str, str, str]:
    """The joints read as (q_1, q_2, phi): the contract's, or an articulated drive's front
    axle and ``tractor_roll`` (:func:`.bagio.vehicle_layout.front_axle_joints`: the first axle
    of the message)."""
    if set(DEFLECTION_JOINTS) <= set(names):
        return DEFLECTION_JOINTS
    from road_force_estimator.bagio.vehicle_layout import front_axle_joints as layout
    return layout({}, names)[0]


def read_deflections(msg: JointState) -> tuple[int, tuple[float, float], float]:
    """``(stamp_ns, (q_1, q_2) (m), phi (rad))`` from a JointState, mapped by joint name.

    Raises
    ------
    MessageRejected
        ``reason`` 'length' (position differs in length from name, or a velocity/effort array
        that is neither empty nor as long), 'names' (a required joint missing, or a name
        repeated), 'nonfinite' (NaN or infinite value). An articulated truck's message
        (``<axle>_left_suspension``, ..., ``tractor_roll``) is read as its front axle's
        (:func:`front_axle_joints`).
    """
    names = list(msg.name)
    n = len(names)
    if len(msg.position) != n or any(len(a) not in (0, n) for a in (msg.velocity, msg.effort)):
        raise MessageRejected('length', f'JointState arrays differ in length from name ({n}): '
                                        f'position {len(msg.position)}, velocity '
                                        f'{len(msg.velocity)}, effort {len(msg.effort)}')
    joints = front_axle_joints(names)
    if len(set(names)) != n or not set(joints) <= set(names):
        raise MessageRejected('names', f'JointState names {_names_text(names)} must include '
                                       f'each of {list(DEFLECTION_JOINTS)} once')
    by_name = dict(zip(names, msg.position))
    q1, q2, phi = (float(by_name[j]) for j in joints)
    if not (math.isfinite(q1) and math.isfinite(q2) and math.isfinite(phi)):
        raise MessageRejected('nonfinite', f'JointState holds a non-finite value: '
                                           f'q = ({q1}, {q2}), phi = {phi}')
    return stamp_to_ns(msg.header.stamp), (q1, q2), phi


def twist_msg(stamp_ns: int, speed_mps: float) -> TwistStamped:
    """``/vehicle/twist``: ``twist.linear.x`` = speed v (m/s), frame ``base_link``."""
    msg = TwistStamped()
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id = BASE_FRAME
    msg.twist.linear.x = float(speed_mps)
    return msg


def read_twist(msg: TwistStamped) -> tuple[int, float]:
    """``(stamp_ns, speed (m/s))``; :class:`MessageRejected` ('nonfinite') for NaN or inf."""
    speed = float(msg.twist.linear.x)
    if not math.isfinite(speed):
        raise MessageRejected('nonfinite', f'TwistStamped linear.x = {speed}')
    return stamp_to_ns(msg.header.stamp), speed


def wrench_msg(stamp_ns: int, frame: str, force_z_n: float) -> WrenchStamped:
    """Vertical wheel load F_n (N, up) in ``wrench.force.z``."""
    msg = WrenchStamped()
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id = frame
    msg.wrench.force.z = float(force_z_n)
    return msg


def road_point_msg(stamp_ns: int, distance_m: float, lateral_m: float,
                   elevation_m: float) -> PointStamped:
    """Road point under a tire: x = distance (m), y = +T/2 (left) / -T/2 (right), z (m)."""
    msg = PointStamped()
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id = ROAD_FRAME
    msg.point.x, msg.point.y, msg.point.z = float(distance_m), float(lateral_m), float(
        elevation_m)
    return msg


def load_transfer_msg(stamp_ns: int, ltr: float, ltr_quasi_static: float) -> Vector3Stamped:
    """``/load_transfer``: x = LTR, y = quasi-static LTR (MODEL.md step 8), z = 0, frame
    ``base_link``."""
    msg = Vector3Stamped()
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id = BASE_FRAME
    msg.vector.x = float(ltr)
    msg.vector.y = float(ltr_quasi_static)
    return msg


def float64_msg(value: float) -> Float64:
    """A ``std_msgs/Float64`` (no header: it is published with its inputs' order)."""
    return Float64(data=float(value))


def states_msg(stamp_ns: int, position: Sequence[float], velocity: Sequence[float]) -> JointState:
    """``/observer/states``: :data:`STATE_JOINTS` with estimated positions and velocities."""
    msg = JointState(name=list(STATE_JOINTS), position=[float(v) for v in position],
                     velocity=[float(v) for v in velocity])
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id = BASE_FRAME
    return msg


def diagnostic_status(st: Status) -> DiagnosticStatus:
    """A ``diagnostic_msgs/DiagnosticStatus`` from the estimator's plain :class:`Status`,
    every text at most :data:`MAX_TEXT` characters."""
    return DiagnosticStatus(level=bytes([st.level]), name=bounded(st.name),
                            message=bounded(st.message), hardware_id=bounded(st.hardware_id),
                            values=[KeyValue(key=bounded(k), value=bounded(v))
                                    for k, v in st.values])
