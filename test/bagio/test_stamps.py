"""Stamps in drive bags (issue 28): any number of outlier stamps costs those messages only;
the files of a split bag are read in time order whatever metadata.yaml lists."""
import shutil

import numpy as np
import yaml

from bag_samples import BASE_NS, joint_state, make_trajectory, twist
from road_force_estimator import bagio, interfaces
from road_force_estimator.bagio import BagWriter
from road_force_estimator.bagio.checks import Rejects, accept_in_order, increasing_run

N = 3000
NAMES = interfaces.DEFLECTION_JOINTS


def write_drive(folder, stamps, q, roll, speed=15.0):
    """Deflections (file order = the order given) and a twist with each, log time = stamp."""
    with BagWriter(folder) as bag:
        bag.add_topic(interfaces.TWIST, 'geometry_msgs/msg/TwistStamped')
        bag.add_topic(interfaces.DEFLECTIONS, 'sensor_msgs/msg/JointState')
        for k, s in enumerate(stamps.tolist()):
            log = BASE_NS + k * 1_000_000            # the recorder's clock: in order
            bag.write(interfaces.TWIST, log, twist(s, speed))
            bag.write(interfaces.DEFLECTIONS, log,
                      joint_state(s, NAMES, [q[k, 0], q[k, 1], roll[k]]))


def test_outlier_stamps_cost_those_messages_only(tmp_path):
    rng = np.random.default_rng(4)
    stamps = BASE_NS + np.arange(N, dtype=np.int64) * 1_000_000
    q = 1e-3 * rng.standard_normal((N, 2))
    roll = 1e-3 * rng.standard_normal(N)
    bad = stamps.copy()
    ahead = [100, 700, 701, 1500, 2990]                 # two in a row among them
    behind = [400, 1200, 2200]
    bad[ahead] += np.array([30, 3600, 3600, 5, 86400]) * 10**9
    bad[behind] -= np.array([2, 600, 10]) * 10**9
    write_drive(tmp_path / 'drive', bad, q, roll)
    drive = bagio.read_drive_bag(tmp_path / 'drive')
    good = np.ones(N, bool)
    good[ahead + behind] = False
    np.testing.assert_array_equal(drive.stamps_ns, stamps[good])
    np.testing.assert_array_equal(drive.q_m, q[good])
    rejected = drive.rejected[interfaces.DEFLECTIONS]
    assert rejected == {'outlier_stamp': 5, 'backwards_stamp': 3}, rejected
    # (a last message stamped ahead is a jump nothing after it contradicts: the reader keeps
    # it, and the estimator holds it back for a next sample that never comes)


def test_the_longest_increasing_run_is_kept():
    values = np.array([5, 1, 2, 9, 3, 4, 4, 8, 6, 7])
    assert values[increasing_run(values)].tolist() == [1, 2, 3, 4, 6, 7]
    rejects = Rejects()
    keep = accept_in_order(values.astype(np.int64), np.ones(values.size, bool), 't', rejects)
    assert values[keep].tolist() == [1, 2, 3, 4, 6, 7]
    assert rejects.counts == {'t': {'outlier_stamp': 3, 'duplicate_stamp': 1}}


def test_a_split_bag_is_read_in_time_order_whatever_metadata_lists(tmp_path):
    trajectory, q, roll = make_trajectory(n=4000)
    bagio.write_drive_bag(tmp_path / 'whole', trajectory, q, roll)
    whole = bagio.read_drive_bag(tmp_path / 'whole')
    half = 2000
    folder = tmp_path / 'split'
    folder.mkdir()
    for k, rows in enumerate((slice(0, half), slice(half, None))):
        part = type(trajectory)(**{key: (value[rows] if np.ndim(value) else value)
                                   for key, value in vars(trajectory).items()})
        bagio.write_drive_bag(tmp_path / f'part{k}', part, q[rows], roll[rows])
        shutil.move(str(tmp_path / f'part{k}' / f'part{k}_0.mcap'), folder / f'split_{k}.mcap')
    doc = yaml.safe_load((tmp_path / 'part0' / 'metadata.yaml').read_text())
    doc['rosbag2_bagfile_information']['relative_file_paths'] = ['split_1.mcap',
                                                                 'split_0.mcap']
    (folder / 'metadata.yaml').write_text(yaml.safe_dump(doc))
    drive = bagio.read_drive_bag(folder)
    np.testing.assert_array_equal(drive.stamps_ns, whole.stamps_ns)
    np.testing.assert_array_equal(drive.q_m, whole.q_m)
    assert drive.rejected == {}
    assert drive.issues == ('the files are not listed in time order: read in the order of '
                            'their first messages (split_0.mcap, split_1.mcap)',)
