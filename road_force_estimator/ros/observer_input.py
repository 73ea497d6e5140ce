"""The observer node's inputs: what queued up, taken at once; one source; the speed by stamp.

:class:`ObserverInput` takes ``/suspension/deflections`` and ``/vehicle/twist`` with a
:class:`.take_loop.TakeLoop` (a thread of its own: every queued message in one round, the
twists of a round before its deflections; a deflection message wakes it, the twists are
taken with them and at least every 0.1 s), so that a node that falls behind estimates what
queued up in one go, and what it cannot take is dropped by DDS from the oldest end of a
queue of :data:`QUEUE_DEPTH`: whole runs of samples, which the estimator's stamp rules take
as the long steps or gaps they are (:mod:`road_force_estimator.estimation.acceptance`),
exactly as ``estimate_bag`` takes the same inputs. Nothing else waits: memory stays bounded
under any flood, and the node's executor (``/diagnostics``, parameters) is never behind a
queue of message events.

Each deflection sample gets the speed of the latest twist stamped at or before it (the first
twist's for a sample stamped before every twist), as :func:`road_force_estimator.bagio.
read_drive_bag` gives it; samples that come before any twist wait (:data:`MAX_WAITING`, the
oldest dropped beyond). A second publisher on ``/suspension/deflections`` (two sources:
:mod:`.sources`) is not mixed in: the first one is followed, the other's samples rejected and
counted (``second_source``), until the first has been silent for :data:`SWITCH_SILENCE_S`.

With ``imu`` (the articulated observer, ``vehicle.tractor_imu: true``) ``/imu/tractor`` is
taken too (sensor-data QoS, taken with the deflections as the twist is, before them in each
round) and each sample gets the tractor IMU's ``(a_y, code)`` by the rule of
:class:`road_force_estimator.estimation.imu_hold.ImuHold` (the latest a_y at or before its
stamp; stale or missing counted by the caller).
"""
from __future__ import annotations

from collections import deque
import time
from typing import Callable

from sensor_msgs.msg import Imu, JointState
from geometry_msgs.msg import TwistStamped

from road_force_estimator import interfaces as api
from road_force_estimator.estimation.imu_hold import ImuHold
from road_force_estimator.ros.messages import MessageRejected, sensor_qos
from road_force_estimator.ros.sources import Sources
from road_force_estimator.ros.take_loop import TakeLoop
from road_force_estimator.ros.wire import Wire

__all__ = ['QUEUE_DEPTH', 'MAX_WAITING', 'SWITCH_SILENCE_S', 'ObserverInput']

#: Deflection messages DDS holds for the node (1 s at 1 kHz); older ones go first.
QUEUE_DEPTH = 1000
#: Twists held by DDS (the twist is cheap: none is lost while deflections are).
TWIST_DEPTH = 10_000
#: Deflection samples held while no speed is known (2 s at 1 kHz).
MAX_WAITING = 2000
#: A second source is followed once the first has been silent this long (s).
SWITCH_SILENCE_S = 0.5
#: Twists kept to give each sample the speed at its stamp.
TWISTS_KEPT = 4096
#: IMU messages held by DDS for the node (as the twists: cheap, none lost).
IMU_DEPTH = 10_000


class ObserverInput:
    """The inputs of one observer (see the module).

    Parameters
    ----------
    owner : str
        The observer node's name (the take loop's hidden node is named after it).
    context : rclpy Context
    sample : callable
        ``sample(stamp_ns, (q1, q2), phi, speed_mps)`` for every sample to estimate, in
        order (from the take thread); with ``read``: ``sample(stamp_ns, *rest, speed_mps)``.
    reject : callable
        ``reject(reason, text)`` for every message not used (bounded text).
    read : callable, optional
        ``read(data) -> (stamp_ns, *rest)`` of a ``/suspension/deflections`` message's bytes
        (raising :class:`.MessageRejected`); default the front axle's
        (:meth:`.Wire.read_deflections`). The articulated observer reads every joint
        (:mod:`.whole_vehicle_observer`).
    imu : callable, optional
        ``imu(data) -> (stamp_ns, a_y)`` of an ``/imu/tractor`` message's bytes (raising
        :class:`.MessageRejected`): the topic is subscribed and ``sample`` gets a last
        argument, the sample's ``(a_y (m/s^2), code)`` (:class:`.imu_hold.ImuHold`).
    """

    def __init__(self, owner: str, context, sample: Callable, reject: Callable,
                 read: Callable | None = None, imu: Callable | None = None) -> None:
        self.loop = TakeLoop(owner, context, batch=QUEUE_DEPTH)
        self.twist_index = self.loop.add(TwistStamped, api.TWIST, sensor_qos(TWIST_DEPTH),
                                         wakes=False)   # taken with the deflections
        self.imu_index = -1
        self.read_imu = imu
        #: the tractor IMU's a_y held for the samples (None: no IMU)
        self.imu_hold = None if imu is None else ImuHold()
        if imu is not None:                                # taken with the deflections
            self.imu_index = self.loop.add(Imu, api.IMU, sensor_qos(IMU_DEPTH), wakes=False)
        self.deflection_index = self.loop.add(JointState, api.DEFLECTIONS,
                                              sensor_qos(QUEUE_DEPTH))
        self.sample, self.reject = sample, reject
        self.wire = Wire()
        self.read = self.wire.read_deflections if read is None else read
        self.sources = Sources()
        self.twists: deque = deque(maxlen=TWISTS_KEPT)     # (stamp_ns, speed), as taken
        self.first_speed = None
        self.waiting: deque = deque()
        self.received = 0            # deflection messages taken
        self.second_source = 0       # of them, from a source not followed

    def start(self) -> None:
        self.loop.start(self.take)

    def take(self, batch) -> None:
        """One round (the take thread): the twists and IMU messages, then the deflections, in
        order."""
        now = time.monotonic()
        for m in batch:
            if m.index == self.twist_index:
                self._twist(m.data)
            elif m.index == self.imu_index:
                self._imu(m.data)
        for m in batch:
            if m.index == self.deflection_index:
                self._deflection(m, now)

    def _twist(self, data: bytes) -> None:
        try:
            stamp, speed = self.wire.read_twist(data)
        except MessageRejected as exc:
            self.reject('twist_' + exc.reason, str(exc))
            return
        if self.first_speed is None:
            self.first_speed = speed
        self.twists.append((stamp, speed))
        while self.waiting:
            stamp, *rest = self.waiting.popleft()
            self._sample(stamp, rest)

    def _imu(self, data: bytes) -> None:
        try:
            stamp, ay = self.read_imu(data)
        except MessageRejected as exc:
            self.reject('imu_' + exc.reason, str(exc))
            return
        self.imu_hold.push(stamp, ay)

    def _sample(self, stamp: int, rest: list) -> None:
        if self.imu_hold is None:
            self.sample(stamp, *rest, self.speed_at(stamp))
        else:
            self.sample(stamp, *rest, self.speed_at(stamp), self.imu_hold.at(stamp))

    def _deflection(self, m, now: float) -> None:
        self.received += 1
        src = self.sources.add(m.sequence, now)
        if not self.sources.follow(src, now, SWITCH_SILENCE_S):
            self.second_source += 1
            self.reject('second_source', 'a second publisher on /suspension/deflections: '
                                         'its samples are not mixed in')
            return
        try:
            stamp, *rest = self.read(m.data)
        except MessageRejected as exc:
            self.reject(exc.reason, str(exc))
            return
        if self.first_speed is None:
            if len(self.waiting) == MAX_WAITING:
                self.waiting.popleft()
                self.reject('no_speed', 'no /vehicle/twist yet: oldest waiting sample dropped')
            self.waiting.append((stamp, *rest))
            return
        self._sample(stamp, rest)

    def speed_at(self, stamp: int) -> float:
        """The speed of the latest twist stamped at or before ``stamp`` (the first twist's
        before them all); twists older than the one used are forgotten (the stamps of the
        samples go forward)."""
        twists = self.twists
        while len(twists) > 1 and twists[1][0] <= stamp:
            twists.popleft()
        if twists and twists[0][0] <= stamp:
            return twists[0][1]
        return self.first_speed

    def live_sources(self, within_s: float = 2.0) -> int:
        return self.sources.live(time.monotonic(), within_s)

    @property
    def missed(self) -> int:
        """Deflection messages published but never taken (the publishers' numbers)."""
        return self.sources.missed

    def stop(self) -> None:
        """Stop the thread, then take and estimate what is still queued."""
        self.loop.stop()
        for _ in range(100):
            batch = self.loop.take_all()
            if not batch:
                break
            self.take(batch)

    def destroy(self) -> None:
        self.loop.destroy()
