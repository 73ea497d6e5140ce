"""bag_recorder node: every message received is in the bag, readable by rosbags and mcap.

Nodes spin in the test process (fresh rclpy context per test); main() runs in a subprocess.
"""
import signal

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import WrenchStamped
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import pytest
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, String
import yaml

from node_harness import close, finish, make_executor, run_main
from road_force_estimator.bagio import iter_messages
from road_force_estimator.ros.bag_recorder import BagRecorder
from road_force_estimator.ros.messages import (
    deflections_msg, reliable_qos, sensor_qos, stamp_to_ns, wrench_msg)
from road_force_estimator.ros.ros_parameters import ParameterError
from ros_helpers import spin_until

N = 300


class Talker(Node):
    """Publishes N numbered messages on topics of INTERFACES.md and on one outside it."""

    def __init__(self, context):
        super().__init__('talker', context=context)
        self.pubs = {
            '/suspension/deflections': self.create_publisher(
                JointState, '/suspension/deflections', sensor_qos(N)),
            '/wheel_load/left': self.create_publisher(WrenchStamped, '/wheel_load/left',
                                                      reliable_qos(N)),
            '/load_transfer_ratio': self.create_publisher(Float64, '/load_transfer_ratio',
                                                          reliable_qos(N)),
            '/diagnostics': self.create_publisher(DiagnosticArray, '/diagnostics',
                                                  reliable_qos(N)),
            '/custom/text': self.create_publisher(String, '/custom/text', QoSProfile(
                depth=N, reliability=ReliabilityPolicy.BEST_EFFORT)),
        }

    def matched(self) -> bool:
        return all(p.get_subscription_count() > 0 for p in self.pubs.values())

    def publish(self, k: int) -> None:
        stamp = 1_000_000_000 + k * 1_000_000
        self.pubs['/suspension/deflections'].publish(deflections_msg(stamp, (k * 1e-6, 0.0),
                                                                     -k * 1e-6))
        self.pubs['/wheel_load/left'].publish(wrench_msg(stamp, 'front_left_wheel', 1000.0 + k))
        self.pubs['/load_transfer_ratio'].publish(Float64(data=k / N))
        self.pubs['/diagnostics'].publish(DiagnosticArray(status=[DiagnosticStatus(
            name='talker', message=str(k))]))
        self.pubs['/custom/text'].publish(String(data=f'text {k}'))


def check_bag(path, topics):
    """The bag holds the N messages of each topic, in order, for both readers."""
    issues = []
    got = {t: [] for t in topics}
    for topic, _, msg in iter_messages(path, issues=issues):
        got[topic].append(msg)
    assert issues == []
    assert {t: len(v) for t, v in got.items()} == dict.fromkeys(topics, N)
    assert [stamp_to_ns(m.header.stamp) for m in got['/suspension/deflections']] == [
        1_000_000_000 + k * 1_000_000 for k in range(N)]
    assert [m.wrench.force.z for m in got['/wheel_load/left']] == [1000.0 + k for k in range(N)]
    assert [m.data for m in got['/custom/text']] == [f'text {k}' for k in range(N)]
    with_mcap = {t: [] for t in topics}
    (mcap_file,) = path.glob('*.mcap')
    with mcap_file.open('rb') as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, channel, _, msg in reader.iter_decoded_messages():
            with_mcap[channel.topic].append(msg)
    assert {t: len(v) for t, v in with_mcap.items()} == dict.fromkeys(topics, N)
    assert [m.data for m in with_mcap['/load_transfer_ratio']] == [k / N for k in range(N)]
    assert [s.status[0].message for s in with_mcap['/diagnostics']] == [
        str(k) for k in range(N)]
    meta = yaml.safe_load((path / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert meta['storage_identifier'] == 'mcap' and meta['message_count'] == N * len(topics)
    offered = {t['topic_metadata']['name']: t['topic_metadata']['offered_qos_profiles']
               for t in meta['topics_with_message_count']}
    return offered


def test_every_message_published_during_its_life_is_in_the_bag(ros_context, tmp_path):
    out = tmp_path / 'bag'
    topics = ['/suspension/deflections', '/wheel_load/left', '/load_transfer_ratio',
              '/diagnostics', '/custom/text']
    recorder = BagRecorder(context=ros_context, parameter_overrides=[
        Parameter('topics', value=topics), Parameter('output', value=str(out))])
    talker = Talker(ros_context)
    executor = make_executor(ros_context, recorder, talker)
    try:
        # /custom/text is outside INTERFACES.md: subscribed once its publisher is seen.
        assert spin_until(executor, talker.matched, 10.0)
        for k in range(N):
            talker.publish(k)
            if k % 50 == 0:
                executor.spin_once(timeout_sec=0.0)
        assert spin_until(executor, lambda: all(c == N for c in recorder.counts.values()),
                          20.0), recorder.counts
    finally:
        recorder.close()
        close(executor, recorder, talker)
    offered = check_bag(out, topics)
    # QoS that matches the publishers: best effort for the sensor stream and for /custom/text
    # (adapted to its publisher), reliable for the others.
    assert {t: q[0]['reliability'] for t, q in offered.items()} == {
        '/suspension/deflections': 'best_effort', '/wheel_load/left': 'reliable',
        '/load_transfer_ratio': 'reliable', '/diagnostics': 'reliable',
        '/custom/text': 'best_effort'}


def test_bad_topic_names_are_refused(ros_context, tmp_path):
    with pytest.raises(ParameterError, match=r"refused topics = \['/ok', 'bad name!'\]"):
        BagRecorder(context=ros_context, parameter_overrides=[
            Parameter('topics', value=['/ok', 'bad name!']),
            Parameter('output', value=str(tmp_path / 'bag'))])
    assert not (tmp_path / 'bag').exists()


def test_an_existing_output_is_never_overwritten(ros_context, tmp_path):
    (tmp_path / 'bag').mkdir()
    (tmp_path / 'bag' / 'keep.txt').write_text('mine')
    with pytest.raises(ParameterError, match=r"output = '.*bag': it exists"):
        BagRecorder(context=ros_context,
                    parameter_overrides=[Parameter('output', value=str(tmp_path / 'bag'))])
    assert (tmp_path / 'bag' / 'keep.txt').read_text() == 'mine'


@pytest.mark.parametrize('stop', [signal.SIGINT, signal.SIGTERM])
def test_main_closes_the_bag_with_all_it_received_on_a_signal(ros_context, tmp_path, stop):
    out = tmp_path / 'bag'
    process = run_main('bag_recorder', '--ros-args', '-p', f'output:={out}', '-p',
                       'topics:=[/wheel_load/left, /load_transfer_ratio]')
    talker = Talker(ros_context)
    executor = make_executor(ros_context, talker)
    try:
        pubs = [talker.pubs['/wheel_load/left'], talker.pubs['/load_transfer_ratio']]
        assert spin_until(executor, lambda: all(p.get_subscription_count() for p in pubs), 30.0)
        for k in range(N):
            pubs[0].publish(wrench_msg(k, 'front_left_wheel', 1000.0 + k))
            pubs[1].publish(Float64(data=k / N))
        # Reliable: acknowledged = received by the recorder's process (maybe not yet taken).
        assert all(p.wait_for_all_acked(Duration(seconds=10.0)) for p in pubs)
    finally:
        close(executor, talker)
    process.send_signal(stop)
    code, _, err = finish(process, 30.0)
    assert code == 0, err
    got = {}
    for topic, _, msg in iter_messages(out):
        got.setdefault(topic, []).append(msg)
    assert [m.wrench.force.z for m in got['/wheel_load/left']] == [1000.0 + k for k in range(N)]
    assert [m.data for m in got['/load_transfer_ratio']] == [k / N for k in range(N)]


def test_main_refuses_an_existing_output(tmp_path):
    (tmp_path / 'bag').mkdir()
    code, _, err = finish(run_main('bag_recorder', '--ros-args', '-p',
                                   f'output:={tmp_path / "bag"}'))
    assert code == 1 and 'it exists' in err and 'Traceback' not in err
