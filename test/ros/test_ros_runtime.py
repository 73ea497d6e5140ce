"""The ROS 2 runtime of the set-up works: in-process pub/sub with a fresh context."""
from geometry_msgs.msg import WrenchStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import JointState

from ros_helpers import spin_until


def test_publisher_and_subscriber_in_one_process(ros_context):
    talker = Node('talker', context=ros_context)
    listener = Node('listener', context=ros_context)
    received: list[JointState] = []
    pub = talker.create_publisher(JointState, '/suspension/deflections', qos_profile_sensor_data)
    listener.create_subscription(JointState, '/suspension/deflections', received.append,
                                 qos_profile_sensor_data)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(talker)
    executor.add_node(listener)
    try:
        assert spin_until(executor, lambda: pub.get_subscription_count() > 0, 10.0)
        msg = JointState(name=['left_suspension', 'right_suspension', 'roll'],
                         position=[0.01, -0.02, 0.003])
        msg.header.stamp.sec = 12
        msg.header.stamp.nanosec = 500
        # Best-effort: publish until one arrives (the first may go before matching settles).
        assert spin_until(executor, lambda: bool(received) or pub.publish(msg), 10.0)
        got = received[0]
        assert list(got.name) == ['left_suspension', 'right_suspension', 'roll']
        assert list(got.position) == [0.01, -0.02, 0.003]
        assert (got.header.stamp.sec, got.header.stamp.nanosec) == (12, 500)
    finally:
        executor.shutdown()
        talker.destroy_node()
        listener.destroy_node()


def test_reliable_wrench_round_trip(ros_context):
    node = Node('wrench_pair', context=ros_context)
    received: list[WrenchStamped] = []
    pub = node.create_publisher(WrenchStamped, '/wheel_load/left', 10)
    node.create_subscription(WrenchStamped, '/wheel_load/left', received.append, 10)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    try:
        assert spin_until(executor, lambda: pub.get_subscription_count() > 0, 10.0)
        for i in range(5):
            msg = WrenchStamped()
            msg.wrench.force.z = 1000.0 * i
            pub.publish(msg)
        assert spin_until(executor, lambda: len(received) == 5, 10.0)
        assert [m.wrench.force.z for m in received] == [0.0, 1000.0, 2000.0, 3000.0, 4000.0]
    finally:
        executor.shutdown()
        node.destroy_node()
