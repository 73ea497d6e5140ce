"""The drive bag read block by block (bagio.drive_blocks) against read_drive_bag in one piece."""
import numpy as np
import pytest

from bag_samples import joint_state, twist
from road_force_estimator import bagio
from road_force_estimator.bagio.drive_blocks import DriveBlocks, streamable
from road_force_estimator.bagio.mcap_file import McapFile
from road_force_estimator.tools.estimate_bag import drive_speed

NAMES = ['left_suspension', 'right_suspension', 'roll']


def _messy_bag(path, monkeypatch):
    """Rejections of every kind, twists before, between and after the deflections, and
    small chunks (a block boundary between any two messages)."""
    monkeypatch.setattr(McapFile, 'CHUNK_BYTES', 256)
    rng = np.random.default_rng(3)
    items = []
    for k in range(1, 120):
        s = 10 * k
        p = [0.01 * rng.standard_normal(), 0.01 * rng.standard_normal(), 0.001 * k]
        kind = k % 13
        if kind == 3:
            s -= 15                                   # backwards
        elif kind == 5:
            s -= 10                                   # duplicate
        elif kind == 7:
            p[1] = np.nan                              # nonfinite
        names = NAMES[:2] if kind == 11 else NAMES     # missing name
        items.append(('/suspension/deflections', s, joint_state(s, names, p, [])))
        if k % 4 == 0 or k in (31, 32):
            ts = s + (7 if k % 8 == 0 else -3)
            if k == 48:
                ts = s - 300                           # a backwards twist
            items.append(('/vehicle/twist', ts, twist(ts, 5.0 + 0.1 * k)))
    items.insert(5, ('/vehicle/twist', 30, twist(30, 4.0)))        # after some samples
    items.insert(9, ('/vehicle/twist', 30, twist(30, 4.5)))        # duplicate twist
    with bagio.BagWriter(path) as bag:
        bag.add_topic('/suspension/deflections', 'sensor_msgs/msg/JointState', 'sensor_data')
        bag.add_topic('/vehicle/twist', 'geometry_msgs/msg/TwistStamped', 'sensor_data')
        for topic, s, msg in items:
            bag.write(topic, s, msg)


@pytest.mark.parametrize('block', [1, 2, 3, 7, 1000])
def test_blocks_equal_one_piece(tmp_path, monkeypatch, block):
    _messy_bag(tmp_path / 'b', monkeypatch)
    whole = bagio.read_drive_bag(tmp_path / 'b')
    speed, early = drive_speed(whole)
    assert early > 0 and whole.rejected_total > 10
    reader = DriveBlocks(tmp_path / 'b', block)
    parts = list(reader)
    if block < 10:
        assert len(parts) > 5
    for name, ref in (('stamps_ns', whole.stamps_ns), ('q_m', whole.q_m),
                      ('roll_rad', whole.roll_rad), ('speed_mps', speed)):
        got = np.concatenate([getattr(p, name) for p in parts])
        np.testing.assert_array_equal(got, ref)
    assert reader.rejected == whole.rejected
    assert reader.messages == whole.messages
    assert reader.early == early
    assert reader.twists == len(whole.twist_stamps_ns)
    assert list(reader.issues) == list(whole.issues)


def test_streamable_counts_the_listed_deflections(tmp_path, monkeypatch):
    """metadata.yaml's deflection messages, ground truth topics or not (every drive goes in
    blocks); 0 without metadata."""
    _messy_bag(tmp_path / 'b', monkeypatch)
    assert streamable(tmp_path / 'b') == 119
    with bagio.BagWriter(tmp_path / 'c') as bag:
        bag.add_topic('/suspension/deflections', 'sensor_msgs/msg/JointState', 'sensor_data')
        bag.add_topic('/ground_truth/wheel_load/left', 'geometry_msgs/msg/WrenchStamped')
        bag.write('/suspension/deflections', 1, joint_state(1, NAMES, [0.0, 0.0, 0.0], []))
    assert streamable(tmp_path / 'c') == 1
    assert streamable(tmp_path / 'missing') == 0



@pytest.mark.parametrize('block', [7, 64, 1000])
def test_blocks_carry_the_truth_at_their_samples(tmp_path, monkeypatch, block):
    """A drive with ground truth in small chunks: each block's truth is the whole drive's
    truth at its samples' stamps (GroundTruth.at), the messages and rejections counted as
    read_drive_bag counts them."""
    from bag_samples import make_trajectory

    monkeypatch.setattr(McapFile, 'CHUNK_BYTES', 512)
    traj, q, roll = make_trajectory(300)
    bagio.write_drive_bag(tmp_path / 'd', traj, q, roll)
    whole = bagio.read_drive_bag(tmp_path / 'd')
    reader = DriveBlocks(tmp_path / 'd', block)
    parts = list(reader)
    assert (len(parts) > 1 or block >= 300) and all(p.truth is not None for p in parts)
    want = whole.truth.at(whole.stamps_ns)
    for name in ('stamps_ns', 'wheel_load_n', 'road_m', 'distance_m'):
        got = np.concatenate([getattr(p.truth, name) for p in parts])
        np.testing.assert_array_equal(got, getattr(want, name), err_msg=name)
    assert reader.messages == whole.messages and reader.rejected == whole.rejected
    assert streamable(tmp_path / 'd') == 300


def test_a_truth_that_ends_early_holds_no_sample_back(tmp_path, monkeypatch):
    """Truth topics that stop before the deflections: once they have given every message
    metadata.yaml lists, the samples go on block by block (not all at the end), NaN truth."""
    from types import SimpleNamespace

    from bag_samples import make_trajectory
    from road_force_estimator.bagio.drive import truth_streams, measurement_streams
    from road_force_estimator.interfaces import TOPIC_TYPES, qos_kind
    from road_force_estimator.serde.messages import stamp_columns

    monkeypatch.setattr(McapFile, 'CHUNK_BYTES', 512)
    traj, q, roll = make_trajectory(600)
    stamps = 10**9 + 5_000_000 * np.arange(600, dtype=np.int64)
    cols = stamp_columns(stamps)
    meas = measurement_streams(stamps, cols, q, roll, np.full(600, 15.0))
    part = SimpleNamespace(wheel_load_n=traj.wheel_load_n[:200], road_m=traj.road_m[:200],
                           distance_m=traj.distance_m[:200])
    truth = truth_streams(part, stamps[:200], stamp_columns(stamps[:200]), 1.8)
    with bagio.BagWriter(tmp_path / 'd') as bag:
        for topic, _, _ in meas + truth:
            bag.add_topic(topic, TOPIC_TYPES[topic], qos_kind(topic))
        bag.write_rows(meas + truth)
    whole = bagio.read_drive_bag(tmp_path / 'd')
    parts = list(DriveBlocks(tmp_path / 'd', 50))
    assert len(parts) >= 10                     # 600 samples, 50 a block: none held back
    got = np.concatenate([p.truth.wheel_load_n for p in parts])
    np.testing.assert_array_equal(got, whole.truth.at(whole.stamps_ns).wheel_load_n)
    assert np.isnan(got[200:]).all() and np.isfinite(got[:200]).all()
