"""Messages and drives shared by the bag tests (test/bagio, test/tools; rosbags, Jazzy)."""
import json
import os
from pathlib import Path
import sys
from types import SimpleNamespace

import numpy as np
import pytest

from road_force_estimator import bagio
from road_force_estimator import serde

T = serde.TYPESTORE.types
BASE_NS = bagio.DEFAULT_START_STAMP_NS


def header(stamp_ns, frame):
    return T['std_msgs/msg/Header'](
        stamp=T['builtin_interfaces/msg/Time'](sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9),
        frame_id=frame)


def joint_state(stamp_ns, names, position, velocity=(), frame='base_link'):
    return T['sensor_msgs/msg/JointState'](
        header=header(stamp_ns, frame), name=list(names),
        position=np.asarray(position, float), velocity=np.asarray(velocity, float),
        effort=np.zeros(0))


def twist(stamp_ns, speed):
    v3 = T['geometry_msgs/msg/Vector3']
    return T['geometry_msgs/msg/TwistStamped'](
        header=header(stamp_ns, 'base_link'),
        twist=T['geometry_msgs/msg/Twist'](linear=v3(x=speed, y=0.0, z=0.0),
                                           angular=v3(x=0.0, y=0.0, z=0.0)))


def jazzy_type_hash(msgtype):
    """RIHS01 hash from the type description that the ROS 2 Jazzy message package installs."""
    package, _, name = msgtype.split('/')
    prefixes = [sys.prefix] + [p for p in os.environ.get('AMENT_PREFIX_PATH', '').split(':')
                               if p]
    for prefix in prefixes:
        path = Path(prefix) / 'share' / package / 'msg' / f'{name}.json'
        if path.is_file():
            hashes = json.loads(path.read_text())['type_hashes']
            return next(h['hash_string'] for h in hashes if h['type_name'] == msgtype)
    pytest.fail(f'no installed type description for {msgtype} (ROS 2 Jazzy message packages)')


def make_trajectory(n=400, rate_hz=200.0, speed=15.0, seed=1):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate_hz
    return SimpleNamespace(
        t_s=t, distance_m=speed * t, speed_mps=speed,
        wheel_load_n=rng.normal(25000.0, 800.0, (n, 2)),
        road_m=rng.normal(0.0, 0.004, (n, 2))), rng.normal(0.0, 0.01, (n, 2)), \
        rng.normal(0.0, 0.002, n)
