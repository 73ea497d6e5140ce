"""simulator.road = topic (ros/live_road.py): an LPA bag written by rosbags (not our code),
played by bag_player into plant_simulator, gives the drive simulate_bag gives over that bag.

The player runs as a process (as a user starts it); the plant and the collector that records
the drive spin in the test process.
"""
from __future__ import annotations

import numpy as np
from rclpy.parameter import Parameter

from node_harness import Collector, close, finish, make_executor, run_main
from road_force_estimator.bagio import read_drive_bag, read_lpa_bag
from road_force_estimator.core.road import iso8608_profile
from road_force_estimator.ros.plant_simulator import PlantSimulator
from road_force_estimator.tools.simulate_bag import main as simulate_bag
from ros_helpers import spin_until

TOPICS = ['/suspension/deflections', '/vehicle/twist', '/ground_truth/wheel_load/left',
          '/ground_truth/wheel_load/right', '/ground_truth/road_profile/left',
          '/ground_truth/road_profile/right']
SURVEY_MPS = 20.0
T0_NS = 1_700_000_000_000_000_000


def write_lpa_with_rosbags(folder, profile) -> None:
    """/lpa/left and /lpa/right (PointStamped, frame road) as a survey at SURVEY_MPS."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore
    store = get_typestore(Stores.ROS2_JAZZY)
    t = store.types
    point = 'geometry_msgs/msg/PointStamped'
    with Writer(folder, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = [writer.add_connection(topic, point, typestore=store)
                 for topic in ('/lpa/left', '/lpa/right')]
        for x, zs in zip(profile.distance_m, profile.elevation_m):
            stamp = T0_NS + round(x / SURVEY_MPS * 1e9)
            for side, conn in enumerate(conns):
                msg = t[point](header=t['std_msgs/msg/Header'](
                    stamp=t['builtin_interfaces/msg/Time'](sec=stamp // 10**9,
                                                           nanosec=stamp % 10**9),
                    frame_id='road'), point=t['geometry_msgs/msg/Point'](
                        x=float(x), y=1.0 - 2.0 * side, z=float(zs[side])))
                writer.write(conn, stamp, store.serialize_cdr(msg, point))


def test_an_lpa_bag_played_into_the_plant_drives_as_simulate_bag(ros_context, tmp_path):
    bag = tmp_path / 'lpa'
    write_lpa_with_rosbags(bag, iso8608_profile('C', 30.0, seed=5))
    assert simulate_bag(['--road', str(bag), '--speed', '20', '--rate', '1000', '--duration',
                         '60', '--output', str(tmp_path / 'ref'), '--no-progress']) == 0
    ref = read_drive_bag(tmp_path / 'ref')

    collector = Collector(ros_context, TOPICS)
    plant = PlantSimulator(context=ros_context, parameter_overrides=[
        Parameter('simulator.road', value='topic'), Parameter('simulator.duration', value=60.0),
        Parameter('road_timeout', value=0.5), Parameter('start_nodes', value=['collector'])])
    player = run_main('bag_player', str(bag), '--wait', '30')
    executor = make_executor(ros_context, collector, plant)
    try:
        assert spin_until(executor, lambda: plant.finished, 60.0), plant.k
        assert spin_until(executor, lambda: all(collector.count(t) >= plant.k for t in TOPICS),
                          10.0)
    finally:
        close(executor, plant, collector)
    code, _, err = finish(player, 30.0)
    assert code == 0 and 'played 1202 messages' in err, err

    n = len(ref.stamps_ns)
    assert plant.k == n == collector.count('/suspension/deflections')
    defl = collector.messages['/suspension/deflections']
    np.testing.assert_allclose([m.position[:2] for m in defl], ref.q_m, rtol=0, atol=1e-9)
    np.testing.assert_allclose([m.position[2] for m in defl], ref.roll_rad, rtol=0, atol=1e-9)
    loads = np.array([[m.wrench.force.z for m in collector.messages[t]] for t in TOPICS[2:4]]).T
    np.testing.assert_allclose(loads, ref.truth.wheel_load_n, rtol=1e-9, atol=1e-9)
    points = [collector.messages[t] for t in TOPICS[4:]]
    road = np.array([[m.point.z for m in p] for p in points]).T
    x = np.array([m.point.x for m in points[0]])
    np.testing.assert_allclose(road, ref.truth.road_m, rtol=0, atol=1e-9)
    # The ground-truth road is the bag's profile under the tires (same 0.25 m envelope).
    expected = read_lpa_bag(bag).enveloped(0.25).elevation_at(x)
    np.testing.assert_allclose(road, expected, rtol=0, atol=1e-12)
    assert 'end of the profile: no new point for 0.5 s (road_timeout)' in plant.live.ended
