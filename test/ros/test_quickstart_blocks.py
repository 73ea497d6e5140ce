"""The node blocks of docs/quickstart.md, run as written (issue 29).

Each block marked ``<!-- block: NAME -->`` is read from the page and its commands started as
processes in the order written, each as soon as the one before it was started (no sleep, no
wait for the graph): what a user who pastes the block does. ros2cli is not on PyPI, so the
commands are the package's console entry points themselves (what ``ros2 run
road_force_estimator NAME`` starts). The only additions are those the page's table lists: a
shorter drive and the output folders in a temporary directory.
"""
from __future__ import annotations

import pathlib
import re
import shlex
import signal
import subprocess
import sys

import numpy as np
import pytest

from node_harness import REPO, Collector, close, finish, make_executor, recorder_received
from road_force_estimator.bagio import iter_messages, read_drive_bag
from road_force_estimator.tools.estimate_bag import main as estimate_bag
from road_force_estimator.tools.simulate_bag import main as simulate_bag
from ros_helpers import spin_until

PAGE = REPO / 'docs' / 'quickstart.md'
BIN = pathlib.Path(sys.executable).parent
OUTPUTS = ['/wheel_load/left', '/wheel_load/right', '/road_profile/left', '/road_profile/right',
           '/load_transfer', '/observer/states']


def block(name: str) -> list[list[str]]:
    """The commands of the block ``name`` (continuations joined, ``&`` dropped)."""
    text = PAGE.read_text()
    m = re.search(rf'<!-- block: {name} -->\s*```bash\n(.*?)```', text, re.S)
    assert m, f'no block {name} in {PAGE}'
    lines = m.group(1).replace('\\\n', ' ').splitlines()
    return [shlex.split(line.rstrip().rstrip('&')) for line in lines if line.strip()]


def start(argv: list[str], extra: dict[str, list[str]], replace: dict[str, str]):
    """Start one command of a block: its executable from this environment, ``extra``
    arguments appended for its name, ``replace`` applied to its words."""
    exe = BIN / argv[0]
    assert exe.is_file(), f'{argv[0]}: not installed beside {sys.executable}'
    words = [replace.get(w, w) for w in argv[1:]] + extra.get(argv[0], [])
    return subprocess.Popen([str(exe), *words], cwd=REPO, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def run_block(name, extra=None, replace=None) -> dict[str, subprocess.Popen]:
    procs = {}
    for argv in block(name):
        procs[argv[0]] = start(argv, extra or {}, replace or {})
    return procs


def stop(*procs) -> list[str]:
    for p in procs:
        p.send_signal(signal.SIGINT)
    errs = []
    for p in procs:
        code, _, err = finish(p, 60.0)
        assert code == 0, err[-3000:]
        errs.append(err)
    return errs


def statuses(collector, name: str) -> list[dict[str, str]]:
    return [{v.key: v.value for v in st.values} for m in collector.messages['/diagnostics']
            for st in m.status if st.name == name]


def test_the_observer_estimates_from_the_plants_first_sample(ros_context):
    collector = Collector(ros_context, ['/diagnostics'])
    executor = make_executor(ros_context, collector)
    procs = run_block('quickstart', extra={'plant_simulator': ['-p', 'simulator.duration:=2']})
    try:
        plant = procs['plant_simulator']
        assert spin_until(executor, lambda: plant.poll() is not None, 120.0)
        code, _, plant_err = finish(plant, 10.0)
        assert code == 0 and 'drive finished after 2001 samples' in plant_err, plant_err

        # the observer's input status is periodic: whenever this process has discovered the
        # observer, it gets one that says its first input and what it missed before it
        def said() -> bool:
            return any(s.get('missed_before_first_input', 'unknown') != 'unknown'
                       for s in statuses(collector, 'observer: input'))
        assert spin_until(executor, said, 60.0), [
            (st.name, {v.key: v.value for v in st.values if 'first' in v.key})
            for m in collector.messages['/diagnostics'] for st in m.status]
    finally:
        close(executor, collector)
        observer_err, = stop(procs['observer'])
    first = re.search(r'first sample published: stamp (\d+) ns', plant_err)
    assert first, plant_err
    observer = [s for s in statuses(collector, 'observer: input')
                if s.get('missed_before_first_input', 'unknown') != 'unknown'][-1]
    assert observer['first_stamp_ns'] == first.group(1)
    assert observer['missed_before_first_input'] == '0'
    assert 'published before the first one arrived' not in observer_err
    assert 'starting the drive anyway' not in plant_err


def test_the_lpa_replay_drives_as_simulate_bag_from_0_m(tmp_path):
    recorded = tmp_path / 'lpa_drive'
    procs = run_block('lpa_replay', extra={'plant_simulator': ['-p', 'simulator.duration:=3']},
                      replace={'output:=lpa_drive': f'output:={recorded}'})
    code, _, player_err = finish(procs['bag_player'], 180.0)
    assert code == 0 and 'played 20002 messages' in player_err, player_err
    code, _, plant_err = finish(procs['plant_simulator'], 120.0)
    assert code == 0 and 'drive finished after 3001 samples' in plant_err, plant_err
    stop(procs['bag_recorder'], procs['observer'])
    assert simulate_bag(['--road', 'bags/lpa_iso8608_c', '--params-file',
                         str(REPO / 'config' / 'road_force_estimator.yaml'), '-p',
                         'simulator.duration:=3', '--output', str(tmp_path / 'ref'),
                         '--no-progress']) == 0 or pytest.fail('simulate_bag')
    got, ref = read_drive_bag(recorded), read_drive_bag(tmp_path / 'ref')
    assert len(got.stamps_ns) == len(ref.stamps_ns) == 3001
    # from the road's start: the tire's centre half its envelope (0.125 m) in, as offline
    assert got.truth.distance_m[0] == ref.truth.distance_m[0] < 0.2
    np.testing.assert_allclose(got.truth.distance_m, ref.truth.distance_m, atol=1e-9)
    np.testing.assert_allclose(got.q_m, ref.q_m, rtol=0, atol=1e-9)
    np.testing.assert_allclose(got.roll_rad, ref.roll_rad, rtol=0, atol=1e-9)
    np.testing.assert_allclose(got.truth.wheel_load_n, ref.truth.wheel_load_n, rtol=1e-9)


def outputs(bag) -> dict[str, list[tuple[int, tuple[float, ...]]]]:
    out = {t: [] for t in OUTPUTS}
    for topic, _, msg in iter_messages(bag, OUTPUTS):
        stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        if topic == '/observer/states':
            values = (*msg.position, *msg.velocity)
        elif topic.startswith('/wheel_load'):
            values = (msg.wrench.force.z,)
        elif topic == '/load_transfer':
            values = (msg.vector.x, msg.vector.y)
        else:
            values = (msg.point.x, msg.point.y, msg.point.z)
        out[topic].append((stamp, tuple(float(v) for v in values)))
    return out


def test_the_drive_replay_gives_estimate_bag_online_on_every_stamp(ros_context, tmp_path):
    drive, recorded = tmp_path / 'drive', tmp_path / 'estimates'
    assert simulate_bag(['--road', 'iso8608:C:seed=3', '--speed', '20', '--rate', '1000',
                         '--duration', '0.8', '--output', str(drive), '--no-progress']) == 0
    assert estimate_bag([str(drive), '--params-file',
                         str(REPO / 'config' / 'road_force_estimator.yaml'), '--output',
                         str(tmp_path / 'est'), '--mode', 'online', '--no-figures',
                         '--no-progress']) == 0
    expected = outputs(tmp_path / 'est' / 'bag')
    n = len(expected['/observer/states'])
    assert n == 801
    collector = Collector(ros_context, ['/diagnostics'])
    executor = make_executor(ros_context, collector)
    procs = run_block('drive_replay', replace={'DRIVE': str(drive),
                                               'output:=estimates': f'output:={recorded}'})
    try:
        player = procs['bag_player']
        assert spin_until(executor, lambda: player.poll() is not None, 180.0)
        code, _, player_err = finish(player, 10.0)
        assert code == 0 and f'played {2 * n} messages' in player_err, player_err
        assert 'playing anyway' not in player_err
        # as the page says: Ctrl-C once the recorder's /diagnostics (periodic) counts every
        # estimate (a burst that a loaded machine's transport dropped is repaired at the next
        # heartbeat); the player waited for the recorder's subscriptions, so it has them all
        assert spin_until(executor, lambda: all(
            recorder_received(collector, OUTPUTS).get(t, 0) >= len(expected[t])
            for t in OUTPUTS), 90.0), recorder_received(collector, OUTPUTS)
    finally:
        close(executor, collector)
        stop(procs['bag_recorder'], procs['observer'])
    got = outputs(recorded)
    for topic in OUTPUTS:
        assert [s for s, _ in got[topic]] == [s for s, _ in expected[topic]], topic
        np.testing.assert_allclose([v for _, v in got[topic]], [v for _, v in expected[topic]],
                                   rtol=1e-9, atol=1e-9, err_msg=topic)
