"""The observer node with ``vehicle.model: articulated`` (INTERFACES.md "The whole vehicle"):
every sample of ``/suspension/deflections`` through
:class:`~road_force_estimator.estimation.whole_vehicle.WholeVehicleEstimator`.

Inputs as the front axle's (:class:`.observer_input.ObserverInput`: the take thread, the speed
of the latest ``/vehicle/twist`` stamped at or before each sample, one source), the readings
taken by joint name in the model's channel order (:class:`JointReader`: both sides of every
instrumented axle, ``tractor_roll``, ``trailer_roll`` where fitted). Rejected, counted in
``/diagnostics`` and skipped (the node keeps running, never publishes NaN): a message missing
a joint or naming one twice, arrays of another length (``names``, ``length``), a non-finite
value (``nonfinite``), a stamp at or before the last accepted one (``time``).

Per estimate (stamped with its sample's stamp, reliable): ``/wheel_loads`` (JointState,
``effort`` = load (N) of each wheel of every instrumented axle, ``<axle>_left_wheel``,
``<axle>_right_wheel``), ``/load_transfer/tractor|trailer|combination`` (Vector3Stamped,
x = LTR = right minus left over their sum, y = quasi-static LTR) and the front axle's topics
from the front axle's wheels: ``/wheel_load/left|right`` (WrenchStamped, N) and
``/load_transfer`` (its two wheels' LTR and quasi-static LTR: the estimate's
``front_ltr``). With the first estimate of
every :data:`.interfaces.STATIC_LOAD_PERIOD_NS`: ``/wheel_loads/static`` and
``/wheel_load/static/left|right`` (the static loads F_c, N). The road: per estimate
``/road_profile/left|right`` (PointStamped, frame ``road``: x = distance (m), y = +- the front
wheels' half track (m), z = the front axle's own road under each wheel (m), after the loads),
and ``/road_profile/fused/left|right`` for every point of the fused profile the last axle has
passed with that estimate (the same, z fused over every axle, stamped with the sample at which
the front axle passed the point: :class:`~road_force_estimator.estimation.fused_stream.
FusedStream`). Not published: ``/load_transfer_ratio`` and ``/observer/states`` (front-axle
model topics INTERFACES.md does not keep for the whole vehicle). Messages go out as CDR bytes
(one :class:`.serde.CdrEncoderGroup` per estimate).

``/diagnostics`` at 1 Hz: ``observer: input`` (counts of the period, ``total.*``),
``observer: estimator`` (``static_load_<axle>_n`` per axle, ``gross_weight_n``,
``max_abs_ltr_<unit>``, ``innovations_gated.<channel>`` and ``gaps`` (steps that restarted
the estimate, :mod:`~.estimation.whole_vehicle`) of the period and ``total.`` of the run;
``sensor.<channel>`` ('ok' | 'stuck' | 'drift', :mod:`~.estimation.sensor_health`) and
``total.stuck.<channel>`` / ``total.drift.<channel>``, flags raised: a fault WARNs naming the
sensor) and ``observer: configuration``.

The tractor IMU (``vehicle.tractor_imu: true`` in the observer's file, the parameter the plant
reads): ``/imu/tractor`` is subscribed (sensor-data QoS) and read from its bytes
(:class:`ImuReader`, ``linear_acceleration.y`` = a_y, m/s^2); each sample takes the latest a_y
at or before its stamp (:mod:`~.estimation.imu_hold`) as the estimator's last channel
(``imu=True``); a sample without a fresh a_y leaves the IMU's row out (and a pendulum's roll
rows: :mod:`~.estimation.whole_vehicle`). ``observer: estimator`` counts ``imu.stale`` and
``imu.missing`` (samples with a held a_y older than
:data:`~.estimation.imu_hold.IMU_MAX_AGE_S`, or no IMU message yet) of the period and
``total.imu.*``, WARN when the period had any.
"""
from __future__ import annotations

from collections import Counter
import math
from operator import itemgetter
import threading
import time
from typing import Any, Iterable, Mapping, Sequence

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped, Vector3Stamped, WrenchStamped
from rclpy.duration import Duration
from sensor_msgs.msg import Imu, JointState

from road_force_estimator import interfaces as api
from road_force_estimator.core.articulated_parameters import ArticulatedParameters
from road_force_estimator.core.parameters import ObserverParameters
from road_force_estimator.estimation import diagnostics
from road_force_estimator.estimation.axle_fit import ADVICE
from road_force_estimator.estimation.imu_hold import FRESH, MISSING, STALE, STATES
from road_force_estimator.estimation.models.articulated import IMU_CHANNEL
from road_force_estimator.estimation.rollover_warning import WARNING_THRESHOLD
from road_force_estimator.estimation.whole_vehicle import UNITS, WholeVehicleEstimator
from road_force_estimator.ros.messages import (
    MessageRejected, bounded, diagnostic_status, reliable_qos)
from road_force_estimator.ros.observer_input import ObserverInput
from road_force_estimator.ros.ros_parameters import (
    ParameterGuard, articulated_names, articulated_specs)
from road_force_estimator.ros.wire import deserialize
from road_force_estimator.serde import CdrEncoder, CdrEncoderGroup, CdrReader, message_template

__all__ = ['JointReader', 'read_joints', 'build', 'specs', 'WholeVehicleObserver', 'OUTPUTS',
           'output_values']

#: The topics of one estimate's messages, in the encoder group's order.
OUTPUTS = (api.WHEEL_LOADS, *api.UNIT_LOAD_TRANSFER, *api.LOAD, api.LOAD_TRANSFER)
#: Estimates each output's publisher keeps for its reliable subscribers (1 s at 1 kHz).
OUTPUT_DEPTH = 1000
FLOW = ('received', 'published')


def specs(node, front_axle_specs: tuple) -> tuple:
    """What the node declares: the front-axle observer's names, the articulated model's
    whole-vehicle ``vehicle.*`` names and the per-axle names of ``vehicle.axles``
    (:func:`.ros_parameters.articulated_specs`, the plant_simulator's)."""
    return (front_axle_specs + articulated_names('vehicle.', 'simulator.')
            + articulated_specs(node))


def build(values: Mapping[str, Any], given: Iterable[str], channels: Sequence[str] = ()
          ) -> tuple[ArticulatedParameters, ObserverParameters, WholeVehicleEstimator]:
    """The vehicle, the observer's settings and a new estimator (leaf-spring friction and
    lagging sensors as the file states them). ``channels``: those of the running estimator (a
    live set), which must stay.

    Raises
    ------
    ValueError
        One line naming the parameter.
    """
    vehicle = ArticulatedParameters.from_parameters(values, [
        n for n in given if n.startswith(('vehicle.', 'simulator.'))])
    observer = ObserverParameters.from_parameters(values)
    estimator = WholeVehicleEstimator(vehicle, observer, imu=vehicle.tractor_imu)
    if channels and tuple(estimator.channel_names) != tuple(channels):
        raise ValueError('vehicle.axles, .instrumented, vehicle.trailer_roll_sensor, '
                         'vehicle.tractor_imu: the channels are set at start (restart the '
                         'node to change them)')
    return vehicle, observer, estimator


def read_joints(msg: JointState, names: Sequence[str]) -> tuple[int, tuple[float, ...]]:
    """``(stamp_ns, positions of names)`` from a JointState, mapped by joint name.

    Raises
    ------
    MessageRejected
        'length' (arrays of another length than ``name``), 'names' (a joint of ``names``
        missing, or a name repeated), 'nonfinite' (NaN or infinite reading).
    """
    got = list(msg.name)
    n = len(got)
    if len(msg.position) != n or any(len(a) not in (0, n) for a in (msg.velocity, msg.effort)):
        raise MessageRejected('length', f'JointState arrays differ in length from name ({n}): '
                                        f'position {len(msg.position)}')
    missing = [j for j in names if j not in got]
    if len(set(got)) != n or missing:
        raise MessageRejected('names', f'JointState lacks {missing[:3]} or repeats a name '
                                       f'({n} names)')
    by_name = dict(zip(got, msg.position))
    values = tuple(float(by_name[j]) for j in names)
    if not math.isfinite(sum(values)) or not all(math.isfinite(v) for v in values):
        raise MessageRejected('nonfinite', 'JointState holds a non-finite reading')
    stamp = msg.header.stamp
    return stamp.sec * 1_000_000_000 + stamp.nanosec, values


class JointReader:
    """The readings of ``names`` from a ``/suspension/deflections`` message's bytes: straight
    from the bytes in the plant_simulator's layout (those names in that order, frame
    ``base_link``, positions only), else by rclpy and :func:`read_joints`."""

    def __init__(self, names: Sequence[str]) -> None:
        self.names = tuple(names)
        self.fast = CdrReader(api.JOINT_STATE, message_template(
            api.JOINT_STATE, api.BASE_FRAME, self.names), ['position'])

    def read(self, data: bytes) -> tuple[int, tuple[float, ...]]:
        fast = self.fast.read(data)
        if fast is not None and math.isfinite(sum(fast[1])):
            return fast
        return read_joints(deserialize(data, JointState), self.names)


class ImuReader:
    """The tractor IMU's ``(stamp_ns, a_y)`` (m/s^2, ``linear_acceleration.y``) from an
    ``/imu/tractor`` message's bytes: straight from the bytes in the plant's layout (frame
    ``base_link``), else by rclpy."""

    def __init__(self) -> None:
        self.fast = CdrReader(api.IMU_MSG, message_template(api.IMU_MSG, api.IMU_FRAME),
                              ['linear_acceleration.y'])

    def read(self, data: bytes) -> tuple[int, float]:
        """Raises :class:`.MessageRejected` 'nonfinite' for a non-finite a_y."""
        fast = self.fast.read(data)
        if fast is not None:
            stamp_ns, (ay,) = fast
        else:
            msg = deserialize(data, Imu)
            stamp_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            ay = float(msg.linear_acceleration.y)
        if not math.isfinite(ay):
            raise MessageRejected('nonfinite', 'Imu with a non-finite linear_acceleration.y')
        return stamp_ns, ay


def _getter(indices: Sequence[int]):
    """A callable giving the tuple of ``indices``' items of a sequence (one or more)."""
    get = itemgetter(*indices)
    return get if len(indices) > 1 else lambda seq: (get(seq),)


def output_values(sample, wheels: Sequence[int]) -> tuple:
    """The numbers of one estimate's messages in :data:`OUTPUTS`' order: the loads of
    ``wheels`` (indices into the sample's), per unit (LTR, quasi-static LTR, 0), the front
    wheels' loads, the front axle's (LTR, quasi-static LTR), 0."""
    ld, ltr, qs, front = sample.load_n, sample.ltr, sample.ltr_quasi_static, sample.front_ltr
    return (*[ld[i] for i in wheels], ltr[0], qs[0], 0.0, ltr[1], qs[1], 0.0, ltr[2], qs[2],
            0.0, ld[0], ld[1], front[0], front[1], 0.0)


class WholeVehicleObserver:
    """The articulated mode of the ``observer`` node ``node`` (its parameters, inputs,
    publishers, timer)."""

    def __init__(self, node, front_axle_specs: tuple) -> None:
        self.node = node
        self.lock = threading.RLock()
        given = set(getattr(node, '_parameter_overrides', None) or {})
        self.names: tuple = ()
        self.params = ParameterGuard(node, specs(node, front_axle_specs),
                                     lambda values: build(values, given, self.names),
                                     self.reconfigure)
        vehicle = self.params.config[0]
        self.names = tuple(self.params.config[2].channel_names)   # the contract's order
        axles = vehicle.axle_names
        instrumented = [j for j, a in enumerate(vehicle.axles) if a.instrumented]
        #: indices of the published wheels (every instrumented axle's) in the estimator's
        self.wheels = tuple(2 * j + s for j in instrumented for s in (0, 1))
        self.take_wheels = _getter(self.wheels)
        self.wheel_names = tuple(api.wheel_joints([axles[j] for j in instrumented]))
        self.axles = axles
        self.period, self.total = Counter(), Counter()
        self.published = 0             # estimates published this period (statuses())
        self.gated_before = [0] * len(self.names)
        self.gated_base: Counter = Counter()
        self.gaps_base = self.gaps_before = 0      # gaps of estimators rebuilt, and reported
        self.max_abs_ltr = [0.0, 0.0, 0.0]
        self.max_abs_ltr_predicted = [0.0, 0.0, 0.0]
        self.last_rejection = ''
        self.last_report = time.monotonic()
        self.speed_mps: float | None = None
        self.reconfigure(self.params.config)
        base = api.BASE_FRAME
        group = [CdrEncoder(api.JOINT_STATE, message_template(
            api.JOINT_STATE, base, self.wheel_names, effort=True), ['effort'])]
        group += [CdrEncoder(api.VECTOR3_STAMPED, message_template(api.VECTOR3_STAMPED, base),
                             ['vector.x', 'vector.y', 'vector.z'])] * 3
        wrench = [CdrEncoder(api.WRENCH, message_template(api.WRENCH, f), ['wrench.force.z'])
                  for f in api.WHEEL_FRAMES]
        group += [*wrench, group[1]]
        self.group = CdrEncoderGroup(group)
        point = CdrEncoder(api.POINT, message_template(api.POINT, api.ROAD_FRAME),
                           ['point.x', 'point.y', 'point.z'])
        #: both wheel paths' points of one stamp (``/road_profile/*`` and the fused ones)
        self.road_group = CdrEncoderGroup([point, point])
        #: an estimate's seven messages and its two road points in one pack
        self.all_group = CdrEncoderGroup([*group, point, point])
        self.half_track_m = float(vehicle.axles[0].wheel_half_track_m)
        self.static_group = CdrEncoderGroup([group[0], *wrench])
        qos = reliable_qos(OUTPUT_DEPTH)
        types = {api.WHEEL_LOADS: JointState, api.STATIC_WHEEL_LOADS: JointState}
        self.pubs = [node.create_publisher(types.get(t, Vector3Stamped if t in (
            *api.UNIT_LOAD_TRANSFER, api.LOAD_TRANSFER) else WrenchStamped), t, qos)
            for t in OUTPUTS]
        self.static_pubs = [node.create_publisher(JointState, api.STATIC_WHEEL_LOADS, qos)] + [
            node.create_publisher(WrenchStamped, t, qos) for t in api.STATIC_LOAD]
        # rclpy's publish of serialized bytes without Publisher.publish's Python
        self.send = [p.handle.publish_raw for p in self.pubs]
        self.send_static = [p.handle.publish_raw for p in self.static_pubs]
        self.road_pubs = [node.create_publisher(PointStamped, t, qos) for t in api.ROAD]
        self.fused_pubs = [node.create_publisher(PointStamped, t, qos) for t in api.ROAD_FUSED]
        self.send_road = [p.handle.publish_raw for p in self.road_pubs]
        self.send_fused = [p.handle.publish_raw for p in self.fused_pubs]
        self.static_stamp_ns: int | None = None
        self.diagnostics_pub = node.create_publisher(DiagnosticArray, api.DIAGNOSTICS,
                                                     reliable_qos(10))
        self.imu = bool(vehicle.tractor_imu)
        self.imu_period, self.imu_total = [0, 0, 0], [0, 0, 0]   # samples by imu_hold code
        self.reader = JointReader([n for n in self.names if n != IMU_CHANNEL]
                                  if self.imu else self.names)
        self.input = ObserverInput(node.get_name(), node.context, self.estimate, self.reject,
                                   read=self.reader.read,
                                   imu=ImuReader().read if self.imu else None)
        self.input.start()
        node.create_timer(1.0, self.diagnostics_callback)
        node.get_logger().info(
            f'vehicle.model: articulated, {len(axles)} axles ({", ".join(axles)}): waiting '
            f'for /suspension/deflections ({len(self.names)} joints) and /vehicle/twist')

    # -- the estimator ----------------------------------------------------------------------
    def reconfigure(self, config) -> None:
        """(Re)build the estimator (at start, and after a good live parameter set: it
        restarts); the estimates a latency still held are published first."""
        with self.lock:
            old = getattr(self, 'estimator', None)
            if old is not None:
                for sample in old.finish():
                    self.publish(sample)
                self.gated_base.update(dict(zip(self.names, old.online.core.gated)))
                self.gated_before = [0] * len(self.names)
                self.gaps_base += old.online.gaps
                self.total['rebuilds'] += 1
                self.node.get_logger().info('parameters changed: estimator rebuilt (it '
                                            'restarts)')
            self.estimator = config[2]
            self.last_stamp_ns: int | None = None
            self.axle_fit = None          # the model fit per axle: the new estimator's

    def reject(self, reason: str, detail: str) -> None:
        with self.lock:
            self.period[reason] += 1
            self.last_rejection = bounded(detail)

    def estimate(self, stamp_ns: int, readings: tuple, speed_mps: float,
                 imu: tuple | None = None) -> None:
        """One sample (the input thread): estimated, its estimates published. ``imu``: the
        tractor IMU's ``(a_y, code)`` at the sample (:mod:`~.estimation.imu_hold`), the
        estimator's last channel."""
        if imu is not None:
            readings = (*readings, imu[0])
        with self.lock:
            self.speed_mps = speed_mps
            last = self.last_stamp_ns
            if last is not None and stamp_ns <= last:
                self.period['time'] += 1
                self.last_rejection = f'stamp {stamp_ns} ns at or before the last ({last} ns)'
                return
            try:
                samples = self.estimator.step(stamp_ns, readings, speed_mps,
                                              imu is None or imu[1] == FRESH)
            except ValueError as exc:
                self.period['nonfinite'] += 1
                self.last_rejection = bounded(str(exc))
                return
            self.last_stamp_ns = stamp_ns
            if imu is not None:
                self.imu_period[imu[1]] += 1
            for sample in samples:
                self.publish(sample)

    def publish(self, sample) -> None:
        """One estimate's messages, and the static loads when due."""
        t = sample.stamp_ns
        ld, ltr, qs, front = sample.load_n, sample.ltr, sample.ltr_quasi_static, sample.front_ltr
        values = (*self.take_wheels(ld), ltr[0], qs[0], 0.0, ltr[1], qs[1], 0.0, ltr[2], qs[2],
                  0.0, ld[0], ld[1], front[0], front[1], 0.0)      # (output_values')
        if not math.isfinite(sum(values)):
            self.period['nonfinite_output'] += 1
            self.last_rejection = f'non-finite estimate at {t} ns'
            return
        x, s, road = sample.distance_m, self.half_track_m, sample.road_m
        u1, u2 = road[0], road[1]
        data = self.all_group.encode(t, (*values, x, s, u1, x, -s, u2))
        for send, one in zip(self.send, data):      # (the first seven)
            send(one)
        if math.isfinite(x + u1 + u2):
            send_left, send_right = self.send_road
            send_left(data[-2])
            send_right(data[-1])
        for stamp, px, left, right in sample.fused:
            if math.isfinite(px + left + right):
                for send, data in zip(self.send_fused, self.road_group.encode(
                        stamp, (px, s, left, px, -s, right))):
                    send(data)
        if api.static_load_due(t, self.static_stamp_ns):
            st = sample.static_n
            loads = [st[i] for i in self.wheels]
            if math.isfinite(sum(loads)):
                self.static_stamp_ns = t
                for send, data in zip(self.send_static, self.static_group.encode(
                        t, (*loads, st[0], st[1]))):
                    send(data)
        self.published += 1
        m, mp = self.max_abs_ltr, self.max_abs_ltr_predicted     # (per unit, in C loops)
        mp[:] = map(max, mp, map(abs, sample.ltr_predicted))
        m[:] = map(max, m, map(abs, sample.ltr))
        self.static_n = sample.static_n
        self.converged = sample.converged
        if sample.axle_fit is not None:
            self.axle_fit = sample.axle_fit

    def finish(self) -> None:
        """Estimate what is still queued, publish what a latency held, wait for the
        subscribers' acknowledgements."""
        self.input.stop()
        with self.lock:
            for sample in self.estimator.finish():
                self.publish(sample)
        for pub in (*self.pubs, *self.static_pubs, *self.road_pubs, *self.fused_pubs):
            pub.wait_for_all_acked(Duration(seconds=1.0))

    def destroy(self) -> None:
        self.input.destroy()

    # -- diagnostics ------------------------------------------------------------------------
    def diagnostics_callback(self) -> None:
        with self.lock:
            msg = DiagnosticArray(status=[diagnostic_status(s) for s in self.statuses()])
        msg.header.stamp = self.node.get_clock().now().to_msg()
        self.diagnostics_pub.publish(msg)

    def statuses(self) -> list[diagnostics.Status]:
        """This period's input, estimator and configuration statuses (the period's counts
        cleared)."""
        now = time.monotonic()
        elapsed, self.last_report = now - self.last_report, now
        period, self.period = self.period, Counter()
        if self.published:
            period['published'] += self.published
            self.published = 0
        period['received'] = self.input.received - self.total['received']
        missed = self.input.missed - self.total['missed']
        period['missed'] = missed
        self.total.update(period)
        name = self.node.get_name()
        rejected = {k: v for k, v in period.items() if k not in (*FLOW, 'missed') and v}
        received = period['received']
        values: dict[str, Any] = {
            'rate_hz': received / elapsed if elapsed > 0 else 0.0, 'received': received,
            'published': period['published'], 'missed': missed,
            'waiting_for_speed': len(self.input.waiting),
            'speed_mps': 'none' if self.speed_mps is None else self.speed_mps}
        values.update({f'rejected.{k}': v for k, v in sorted(rejected.items())})
        values.update({f'total.{k}': v for k, v in sorted(self.total.items())})
        if rejected:
            values['last_rejection'] = self.last_rejection
            self.node.get_logger().warning(
                'rejected inputs: ' + ', '.join(f'{k} {v}' for k, v in sorted(rejected.items()))
                + f' (last: {self.last_rejection})')
        message = ('no input' if not received else f'{sum(rejected.values())} rejected'
                   if rejected else f'falling behind: {missed} inputs missed' if missed
                   else 'ok')
        input_status = diagnostics.status('observer: input', name, message, values)
        return [input_status, self.estimator_status(name), diagnostics.status(
            'observer: configuration', name, 'ok', {
                'vehicle.model': 'articulated', 'axles': ', '.join(self.axles),
                'channels': len(self.names), 'road_online': 'every axle, fused',
                'refused_parameter_sets': len(self.params.refusals)})]

    def estimator_status(self, name: str) -> diagnostics.Status:
        est = self.estimator
        static = getattr(self, 'static_n', est.static_n)
        values: dict[str, Any] = {'converged': bool(getattr(self, 'converged', False))}
        for j, axle in enumerate(self.axles):
            values[f'static_load_{axle}_n'] = static[2 * j] + static[2 * j + 1]
        values['gross_weight_n'] = sum(static)
        m, self.max_abs_ltr = self.max_abs_ltr, [0.0, 0.0, 0.0]
        values.update({f'max_abs_ltr_{u}': v for u, v in zip(UNITS, m)})
        mp, self.max_abs_ltr_predicted = self.max_abs_ltr_predicted, [0.0, 0.0, 0.0]
        values.update({f'max_abs_ltr_{u}_predicted': v for u, v in zip(UNITS, mp)})
        gated = list(est.online.core.gated)
        values.update({f'innovations_gated.{c}': g - b for c, g, b in
                       zip(self.names, gated, self.gated_before)})
        self.gated_before = gated
        gaps = self.gaps_base + est.online.gaps
        values['gaps'], values['total.gaps'] = gaps - self.gaps_before, gaps
        self.gaps_before = gaps
        total = self.gated_base + Counter(dict(zip(self.names, gated)))
        values.update({f'total.innovations_gated.{c}': total[c] for c in self.names})
        fc = est.faults.counts()               # stuck and drifting sensors (sensor_health)
        values.update(diagnostics.sensor_values(fc.flags))
        values.update({f'total.stuck.{c}': n for c, n in fc.stuck_episodes.items()})
        values.update({f'total.drift.{c}': n for c, n in fc.drift_episodes.items()})
        message = diagnostics.fault_message(fc.flags) or (
            'ok' if values['converged'] else 'converging')
        warned = [u for u, v in zip(UNITS, mp) if v >= WARNING_THRESHOLD]
        if warned:
            message += (f'; rollover warning: {", ".join(warned)} predicted |LTR| >= '
                        f'{WARNING_THRESHOLD:g}')
        if self.imu:            # the tractor IMU's pairing (estimation.imu_hold)
            period, self.imu_period = self.imu_period, [0, 0, 0]
            self.imu_total = [a + b for a, b in zip(self.imu_total, period)]
            late = []
            for code in (STALE, MISSING):
                values[f'imu.{STATES[code]}'] = period[code]
                values[f'total.imu.{STATES[code]}'] = self.imu_total[code]
                if period[code]:
                    late.append(f'{period[code]} {STATES[code]}')
            if late:
                message += f'; tractor IMU: {", ".join(late)} samples'
        fit = self.axle_fit
        if fit is not None:
            values.update(fit.status_values())
            if fit.culprits:
                message += f'; model fit: {", ".join(fit.culprits)} {ADVICE}'
        return diagnostics.status('observer: estimator', name, message, values)
