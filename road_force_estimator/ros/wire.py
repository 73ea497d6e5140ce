"""The observer's messages as CDR bytes: its inputs read and its outputs written without rclpy
building a message object (:mod:`road_force_estimator.serde.live`), the same bytes as before.

rclpy takes a message as serialized bytes (``Publisher.publish(bytes)``) and gives it so
(``create_subscription(..., raw=True)``). An input in the layout our publishers and bag_player
send (names in the contract's order, frame ``base_link``, no velocity or effort) is read
straight from its bytes; any other goes through rclpy's deserialisation and
:func:`.messages.read_deflections` / :func:`.messages.read_twist` (mapped by name, rejected as
they reject). The outputs are the bytes rmw sends for the messages :mod:`.messages` builds
(:func:`.messages.wrench_msg`, ...): test_wire compares them.
"""
from __future__ import annotations

import math

from geometry_msgs.msg import TwistStamped
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState

from road_force_estimator import interfaces as api
from road_force_estimator.serde import CdrEncoder, CdrEncoderGroup, CdrReader, message_template
from road_force_estimator.ros.messages import (
    MessageRejected, front_axle_joints, read_deflections, read_twist)

__all__ = ['Wire', 'OUTPUTS', 'SimulatorWire', 'deserialize']

#: The topics of :attr:`Wire.outputs`' messages, in its order (one of each per estimate).
OUTPUTS = (*api.LOAD, *api.ROAD, api.LTR, api.LOAD_TRANSFER, api.STATES)


class Wire:
    """Readers of the observer's two inputs and encoders of its seven outputs.

    Attributes
    ----------
    deflections, twist : CdrReader
        The usual layouts of ``/suspension/deflections`` and ``/vehicle/twist``.
    loads : list of CdrEncoder
        ``/wheel_load/left|right`` (WrenchStamped): ``wrench.force.z`` F_n (N); the same
        layout (frames ``front_left_wheel`` / ``front_right_wheel``) carries
        ``/wheel_load/static/left|right``, F_c,i (N).
    road : CdrEncoder
        ``/road_profile/left|right`` (PointStamped): ``point.x, y, z`` (m).
    ltr : CdrEncoder
        ``/load_transfer_ratio`` (Float64, no header).
    load_transfer : CdrEncoder
        ``/load_transfer`` (Vector3Stamped): x = LTR, y = quasi-static LTR, z = 0.
    states : CdrEncoder
        ``/observer/states`` (JointState of :data:`.interfaces.STATE_JOINTS`): positions,
        then velocities.
    outputs : CdrEncoderGroup
        The seven messages of one estimate at once, in :data:`OUTPUTS`' order (the bytes of
        the encoders above): 24 numbers, F_1, F_2; x, +T/2, z_1; x, -T/2, z_2; LTR; LTR,
        quasi-static LTR, 0; six positions, six velocities.
    """

    def __init__(self) -> None:
        self.deflections = CdrReader(api.JOINT_STATE, message_template(
            api.JOINT_STATE, api.BASE_FRAME, api.DEFLECTION_JOINTS), ['position'])
        self.twist = CdrReader(api.TWIST_STAMPED, message_template(
            api.TWIST_STAMPED, api.BASE_FRAME), ['twist.linear.x'])
        self.loads, self.road = _load_and_road_encoders()
        self.ltr = CdrEncoder(api.FLOAT64, message_template(api.FLOAT64), ['data'])
        self.load_transfer = CdrEncoder(api.VECTOR3_STAMPED, message_template(
            api.VECTOR3_STAMPED, api.BASE_FRAME), ['vector.x', 'vector.y', 'vector.z'])
        self.states = CdrEncoder(api.JOINT_STATE, message_template(
            api.JOINT_STATE, api.BASE_FRAME, api.STATE_JOINTS, velocity=True),
            ['position', 'velocity'])
        self.outputs = CdrEncoderGroup([*self.loads, self.road, self.road, self.ltr,
                                        self.load_transfer, self.states])
        #: called once with a line when an articulated truck's deflections are read as its
        #: front axle's (the observer logs it); None: say nothing
        self.on_note = None

    def read_deflections(self, data: bytes) -> tuple[int, tuple[float, float], float]:
        """:func:`.read_deflections` of the JointState in ``data``: read straight from the
        bytes when their layout is the usual one and the numbers are finite."""
        fast = self.deflections.read(data)
        if fast is not None and math.isfinite(sum(fast[1])):
            stamp_ns, (q1, q2, phi) = fast
            return stamp_ns, (q1, q2), phi
        msg = deserialize(data, JointState)
        if self.on_note is not None and api.TRACTOR_ROLL_JOINT in msg.name:
            joints = front_axle_joints(list(msg.name))
            if joints != api.DEFLECTION_JOINTS:
                self.on_note(f"an articulated truck's deflections: the front axle estimated "
                             f'from {", ".join(joints)} (the first axle of the message) with '
                             'the front-axle model of the parameters')
                self.on_note = None             # said once
        return read_deflections(msg)

    def read_twist(self, data: bytes) -> tuple[int, float]:
        """:func:`.read_twist` of the TwistStamped in ``data`` (straight from the bytes, as
        :meth:`read_deflections`)."""
        fast = self.twist.read(data)
        if fast is not None and math.isfinite(fast[1][0]):
            return fast[0], fast[1][0]
        return read_twist(deserialize(data, TwistStamped))


class SimulatorWire:
    """Encoders of the plant_simulator's messages of every sample (the bytes rmw sends for
    :func:`.messages.deflections_msg`, :func:`.messages.twist_msg`, :func:`.messages.wrench_msg`
    and :func:`.messages.road_point_msg`: test_wire).

    Attributes
    ----------
    deflections : CdrEncoder
        ``/suspension/deflections``: ``position`` = q_1, q_2 (m), phi (rad).
    twist : CdrEncoder
        ``/vehicle/twist``: ``twist.linear.x`` (m/s).
    loads : list of CdrEncoder
        ``/ground_truth/wheel_load/left|right``: ``wrench.force.z`` (N).
    road : CdrEncoder
        ``/ground_truth/road_profile/left|right``: ``point.x, y, z`` (m).
    """

    def __init__(self) -> None:
        self.deflections = CdrEncoder(api.JOINT_STATE, message_template(
            api.JOINT_STATE, api.BASE_FRAME, api.DEFLECTION_JOINTS), ['position'])
        self.twist = CdrEncoder(api.TWIST_STAMPED, message_template(
            api.TWIST_STAMPED, api.BASE_FRAME), ['twist.linear.x'])
        self.loads, self.road = _load_and_road_encoders()


def _load_and_road_encoders() -> tuple[list, CdrEncoder]:
    """The per-wheel WrenchStamped encoders (``wrench.force.z``, N) and the PointStamped
    one (``point.x, y, z``, m): the observer's and the simulator's alike."""
    loads = [CdrEncoder(api.WRENCH, message_template(api.WRENCH, frame), ['wrench.force.z'])
             for frame in api.WHEEL_FRAMES]
    return loads, CdrEncoder(api.POINT, message_template(api.POINT, api.ROAD_FRAME),
                             ['point.x', 'point.y', 'point.z'])


def deserialize(data: bytes, msg_type):
    """The message of ``msg_type`` rclpy reads from ``data``; :class:`.MessageRejected`
    ('undecodable') when it cannot."""
    try:
        return deserialize_message(data, msg_type)
    except Exception as err:  # noqa: BLE001 - any failure means: not a message of this type
        raise MessageRejected('undecodable', f'not a {msg_type.__name__} '
                                             f'({len(data)} bytes)') from err
