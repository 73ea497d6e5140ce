"""observer node: the bytes it publishes are those of today's messages of the core's estimates.

The reference is independent of the node's encoders: the same inputs through a fresh
:class:`.Estimator` (the per-sample path), each estimate made into the message objects of
:mod:`.messages` (``wrench_msg``, ``road_point_msg``, ...) and serialized by rclpy; the node's
outputs are taken raw (the bytes rmw delivered) and compared byte for byte (alignment padding
apart, which rclpy's serializer leaves uninitialised and rmw sends zeroed: test_wire).
"""
import math

import numpy as np
import pytest
from geometry_msgs.msg import TwistStamped
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState

from node_harness import close, make_executor
from road_force_estimator import interfaces as api
from road_force_estimator.serde.live import CdrEncoder
from road_force_estimator.serde.messages import message_template
from road_force_estimator.estimation import Estimator
from road_force_estimator.ros.bag_recorder import message_class
from road_force_estimator.ros.messages import (
    deflections_msg, float64_msg, load_transfer_msg, reliable_qos, road_point_msg,
    sensor_qos, states_msg, twist_msg, wrench_msg)
from road_force_estimator.ros.observer import Observer
from ros_helpers import spin_until
from test_wire import assert_same_bytes

T0_NS = 1_700_000_000_050_000_000
OUTPUTS = [*api.LOAD, *api.ROAD, api.LTR, api.LOAD_TRANSFER, api.STATES, *api.STATIC_LOAD]
N = 700


class RawCollector(Node):
    """Every output topic taken raw (the bytes rmw delivers), in arrival order."""

    def __init__(self, context):
        super().__init__('raw_collector', context=context)
        self.data: dict[str, list[bytes]] = {}
        for topic in OUTPUTS:
            self.data[topic] = []
            self.create_subscription(message_class(api.TOPIC_TYPES[topic]), topic,
                                     self.data[topic].append, reliable_qos(10000), raw=True)


BLOCK = 50  # samples per speed: the speed steps between blocks (the node synced at each)


def inputs(n: int):
    """``(stamp_ns, (q1, q2), phi, speed)``: a rough road, a speed that steps, a gap."""
    rng = np.random.default_rng(11)
    k = np.arange(n)
    q = np.column_stack([2e-3 * np.sin(0.031 * k), -1.5e-3 * np.cos(0.017 * k)])
    q += 3e-4 * rng.standard_normal(q.shape)
    phi = 1e-3 * np.sin(0.009 * k) + 1e-5 * rng.standard_normal(n)
    speed = 18.0 + 0.2 * (k // BLOCK)
    stamps = T0_NS + k * 1_000_000 + np.where(k >= n // 2, 7_000_000, 0)  # 6 samples lost
    for i in range(n):
        yield int(stamps[i]), (float(q[i, 0]), float(q[i, 1])), float(phi[i]), float(speed[i])


def reference(estimator: Estimator, half_track_m: float, samples) -> dict[str, list[bytes]]:
    """The message objects of today's code for the estimates of ``samples``, serialized."""
    out = {topic: [] for topic in OUTPUTS}
    static_stamp = None

    def emit(est):
        nonlocal static_stamp
        t = est.stamp_ns
        msgs = [(api.LOAD[i], wrench_msg(t, api.WHEEL_FRAMES[i], est.wheel_load_n[i]))
                for i in range(2)]
        msgs += [(api.ROAD[i], road_point_msg(t, est.distance_m, y, est.road_m[i]))
                 for i, y in enumerate((half_track_m, -half_track_m))]
        msgs += [(api.LTR, float64_msg(est.ltr)),
                 (api.LOAD_TRANSFER, load_transfer_msg(t, est.ltr, est.ltr_quasi_static)),
                 (api.STATES, states_msg(t, (*est.q_m, est.roll_rad, est.body_heave_m,
                                             *est.wheel_heave_m),
                                         (*est.dq, est.droll, est.body_heave_rate,
                                          *est.wheel_heave_rate)))]
        if api.static_load_due(t, static_stamp) and all(map(math.isfinite,
                                                                est.static_load_n)):
            static_stamp = t
            msgs += [(api.STATIC_LOAD[i], wrench_msg(t, api.WHEEL_FRAMES[i],
                                                     est.static_load_n[i]))
                     for i in range(2)]
        for topic, msg in msgs:
            out[topic].append(serialize_message(msg))

    for stamp, q, phi, speed in samples:
        est = estimator.update(stamp, q, phi, speed)
        if est is not None:
            emit(est)
    for est in estimator.flush():
        emit(est)
    return out


@pytest.mark.parametrize('params', [{}, {'observer.latency': 0.004,
                                         'vehicle.deflection_reference': 'zero_load'}])
def test_the_observer_publishes_the_bytes_of_todays_messages(ros_context, params):
    observer = Observer(context=ros_context, parameter_overrides=[
        Parameter(k, value=v) for k, v in params.items()])
    expected = reference(Estimator(*observer.params.config), observer.half_track_m,
                         inputs(N))
    feeder = Node('bytes_feeder', context=ros_context)
    deflections = feeder.create_publisher(JointState, api.DEFLECTIONS, sensor_qos(1000))
    twist = feeder.create_publisher(TwistStamped, api.TWIST, reliable_qos())
    collector = RawCollector(ros_context)
    executor = make_executor(ros_context, observer, feeder, collector)
    try:
        assert spin_until(executor, lambda: deflections.get_subscription_count() > 0
                          and twist.get_subscription_count() > 0 and all(
                              p.get_subscription_count() > 0 for p in (
                                  *observer.load_pubs, *observer.road_pubs,
                                  *observer.static_pubs, observer.ltr_pub,
                                  observer.load_transfer_pub, observer.states_pub)), 10.0)
        for i, (stamp, q, phi, speed) in enumerate(inputs(N)):
            twist.publish(twist_msg(stamp, speed))
            if i % BLOCK == 0:  # a new speed: taken before the block's first sample
                assert spin_until(executor, lambda: observer.input.twists and
                                  observer.input.twists[-1][1] == speed, 10.0)
            deflections.publish(deflections_msg(stamp, q, phi))
            if i % BLOCK == BLOCK - 1:  # the block received (a short best-effort queue)
                assert spin_until(executor, lambda: observer.input.received == i + 1, 10.0)
        observer.finish()   # what the latency holds back, as at shutdown
        assert spin_until(executor, lambda: all(
            len(collector.data[t]) == len(expected[t]) for t in OUTPUTS), 10.0)
        executor.spin_once(timeout_sec=0.05)  # nothing more may come
    finally:
        close(executor, observer, feeder, collector)
    assert len(expected[api.STATES]) == N
    assert len(expected[api.STATIC_LOAD[0]]) >= 7
    for topic in OUTPUTS:
        msgtype = api.TOPIC_TYPES[topic]
        assert len(collector.data[topic]) == len(expected[topic]), topic
        for got, want in zip(collector.data[topic], expected[topic]):
            assert_same_bytes(msgtype, got, want)


def test_the_comparison_sees_one_changed_bit():
    """assert_same_bytes, as used above, refuses a message one bit away from the reference."""
    encoder = CdrEncoder(api.JOINT_STATE, message_template(
        api.JOINT_STATE, api.BASE_FRAME, api.STATE_JOINTS, velocity=True),
        ['position', 'velocity'])
    values = tuple(float(v) for v in np.linspace(-1.0, 1.0, 12))
    data = encoder.encode(T0_NS, values)
    want = serialize_message(states_msg(T0_NS, values[:6], values[6:]))
    assert_same_bytes(api.JOINT_STATE, data, want)
    changed = bytearray(data)
    changed[-5] ^= 1  # the last velocity's sign byte (the effort length follows)
    with pytest.raises(AssertionError):
        assert_same_bytes(api.JOINT_STATE, bytes(changed), want)
