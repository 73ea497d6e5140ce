"""observer node: plant_simulator -> observer end to end, bad messages, parameters, main().

Nodes spin in the test process (fresh rclpy context per test); main() runs in a subprocess.
Load-error bound: the one the observer core states in test_estimator.py for its implicit chain
(no noise, ISO 8608 class C at 20 m/s and 1 kHz, after 2 s: RMS error <= 8 % of the true
dynamic-load RMS); the node runs the default observer (``observer.discretization``), which must
meet it too.
"""
import math
import time
import signal

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import TwistStamped
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState

from node_harness import Collector, close, finish, make_executor, run_main
from road_force_estimator.estimation import estimate_batch
from road_force_estimator.interfaces import STATE_JOINTS
from road_force_estimator.ros.messages import (
    deflections_msg, ns_to_stamp, reliable_qos, sensor_qos, twist_msg)
from road_force_estimator.ros.observer import Observer
from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
from road_force_estimator.ros.plant_simulator import PlantSimulator
from road_force_estimator.ros.ros_parameters import ParameterError
from ros_helpers import spin_until

OUTPUTS = ['/wheel_load/left', '/wheel_load/right', '/road_profile/left', '/road_profile/right',
           '/load_transfer_ratio', '/load_transfer', '/observer/states']
STAMPED = [t for t in OUTPUTS if t != '/load_transfer_ratio']
T0_NS = 1_700_000_000_000_000_000


def test_plant_to_observer_one_output_per_input_and_load_error(ros_context):
    collector = Collector(ros_context, ['/suspension/deflections', '/vehicle/twist',
                                        '/ground_truth/wheel_load/left',
                                        '/ground_truth/wheel_load/right', *OUTPUTS])
    observer = Observer(context=ros_context)
    plant = PlantSimulator(context=ros_context, parameter_overrides=[
        Parameter('simulator.duration', value=4.0), Parameter('simulator.road',
                                                              value='iso8608:C:seed=3'),
        Parameter('simulator.noise.deflection', value=0.0),
        Parameter('simulator.noise.roll', value=0.0), Parameter('realtime_factor', value=0.5)])
    executor = make_executor(ros_context, collector, observer, plant)
    try:
        assert spin_until(executor, lambda: plant.finished, 60.0)
        n = plant.k
        assert n == 4001
        assert spin_until(executor, lambda: all(
            collector.count(t) >= n for t in ['/suspension/deflections', *OUTPUTS]), 30.0)
        executor.spin_once(timeout_sec=0.1)  # nothing more may come
    finally:
        close(executor, plant, observer, collector)
    received = observer.input.received
    stamps = collector.stamps('/observer/states')
    # One output per input on every output topic, in order, with the input's stamp.
    for topic in STAMPED:
        assert collector.stamps(topic) == stamps, topic
    assert collector.count('/load_transfer_ratio') == len(stamps)
    assert len(stamps) == received == n
    by_stamp = dict(zip(collector.stamps('/suspension/deflections'),
                        collector.messages['/suspension/deflections']))
    inputs = [by_stamp[s] for s in stamps]
    # The outputs are the core's estimates on these inputs (field mapping, order, signs).
    q = np.array([m.position[:2] for m in inputs])
    phi = np.array([m.position[2] for m in inputs])
    ref = estimate_batch(np.array(stamps), q, phi, 20.0, VehicleParameters(),
                         ObserverParameters())
    got = {t: collector.messages[t] for t in OUTPUTS}
    loads = np.array([[m.wrench.force.z for m in got[t]] for t in OUTPUTS[:2]]).T
    np.testing.assert_allclose(loads, ref.wheel_load_n, rtol=1e-12)
    np.testing.assert_allclose([[m.point.z for m in got[t]] for t in OUTPUTS[2:4]],
                               ref.road_m.T, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose([m.point.x for m in got['/road_profile/left']], ref.distance_m)
    assert {m.point.y for m in got['/road_profile/left']} == {1.0}
    assert {m.point.y for m in got['/road_profile/right']} == {-1.0}
    np.testing.assert_allclose([m.data for m in got['/load_transfer_ratio']], ref.ltr,
                               rtol=1e-12, atol=1e-15)
    # /load_transfer: x = LTR, y = quasi-static LTR (MODEL.md step 8), z = 0, base_link
    both = got['/load_transfer']
    assert {m.header.frame_id for m in both} == {'base_link'}
    np.testing.assert_allclose([[m.vector.x, m.vector.y, m.vector.z] for m in both],
                               np.column_stack([ref.ltr, ref.ltr_quasi_static,
                                                np.zeros(len(ref.ltr))]), rtol=1e-12,
                               atol=1e-15)
    states = got['/observer/states']
    assert {tuple(m.name) for m in states} == {STATE_JOINTS}
    np.testing.assert_allclose([m.position for m in states], np.column_stack(
        [ref.q_m, ref.roll_rad, ref.body_heave_m, ref.wheel_heave_m]), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose([m.velocity for m in states], np.column_stack(
        [ref.dq, ref.droll, ref.body_heave_rate, ref.wheel_heave_rate]), rtol=1e-12,
        atol=1e-15)
    # Load error against the ground truth topics, after convergence (t >= 2 s).
    truth = np.array([[m.wrench.force.z for m in collector.messages[t]] for t in (
        '/ground_truth/wheel_load/left', '/ground_truth/wheel_load/right')]).T
    after = (np.array(stamps) - stamps[0]) >= 2_000_000_000
    err = loads[after] - truth[after]
    dynamic_rms = truth[after].std(axis=0)
    assert np.all(np.sqrt(np.mean(err ** 2, axis=0)) <= 0.08 * dynamic_rms), (
        np.sqrt(np.mean(err ** 2, axis=0)) / dynamic_rms)


class Feeder(Node):
    """Publishes hand-made measurement messages to the observer."""

    def __init__(self, context):
        super().__init__('feeder', context=context)
        self.deflections = self.create_publisher(JointState, '/suspension/deflections',
                                                 sensor_qos(1000))
        self.twist = self.create_publisher(TwistStamped, '/vehicle/twist', reliable_qos())

    def sample(self, k, speed=None):
        q = (1e-3 * math.sin(0.05 * k), -1e-3 * math.cos(0.05 * k))
        if speed is not None:
            self.twist.publish(twist_msg(T0_NS + k * 1_000_000, speed))
        self.deflections.publish(deflections_msg(T0_NS + k * 1_000_000, q, 1e-4 * k))

    def raw(self, stamp_ns, names, position):
        msg = JointState(name=names, position=position)
        msg.header.stamp = ns_to_stamp(stamp_ns)
        self.deflections.publish(msg)


@pytest.fixture
def make_rig(ros_context):
    """make_rig(**parameters): an observer, a feeder and a collector of the outputs and the
    diagnostics, matched."""
    made = []

    def make(**params):
        overrides = [Parameter(k.replace('__', '.'), value=v) for k, v in params.items()]
        observer = Observer(context=ros_context, parameter_overrides=overrides)
        feeder = Feeder(ros_context)
        collector = Collector(ros_context, [*OUTPUTS, '/diagnostics'])
        executor = make_executor(ros_context, observer, feeder, collector)
        made.append((executor, observer, feeder, collector))
        assert spin_until(executor, lambda: feeder.deflections.get_subscription_count() > 0
                          and feeder.twist.get_subscription_count() > 0
                          and observer.states_pub.get_subscription_count() > 0, 10.0)
        return observer, feeder, collector, executor

    yield make
    for executor, *nodes in made:
        close(executor, *nodes)


@pytest.fixture
def rig(make_rig):
    return make_rig()


def input_diagnostics(collector):
    """Key-values of the newest 'observer: input' status."""
    for msg in reversed(collector.messages['/diagnostics']):
        for status in msg.status:
            if status.name == 'observer: input':
                return {kv.key: kv.value for kv in status.values}
    return {}


def test_bad_messages_are_counted_and_the_node_keeps_going(rig):
    observer, feeder, collector, executor = rig
    for k in range(10):
        feeder.sample(k, speed=20.0)
    stamp = T0_NS + 10 * 1_000_000
    feeder.raw(stamp, ['left_suspension', 'right_suspension', 'roll'], [0.0, math.nan, 0.0])
    feeder.raw(stamp, ['a', 'b', 'c'], [0.0, 0.0, 0.0])
    feeder.raw(stamp, ['left_suspension', 'roll'], [0.0, 0.0])
    feeder.raw(stamp, ['left_suspension', 'right_suspension', 'roll'], [0.0, 0.0])
    feeder.raw(T0_NS + 9 * 1_000_000, ['roll', 'left_suspension', 'right_suspension'],
               [0.0, 0.0, 0.0])                                    # duplicate stamp
    feeder.raw(T0_NS + 5 * 1_000_000, ['roll', 'left_suspension', 'right_suspension'],
               [0.0, 0.0, 0.0])                                    # backwards
    for k in range(10, 20):
        feeder.sample(k, speed=20.0)
    assert spin_until(executor, lambda: collector.count('/observer/states') >= 20, 10.0)
    want = {'total.nonfinite': '1', 'total.names': '2', 'total.length': '1',
            'total.time': '2'}
    assert spin_until(executor, lambda: all(
        input_diagnostics(collector).get(k) == v for k, v in want.items()), 5.0), (
        input_diagnostics(collector))
    # Only the 20 good samples gave outputs, in order, never a NaN.
    assert collector.stamps('/observer/states') == [T0_NS + k * 1_000_000 for k in range(20)]
    for topic in STAMPED:
        assert collector.count(topic) == 20
    values = [m.wrench.force.z for t in OUTPUTS[:2] for m in collector.messages[t]]
    values += [m.data for m in collector.messages['/load_transfer_ratio']]
    values += [v for m in collector.messages['/observer/states'] for v in m.position]
    assert np.all(np.isfinite(values))
    # The names were mapped by name: a reordered JointState reads the same.
    assert observer.estimator.status.accepted == 20


def test_samples_before_the_first_speed_wait_for_it(rig):
    observer, feeder, collector, executor = rig
    for k in range(5):
        feeder.sample(k)
    assert spin_until(executor, lambda: len(observer.input.waiting) == 5, 10.0)
    assert collector.count('/observer/states') == 0
    feeder.twist.publish(twist_msg(T0_NS, 10.0))
    assert spin_until(executor, lambda: collector.count('/road_profile/left') == 5, 10.0)
    # Distance = v t at the speed that arrived (10 m/s, 1 ms apart).
    np.testing.assert_allclose([m.point.x for m in collector.messages['/road_profile/left']],
                               10.0 * np.arange(5) * 1e-3, atol=1e-12)


def test_live_parameters_refused_or_rebuilding(rig):
    observer, feeder, collector, executor = rig
    for k in range(10):
        feeder.sample(k, speed=20.0)
    assert spin_until(executor, lambda: collector.count('/observer/states') == 10, 10.0)
    estimator = observer.estimator
    for name, value, pattern in [
            ('observer.lipschitz_deflection', -1.0, 'observer.lipschitz_deflection'),
            ('observer.discretization', 'rk4', "observer.discretization = 'rk4'"),
            ('vehicle.tire_stiffness', [1e6, 0.0], 'vehicle.tire_stiffness = [1000000.0, 0.0]')]:
        result, = observer.set_parameters([Parameter(name, value=value)])
        assert not result.successful and pattern in result.reason, result.reason
    # The running estimate is untouched: same estimator, it goes on without a restart.
    assert observer.estimator is estimator
    for k in range(10, 20):
        feeder.sample(k, speed=20.0)
    assert spin_until(executor, lambda: collector.count('/observer/states') == 20, 10.0)
    assert estimator.status.accepted == 20 and estimator.status.time_since_start_s == (
        pytest.approx(0.019))
    result, = observer.set_parameters([Parameter('observer.discretization', value='euler')])
    assert result.successful
    assert observer.estimator is not estimator
    assert observer.estimator.observer.discretization == 'euler'
    assert observer.get_parameter('observer.discretization').value == 'euler'
    assert any('euler' in f for f in observer.findings)


def test_latency_stamps_each_estimate_with_its_sample_and_nothing_is_lost(make_rig):
    observer, feeder, collector, executor = make_rig(observer__latency=0.005)
    for k in range(30):
        feeder.sample(k, speed=20.0)
    # 5 ms at 1 kHz: the estimate of sample k comes with input k + 5, stamped as sample k.
    assert spin_until(executor, lambda: collector.count('/observer/states') == 25, 10.0)
    executor.spin_once(timeout_sec=0.05)
    assert collector.stamps('/observer/states') == [T0_NS + k * 1_000_000 for k in range(25)]
    # A rebuild (good live set) first publishes the estimates still held back.
    result, = observer.set_parameters([Parameter('observer.latency', value=0.0)])
    assert result.successful
    assert spin_until(executor, lambda: collector.count('/observer/states') == 30, 10.0)
    for topic in STAMPED:
        assert collector.stamps(topic) == [T0_NS + k * 1_000_000 for k in range(30)], topic


@pytest.mark.parametrize('name, value, pattern', [
    ('observer.profile_cutoff_wavelength', 1.0, r'observer\.profile_cutoff_wavelength = 1\.0'),
    ('vehicle.unsprung_mass', [450.0, -1.0], r'vehicle\.unsprung_mass = \[450\.0, -1\.0\]'),
    ('observer.lipschitz_roll', 'high', r"observer\.lipschitz_roll = 'high'"),
])
def test_bad_start_up_parameter_is_refused_naming_it(ros_context, name, value, pattern):
    with pytest.raises(ParameterError, match=pattern):
        Observer(context=ros_context, parameter_overrides=[Parameter(name, value=value)])


def test_main_exits_cleanly_on_sigint_and_refuses_bad_parameters(ros_context):
    process = run_main('observer')
    probe = Node('probe', context=ros_context)
    executor = make_executor(ros_context, probe)
    try:
        seen = spin_until(executor, lambda: 'observer' in probe.get_node_names(), 30.0)
    finally:
        close(executor, probe)
    process.send_signal(signal.SIGINT)
    code, _, err = finish(process, 30.0)
    assert seen and code == 0, err
    code, _, err = finish(run_main('observer', '--ros-args', '-p', 'observer.latency:=2.0'))
    assert code == 1 and err.strip() == (
        'observer: refused observer.latency = 2.0 is out of range [0, 1] s')



def test_finish_at_shutdown_publishes_what_latency_holds_back(make_rig):
    observer, feeder, collector, executor = make_rig(observer__latency=0.005)
    for k in range(30):
        feeder.sample(k, speed=20.0)
    assert spin_until(executor, lambda: collector.count('/observer/states') == 25, 10.0)
    observer.finish()   # what main() calls on SIGINT / SIGTERM, before the context goes
    assert spin_until(executor, lambda: collector.count('/observer/states') == 30, 10.0)
    for topic in STAMPED:
        assert collector.stamps(topic) == [T0_NS + k * 1_000_000 for k in range(30)], topic


def test_inputs_lost_on_the_way_are_counted_and_warned(rig):
    """Samples dropped by DDS (the node's input paused while 1500 come into a queue of
    1000: the oldest 500 go) are counted from the publisher's sequence numbers, and the input
    status warns; the queue's 1000 are estimated, the hole is a gap."""
    observer, feeder, collector, executor = rig
    for k in range(100):
        feeder.sample(k, speed=20.0)
    assert spin_until(executor, lambda: collector.count('/observer/states') == 100, 10.0)
    observer.input.loop.stop()
    for k in range(100, 1600):
        feeder.sample(k, speed=20.0)
    time.sleep(0.5)                       # (best effort: nothing acknowledges the samples)
    observer.input.loop.start(observer.input.take)
    # 600..1599 taken; 600 is held (a jump), 601 confirms it: a gap, the estimate restarts
    assert spin_until(executor, lambda: collector.count('/observer/states') == 100 + 999, 10.0)
    assert collector.stamps('/observer/states')[100] == T0_NS + 601 * 1_000_000

    def warned():
        statuses = [st for msg in collector.messages['/diagnostics'] for st in msg.status
                    if st.name == 'observer: input']
        return any(st.level == DiagnosticStatus.WARN and {v.key: v.value for v in st.values}
                   .get('missed') == '500' for st in statuses) and \
            input_diagnostics(collector).get('total.missed') == '500'

    assert spin_until(executor, warned, 5.0), input_diagnostics(collector)


def test_stamps_skipped_by_the_publisher_are_no_loss(rig):
    """Stamps that skip (the publisher sent no sample there) are counted as skipped; nothing
    was lost on the way (the sequence numbers follow): no warning of falling behind."""
    observer, feeder, collector, executor = rig
    sent = list(range(100)) + list(range(101, 121, 2))   # every other stamp absent: 10
    for k in sent:
        feeder.sample(k, speed=20.0)
    assert spin_until(executor, lambda: collector.count('/observer/states') == len(sent), 10.0)
    assert spin_until(executor, lambda: input_diagnostics(collector).get(
        'total.stamps_skipped') == '10', 5.0), input_diagnostics(collector)
    assert input_diagnostics(collector).get('total.missed', '0') == '0'


def test_the_log_says_waiting_then_the_input_rate_then_only_rejections(make_rig, capfd):
    observer, feeder, collector, executor = make_rig()
    for k in range(10):
        feeder.sample(k, speed=20.0)
    assert spin_until(executor, lambda: observer.input_seen
                      and collector.count('/observer/states') == 10, 10.0)
    feeder.raw(T0_NS + 10 * 1_000_000, ['a', 'b', 'c'], [0.0, 0.0, 0.0])
    assert spin_until(executor, lambda: observer.total['names'] == 1, 10.0)  # reported
    lines = [line for line in capfd.readouterr().err.splitlines() if '[observer]' in line]
    assert len(lines) == 3, lines
    assert 'waiting for /suspension/deflections and /vehicle/twist' in lines[0]
    assert 'input arriving on /suspension/deflections at' in lines[1]
    assert 'rejected inputs: names 1 (last: JointState names' in lines[2]


def test_static_loads_from_a_mechanical_zero_are_published_at_10_hz(ros_context):
    # The plant: a truck 40 % heavier than the observer's file, its deflections read from
    # the unloaded spring (vehicle.deflection_reference: zero_load, both nodes). The
    # observer's /wheel_load/static/* are its core's static loads (estimate_batch on the same
    # inputs), one per 0.1 s of stamps, and near the truth file's F_c,i = (M/2 + m_i) g.
    static = ['/wheel_load/static/left', '/wheel_load/static/right']
    collector = Collector(ros_context, ['/suspension/deflections', '/observer/states', *static])
    zero = Parameter('vehicle.deflection_reference', value='zero_load')
    observer = Observer(context=ros_context, parameter_overrides=[zero])
    plant = PlantSimulator(context=ros_context, parameter_overrides=[
        zero, Parameter('vehicle.sprung_mass', value=7000.0),
        Parameter('vehicle.roll_inertia', value=4200.0),
        Parameter('simulator.duration', value=3.0), Parameter('simulator.road',
                                                              value='iso8608:C:seed=3'),
        Parameter('realtime_factor', value=0.5)])
    executor = make_executor(ros_context, collector, observer, plant)
    try:
        assert spin_until(executor, lambda: plant.finished, 60.0)
        assert spin_until(executor, lambda: collector.count('/observer/states') >= plant.k,
                          30.0)
        executor.spin_once(timeout_sec=0.1)
    finally:
        close(executor, plant, observer, collector)
    stamps = collector.stamps('/observer/states')
    by_stamp = dict(zip(collector.stamps('/suspension/deflections'),
                        collector.messages['/suspension/deflections']))
    inputs = [by_stamp[s] for s in stamps]
    ref = estimate_batch(np.array(stamps), np.array([m.position[:2] for m in inputs]),
                         np.array([m.position[2] for m in inputs]), 20.0,
                         VehicleParameters(deflection_reference='zero_load'),
                         ObserverParameters())
    index = {s: k for k, s in enumerate(stamps)}
    for side, topic in enumerate(static):
        got = collector.stamps(topic)
        assert got == [s for k, s in enumerate(stamps)
                       if k == 0 or s // 10**8 != stamps[k - 1] // 10**8]
        values = [m.wrench.force.z for m in collector.messages[topic]]
        np.testing.assert_allclose(values, ref.static_load_n[[index[s] for s in got], side],
                                   rtol=1e-12)
        assert values[-1] == pytest.approx((3500.0 + 450.0) * 9.80665, rel=0.03)


@pytest.mark.parametrize('wrong', [False, True])
def test_model_fit_on_the_estimator_status(ros_context, wrong):
    # a 6 s ISO C drive (10 um noise) from core.plant, fed to the node's estimate() as its
    # input thread does; with every parameter off by 10 % (mixed signs) the status says mismatch
    from road_force_estimator.core.plant import simulate
    from road_force_estimator.core.road import iso8608_profile
    from collections import Counter
    vehicle = VehicleParameters()
    tr = simulate(vehicle, iso8608_profile('C', 150.0, seed=7), speed_mps=20.0,
                  rate_hz=1000.0, duration_s=6.0, tire_envelope_m=0.25)
    rng = np.random.default_rng(2)
    q = tr.q_m + rng.normal(0.0, 1e-5, tr.q_m.shape)
    phi = tr.roll_rad + rng.normal(0.0, 1e-4, tr.roll_rad.shape)
    overrides = []
    if wrong:
        overrides = [Parameter('vehicle.sprung_mass', value=4500.0),
                     Parameter('vehicle.roll_inertia', value=3300.0),
                     Parameter('vehicle.suspension_stiffness', value=[440000.0, 360000.0]),
                     Parameter('vehicle.suspension_damping', value=[16500.0, 13500.0]),
                     Parameter('vehicle.tire_stiffness', value=[900000.0, 1100000.0]),
                     Parameter('vehicle.unsprung_mass', value=[495.0, 405.0]),
                     Parameter('vehicle.static_load', value=list(vehicle.static_load_n))]
    observer = Observer(context=ros_context, parameter_overrides=overrides)
    try:
        for k in range(tr.t_s.size):
            observer.estimate(T0_NS + k * 1_000_000, (float(q[k, 0]), float(q[k, 1])),
                              float(phi[k]), 20.0)
        st = observer.estimator_status(Counter(), Counter())
    finally:
        observer.destroy_node()
    values = dict(st.values)
    assert values['model_fit'] == ('mismatch' if wrong else 'ok'), values['model_fit_ratio']
    assert (st.level == 1) == wrong
    if wrong:
        assert 'calibrate_vehicle' in st.message


def test_a_gap_where_the_model_fit_starts_is_taken_and_publishing_goes_on(rig):
    # The model-fit monitor designs its band-pass at its first step after 2 s: a 0.6 s gap
    # there (a step its band cannot be designed at) once stopped the node; the monitor now
    # designs at the first step that is not a gap, and restarts its band-pass at gaps.
    observer, feeder, collector, executor = rig
    ks = [*range(1900), *range(2500, 2700)]
    # (the first sample after the gap is held back, and lost: the next one confirms the jump)
    out = [k for k in ks if k != 2500]
    for i, k in enumerate(ks):
        feeder.sample(k, speed=20.0)
        if i % 100 == 99:
            done = sum(1 for j in out if j <= k)
            assert spin_until(executor, lambda: collector.count('/observer/states') == done,
                              10.0)
    assert collector.stamps('/observer/states') == [T0_NS + k * 1_000_000 for k in out]
    assert observer.total['gaps'] + observer.core_counts()['gaps'] == 1


# ---------------------------------------------------------------------------------------------
# Issue 28: a second publisher, huge messages

class Intruder(Node):
    """A second publisher on /suspension/deflections: other values, stamps among the
    feeder's (as a second node of the truck, or a bag played by mistake)."""

    def __init__(self, context):
        super().__init__('intruder', context=context)
        self.deflections = self.create_publisher(JointState, '/suspension/deflections',
                                                 sensor_qos(1000))

    def sample(self, k):
        self.deflections.publish(deflections_msg(T0_NS + k * 1_000_000 + 500_000,
                                                 (5e-3, -5e-3), 0.01))


def test_a_second_publisher_is_detected_named_and_not_mixed_in(make_rig, ros_context, capfd):
    """Issue 28: a second publisher interleaving other values was taken as data (load error
    116 %). Its samples are rejected (second_source), the publishers named once in the log
    and in the diagnostics; the estimates are those of the first publisher alone."""
    observer, feeder, collector, executor = make_rig()
    intruder = Intruder(ros_context)
    executor.add_node(intruder)
    try:
        assert spin_until(executor, lambda: intruder.deflections.get_subscription_count() > 0,
                          10.0)
        time.sleep(0.3)
        n = 400
        for k in range(n):
            feeder.sample(k, speed=20.0)
            intruder.sample(k)
            if k % 50 == 49:
                assert spin_until(executor, lambda: collector.count('/observer/states')
                                  == k + 1, 10.0)
        assert collector.stamps('/observer/states') == [T0_NS + k * 1_000_000
                                                        for k in range(n)]
        assert spin_until(executor, lambda: input_diagnostics(collector).get('sources') == '2',
                          5.0), input_diagnostics(collector)
        values = input_diagnostics(collector)
        assert values['publishers'] == '/feeder, /intruder'
    finally:
        executor.remove_node(intruder)
        intruder.destroy_node()
    assert observer.input.second_source == n
    # the estimates: those of the feeder's samples alone (the estimator, fed the same)
    from road_force_estimator.estimation import Estimator
    ref = Estimator(*observer.params.config)
    want = [ref.update(T0_NS + k * 1_000_000, (1e-3 * math.sin(0.05 * k),
                                               -1e-3 * math.cos(0.05 * k)), 1e-4 * k, 20.0)
            for k in range(n)]
    got = [m.wrench.force.z for m in collector.messages['/wheel_load/left']]
    assert got == [w.wheel_load_n[0] for w in want]
    lines = [line for line in capfd.readouterr().err.splitlines() if 'interleave' in line]
    assert len(lines) == 1 and '2 publishers interleave on /suspension/deflections ' \
        '(/feeder, /intruder)' in lines[0], lines


def test_log_lines_and_diagnostic_values_are_bounded(rig, capfd):
    """Issue 28: a JointState with 1e5 names made each WARN line 1 MB and put a 489,000
    character last_rejection on /diagnostics every second."""
    observer, feeder, collector, executor = rig
    names = [f'joint_{i}' for i in range(100_000)]
    feeder.raw(T0_NS, names, [0.0] * len(names))
    assert spin_until(executor, lambda: observer.total['names'] == 1, 10.0)
    assert spin_until(executor, lambda: 'last_rejection' in input_diagnostics(collector), 5.0)
    text = input_diagnostics(collector)['last_rejection']
    assert len(text) <= 240 and "'joint_0', 'joint_1'" in text and '(100000 names)' in text
    for msg in collector.messages['/diagnostics']:
        for status in msg.status:
            assert len(status.message) <= 240
            assert all(len(v.value) <= 240 for v in status.values)
    lines = [line for line in capfd.readouterr().err.splitlines() if '[observer]' in line]
    assert lines and max(len(line) for line in lines) < 1000


def test_a_flood_keeps_memory_and_diagnostics(tmp_path):
    """Issue 28: under a 13.5 kHz flood the node's memory grew from 131 to 359 MB and its
    /diagnostics stopped (2 messages in 120 s): the message events queued up ahead of its
    timer. bench.probes.observer_flood, short: an observer process flooded at 15 kHz for 4 s."""
    import json

    from bench.probes import observer_flood
    out = tmp_path / 'flood.json'
    assert observer_flood.main(['--rate', '15000', '--seconds', '4', '--steady', '3',
                                '--json', str(out)]) == 0
    summary = json.loads(out.read_text())['summary']
    # one a second (a loaded machine delays a timer now and then; before: none at all)
    assert summary['flood_longest_wait_for_diagnostics_s'] < 2.5, summary
    assert summary['flood_max_rss_mb'] - summary['steady_rss_mb'] < 50.0, summary
    assert summary['flood_published'] > 0


def estimator_diagnostics(collector):
    """Key-values of the newest 'observer: estimator' status, and its message."""
    for msg in reversed(collector.messages['/diagnostics']):
        for status in msg.status:
            if status.name == 'observer: estimator':
                return {kv.key: kv.value for kv in status.values}, status.message
    return {}, ''


def test_a_stuck_sensor_is_named_in_the_diagnostics(rig):
    """The right deflection held for 1 s while the others move (estimation.sensor_health):
    'sensor.right_suspension' reads 'stuck', the status WARNs naming it, the flag is counted;
    the others read 'ok' and no innovation was gated."""
    observer, feeder, collector, executor = rig
    held = None
    for k in range(1600):
        q = (1e-3 * math.sin(0.05 * k), -1e-3 * math.cos(0.05 * k))
        if k >= 500:
            held = held or q[1]
            q = (q[0], held)
        if k % 100 == 0:
            feeder.twist.publish(twist_msg(T0_NS + k * 1_000_000, 20.0))
        feeder.deflections.publish(deflections_msg(T0_NS + k * 1_000_000, q, 1e-4 * k))
        if k % 100 == 99:       # (best effort, 1000 deep: the observer keeps up)
            assert spin_until(executor, lambda k=k: collector.count('/observer/states') > k,
                              10.0), (k, collector.count('/observer/states'))

    def flagged():
        values, message = estimator_diagnostics(collector)
        return values.get('sensor.right_suspension') == 'stuck'
    assert spin_until(executor, flagged, 5.0), estimator_diagnostics(collector)
    values, message = estimator_diagnostics(collector)
    assert message == 'sensor fault: right_suspension stuck'
    assert values['sensor.left_suspension'] == values['sensor.roll'] == 'ok'
    assert values['total.stuck.right_suspension'] == '1'
    assert values['total.stuck.left_suspension'] == values['total.drift.roll'] == '0'
    assert values['innovations_gated.left_suspension'] == '0'
    assert values['total.innovations_gated.right_suspension'] == '0'


@pytest.mark.parametrize('kind, word', [('pendulum', 'plain roll'), ('gyro', 'drift')])
def test_a_roll_sensor_the_front_axle_cannot_model_is_a_finding(kind, word):
    from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
    from road_force_estimator.ros.observer import static_findings

    assert static_findings(VehicleParameters(), ObserverParameters()) == []
    found = static_findings(VehicleParameters(roll_sensor=kind), ObserverParameters())
    assert len(found) == 1 and kind in found[0] and word in found[0]
