"""The take loop's thread (ros/take_loop.py): it waits on its subscriptions, it does not poll."""
import time

from sensor_msgs.msg import JointState

from road_force_estimator.ros.messages import sensor_qos
from road_force_estimator.ros.take_loop import TakeLoop


def waits_after(loop: TakeLoop, count: int, timeout_s: float = 30.0) -> tuple[int, float]:
    """Let the started loop wait ``count`` times: (its waits, the seconds that took)."""
    start = time.monotonic()
    while loop.waits < count and time.monotonic() < start + timeout_s:
        time.sleep(0.005)
    return loop.waits, time.monotonic() - start


def test_an_idle_loop_without_an_idle_callback_waits_its_period(ros_context):
    """Issue 32: with no ``idle`` (the observer's inputs) the wait's timeout fell to 0 s once the
    first period had passed, and the thread polled the wait set: about 30 % of a core at 1 kHz
    of input (bench.probes.node_latency). Each wait lasts its period unless a message comes,
    so an idle loop waits at most once per period (a loaded machine: fewer)."""
    period_s = 0.05
    loop = TakeLoop('take_loop_test', ros_context)
    try:
        loop.add(JointState, '/take_loop_test', sensor_qos(10))
        loop.start(lambda batch: None, period_s=period_s)
        waits, elapsed_s = waits_after(loop, 6)
        assert waits >= 6
        assert waits <= elapsed_s / period_s + 2, (waits, elapsed_s)
    finally:
        loop.destroy()


def test_an_idle_callback_comes_every_period(ros_context):
    """With ``idle``: called about once per period while nothing arrives."""
    calls = []
    period_s = 0.05
    loop = TakeLoop('take_loop_test', ros_context)
    try:
        loop.add(JointState, '/take_loop_test', sensor_qos(10))
        loop.start(lambda batch: None, idle=lambda: calls.append(time.monotonic()),
                   period_s=period_s)
        waits, elapsed_s = waits_after(loop, 6)
        assert waits <= elapsed_s / period_s + 2, (waits, elapsed_s)
        assert len(calls) >= 3
    finally:
        loop.destroy()
