"""``observer`` node: the estimator (estimator.py), one estimate per measurement message.

Subscribes ``/suspension/deflections`` (sensor-data QoS) and ``/vehicle/twist`` (best effort,
which matches reliable and best-effort publishers); per accepted deflection message publishes
``/wheel_load/left|right``, ``/road_profile/left|right``, ``/load_transfer_ratio``,
``/load_transfer`` (x = LTR, y = quasi-static LTR) and ``/observer/states`` (reliable),
stamped with the estimate's stamp (the input's), ``/wheel_load/static/left|right`` (the static
loads F_c,i: configured, or estimated under ``vehicle.deflection_reference: zero_load``) with
the first estimate of every 0.1 s of stamps, and ``/diagnostics`` at 1 Hz
(INTERFACES.md). Messages come and go as CDR bytes (:mod:`.wire`: the same bytes as rclpy's,
without a message object per message).

Inputs (:mod:`.observer_input`): taken by a thread of their own, what queued up at once, so a
node that falls behind estimates what it took, and what it could not take is dropped by DDS
as whole runs of samples, which the estimator's stamp rules take as the long steps or gaps
they are: the estimates it publishes are those ``estimate_bag`` gives on the inputs it took,
gaps included. Memory stays bounded under any flood and ``/diagnostics`` comes on time. Each
sample gets the speed of the latest twist stamped at or before it (as ``estimate_bag``);
samples before the first twist wait (up to :data:`.observer_input.MAX_WAITING`, the oldest
dropped and counted beyond). A second publisher on ``/suspension/deflections`` is detected by
its sequence numbers (:mod:`.sources`), named (the topic's publishers) in one warning and in
the diagnostics, and its samples are not mixed in.

Rejected and counted, never misread (the node keeps running and never publishes NaN): a
JointState whose arrays differ in length from ``name`` or that lacks a joint, a non-finite value
(:mod:`.messages`); a duplicate or backwards stamp, an impossible value, and gaps (a restart) in
the core. Log lines and diagnostic values are bounded in size (:data:`.messages.MAX_TEXT`).
Live parameter changes are vetted (:class:`.ros_parameters.ParameterGuard`); a good one
rebuilds the estimator, which restarts.

With ``vehicle.model: articulated`` given at start (``-p`` or ``--params-file``) the node
estimates the whole tractor and semi-trailer instead (:mod:`.whole_vehicle_observer`: its
parameters, inputs, outputs and diagnostics); a live set cannot switch the model.

Started after its publisher, the observer says what it missed: when a publisher's
``/diagnostics`` give the stamp of its first measurement (``first_stamp_ns:<topic>``:
plant_simulator, bag_player), the samples before the observer's first input (that gap over
the stamps' own period) are counted as ``missed`` and reported as ``missed_before_first_input``
with a warning; the input status also gives ``first_stamp_ns``, the stamp of its first input.
"""
from __future__ import annotations

from collections import Counter
import math
import sys
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped, Vector3Stamped, WrenchStamped
from rclpy.duration import Duration
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from road_force_estimator import interfaces as api
from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
from road_force_estimator.estimation import Estimator, diagnostics, fit_check
from road_force_estimator.ros.messages import bounded, diagnostic_status, reliable_qos
from road_force_estimator.ros.node_runner import run_node
from road_force_estimator.ros.observer_input import MAX_WAITING, ObserverInput
from road_force_estimator.ros.ros_parameters import (
    ParameterGuard, articulated_requested, specs_with_prefix)
from road_force_estimator.ros.start_gate import first_stamps
from road_force_estimator.ros.whole_vehicle_observer import WholeVehicleObserver
from road_force_estimator.ros.wire import Wire

SPECS = specs_with_prefix('vehicle.', 'observer.')
#: Estimates each output's publisher keeps until its reliable subscribers acknowledge them
#: (1 s at 1 kHz): what the input thread publishes in one go after a backlog is not
#: overwritten before a slow subscriber (a recorder on a loaded machine) has taken it.
OUTPUT_DEPTH = 1000
__all__ = ['MAX_WAITING', 'Observer', 'main']
# The core's counters, by the names the diagnostics give them.
CORE_COUNTERS = {'rejected_nonfinite': 'nonfinite', 'rejected_range': 'range',
                 'rejected_speed': 'speed', 'rejected_stale': 'stale',
                 'speed_contradicted': 'speed_contradicted',
                 'negative_load_samples': 'negative_loads',
                 'rejected_time': 'time', 'resets': 'resets', 'gaps': 'gaps'}
# Further EstimatorStatus fields reported as they are (those the core has).
ESTIMATOR_VALUES = ('method', 'latency_samples', 'pending', 'noise_deflection_m',
                    'noise_roll_rad', 'road_roughness_m3')
# The rest of a period's counts are rejections. 'missed': inputs published that never arrived
# (lost on the way, e.g. dropped by DDS when the node falls behind a burst), from the
# publishers' sequence numbers; where the middleware gives none, inferred from the stamps (a
# step of k typical periods means k - 1 samples lost). They are not rejections but make the
# input WARN. 'stamps_skipped': what the stamps say is absent (lost before it was published,
# or on the way), with the sequence numbers beside it.
FLOW_COUNTS = ('received', 'published', 'lift_offs', 'missed', 'stamps_skipped')
MISSED_MAX_PERIODS = 1000  # a longer silence is a pause or a restart, not a burst of losses
MISSED_BEFORE_MAX_NS = 3600 * 10**9  # a publisher's first stamp further back: another drive


def build(values):
    if values.get('vehicle.model') == 'articulated':
        raise ValueError("vehicle.model = 'articulated': the vehicle model is set at start "
                         '(-p or --params-file); with front-axle parameters the observer '
                         "estimates an articulated truck's front axle")
    return VehicleParameters.from_parameters(values), ObserverParameters.from_parameters(values)


def static_findings(vehicle: VehicleParameters, observer: ObserverParameters) -> list[str]:
    """Configuration findings (robot_localization style: reported with every diagnostic)."""
    found = []
    if observer.discretization == 'euler':
        found.append("observer.discretization = 'euler': the paper's explicit scheme, a "
                     'reference; expect about a quarter of the dynamic-load RMS as error')
    if observer.latency_s > 0.0:
        found.append(f'observer.latency = {observer.latency_s:g} s: estimates are published '
                     f'with the stamp of the sample they are for')
    if vehicle.roll_sensor == 'pendulum':
        found.append("vehicle.roll_sensor = 'pendulum': the front-axle model has no lateral "
                     'acceleration to read it with, so it is read as plain roll; in curves the '
                     'loads err (docs/sensors.md)')
    elif vehicle.roll_sensor == 'gyro':
        found.append("vehicle.roll_sensor = 'gyro': read as roll; its drift is not estimated "
                     '(docs/sensors.md)')
    return found


class Observer(Node):
    """Thin wrapper: messages in, :meth:`.Estimator.update`, messages out."""

    def __init__(self, **kwargs):
        super().__init__('observer', **kwargs)
        #: vehicle.model: articulated given at start: the whole vehicle's mode, else None
        self.whole = None
        if articulated_requested(self):
            self.whole = WholeVehicleObserver(self, SPECS)
            return
        self.lock = threading.RLock()      # the estimator and counters: input thread, executor
        self.params = ParameterGuard(self, SPECS, build, self.reconfigure)
        self.period, self.total = Counter(), Counter()   # node-side counters
        self.core_base = Counter()                        # counters of retired estimators
        self.core_reported = Counter()
        self.last_rejection = ''
        self.extremes = {'max_abs_ltr': 0.0, 'max_abs_residual_nm': 0.0}
        self.last_report = time.monotonic()
        self.last_stamp_ns = None
        self.shortest_step_ns = [math.inf, math.inf]   # (last period, this period)
        self.reconfigure(self.params.config)
        self.load_pubs = [self.create_publisher(WrenchStamped, topic, reliable_qos(OUTPUT_DEPTH))
                          for topic in api.LOAD]
        self.static_pubs = [self.create_publisher(WrenchStamped, topic, reliable_qos(OUTPUT_DEPTH))
                            for topic in api.STATIC_LOAD]
        self.static_stamp_ns = None   # stamp of the last static loads published
        self.road_pubs = [self.create_publisher(PointStamped, topic, reliable_qos(OUTPUT_DEPTH))
                          for topic in api.ROAD]
        self.ltr_pub = self.create_publisher(Float64, api.LTR, reliable_qos(OUTPUT_DEPTH))
        self.load_transfer_pub = self.create_publisher(Vector3Stamped, api.LOAD_TRANSFER,
                                                       reliable_qos(OUTPUT_DEPTH))
        self.states_pub = self.create_publisher(JointState, api.STATES, reliable_qos(OUTPUT_DEPTH))
        # Per estimate: rclpy's publish of serialized bytes without Publisher.publish's
        # Python (its type check and handle guard: 1.5-2 us a call); in wire.OUTPUTS' order.
        self.send = [pub.handle.publish_raw for pub in (
            *self.load_pubs, *self.road_pubs, self.ltr_pub, self.load_transfer_pub,
            self.states_pub)]
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, api.DIAGNOSTICS,
                                                     reliable_qos(10))
        self.wire = Wire()
        self.speed_mps = None
        self.sources_said = 1      # sources on /suspension/deflections last told in the log
        self.taken = (0, 0)        # the input's (received, missed) at the last report
        self.input = ObserverInput(self.get_name(), self.context, self.estimate, self.reject)
        self.input.wire.on_note = self.get_logger().warning
        self.input_topic = self.resolve_topic_name(api.DEFLECTIONS)
        # the publishers' first stamps (status name -> ns), and the count they give
        self.first_input_ns = self.missed_before = None
        self.publisher_first_ns: dict[str, int] = {}
        self.create_subscription(DiagnosticArray, api.DIAGNOSTICS, self.publisher_diagnostics,
                                 reliable_qos(10))
        self.input.start()
        self.create_timer(1.0, self.diagnostics_callback)
        self.input_seen = False  # logged once: waiting, then the rate input arrives at
        self.get_logger().info('waiting for /suspension/deflections and /vehicle/twist')

    def reconfigure(self, config) -> None:
        """(Re)build the estimator from ``(VehicleParameters, ObserverParameters)``."""
        with self.lock:
            self._reconfigure(config)

    def _reconfigure(self, config) -> None:
        old = getattr(self, 'estimator', None)
        if old is not None:
            for est in old.flush():  # estimates held back (observer.latency > 0): publish them
                self.publish(est)
            self.core_base.update(self.core_counts(old))
            self.total['rebuilds'] += 1
            self.get_logger().info('parameters changed: estimator rebuilt (it restarts)')
        self.estimator = Estimator(*config)
        # observer.latency > 0: an accepted sample may give no estimate yet (held back)
        self.holds_back = config[1].latency_s > 0.0
        self.fit = fit_check.ModelFitMonitor()    # restarts with the estimator
        self.findings = static_findings(*config)
        self.half_track_m = config[0].half_track_m

    def finish(self) -> None:
        """Estimate what is still queued, publish the estimates still held back
        (``observer.latency`` > 0) before leaving."""
        if self.whole is not None:
            self.whole.finish()
            return
        self.input.stop()
        with self.lock:
            for est in self.estimator.flush():
                self.publish(est)
        for pub in (*self.load_pubs, *self.static_pubs, *self.road_pubs, self.ltr_pub,
                    self.load_transfer_pub, self.states_pub):
            pub.wait_for_all_acked(Duration(seconds=1.0))

    def core_counts(self, estimator=None) -> Counter:
        st = (estimator or self.estimator).status
        return Counter({short: getattr(st, name) for name, short in CORE_COUNTERS.items()})

    def reject(self, reason: str, detail: str) -> None:
        with self.lock:
            self.period[reason] += 1
            self.last_rejection = bounded(detail)

    def publisher_diagnostics(self, msg: DiagnosticArray) -> None:
        """Keep the first stamp a publisher's diagnostics give for our input topic."""
        for status in msg.status:
            if not status.name.startswith('observer:'):
                first = first_stamps(((v.key, v.value) for v in status.values),
                                     self.input_topic)
                if first is not None:
                    with self.lock:
                        self.publisher_first_ns[status.name] = first

    def count_missed_before_first(self) -> None:
        """Once the first input and a publisher's first stamp are known: the samples between
        them (over the stamps' period) were sent before the observer listened."""
        dt_s = self.estimator.status.typical_dt_s
        if self.missed_before is not None or self.first_input_ns is None or not dt_s > 0.0:
            return
        earlier = [f for f in self.publisher_first_ns.values()
                   if 0 <= self.first_input_ns - f <= MISSED_BEFORE_MAX_NS]
        if not earlier:
            return
        self.missed_before = round((self.first_input_ns - max(earlier)) * 1e-9 / dt_s)
        if self.missed_before:
            self.period['missed'] += self.missed_before
            self.get_logger().warning(
                f'{self.missed_before} samples of {self.input_topic} were published before '
                f'the first one arrived here: start the observer before its publisher, or let '
                f'the publisher wait for it (plant_simulator start_nodes, bag_player '
                f'--wait-for)')

    def count_missed(self, stamp_ns: int) -> None:
        """Count the samples the stamps say were sent but never arrived, between two samples
        the core accepted: a step of k sample periods (the shortest step of this and the last
        diagnostics period) means k - 1 lost."""
        last, self.last_stamp_ns = self.last_stamp_ns, stamp_ns
        if last is None:
            return
        step, period = stamp_ns - last, min(self.shortest_step_ns)
        self.shortest_step_ns[1] = min(self.shortest_step_ns[1], step)
        if period < math.inf and 1 < (periods := round(step / period)) <= MISSED_MAX_PERIODS:
            self.period['missed'] += periods - 1

    def estimate(self, stamp_ns: int, q_m, roll_rad: float, speed_mps: float) -> None:
        """One sample (the input thread), with its speed: estimated, published."""
        with self.lock:
            self.speed_mps = speed_mps
            if self.first_input_ns is None:
                self.first_input_ns = stamp_ns
            if self.holds_back:   # accepted or not: the core's count says (held back)
                accepted = self.estimator.status.accepted
                est = self.estimator.update(stamp_ns, q_m, roll_rad, speed_mps)
                if self.estimator.status.accepted > accepted:
                    self.count_missed(stamp_ns)
            else:  # no latency: an accepted sample gives its estimate at once, a rejected none
                est = self.estimator.update(stamp_ns, q_m, roll_rad, speed_mps)
                if est is not None:
                    self.count_missed(stamp_ns)
            if est is not None:  # None: rejected by the core (counted), or held back
                self.publish(est)

    def publish(self, est) -> None:
        """The seven output messages of one estimate, stamped with its sample's stamp, and
        the static loads once per :data:`.interfaces.STATIC_LOAD_PERIOD_NS`."""
        (f1, f2), (u1, u2), s = est.wheel_load_n, est.road_m, self.half_track_m
        x, ltr, ltr_qs = est.distance_m, est.ltr, est.ltr_quasi_static
        states = (*est.q_m, est.roll_rad, est.body_heave_m, *est.wheel_heave_m,
                  *est.dq, est.droll, est.body_heave_rate, *est.wheel_heave_rate)
        if not math.isfinite(f1 + f2 + u1 + u2 + ltr + ltr_qs + x + sum(states)):
            self.reject('nonfinite_output', f'non-finite estimate at {est.stamp_ns} ns')
            return
        t = est.stamp_ns
        for send, data in zip(self.send, self.wire.outputs.encode(
                t, (f1, f2, x, s, u1, x, -s, u2, ltr, ltr, ltr_qs, 0.0, *states))):
            send(data)
        if api.static_load_due(t, self.static_stamp_ns) and math.isfinite(
                sum(est.static_load_n)):
            self.static_stamp_ns = t
            for pub, encoder, load in zip(self.static_pubs, self.wire.loads,
                                          est.static_load_n):
                pub.publish(encoder.encode(t, (load,)))
        period, ex = self.period, self.extremes
        period['published'] += 1
        period['lift_offs'] += est.lift_off[0] or est.lift_off[1]
        ex['max_abs_ltr'] = max(ex['max_abs_ltr'], abs(ltr))
        ex['max_abs_residual_nm'] = max(ex['max_abs_residual_nm'], abs(est.residual_nm))
        self.fit.update(t * 1e-9, est.residual_nm)

    def log_input(self, values: dict, rejected: Counter) -> None:
        """One line when input first arrives (its rate), then only when inputs are rejected."""
        if values['received'] and not self.input_seen:
            self.input_seen = True
            self.get_logger().info(f"input arriving on /suspension/deflections at "
                                   f"{values['rate_hz']:.0f} Hz")
        if rejected:
            reasons = ', '.join(f'{k} {v}' for k, v in sorted(rejected.items()))
            last = f' (last: {self.last_rejection})' if self.last_rejection else ''
            self.get_logger().warning(f'rejected inputs: {reasons}{last}')

    def diagnostics_callback(self) -> None:
        """Input, estimator and configuration statuses: this period's counts (cleared after
        each report), then the totals."""
        with self.lock:
            self._diagnostics()

    def _sources(self, values: dict) -> None:
        """Two or more publishers interleaving on /suspension/deflections: named once in the
        log and in the diagnostics."""
        live = self.input.live_sources()
        if live > 1:
            infos = self.get_publishers_info_by_topic(api.DEFLECTIONS)
            names = ', '.join(sorted(f"{i.node_namespace.rstrip('/')}/{i.node_name}"
                                     for i in infos)) or 'unknown'
            values['sources'] = live
            values['publishers'] = bounded(names)
            if live != self.sources_said:
                self.get_logger().warning(bounded(
                    f'{live} publishers interleave on {api.DEFLECTIONS} ({names}): the first '
                    'one is followed, the samples of the others are rejected (second_source)',
                    2 * 240))
        self.sources_said = live

    def _diagnostics(self) -> None:
        now = time.monotonic()
        elapsed, self.last_report = now - self.last_report, now
        core = self.core_base + self.core_counts()
        fresh, self.core_reported = core - self.core_reported, core
        self.count_missed_before_first()
        period, self.period = self.period, Counter()
        taken, self.taken = self.taken, (self.input.received, self.input.missed)
        period['received'] = self.taken[0] - taken[0]
        if self.input.sources.started:   # lost on the way, the publishers' numbers say;
            period['stamps_skipped'] = period['missed']   # the stamps: maybe never sent
            period['missed'] = self.taken[1] - taken[1]
        self.total.update(period)
        self.shortest_step_ns = [self.shortest_step_ns[1], math.inf]
        msg = DiagnosticArray(status=[diagnostic_status(st) for st in (
            self.input_status(period, fresh, core, elapsed),
            self.estimator_status(period, fresh), self.configuration_status())])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.diagnostics_pub.publish(msg)

    def input_status(self, period: Counter, fresh: Counter, core: Counter,
                     elapsed: float) -> diagnostics.Status:
        st = self.estimator.status
        rejected = Counter({k: v for k, v in period.items() if k not in FLOW_COUNTS})
        rejected.update({k: fresh[k] for k in ('nonfinite', 'range', 'speed', 'stale', 'time')
                        if fresh[k]})
        received, missed = period['received'], period['missed']
        waiting = self.input.waiting
        values = {'rate_hz': received / elapsed if elapsed > 0 else 0.0, 'received': received,
                  'published': period['published'], 'missed': missed,
                  'waiting_for_speed': len(waiting),
                  'first_stamp_ns': 'none' if self.first_input_ns is None else
                  self.first_input_ns,
                  'missed_before_first_input': 'unknown' if self.missed_before is None else
                  self.missed_before,
                  'speed_mps': 'none' if self.speed_mps is None else self.speed_mps}
        self._sources(values)
        values.update({f'rejected.{k}': v for k, v in sorted(rejected.items())})
        values.update({f'total.{k}': v for k, v in sorted((self.total + core).items())})
        message = ('no input' if not received else f'{sum(rejected.values())} rejected'
                   if rejected else f'{len(waiting)} waiting for a speed' if waiting
                   else f'falling behind: {missed} of {received + missed} inputs missed'
                   if missed else 'ok')
        if period.keys() - FLOW_COUNTS:  # rejected here (not in the core): say the last why
            values['last_rejection'] = self.last_rejection
        if st.typical_dt_s > 0.0:  # the rate the stamps say, against the rate that came
            values['stamp_rate_hz'] = 1.0 / st.typical_dt_s
        self.log_input(values, rejected)
        return diagnostics.status('observer: input', self.get_name(), message, values)

    def estimator_status(self, period: Counter, fresh: Counter) -> diagnostics.Status:
        st = self.estimator.status
        ex, self.extremes = self.extremes, dict.fromkeys(self.extremes, 0.0)
        lifts, resets = period['lift_offs'], fresh['resets']
        values = {'converged': st.converged, 'time_since_start_s': st.time_since_start_s,
                  'settling_time_s': getattr(self.estimator, 'settling_time_s',
                                             st.settling_time_s), 'resets': resets,
                  'gaps': fresh['gaps'], 'residual_nm': st.last_residual_nm,
                  'lift_off_samples': lifts, 'lift_off_left': st.lift_off[0],
                  'lift_off_right': st.lift_off[1], **ex}
        values.update({k: getattr(st, k) for k in ESTIMATOR_VALUES if hasattr(st, k)})
        if getattr(self.estimator, 'static_load', None) is not None:   # zero_load: estimated
            values.update(sprung_mass_kg=st.sprung_mass_kg,
                          static_load_left_n=st.static_load_n[0],
                          static_load_right_n=st.static_load_n[1])
        if fresh['speed_contradicted']:
            values['speed_contradicted_samples'] = fresh['speed_contradicted']
        if fresh['negative_loads']:
            values['negative_load_samples'] = fresh['negative_loads']
        gated = dict(getattr(st, 'innovations_gated', None) or {})    # (the model's core)
        before, self.gated_reported = getattr(self, 'gated_reported', {}), gated
        values.update(diagnostics.sensor_values(
            getattr(st, 'sensor_faults', None) or {},
            {name: n - before.get(name, 0) if n >= before.get(name, 0) else n
             for name, n in gated.items()}))     # (a new estimator counts from 0)
        values.update({f'total.{k}': v for k, v in diagnostics.sensor_totals(st).items()})
        gains = getattr(self.estimator.core, 'gains', None)   # the model's gains in use
        ratio = self.fit.ratio(fit_check.gains_sigma_nm(gains)) if gains else math.nan
        word = fit_check.verdict(ratio)
        values.update(diagnostics.model_fit_values(ratio, word))
        return diagnostics.estimator_status('observer: estimator', self.get_name(), values,
                                            converged=st.converged, lift_off_samples=lifts,
                                            restarts=resets,
                                            speed_contradicted=fresh['speed_contradicted'],
                                            model_fit=word)

    def configuration_status(self) -> diagnostics.Status:
        values = {f'finding.{i}': f for i, f in enumerate(self.findings)}
        values['refused_parameter_sets'] = len(self.params.refusals)
        return diagnostics.status('observer: configuration', self.get_name(),
                                  '; '.join(self.findings) or 'ok', values,
                                  level=diagnostics.WARN if self.findings else diagnostics.OK)


    def destroy_node(self):
        (self.whole or self.input).destroy()
        super().destroy_node()


def main(args=None) -> int:
    return run_node('observer', __doc__.splitlines()[0], SPECS, args, Observer,
                    finish=lambda executor, node: node.finish())


if __name__ == '__main__':
    sys.exit(main())
