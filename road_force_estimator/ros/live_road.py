"""``simulator.road = topic``: the plant_simulator drives over the profile as it arrives.

:class:`LiveRoad` subscribes ``/lpa/left`` and ``/lpa/right`` (reliable, as LPA bags are
played), buffers the points by distance (:class:`core.road_stream.RoadStream`) and gives the
plant its road: the plant is built once the start of the profile (longer than the tire
envelope) has arrived, and its road is extended (:meth:`core.plant.Plant.extend_road`) when the
tires need more; meanwhile the drive waits. The profile ends when no new point came for
``road_timeout`` (s) after the tires reached the last point received.
"""
from __future__ import annotations

import math
import time

from geometry_msgs.msg import PointStamped

from road_force_estimator.core.plant import Plant
from road_force_estimator.core.road_stream import RoadStream
from road_force_estimator.core.vehicle_model import SpringOptions
from road_force_estimator.interfaces import LPA
from road_force_estimator.ros.messages import reliable_qos

__all__ = ['LiveRoad', 'TOPIC_ROAD']

#: The ``simulator.road`` value that selects the live profile.
TOPIC_ROAD = 'topic'
#: Points queued per path between two callbacks.
QUEUE_DEPTH = 10000
#: Profile gathered before the road is extended (m), at least; or what came once no point
#: arrived for :data:`QUIET_S`.
MIN_EXTENSION_M = 1.0
QUIET_S = 0.1


class LiveRoad:
    """The road of a plant_simulator as it arrives on the LPA topics."""

    def __init__(self, node, vehicle, sim, road_timeout_s: float, make_plant=None):
        self.node = node
        self.vehicle, self.sim = vehicle, sim
        #: ``make_plant(profile)``: the plant on the profile's start (default: the front
        #: axle's :class:`.Plant`; an articulated drive's plant, whose axles all need road)
        self.make_plant = make_plant
        self.road_timeout_s = road_timeout_s
        self.stream = RoadStream(f'topic {LPA[0]}, {LPA[1]}')
        self.last_point = time.monotonic()
        self.used = 0            # joined points given to the plant
        self.used_end_m = -math.inf
        self.ended = ''          # why the profile ended ('' while it goes on)
        self.quantum_m = max(MIN_EXTENSION_M, 0.25 * sim.speed_mps)
        for side, topic in enumerate(LPA):
            node.create_subscription(PointStamped, topic,
                                     lambda msg, side=side: self.point(side, msg),
                                     reliable_qos(QUEUE_DEPTH))
        node.get_logger().info(f'simulator.road = topic: waiting for the profile on {LPA[0]} '
                               f'and {LPA[1]}')

    def point(self, side: int, msg: PointStamped) -> None:
        self.stream.add(side, msg.point.x, msg.point.z)
        self.last_point = time.monotonic()

    def quiet_s(self) -> float:
        """Seconds since the last profile point."""
        return time.monotonic() - self.last_point

    def plant(self) -> Plant | None:
        """The plant on the profile's start, once it has come (None before; :attr:`ended`
        says why when the profile ended before a drive was possible)."""
        stream = self.stream
        envelope = self.sim.tire_envelope_length_m
        quiet = self.quiet_s()
        if quiet >= self.road_timeout_s and sum(stream.received):
            stream.close()
        profile = stream.profile()
        if profile is None or (profile.length_m < envelope + self.quantum_m
                               and not stream.closed):
            if stream.closed:
                self.ended = (f'the profile on {LPA[0]}, {LPA[1]} ended with {len(stream)} '
                              f'usable points: too short for a drive')
            return None
        try:
            plant = self.make_plant(profile) if self.make_plant is not None else Plant(
                self.vehicle, profile, speed_mps=self.sim.speed_mps, rate_hz=self.sim.rate_hz,
                tire_envelope_m=envelope, springs=SpringOptions.from_simulator(self.sim))
        except ValueError as exc:
            if stream.closed:
                self.ended = f'the profile on {LPA[0]}, {LPA[1]} cannot be driven: {exc}'
            return None
        self.used, self.used_end_m = len(stream), stream.end_m
        self.node.get_logger().info(f'profile arriving: driving from {profile.start_m:g} m')
        return plant

    def ahead(self, plant: Plant) -> bool:
        """True when the road of the plant's next sample is there (extending the plant's
        road with what arrived); False while it is not (the drive waits) or after the
        profile ended (:attr:`ended`)."""
        if plant.sample_index < plant.last_sample_index:
            return True
        stream, quiet = self.stream, self.quiet_s()
        if len(stream) > self.used and (stream.end_m - self.used_end_m >= self.quantum_m
                                        or quiet >= QUIET_S):
            plant.extend_road(stream.profile())
            self.used, self.used_end_m = len(stream), stream.end_m
            return plant.sample_index < plant.last_sample_index
        if len(stream) == self.used and quiet >= self.road_timeout_s:
            self.ended = (f'end of the profile: no new point for {self.road_timeout_s:g} s '
                          f'(road_timeout) after the tires reached {plant.road.end_m:g} m')
        return False
