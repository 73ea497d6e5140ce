"""The observer's messages as CDR bytes (ros.wire): the bytes of today's messages, bit for bit,
and inputs read as read_deflections / read_twist read them (the same values, the same
rejections)."""
import math
import struct

import numpy as np
import pytest
from geometry_msgs.msg import PointStamped, TwistStamped, WrenchStamped
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from road_force_estimator import interfaces as api
from road_force_estimator.serde import CdrEncoder, cdr_layout, message_template
from road_force_estimator.ros.messages import (
    MessageRejected, deflections_msg, float64_msg, load_transfer_msg, read_deflections,
    read_twist, reliable_qos, road_point_msg, states_msg, twist_msg, wrench_msg)
from road_force_estimator.ros.wire import OUTPUTS, SimulatorWire, Wire
from ros_helpers import spin_until

EXTREMES = [0.0, -0.0, 5e-324, -5e-324, 2.2250738585072014e-308, 1e-300, -1e300,
            1.7976931348623157e308, -1.7976931348623157e308, 1 / 3]
STAMPS = [0, 1, 999_999_999, 10**9, 10**9 + 1, 1_700_000_000_123_456_789,
          2**31 * 10**9 - 1]


def numbers(rng, k):
    values = rng.normal(size=k) * 10.0 ** rng.integers(-300, 300, size=k)
    values[rng.random(k) < 0.3] = rng.choice(EXTREMES)
    return [float(v) for v in values]


def samples(n=400, seed=3):
    """``(stamp_ns, 19 numbers)`` per sample: odd stamps, extremes and signed zeros."""
    rng = np.random.default_rng(seed)
    for i in range(n):
        stamp = STAMPS[i] if i < len(STAMPS) else int(rng.integers(0, 2**31 * 10**9))
        yield stamp, numbers(rng, 19)


def outputs(wire, stamp, v):
    """Each output twice: ``(msgtype, message today's code builds, bytes the wire writes)``."""
    t, s = stamp, v[18]
    for encoder, frame, load in zip(wire.loads, api.WHEEL_FRAMES, v[0:2]):
        yield api.WRENCH, wrench_msg(t, frame, load), encoder.encode(t, (load,))
    for y, road in zip((s, -s), v[2:4]):
        yield (api.POINT, road_point_msg(t, v[4], y, road),
               wire.road.encode(t, (v[4], y, road)))
    yield api.FLOAT64, float64_msg(v[5]), wire.ltr.encode(None, (v[5],))
    position, velocity = tuple(v[6:12]), tuple(v[12:18])
    yield (api.JOINT_STATE, states_msg(t, position, velocity),
           wire.states.encode(t, position + velocity))


def assert_same_bytes(msgtype, data, rclpy_bytes):
    """``data`` is rclpy's serialization byte for byte, but for the alignment padding, which
    rclpy's buffer leaves uninitialised (rmw sends it zeroed, as ``data`` has it), and for
    the spare bytes at the end of rclpy's buffer (rmw does not send them)."""
    layout = cdr_layout(msgtype, data)
    meant = np.zeros(len(data), dtype=bool)
    meant[:4] = True
    meant[layout.skeleton] = True
    for offset, dtype, count in layout.fields.values():
        meant[offset:offset + dtype.itemsize * (1 if count is None else count)] = True
    ours = np.frombuffer(data, dtype=np.uint8)
    theirs = np.frombuffer(rclpy_bytes[:len(data)], dtype=np.uint8)
    assert len(rclpy_bytes) - len(data) in range(0, 9)
    assert np.array_equal(ours[meant], theirs[meant])
    assert not ours[~meant].any()
    assert layout.end == len(data)


def same_floats(a, b):
    return struct.pack(f'<{len(a)}d', *a) == struct.pack(f'<{len(b)}d', *b)


def test_outputs_are_todays_bytes():
    wire = Wire()
    classes = {api.WRENCH: WrenchStamped, api.POINT: PointStamped, api.FLOAT64: Float64,
               api.JOINT_STATE: JointState}
    for stamp, v in samples():
        for msgtype, msg, data in outputs(wire, stamp, v):
            assert_same_bytes(msgtype, data, serialize_message(msg))
            back = deserialize_message(data, classes[msgtype])
            assert back == msg
    # Negative zero stays negative zero.
    data = wire.ltr.encode(None, (-0.0,))
    assert math.copysign(1.0, deserialize_message(data, Float64).data) == -1.0


def test_the_seven_outputs_at_once_are_todays_bytes():
    """Wire.outputs (one struct for the seven messages of an estimate): each message the
    bytes of the object messages.py builds, in wire.OUTPUTS' order."""
    wire, rng = Wire(), np.random.default_rng(13)
    for stamp, _ in samples(300, seed=13):
        f1, f2, x, s, u1, u2, ltr, lqs, *states = numbers(rng, 20)
        want = [wrench_msg(stamp, api.WHEEL_FRAMES[0], f1),
                wrench_msg(stamp, api.WHEEL_FRAMES[1], f2),
                road_point_msg(stamp, x, s, u1), road_point_msg(stamp, x, -s, u2),
                float64_msg(ltr), load_transfer_msg(stamp, ltr, lqs),
                states_msg(stamp, states[:6], states[6:])]
        got = wire.outputs.encode(stamp, (f1, f2, x, s, u1, x, -s, u2, ltr, ltr, lqs, 0.0,
                                          *states))
        assert len(got) == len(want) == len(OUTPUTS)
        for topic, data, msg in zip(OUTPUTS, got, want):
            assert_same_bytes(api.TOPIC_TYPES[topic], data, serialize_message(msg))


def test_simulator_messages_are_todays_bytes():
    """The plant_simulator's per-sample messages: the bytes of the messages.py objects."""
    wire = SimulatorWire()
    for stamp, v in samples(200, seed=5):
        pairs = [(api.JOINT_STATE, deflections_msg(stamp, v[0:2], v[2]),
                  wire.deflections.encode(stamp, v[0:3])),
                 (api.TWIST_STAMPED, twist_msg(stamp, v[3]), wire.twist.encode(stamp, v[3:4]))]
        pairs += [(api.WRENCH, wrench_msg(stamp, frame, load), encoder.encode(stamp, (load,)))
                  for encoder, frame, load in zip(wire.loads, api.WHEEL_FRAMES, v[4:6])]
        pairs.append((api.POINT, road_point_msg(stamp, v[6], v[7], v[8]),
                      wire.road.encode(stamp, v[6:9])))
        for msgtype, msg, data in pairs:
            assert_same_bytes(msgtype, data, serialize_message(msg))
            assert deserialize_message(data, type(msg)) == msg


def test_rmw_sends_the_same_bytes(ros_context):
    """Today's message objects and the wire's bytes, published through rmw and taken raw:
    the same bytes arrive, in order; and the deflections and twists our publishers send take
    the direct path."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    wire, node = Wire(), Node('wire_test', context=ros_context)
    types = {api.WRENCH: WrenchStamped, api.POINT: PointStamped, api.FLOAT64: Float64,
             api.JOINT_STATE: JointState, api.TWIST_STAMPED: TwistStamped}
    got = {(kind, t): [] for kind in ('objects', 'bytes') for t in list(types)[:4]}
    got.update({('inputs', t): [] for t in (api.JOINT_STATE, api.TWIST_STAMPED)})
    pubs = {}
    for i, (kind, msgtype) in enumerate(got):
        topic = f'/wire_test/topic_{i}'
        pubs[kind, msgtype] = node.create_publisher(types[msgtype], topic, reliable_qos(1000))
        node.create_subscription(types[msgtype], topic, got[kind, msgtype].append,
                                 reliable_qos(1000), raw=True)
    inputs = {api.JOINT_STATE: [], api.TWIST_STAMPED: []}
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    try:
        assert spin_until(executor, lambda: all(p.get_subscription_count()
                                                for p in pubs.values()), 10.0)
        sent = 0
        for stamp, v in samples(20, seed=8):
            for msgtype, msg, data in outputs(wire, stamp, v):
                pubs['objects', msgtype].publish(msg)
                pubs['bytes', msgtype].publish(data)
                sent += 1
            for msgtype, msg in ((api.JOINT_STATE, deflections_msg(stamp, v[0:2], v[2])),
                                 (api.TWIST_STAMPED, twist_msg(stamp, v[3]))):
                pubs['inputs', msgtype].publish(msg)
                inputs[msgtype].append(msg)
        assert spin_until(executor, lambda: sum(map(len, got.values())) == 2 * sent + 40,
                          10.0)
    finally:
        executor.shutdown()
        node.destroy_node()
    for msgtype in (api.WRENCH, api.POINT, api.FLOAT64, api.JOINT_STATE):
        assert got['objects', msgtype] == got['bytes', msgtype]
    for data, msg in zip(got['inputs', api.JOINT_STATE], inputs[api.JOINT_STATE]):
        assert wire.deflections.read(data) is not None
        assert wire.read_deflections(data) == read_deflections(msg)
    for data, msg in zip(got['inputs', api.TWIST_STAMPED], inputs[api.TWIST_STAMPED]):
        assert wire.twist.read(data) is not None and wire.read_twist(data) == read_twist(msg)


def rclpy_result(read, msg):
    try:
        return read(msg)
    except MessageRejected as exc:
        return exc.reason, str(exc)


def wire_result(read, data):
    try:
        return read(data)
    except MessageRejected as exc:
        return exc.reason, str(exc)


def joint_state(stamp, names, position, velocity=(), effort=(), frame='base_link'):
    msg = JointState(name=list(names), position=[float(p) for p in position],
                     velocity=[float(p) for p in velocity], effort=[float(p) for p in effort])
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, 10**9)
    msg.header.frame_id = frame
    return msg


def test_deflections_read_as_read_deflections_reads_them():
    wire, rng = Wire(), np.random.default_rng(4)
    direct = CdrEncoder(api.JOINT_STATE, message_template(
        api.JOINT_STATE, api.BASE_FRAME, api.DEFLECTION_JOINTS), ['position'])
    left, right, roll = api.DEFLECTION_JOINTS
    nan, inf = math.nan, math.inf
    cases = [((left, right, roll), (1e308, 1e308, -0.0), (), ()),  # sum overflows: finite
             ((roll, left, right), (1.0, 2.0, 3.0), (), ()),
             ((left, 'steer', right, roll), (1.0, 9.0, 2.0, 3.0), (), ()),
             ((left, right, roll), (1.0, 2.0, 3.0), (4.0, 5.0, 6.0), ()),
             ((left, right, roll), (1.0, 2.0), (), ()),
             ((left, right, roll), (1.0, 2.0, 3.0), (4.0,), ()),
             ((left, right, roll), (1.0, 2.0, 3.0), (), (1.0, 2.0)),
             ((left, right), (1.0, 2.0), (), ()),
             ((left, left, right, roll), (1.0, 1.0, 2.0, 3.0), (), ()),
             ((left, right, roll), (nan, 2.0, 3.0), (), ()),
             ((left, right, roll), (1.0, -inf, 3.0), (), ()),
             ((roll, left, right), (inf, 2.0, 3.0), (), ()),
             ((), (), (), ())]
    for stamp, v in samples(300, seed=6):
        q, phi = v[0:2], v[2]
        msg = deflections_msg(stamp, q, phi)
        data = direct.encode(stamp, (*q, phi))
        assert_same_bytes(api.JOINT_STATE, data, serialize_message(msg))
        assert wire.deflections.read(data) is not None
        want = rclpy_result(read_deflections, msg)
        for got in (wire_result(wire.read_deflections, data),
                    wire_result(wire.read_deflections, serialize_message(msg))):
            assert got[0] == want[0] and same_floats((*got[1], got[2]), (*want[1], want[2]))
        names, position, velocity, effort = cases[int(rng.integers(len(cases)))]
        other = joint_state(stamp, names, position, velocity, effort,
                            frame=str(rng.choice(['base_link', 'imu', ''])))
        want = rclpy_result(read_deflections, other)
        got = wire_result(wire.read_deflections, serialize_message(other))
        assert type(got) is type(want) and got[0] == want[0]
        assert got[1:] == want[1:] if isinstance(want[1], str) else same_floats(
            (*got[1], got[2]), (*want[1], want[2]))
    with pytest.raises(MessageRejected) as err:
        wire.read_deflections(b'\x00\x01\x00\x00\x05')
    assert err.value.reason == 'undecodable'


def test_twist_read_as_read_twist_reads_it():
    wire = Wire()
    for stamp, v in samples(200, seed=9):
        for speed, frame in ((v[0], 'base_link'), (v[1], 'odom'), (math.nan, 'base_link'),
                             (-math.inf, 'base_link')):
            msg = twist_msg(stamp, speed)
            msg.header.frame_id = frame
            want = rclpy_result(read_twist, msg)
            got = wire_result(wire.read_twist, serialize_message(msg))
            assert got[0] == want[0] and (got[1] == want[1] if isinstance(want[1], str)
                                          else same_floats(got[1:], want[1:]))
    with pytest.raises(MessageRejected) as err:
        wire.read_twist(b'')
    assert err.value.reason == 'undecodable'
