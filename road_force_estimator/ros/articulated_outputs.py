"""The plant_simulator's messages with ``vehicle.model: articulated`` (INTERFACES.md "The whole
vehicle"): the same topics and bytes as :mod:`road_force_estimator.bagio.articulated_drive`
writes.

Per sample: ``/vehicle/twist``; ``/suspension/deflections`` (every instrumented axle, the
rolls; sensor-data QoS); ``/imu/tractor`` where fitted (sensor data); the truth (reliable):
the front axle's ``/ground_truth/wheel_load/left|right`` and ``/ground_truth/road_profile/
left|right``, ``/ground_truth/wheel_loads`` (every wheel) and
``/ground_truth/load_transfer_ratios`` (each unit's LTR and quasi-static LTR). The sensors,
the IMU and the units' load transfer run their per-sample paths
(:mod:`.core.articulated_sensors`, :mod:`.core.unit_loads`): a drive recorded from the node
carries the numbers ``simulate_bag`` writes for the same drive.
"""
from __future__ import annotations

from geometry_msgs.msg import PointStamped, TwistStamped, WrenchStamped
from sensor_msgs.msg import Imu, JointState

from road_force_estimator import interfaces as api
from road_force_estimator.serde import CdrEncoder, CdrEncoderGroup, message_template
from road_force_estimator.serde.messages import IMU_PATHS, imu_template
from road_force_estimator.core.unit_loads import UnitLoadTransfer
from road_force_estimator.ros.messages import reliable_qos, sensor_qos

__all__ = ['ArticulatedOutputs']


class ArticulatedOutputs:
    """Publishers and encoders of an articulated drive on ``node``.

    Parameters
    ----------
    node : rclpy Node
    drive : ArticulatedDrive
        The drive (:mod:`.core.articulated_setup`).
    layout : RowLayout
        The plant's output record (:class:`.core.articulated_plant.RowLayout`).
    """

    def __init__(self, node, drive, layout) -> None:
        v = drive.vehicle
        self.names = api.articulated_deflection_joints(drive.instrumented_axles,
                                                       v.trailer_roll_sensor)
        sensors = drive.sensors(self.names)
        self.sensors = sensors
        self.measure = sensors.sampler(layout)
        self.imu = sensors.imu_sampler(layout) if v.tractor_imu else None
        self.stamp_offset = sensors.stamps.stamp_sampler()
        statics = drive.model.statics()
        self.ltr = UnitLoadTransfer([a.body for a in v.axles], statics.output_wheel_load_n,
                                    1.0 / drive.sim.rate_hz)
        index = layout.index
        self.load_slice, self.road_slice = index['wheel_load_n'], index['road_m']
        self.t_col, self.x_col = index['t_s'].start, index['distance_m'].start
        self.half = v.axles[0].wheel_half_track_m
        base = api.BASE_FRAME
        self.twist = CdrEncoder(api.TWIST_STAMPED, message_template(api.TWIST_STAMPED, base),
                                ['twist.linear.x'])
        self.deflections = CdrEncoder(api.JOINT_STATE, message_template(
            api.JOINT_STATE, base, self.names), ['position'])
        wheels = api.wheel_joints(v.axle_names)
        loads = [CdrEncoder(api.WRENCH, message_template(api.WRENCH, f), ['wrench.force.z'])
                 for f in api.WHEEL_FRAMES]
        road = CdrEncoder(api.POINT, message_template(api.POINT, api.ROAD_FRAME),
                          ['point.x', 'point.y', 'point.z'])
        every = CdrEncoder(api.JOINT_STATE, message_template(api.JOINT_STATE, base, wheels,
                                                             effort=True), ['effort'])
        units = CdrEncoder(api.JOINT_STATE, message_template(api.JOINT_STATE, base, api.UNITS,
                                                             velocity=True),
                           ['position', 'velocity'])
        #: the truth's six messages of a sample at once
        self.truth = CdrEncoderGroup([*loads, road, road, every, units])
        self.twist_pub = node.create_publisher(TwistStamped, api.TWIST, sensor_qos(100))
        self.deflections_pub = node.create_publisher(JointState, api.DEFLECTIONS,
                                                     sensor_qos(100))
        self.imu_pub = self.imu_encoder = None
        if self.imu is not None:
            self.imu_encoder = CdrEncoder(api.IMU_MSG, imu_template(api.IMU_FRAME,
                                                                    *drive.imu_noise),
                                          list(IMU_PATHS))
            self.imu_pub = node.create_publisher(Imu, api.IMU, sensor_qos(100))
        topics = [(WrenchStamped, t) for t in api.TRUE_LOAD] + [
            (PointStamped, t) for t in api.TRUE_ROAD] + [
            (JointState, api.TRUE_WHEEL_LOADS), (JointState, api.TRUE_LOAD_TRANSFER_RATIOS)]
        #: the reliable (truth) publishers, in the truth group's order
        self.reliable = [node.create_publisher(cls, topic, reliable_qos())
                         for cls, topic in topics]
        # rclpy's publish of serialized bytes without Publisher.publish's Python (as the
        # observer node does): the measurements', then the truth's
        self.send_twist = self.twist_pub.handle.publish_raw
        self.send_deflections = self.deflections_pub.handle.publish_raw
        self.send_truth = [pub.handle.publish_raw for pub in self.reliable]

    def publish(self, sample, stamp_ns: int, speed_mps: float) -> None:
        """Every message of one sample (:class:`.ArticulatedSample`), stamped ``stamp_ns``."""
        row = sample.row
        readings = self.measure(row)
        loads = row[self.load_slice]
        road = row[self.road_slice]
        x = row[self.x_col]
        self.send_twist(self.twist.encode(stamp_ns, (speed_mps,)))
        if self.imu is not None:     # before the deflections: the observer pairs it with them
            a = self.imu(row)
            self.imu_pub.handle.publish_raw(self.imu_encoder.encode(
                stamp_ns, (a[3], a[4], a[5], a[0], a[1], a[2])))
        self.send_deflections(self.deflections.encode(stamp_ns, readings))
        ltr = self.ltr.update(loads)
        values = (loads[0], loads[1], x, self.half, road[0], x, -self.half, road[1], *loads,
                  ltr[0], ltr[2], ltr[4], ltr[1], ltr[3], ltr[5])
        for send, data in zip(self.send_truth, self.truth.encode(stamp_ns, values)):
            send(data)
