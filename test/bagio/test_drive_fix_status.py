"""Drive reader: a NavSatFix whose status is "unknown" (-2, what Jazzy reads when the
publisher never set it) but whose position is finite is a fix of unknown quality, kept;
"no fix" (-1) is still refused (issue 17).

The reader's side of this belongs to bagio's drive reader (rewritten under issue 15); until
that lands this test is expected to fail (strict: it turns red once the reader keeps them,
and the marker must then go).
"""
from __future__ import annotations

import numpy as np
from rosbags.typesys import Stores, get_typestore

from road_force_estimator.bagio import BagWriter, read_drive_bag

STORE = get_typestore(Stores.ROS2_JAZZY)
T = STORE.types
BASE_NS = 1_700_000_000_000_000_000


def header(stamp_ns: int, frame: str):
    return T['std_msgs/msg/Header'](stamp=T['builtin_interfaces/msg/Time'](
        sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9), frame_id=frame)


def test_fixes_of_unknown_status_with_a_position_are_kept(tmp_path):
    joint, twist, fix = ('sensor_msgs/msg/JointState', 'geometry_msgs/msg/TwistStamped',
                         'sensor_msgs/msg/NavSatFix')
    with BagWriter(tmp_path / 'b') as bag:
        bag.add_topic('/suspension/deflections', joint, 'sensor_data')
        bag.add_topic('/vehicle/twist', twist, 'sensor_data')
        bag.add_topic('/fix', fix, 'sensor_data')
        for k in range(101):
            t = BASE_NS + k * 10_000_000
            bag.write('/suspension/deflections', t, T[joint](
                header=header(t, 'base_link'), name=['left_suspension', 'right_suspension',
                                                     'roll'],
                position=np.zeros(3), velocity=np.zeros(0), effort=np.zeros(0)))
            bag.write('/vehicle/twist', t, T[twist](header=header(t, 'base_link'), twist=T[
                'geometry_msgs/msg/Twist'](linear=T['geometry_msgs/msg/Vector3'](x=20.0, y=0.0,
                                                                                 z=0.0),
                                           angular=T['geometry_msgs/msg/Vector3'](0.0, 0.0,
                                                                                  0.0))))
            if k % 10 == 0:
                status = -1 if k == 50 else -2   # one "no fix", the others "unknown"
                bag.write('/fix', t, T[fix](
                    header=header(t, 'gnss'), status=T['sensor_msgs/msg/NavSatStatus'](
                        status=status, service=0),
                    latitude=48.0 + k * 1e-6, longitude=17.0, altitude=0.0,
                    position_covariance=np.zeros(9), position_covariance_type=0))
    drive = read_drive_bag(tmp_path / 'b')
    assert drive.fixes is not None and len(drive.fixes.stamps_ns) == 10
    assert 50 * 1e-6 + 48.0 not in drive.fixes.latitude_deg.tolist()
    assert drive.rejected['/fix'].get('no_fix') == 1
