"""``plant_simulator`` node: the plant driven over a road, publishing measurements and truth.

Publishes, at ``simulator.rate``, the measurements ``/suspension/deflections`` and
``/vehicle/twist`` (sensor-data QoS, as INTERFACES.md has the sensor streams), the ground
truth ``/ground_truth/wheel_load/left|right`` and ``/ground_truth/road_profile/left|right``
(reliable), ``/fix`` at ``simulator.gnss.rate`` (a
straight route) and ``/diagnostics`` at 1 Hz (INTERFACES.md). Sample k is stamped
``start + k / rate`` exactly (integer ns; start = the node clock at the first sample), never a
wall-clock read. A timer publishes every sample that is due, so the stream keeps real time
(times ``realtime_factor``, a node-local parameter: > 1 runs faster, < 1 slower). At the end of
the road or of ``simulator.duration`` it stops publishing and :attr:`finished` turns true; its
``main`` then returns 0. Parameters are read once (read-only): restart to change the drive.

Start-up order: the drive (sample 0) starts once the nodes of the node-local ``start_nodes``
(default ``[observer]``) subscribe to ``/suspension/deflections`` and ``/vehicle/twist`` (or,
with ``start_subscribers`` > 0, once ``/suspension/deflections`` has that many subscribers,
whoever they are), then :data:`.start_gate.SETTLE_S` and, for the other topics'
subscribers, at most :data:`START_GRACE_S`; or after ``start_timeout`` (s) with a warning
naming what is missing. A recorder that must have every sample is named too
(``start_nodes: [observer, bag_recorder]``, as ``simulation.launch.xml`` has it).
``/diagnostics`` says the stamp of the first sample (``first_stamp_ns:<topic>``), from which
a late observer counts what it missed.
``/fix`` carries status FIX, service GPS, and the receiver noise ``simulator.gnss.noise``
(:class:`~.core.gnss.FixNoise`, the numbers of ``simulate_bag``); the twist carries the speed
times ``1 + simulator.speed_scale_error`` (an odometer error; the route stays true).
"""
from __future__ import annotations

from fractions import Fraction
import math
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped, TwistStamped, WrenchStamped
from rclpy.duration import Duration
from rclpy.node import Node
from sensor_msgs.msg import JointState, NavSatFix, NavSatStatus

from road_force_estimator import interfaces as api
from road_force_estimator.core.gnss import FixNoise, route
from road_force_estimator.estimation import diagnostics
from road_force_estimator.ros.messages import (
    diagnostic_status, ns_to_stamp, reliable_qos, sensor_qos)
from road_force_estimator.core.articulated_parameters import check_model_names
from road_force_estimator.core.articulated_plant import RowLayout
from road_force_estimator.core.articulated_setup import ArticulatedDrive
from road_force_estimator.core.lateral_profile import parse_lateral_profile
from road_force_estimator.core.parameters import SimulatorParameters, VehicleParameters
from road_force_estimator.core.plant import Plant
from road_force_estimator.core.speed_profile import (profile_distance, read_speed_profile,
                                                     speed_knots)
from road_force_estimator.bagio import road_from_source
from road_force_estimator.ros.articulated_outputs import ArticulatedOutputs
from road_force_estimator.ros.live_road import TOPIC_ROAD, LiveRoad
from road_force_estimator.ros.node_runner import run_node
from road_force_estimator.ros.ros_parameters import (
    ParameterError, ParameterGuard, articulated_names, articulated_specs, local_spec,
    specs_with_prefix)
from road_force_estimator.ros.start_gate import SETTLE_S, SubscriberGate, first_stamp_values
from road_force_estimator.ros.wire import SimulatorWire
from road_force_estimator.core.sensors import SensorModel
from road_force_estimator.core.vehicle_model import SpringOptions

MAX_SYNTHETIC_LENGTH_M = 200e3  # a synthetic road longer than this is cut (memory)
#: vehicle.model: articulated: its names beside the shared ones (the per-axle names are
#: declared from vehicle.axles, :func:`articulated_specs`)
ARTICULATED = articulated_names('vehicle.', 'simulator.')
SPECS = specs_with_prefix('vehicle.', 'simulator.') + ARTICULATED + (local_spec(
    'realtime_factor', 'double', 1.0, '',
    'simulated seconds per wall-clock second (1 = real time)', 0.01, 100.0), local_spec(
    'start_timeout', 'double', 30.0, 's',
    'the drive starts once start_nodes (or start_subscribers) subscribe to the measurements, '
    'or after this', 0.0, 3600.0), local_spec(
    'start_nodes', 'string_list', ('observer',), '',
    'nodes that must subscribe to /suspension/deflections and /vehicle/twist before the drive '
    'starts (a name, any namespace; /ns/name: that one)'), local_spec(
    'start_subscribers', 'integer', 0, '',
    '> 0: instead of start_nodes, the drive starts once /suspension/deflections has this '
    'many subscribers (whoever they are)', 0, 1000), local_spec(
    'road_timeout', 'double', 2.0, 's',
    'simulator.road = topic: the drive ends when no profile point came for this long after '
    'the tires reached the last one', 0.01, 3600.0))
#: Once the measurement topics have the subscribers that matter: the longest wait for the
#: other topics' subscribers of the same recorder or node (s).
START_GRACE_S = 0.5
#: The topics whose subscribers start the drive: the observer's inputs.
START_TOPICS = (api.DEFLECTIONS, api.TWIST)


def build(values, given=()):
    """The node's configuration: ``(vehicle, sim, realtime_factor, start_timeout,
    road_timeout)``; the vehicle a :class:`.VehicleParameters`, or with ``vehicle.model:
    articulated`` an :class:`.ArticulatedDrive`. ``given``: the names set at start (a name of
    the other vehicle model is refused)."""
    if values.get('vehicle.model') == 'articulated':
        vehicle = ArticulatedDrive.from_values(values, given)
    else:
        check_model_names(given, values)
        vehicle = VehicleParameters.from_parameters(values)
    return (vehicle, SimulatorParameters.from_parameters(values),
            values['realtime_factor'], values['start_timeout'], values['road_timeout'])


class PlantSimulator(Node):
    """The plant of :mod:`.plant` with the sensors of :mod:`.sensors`, on a timer."""

    def __init__(self, **kwargs):
        super().__init__('plant_simulator', **kwargs)
        given = set(getattr(self, '_parameter_overrides', None) or {})
        self.params = ParameterGuard(self, SPECS + articulated_specs(self),
                                     lambda values: build(values, given), read_only=True)
        vehicle, self.sim, self.realtime_factor, self.start_timeout_s, self.road_timeout_s = \
            self.params.config
        sim = self.sim
        self.live = self.road = self.plant = None
        #: vehicle.model: articulated: the drive (:class:`.ArticulatedDrive`), else None
        self.articulated = vehicle if isinstance(vehicle, ArticulatedDrive) else None
        self.last_index = int(math.floor(sim.duration_s * sim.rate_hz + 1e-9))
        if sim.road.strip().lower() == TOPIC_ROAD:  # the road arrives on /lpa/*: live_road
            self.live = LiveRoad(self, vehicle, sim, self.road_timeout_s,
                                 make_plant=self.articulated.plant if self.articulated
                                 else lambda profile: self.front_axle_plant(vehicle, profile))
        else:
            self.build_plant(vehicle, sim)
            self.last_index = min(self.last_index, self.plant.last_sample_index)
        self.wait_since = None         # when the drive began waiting for the live road
        self.period_ns = Fraction(10**9) / Fraction(sim.rate_hz)
        self.outputs = None
        if self.articulated is not None:    # its sensors and topics: .articulated_outputs
            model = self.articulated.model
            self.outputs = ArticulatedOutputs(self, self.articulated,
                                              RowLayout(model.n_dof, model.n_axles))
            self.deflections_pub, self.twist_pub = (self.outputs.deflections_pub,
                                                    self.outputs.twist_pub)
            self.reliable = self.outputs.reliable
            self.stamp_offset = self.outputs.stamp_offset
        else:
            self.front_axle_outputs(vehicle, sim)
        self.fix_pub = self.create_publisher(NavSatFix, api.FIX, sensor_qos(10)) if (
            sim.gnss_rate_hz > 0.0) else None
        self.odometer = 1.0 + sim.speed_scale_error   # the twist reads (1 + e) v
        self.fix_noise = FixNoise(sim.gnss_noise_m, sim.seed)
        self.fix = (-1, 0.0, sim.gnss_start_latitude_deg, sim.gnss_start_longitude_deg,
                    sim.gnss_heading_deg)  # (fix index, t_s, lat, lon, heading) of the last fix
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, api.DIAGNOSTICS,
                                                     reliable_qos(10))
        self.wire = SimulatorWire()   # the messages of every sample as CDR bytes
        self.k = 0                     # next sample index
        self.start_ns = self.start_wall = None
        self.created_wall = time.monotonic()
        values = self.params.values
        count = values['start_subscribers']
        self.gate = SubscriberGate(self, {api.DEFLECTIONS: ()} if count else {
            t: tuple(values['start_nodes']) for t in START_TOPICS}, count)
        self.subscribed_wall = None    # when the gate opened
        self.first_stamp_ns = None     # stamp of sample 0, for /diagnostics
        self.get_logger().info(f'the drive starts once {self.gate.describe()} '
                               f'(at most {self.start_timeout_s:g} s: start_timeout)')
        self.lag_s = 0.0
        self.finished = False
        period_s = max(1.0 / (sim.rate_hz * self.realtime_factor), 1e-3)
        self.timer = self.create_timer(period_s, self.timer_callback)
        self.diagnostics_timer = self.create_timer(1.0, self.diagnostics_callback)

    def front_axle_outputs(self, vehicle, sim) -> None:
        """The front axle's sensors and the publishers of its measurements and truth."""
        sensors = SensorModel.from_simulator(sim, vehicle, channels=api.DEFLECTION_JOINTS)
        self.measure = sensors.sampler()
        self.pendulum = sensors.roll_sensor is not None  # a roll sensor that reads a_y too
        self.stamp_offset = sensors.stamp_sampler()     # stamp jitter (s), simulator.*
        self.half_track_m = vehicle.half_track_m
        self.deflections_pub = self.create_publisher(JointState, api.DEFLECTIONS,
                                                     sensor_qos(100))
        self.twist_pub = self.create_publisher(TwistStamped, api.TWIST, sensor_qos(100))
        self.reliable = [self.create_publisher(WrenchStamped, topic, reliable_qos())
                         for topic in api.TRUE_LOAD]
        self.reliable += [self.create_publisher(PointStamped, topic, reliable_qos())
                          for topic in api.TRUE_ROAD]

    def front_axle_plant(self, vehicle, road) -> Plant:
        """The front axle's plant on ``road`` with the drive's options."""
        sim = self.sim
        profile = read_speed_profile(sim.speed_profile) if sim.speed_profile else None
        return Plant(vehicle, road, speed_mps=sim.speed_mps, rate_hz=sim.rate_hz,
                     tire_envelope_m=sim.tire_envelope_length_m, speed_profile=profile,
                     springs=SpringOptions.from_simulator(sim),
                     lateral_acceleration=parse_lateral_profile(sim.lateral_profile),
                     friction_start=sim.leaf_spring_friction_start,
                     crossfall_rad=sim.road_crossfall_rad)

    def build_plant(self, vehicle, sim) -> None:
        """The road of ``simulator.road`` and the plant on it (refused: ParameterError)."""
        if self.articulated is not None:
            try:
                self.road = road_from_source(sim.road, length_m=min(
                    self.articulated.road_length_m, MAX_SYNTHETIC_LENGTH_M))
                self.plant = self.articulated.plant(self.road)
            except Exception as exc:  # ValueError, OSError, BagReadError: any road refused
                raise ParameterError(f'plant_simulator: refused simulator.road = '
                                     f'{sim.road!r}: {exc}') from None
            return
        try:
            profile = read_speed_profile(sim.speed_profile) if sim.speed_profile else None
            travel = sim.speed_mps * sim.duration_s if profile is None else \
                profile_distance(speed_knots(*profile), sim.duration_s)
            length = min(travel + 2.0 * sim.tire_envelope_length_m + 1.0,
                         MAX_SYNTHETIC_LENGTH_M)
            self.road = road_from_source(sim.road, length_m=length)
            self.plant = self.front_axle_plant(vehicle, self.road)
        except Exception as exc:  # ValueError, OSError, BagReadError: any road refused
            raise ParameterError(f'plant_simulator: refused simulator.road = {sim.road!r}: '
                                 f'{exc}') from None

    def timer_callback(self) -> None:
        """Publish every sample due by now (wall clock times ``realtime_factor``)."""
        if self.start_ns is None:
            if self.plant is None:  # live road: the start of the profile has not come yet
                self.plant = self.live.plant()
                if self.plant is None:
                    if self.live.ended:
                        self.finish()
                    return
            if not self.ready_to_start():
                return
            self.start_ns = self.get_clock().now().nanoseconds
            self.start_wall = time.monotonic()
        if self.live is not None and not self.follow_live_road():
            return
        elapsed = (time.monotonic() - self.start_wall) * self.realtime_factor
        due = min(int(elapsed * self.sim.rate_hz) + 1, self.last_index + 1)
        self.lag_s = max(0.0, elapsed - self.k / self.sim.rate_hz)
        while self.k < due and not self.finished:
            if self.live is not None and self.k > 0 and not self.live.ahead(self.plant):
                break  # the road ahead has not arrived yet
            sample = self.plant.step()
            if sample is None:
                break
            stamp_ns = self.start_ns + round(self.k * self.period_ns)
            self.publish(sample, stamp_ns)
            self.k += 1
            if self.first_stamp_ns is None:    # said at once: a late observer counts from it
                self.first_stamp_ns = stamp_ns + self.last_jitter_ns
                self.diagnostics_callback()
                self.get_logger().info(f'first sample published: stamp {self.first_stamp_ns} ns')
        if self.k > self.last_index or self.plant.finished:
            self.finish()

    def follow_live_road(self) -> bool:
        """Live road: False while the road ahead has not arrived (the drive's clock waits
        too) or once the profile ended (the drive finishes)."""
        if self.k == 0 or self.live.ahead(self.plant):
            if self.wait_since is not None:
                self.start_wall += time.monotonic() - self.wait_since
                self.wait_since = None
            return True
        if self.wait_since is None:
            self.wait_since = time.monotonic()
        if self.live.ended:
            self.finish()
        return False

    def ready_to_start(self) -> bool:
        """True once the gate is open (:data:`.start_gate.SETTLE_S` ago, and the other
        publishers have subscribers or :data:`START_GRACE_S` passed), or ``start_timeout``
        passed (with a warning naming what is missing)."""
        now = time.monotonic()
        missing = self.gate.missing()
        if not missing:
            if self.subscribed_wall is None:
                self.subscribed_wall = now
            waited = now - self.subscribed_wall
            return waited >= SETTLE_S and (waited >= START_GRACE_S or all(
                p.get_subscription_count() for p in self.reliable))
        self.subscribed_wall = None
        if now - self.created_wall >= self.start_timeout_s:
            self.get_logger().warning(
                f'no {", ".join(missing)} after {self.start_timeout_s:g} s (start_timeout): '
                f'starting the drive anyway')
            return True
        return False

    def publish(self, sample, stamp_ns: int) -> None:
        if self.outputs is not None:        # vehicle.model: articulated
            jitter = self.stamp_offset()
            self.last_jitter_ns = int(round(jitter * 1e9)) if jitter else 0
            stamp_ns += self.last_jitter_ns
            self.outputs.publish(sample, stamp_ns,
                                 float(self.speed_at(sample.t_s) * self.odometer))
            if self.fix_pub is not None and int(sample.t_s * self.sim.gnss_rate_hz) > \
                    self.fix[0]:
                self.publish_fix(sample.t_s, stamp_ns)
            return
        if self.pendulum:
            q_meas, roll_meas = self.measure(sample.q_m, sample.roll_rad,
                                             sample.lateral_accel_mps2)
        else:
            q_meas, roll_meas = self.measure(sample.q_m, sample.roll_rad)
        jitter = self.stamp_offset()
        self.last_jitter_ns = int(round(jitter * 1e9)) if jitter else 0
        if jitter:      # the sample at its true time, its stamp moved (simulator.stamp_jitter)
            stamp_ns += self.last_jitter_ns
        load_l, load_r, road_l, road_r = self.reliable
        wire, x = self.wire, float(sample.distance_m)
        self.twist_pub.publish(wire.twist.encode(stamp_ns, (
            float(self.speed_at(sample.t_s) * self.odometer),)))
        self.deflections_pub.publish(wire.deflections.encode(stamp_ns, (
            float(q_meas[0]), float(q_meas[1]), float(roll_meas))))
        for pub, encoder, load in zip((load_l, load_r), wire.loads, sample.wheel_load_n):
            pub.publish(encoder.encode(stamp_ns, (float(load),)))
        for pub, y, road in zip((road_l, road_r), (self.half_track_m, -self.half_track_m),
                                sample.road_m):
            pub.publish(wire.road.encode(stamp_ns, (x, float(y), float(road))))
        if self.fix_pub is not None and int(sample.t_s * self.sim.gnss_rate_hz) > self.fix[0]:
            self.publish_fix(sample.t_s, stamp_ns)

    def speed_at(self, t_s: float) -> float:
        """The speed (m/s) at t_s: simulator.speed, or simulator.speed_profile's."""
        if self.plant is None or self.plant.speed_profile is None:
            return self.sim.speed_mps
        return float(self.plant.speed_at(t_s))

    def publish_fix(self, t_s: float, stamp_ns: int) -> None:
        """``/fix`` on the straight route (WGS84), integrated from the previous fix."""
        j, t0, lat, lon, heading = self.fix
        if j >= 0:
            r = route([t0, t_s], [self.speed_at(t0), self.speed_at(t_s)], start_latitude_deg=lat,
                      start_longitude_deg=lon, heading_deg=heading)
            lat, lon, heading = r.latitude_deg[-1], r.longitude_deg[-1], r.heading_deg[-1]
        self.fix = (int(t_s * self.sim.gnss_rate_hz), t_s, float(lat), float(lon), heading)
        noisy_lat, noisy_lon = self.fix_noise.apply(lat, lon)
        msg = NavSatFix(latitude=float(noisy_lat[0]), longitude=float(noisy_lon[0]), altitude=0.0)
        msg.header.stamp, msg.header.frame_id = ns_to_stamp(stamp_ns), 'gnss'
        msg.position_covariance_type = NavSatFix.COVARIANCE_TYPE_UNKNOWN
        msg.status.status, msg.status.service = NavSatStatus.STATUS_FIX, NavSatStatus.SERVICE_GPS
        self.fix_pub.publish(msg)

    def finish(self) -> None:
        if not self.finished:
            self.finished = True
            self.timer.cancel()
            reason = ((self.live.ended if self.live is not None else '')
                      or (self.plant.stop_reason if self.plant is not None else '')
                      or f'duration {self.sim.duration_s:g} s simulated')
            self.get_logger().info(f'drive finished after {self.k} samples: {reason}')
            self.diagnostics_callback()

    def diagnostics_callback(self) -> None:
        sim = self.sim
        late = self.lag_s > 0.1 and not self.finished
        values = {'samples': self.k, 'simulated_time_s': self.k / sim.rate_hz,
                  'rate_hz': sim.rate_hz, 'realtime_factor': self.realtime_factor,
                  'lag_s': self.lag_s, 'road': (self.road.name if self.road else '') or sim.road,
                  'road_end_m': self.road.end_m if self.road else (
                      self.live.stream.end_m if self.live else math.nan),
                  'finished': self.finished}
        if self.first_stamp_ns is not None:    # a late subscriber counts what it missed
            values.update(first_stamp_values(dict.fromkeys(START_TOPICS, self.first_stamp_ns)))
        message = ('finished' if self.finished else
                   f'behind real time by {self.lag_s:.3f} s' if late else 'publishing')
        msg = DiagnosticArray(status=[diagnostic_status(diagnostics.status(
            'plant_simulator: drive', self.get_name(), message, values,
            level=diagnostics.WARN if late else diagnostics.OK))])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.diagnostics_pub.publish(msg)


def main(args=None) -> int:
    return run_node('plant_simulator', __doc__.splitlines()[0], SPECS, args, PlantSimulator,
                    done=lambda node: node.finished, finish=_wait_for_subscribers)


def _wait_for_subscribers(executor, node: PlantSimulator) -> None:
    for pub in (*node.reliable, node.diagnostics_pub):  # let subscribers take the last
        pub.wait_for_all_acked(Duration(seconds=2.0))    # samples and status before leaving


if __name__ == '__main__':
    sys.exit(main())
