"""bag_player node: order, count, --topics / --start-offset / --remap / --loop, bytes as in the
bag, --clock, the wait for subscribers, bad input and signals (not timing: bench/).

The player and the collectors spin in the test process (fresh rclpy context per test); main()
runs in a subprocess.
"""
from __future__ import annotations

import signal

from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
import pytest

from bag_writers import (
    BASE_NS, FLOAT, POINT, STORE, expected, write_mcap, write_ours, write_rosbags)
from node_harness import close, finish, make_executor, run_main
from road_force_estimator.ros.bag_player import BagPlayer, build_parser, message_class
from road_force_estimator.bagio.playback import open_playback
from ros_helpers import spin_until


TYPES = {'/lpa/left': POINT, '/lpa/right': POINT, '/ratio': FLOAT}


class RawCollector(Node):
    """Subscribes raw (serialized bytes) to ``topics`` ({name: type}); keeps all (best
    effort, which matches reliable and best-effort publishers)."""

    def __init__(self, context, topics: dict[str, str], name: str = 'raw_collector'):
        super().__init__(name, context=context)
        self.messages: dict[str, list[bytes]] = {}
        for topic, msgtype in topics.items():
            self.messages[topic] = []
            self.create_subscription(message_class(msgtype), topic, self.messages[topic].append,
                                     QoSProfile(
                depth=10000, reliability=ReliabilityPolicy.BEST_EFFORT), raw=True)

    def total(self) -> int:
        return sum(len(v) for v in self.messages.values())


def play(context, bag, *args, topics=TYPES, until=None, timeout_s=30.0):
    """Play ``bag`` with the options ``args`` into a raw collector; (player, collector)."""
    # the collector is the only subscriber: any one will do (not the package's readers)
    options = build_parser().parse_args([str(bag), '--wait-count', '1', *args])
    collector = RawCollector(context, topics)
    player = BagPlayer(open_playback(bag), options, context=context)
    executor = make_executor(context, collector, player)
    try:
        assert spin_until(executor, lambda: player.done if until is None else until(
            player, collector), timeout_s)
        assert spin_until(executor, lambda: collector.total() >= sum(
            player.published.get(t, 0) for t in topics), 10.0)
        executor.spin_once(timeout_sec=0.05)
    finally:
        player.stop()
        close(executor, player, collector)
    return player, collector


def by_topic(items, start_ns=0):
    out = {}
    for t, topic, data in items:
        if t - BASE_NS >= start_ns:
            out.setdefault(topic, []).append(data)
    return out


@pytest.mark.parametrize('writer', [write_ours, write_rosbags,
                                    lambda f, m: write_mcap(f, m, 'zstd'),
                                    lambda f, m: write_mcap(f, m, 'lz4')],
                         ids=['ours', 'rosbags', 'mcap_zstd', 'mcap_lz4'])
def test_every_message_arrives_in_order_as_the_bytes_in_the_bag(ros_context, tmp_path, writer):
    items = expected()
    writer(tmp_path / 'bag', items)
    player, col = play(ros_context, tmp_path / 'bag', '--rate', '5')
    assert col.messages == by_topic(items)
    assert player.published == {t: len(v) for t, v in by_topic(items).items()}
    assert len(player.lateness_s) == len(items)


def test_topics_start_offset_and_remap(ros_context, tmp_path):
    items = expected()
    write_ours(tmp_path / 'bag', items)
    player, col = play(ros_context, tmp_path / 'bag', '--rate', '5', '--topics', '/lpa/left',
                       '/ratio', '--start-offset', '0.2', '--remap', '/lpa/left:=/lpa/other',
                       '--delay', '0.1',
                       topics={'/lpa/other': POINT, '/lpa/left': POINT, '/lpa/right': POINT,
                               '/ratio': FLOAT})
    want = by_topic(items, start_ns=200 * 10**6)
    assert col.messages == {'/lpa/other': want['/lpa/left'], '/lpa/left': [], '/lpa/right': [],
                            '/ratio': want['/ratio']}
    assert player.published == {'/lpa/other': 300, '/ratio': 30}


def test_loop_plays_the_bag_again_until_stopped(ros_context, tmp_path):
    items = expected(50)
    write_ours(tmp_path / 'bag', items)
    player, col = play(ros_context, tmp_path / 'bag', '--rate', '10', '--loop',
                       until=lambda p, c: len(c.messages['/ratio']) >= 12)
    assert not player.thread.is_alive()
    one = by_topic(items)
    for topic, got in col.messages.items():
        loops = len(got) // len(one[topic])
        assert loops >= 2 and got[:loops * len(one[topic])] == one[topic] * loops, topic


def test_clock_publishes_the_bag_time(ros_context, tmp_path):
    items = expected(300)
    write_ours(tmp_path / 'bag', items)
    options = build_parser().parse_args([str(tmp_path / 'bag'), '--clock', '--rate', '2',
                                         '--wait-count', '1'])
    assert options.clock == 100.0
    clocks = []
    listener = Node('clock_listener', context=ros_context)
    listener.create_subscription(Clock, '/clock', clocks.append, QoSProfile(
        depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT))
    collector = RawCollector(ros_context, TYPES)
    player = BagPlayer(open_playback(tmp_path / 'bag'), options, context=ros_context)
    executor = make_executor(ros_context, listener, collector, player)
    try:
        assert spin_until(executor, lambda: player.done, 30.0)
        assert spin_until(executor, lambda: len(clocks) >= player.clock_ticks - 1, 5.0)
    finally:
        player.stop()
        close(executor, player, collector, listener)
    # 0.3 s of bag at 100 Hz of bag time... played at rate 2: 0.15 s of wall time, 100 Hz.
    assert 10 <= player.clock_ticks <= 17
    stamps = [c.clock.sec * 10**9 + c.clock.nanosec for c in clocks]
    assert stamps == sorted(stamps) and stamps[0] == BASE_NS
    assert all(BASE_NS <= s <= BASE_NS + 300 * 10**6 for s in stamps)


def test_an_unknown_type_is_skipped_with_one_warning(ros_context, tmp_path):
    from mcap.writer import Writer
    folder = tmp_path / 'bag'
    folder.mkdir()
    with (folder / 'bag_0.mcap').open('wb') as f:
        writer = Writer(f)
        writer.start(profile='ros2', library='test')
        thing = writer.register_schema('my_pkg/msg/Thing', 'ros2msg', b'float64 a\n')
        point = writer.register_schema(POINT, 'ros2msg', STORE.generate_msgdef(
            POINT, ros_version=2)[0].encode())
        cids = [writer.register_channel('/thing', 'cdr', thing, {}),
                writer.register_channel('/lpa/left', 'cdr', point, {})]
        for t, topic, data in expected(20):
            if topic == '/lpa/left':
                writer.add_message(cids[0], t, b'\x00\x01\x00\x00' + bytes(8), t)
                writer.add_message(cids[1], t, data, t)
        writer.finish()
    code, _, err = finish(run_main('bag_player', str(folder), '--wait', '0', '--rate', '10'))
    assert code == 0, err
    assert err.count("skipping /thing: cannot publish type 'my_pkg/msg/Thing'") == 1, err
    assert 'played 20 messages' in err and 'Traceback' not in err


def test_main_plays_waits_for_a_subscriber_and_exits_0(ros_context, tmp_path):
    items = expected(100)
    write_rosbags(tmp_path / 'bag', items)
    process = run_main('bag_player', str(tmp_path / 'bag'), '--topics', '/lpa/left',
                       '--wait', '20', '--wait-for', 'raw_collector')
    col = RawCollector(ros_context, {'/lpa/left': POINT})
    executor = make_executor(ros_context, col)
    try:
        assert spin_until(executor, lambda: len(col.messages['/lpa/left']) == 100, 60.0)
    finally:
        close(executor, col)
    code, _, err = finish(process, 30.0)
    assert code == 0, err
    assert 'waiting up to 20 s for raw_collector on /lpa/left' in err
    assert 'played 100 messages' in err and 'Traceback' not in err
    assert col.messages['/lpa/left'] == by_topic(items)['/lpa/left']


def test_main_stops_cleanly_on_sigint(ros_context, tmp_path):
    write_ours(tmp_path / 'bag', expected(2000))  # 2 s of bag
    process = run_main('bag_player', str(tmp_path / 'bag'), '--topics', '/ratio', '--loop',
                       '--wait', '20')
    col = RawCollector(ros_context, {'/ratio': FLOAT})
    executor = make_executor(ros_context, col)
    try:
        assert spin_until(executor, lambda: len(col.messages['/ratio']) > 5, 60.0)
    finally:
        close(executor, col)
    process.send_signal(signal.SIGINT)
    code, _, err = finish(process, 30.0)
    assert code == 0 and 'Traceback' not in err, err


def test_a_cut_bag_plays_up_to_the_break_and_says_so(tmp_path):
    items = expected(2000)
    write_mcap(tmp_path / 'bag', items, 'lz4')
    (path,) = (tmp_path / 'bag').glob('*.mcap')
    path.write_bytes(path.read_bytes()[:len(path.read_bytes()) // 2])
    code, _, err = finish(run_main('bag_player', str(tmp_path / 'bag'), '--wait', '0',
                                   '--rate', '20'))
    assert code == 0, err
    assert 'is cut or damaged' in err and 'played up to the break' in err
    assert 'Traceback' not in err


@pytest.mark.parametrize('args, code, line', [
    (['{tmp}/missing'], 1, 'bag_player: {tmp}/missing: no such bag folder or file'),
    (['{tmp}', '--rate', '0'], 2, 'bag_player: error: argument --rate: 0 must be a number > 0'),
    (['{tmp}', '--remap', 'a=b'], 2,
     "bag_player: error: argument --remap: 'a=b' is not FROM:=TO (two absolute topic names)"),
    (['{tmp}'], 1, 'bag_player: {tmp}: no metadata.yaml and no .mcap file: not an MCAP bag'),
])
def test_bad_input_gives_one_line(tmp_path, args, code, line):
    args = [a.format(tmp=tmp_path) for a in args]
    got, out, err = finish(run_main('bag_player', *args))
    assert (got, err.strip().splitlines()) == (code, [line.format(tmp=tmp_path)])


# ---------------------------------------------------------------------------------------------
# Issue 28: names, depths, clocks and loops that cannot work; split bags

@pytest.mark.parametrize('args, line', [
    (['--remap', '/lpa/left:=/bad name!'],
     "bag_player: error: argument --remap: '/lpa/left:=/bad name!': '/bad name!' is not a "
     "valid topic name (topic name must not contain characters other than alphanumerics, "
     "'_', or '/')"),
    (['--clock', '1e6'], 'bag_player: error: argument --clock: 1e6 Hz: at most 10000 Hz (a '
                         'faster /clock would slow the playback down)'),
    (['--clock', '1e9'], 'bag_player: error: argument --clock: 1e9 Hz: at most 10000 Hz (a '
                         'faster /clock would slow the playback down)'),
    (['--rate', 'nan'], 'bag_player: error: argument --rate: nan must be a number > 0'),
])
def test_options_that_cannot_work_are_one_line(tmp_path, args, line):
    write_ours(tmp_path / 'bag', expected(10))
    got, out, err = finish(run_main('bag_player', str(tmp_path / 'bag'), *args))
    assert (got, err.strip().splitlines()) == (2, [line])


def test_a_huge_recorded_queue_depth_plays_with_the_largest_one(tmp_path):
    import yaml
    write_ours(tmp_path / 'bag', expected(20))
    meta = tmp_path / 'bag' / 'metadata.yaml'
    doc = yaml.safe_load(meta.read_text())
    for entry in doc['rosbag2_bagfile_information']['topics_with_message_count']:
        entry['topic_metadata']['offered_qos_profiles'][0]['depth'] = 10**11
    meta.write_text(yaml.safe_dump(doc))
    code, _, err = finish(run_main('bag_player', str(tmp_path / 'bag'), '--wait', '0',
                                   '--rate', '10'))
    assert code == 0 and 'Traceback' not in err, err
    assert err.count('the recorded QoS depth 100000000000 is more than 100000: played with '
                     '100000') == 3
    assert 'played 42 messages' in err


def split_bag(folder, items, listed):
    """The items in two files bag_0.mcap (first half) and bag_1.mcap, metadata.yaml listing
    ``listed``."""
    import shutil
    import yaml
    half = len(items) // 2
    for k, part in enumerate((items[:half], items[half:])):
        write_ours(folder.parent / f'part{k}', part)
        folder.mkdir(exist_ok=True)
        shutil.move(str(folder.parent / f'part{k}' / f'part{k}_0.mcap'), folder / f'bag_{k}.mcap')
    doc = yaml.safe_load((folder.parent / 'part0' / 'metadata.yaml').read_text())
    info = doc['rosbag2_bagfile_information']
    info['relative_file_paths'] = listed
    (folder / 'metadata.yaml').write_text(yaml.safe_dump(doc))


def test_a_split_bag_plays_in_time_order_whatever_metadata_lists(ros_context, tmp_path):
    items = expected(200)
    split_bag(tmp_path / 'bag', items, ['bag_1.mcap', 'bag_0.mcap'])
    playback = open_playback(tmp_path / 'bag')
    assert [f.name for f in playback.files] == ['bag_0.mcap', 'bag_1.mcap']
    assert playback.issues == ['the files are not listed in time order: read in the order of '
                               'their first messages (bag_0.mcap, bag_1.mcap)']
    player, col = play(ros_context, tmp_path / 'bag', '--rate', '10')
    assert col.messages == by_topic(items)


def test_a_missing_file_of_a_split_bag_is_a_warning(tmp_path):
    items = expected(200)
    split_bag(tmp_path / 'bag', items, ['bag_0.mcap', 'bag_1.mcap'])
    (tmp_path / 'bag' / 'bag_1.mcap').unlink()
    code, _, err = finish(run_main('bag_player', str(tmp_path / 'bag'), '--wait', '0',
                                   '--rate', '10'))
    assert code == 0 and 'Traceback' not in err, err
    assert f'{tmp_path}/bag: bag_1.mcap: listed in metadata.yaml but missing' in err
    assert f'played {len(items) // 2} messages' in err


def test_a_loop_of_one_message_is_paced_and_a_loop_keeps_bounded_memory(ros_context, tmp_path,
                                                                         monkeypatch):
    """Issue 28: --loop busy-looped a one-message bag and kept 32 bytes per message played."""
    import tracemalloc

    from road_force_estimator.ros import bag_player
    write_ours(tmp_path / 'one', expected(1))
    options = build_parser().parse_args([str(tmp_path / 'one'), '--rate', '4', '--wait', '0'])
    player = BagPlayer(open_playback(tmp_path / 'one'), options, context=ros_context)
    player.stop()                                       # its thread: the passes run here
    player.stopping.clear()
    count, origin = player.play_once()
    assert count == len(expected(1)) == 3               # /lpa/left, /lpa/right, /ratio at t0
    # the next pass LOOP_SINGLE_S of bag time later: 0.25 s at --rate 4
    assert origin[0] - player.schedule[0] == pytest.approx(bag_player.LOOP_SINGLE_S / 4)
    player.destroy_node()
    monkeypatch.setattr(bag_player, 'LATENESS_KEPT', 100)
    write_ours(tmp_path / 'bag', expected(200))
    options = build_parser().parse_args([str(tmp_path / 'bag'), '--rate', '1000', '--wait',
                                         '0'])
    player = BagPlayer(open_playback(tmp_path / 'bag'), options, context=ros_context)
    player.stop()
    player.stopping.clear()
    tracemalloc.start()
    try:
        origin = None
        for k in range(30):
            if k == 10:
                before = tracemalloc.get_traced_memory()[0]
            count, origin = player.play_once(origin)
            assert count == len(expected(200))
        grown = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
        player.destroy_node()
    assert len(player.lateness_s) == 100
    assert grown < 20 * count * 8, grown        # well under a byte per message played
