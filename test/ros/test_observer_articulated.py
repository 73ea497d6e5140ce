"""observer with vehicle.model: articulated, spun in-process beside the plant_simulator driving
MODEL.md's 5-axle combination: every wheel's load arrives, named by the contract; the loads
follow the plant's truth; the numbers are those of estimate_whole_vehicle on the inputs the
node took (recorded as it took them) and the bytes those rclpy serialises for the same
messages, the road (/road_profile/left|right per sample, /road_profile/fused/* per point the
last axle passed) among them; bad messages are counted and skipped, the node keeps running.
Again with the tractor IMU (``vehicle.tractor_imu: true``, pendulum roll sensors, a curve to
3 m/s^2): the node subscribes ``/imu/tractor`` and gives each sample the plant's a_y of its
own stamp (or the one before, as it arrives: counted), the numbers those of
``estimate_whole_vehicle(..., imu=True)`` on what it took."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from geometry_msgs.msg import PointStamped, Vector3Stamped, WrenchStamped
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState

from node_harness import Collector, close, make_executor
from road_force_estimator import interfaces as api
from road_force_estimator.core.articulated_parameters import ArticulatedParameters
from road_force_estimator.core.parameters import ObserverParameters, load_params_file
from road_force_estimator.estimation.fused_stream import FUSED_SPACING_M
from road_force_estimator.estimation.whole_vehicle import estimate_whole_vehicle
from road_force_estimator.ros.bag_recorder import message_class
from road_force_estimator.ros.messages import (
    ns_to_stamp, reliable_qos, sensor_qos, stamp_to_ns, twist_msg, wrench_msg)
from road_force_estimator.ros.observer import Observer
from road_force_estimator.ros.plant_simulator import PlantSimulator
from ros_helpers import spin_until
from test_wire import assert_same_bytes

REPO = Path(__file__).resolve().parents[2]
CONFIG = REPO / 'config' / 'tractor_semitrailer.yaml'
AXLES = ('front', 'drive', 'trailer_1', 'trailer_2', 'trailer_3')
WHEELS = tuple(f'{a}_{s}_wheel' for a in AXLES for s in ('left', 'right'))
RAW = (api.WHEEL_LOADS, *api.UNIT_LOAD_TRANSFER, *api.LOAD, api.LOAD_TRANSFER,
       api.STATIC_WHEEL_LOADS, *api.STATIC_LOAD, *api.ROAD, *api.ROAD_FUSED)
DURATION_S = 4.0
SETTLED_S = 2.0
#: each wheel's online dynamic-load error allowed from SETTLED_S on (RMS, of the true dynamic
#: load's RMS): docs/articulated.md measures 16-27 % at zero latency after 5 s
#: (bench.accuracy.articulated_observer, classes A and C); this drive's drive axle, the last
#: to settle, is at 28 % (the same drive through simulate_bag and estimate_whole_vehicle)
LOAD_TOLERANCE = 0.35


def file_values(**extra) -> dict:
    values = load_params_file(CONFIG)
    values.update(extra)
    return values


def overrides(values: dict) -> list[Parameter]:
    return [Parameter(n, value=list(v) if isinstance(v, tuple) else v)
            for n, v in values.items()]


class RawCollector(Node):
    """The observer's outputs taken raw (the bytes rmw delivers)."""

    def __init__(self, context):
        super().__init__('raw_collector', context=context)
        self.data: dict[str, list[bytes]] = {}
        for topic in RAW:
            self.data[topic] = []
            self.create_subscription(message_class(api.TOPIC_TYPES[topic]), topic,
                                     self.data[topic].append, reliable_qos(10000), raw=True)


def record_inputs(observer: Observer) -> list:
    """What the node's input hands its estimator, recorded as it goes in."""
    taken = []
    whole = observer.whole
    sample = whole.input.sample

    def recording(stamp_ns, readings, speed_mps, *imu):
        taken.append((stamp_ns, readings, speed_mps, *imu))
        sample(stamp_ns, readings, speed_mps, *imu)

    whole.input.sample = recording
    return taken


def record_published(observer: Observer) -> list:
    """How many samples the node has published, and their fused points (a cheap count for the
    waits: the node's input thread shares the GIL with them)."""
    published = [0, 0]
    whole = observer.whole
    publish = whole.publish

    def recording(sample):
        publish(sample)
        published[0] += 1
        published[1] += len(sample.fused)

    whole.publish = recording
    return published


def point_bytes(stamp_ns: int, x: float, y: float, z: float) -> bytes:
    msg = PointStamped()
    msg.header.stamp, msg.header.frame_id = ns_to_stamp(stamp_ns), api.ROAD_FRAME
    msg.point.x, msg.point.y, msg.point.z = float(x), float(y), float(z)
    return serialize_message(msg)


def vector_bytes(stamp_ns: int, x: float, y: float) -> bytes:
    msg = Vector3Stamped()
    msg.header.stamp, msg.header.frame_id = ns_to_stamp(stamp_ns), api.BASE_FRAME
    msg.vector.x, msg.vector.y = float(x), float(y)
    return serialize_message(msg)


def joint_bytes(stamp_ns: int, names, effort) -> bytes:
    msg = JointState(name=list(names), effort=[float(v) for v in effort])
    msg.header.stamp, msg.header.frame_id = ns_to_stamp(stamp_ns), api.BASE_FRAME
    return serialize_message(msg)


#: the tractor IMU's drive: pendulum roll sensors (plant and observer) through a curve
IMU_VALUES = {'vehicle.tractor_imu': True, 'vehicle.roll_sensor': 'pendulum',
              'simulator.roll_sensor': 'pendulum',
              'simulator.lateral_profile': 'curve:start=0.5,ramp=1.5,hold=2,ay=3'}


@pytest.mark.parametrize('imu', [False, True], ids=['no_imu', 'imu'])
def test_the_articulated_observer_beside_the_plant(ros_context, imu):
    """4 s of class C at 20 m/s, 1 kHz: every estimate's messages, the truth followed, the
    batch's numbers and rclpy's bytes; with ``imu`` the tractor IMU's drive."""
    values = file_values(**{'simulator.duration': DURATION_S,
                            'simulator.road': 'iso8608:C:seed=1',
                            **(IMU_VALUES if imu else {})})
    observer = Observer(context=ros_context, parameter_overrides=overrides(values))
    taken = record_inputs(observer)
    published = record_published(observer)
    raw = RawCollector(ros_context)
    # the truth's collector subscribes to the inputs too: the plant starts once it listens
    truth = Collector(ros_context, [api.TRUE_WHEEL_LOADS, api.DEFLECTIONS, api.TWIST])
    imu_raw: list[bytes] = []         # the plant's IMU, taken raw (decoded after the drive)
    if imu:
        truth.create_subscription(message_class(api.IMU_MSG), api.IMU, imu_raw.append,
                                  sensor_qos(10000), raw=True)
    executor = make_executor(ros_context, observer, raw, truth)
    outputs = (*observer.whole.pubs, *observer.whole.static_pubs, *observer.whole.road_pubs,
               *observer.whole.fused_pubs)
    assert spin_until(executor, lambda: all(p.get_subscription_count() for p in outputs), 30.0)
    plant = PlantSimulator(context=ros_context, parameter_overrides=overrides({
        **values, 'start_nodes': ['observer', 'collector']}))
    executor.add_node(plant)
    try:
        assert spin_until(executor, lambda: plant.finished, 60.0)
        n = plant.k
        # the backlog drained (every node of the drive on this one executor: on a loaded
        # machine the observer catches up after the plant's last sample)
        assert spin_until(executor, lambda: len(taken) == n and truth.count(
            api.TRUE_WHEEL_LOADS) == n and all(len(raw.data[t]) == n for t in (
                *RAW[:7], *api.ROAD)) and published[0] == n and all(
                len(raw.data[t]) == published[1] for t in api.ROAD_FUSED), 120.0), (
            n, len(taken), published, {t: len(raw.data[t]) for t in RAW})
    finally:
        close(executor, observer, raw, truth, plant)
    assert n == round(DURATION_S * 1000) + 1
    stamps = np.array([s[0] for s in taken], np.int64)
    readings = np.array([s[1] for s in taken])
    speed = np.array([s[2] for s in taken])
    assert readings.shape == (n, 12) and np.all(np.diff(stamps) > 0)
    if imu:
        # each sample's a_y: the plant's IMU message of its own stamp or of one before it
        # (the latest the node had taken when the deflections came: which one depends on
        # the messages' arrival order, not asserted), fresh (code 0) within 0.1 s of it, or
        # none yet (code 2) only before the first; every one counted
        ay = np.array([s[3][0] for s in taken])
        codes = np.array([s[3][1] for s in taken])
        plant = {stamp_to_ns(m.header.stamp): m.linear_acceleration.y
                 for m in (deserialize_message(d, message_class(api.IMU_MSG))
                           for d in imu_raw)}
        assert len(plant) > 0.9 * n
        ms = 10**6

        def age_ms(t: int, a: float) -> int | None:
            return next((j for j in range(0, round(1e3 * DURATION_S) + 1)
                         if plant.get(t - j * ms) == a), None)

        ages = [age_ms(t, a) if c != 2 else None
                for t, a, c in zip(stamps.tolist(), ay.tolist(), codes.tolist())]
        assert all(g is not None for g, c in zip(ages, codes) if c != 2)
        assert all((g <= 100) == (c == 0) for g, c in zip(ages, codes) if c != 2)
        missing = np.flatnonzero(codes == 2)
        assert np.array_equal(missing, np.arange(missing.size))      # a prefix
        # /diagnostics' observer: estimator (its values as the timer would publish them)
        status = dict(observer.whole.estimator_status('observer').values)
        assert status['total.imu.missing'] == str(np.count_nonzero(codes == 2))
        assert status['total.imu.stale'] == str(np.count_nonzero(codes == 1))
        assert np.abs(ay).max() > 2.5               # the curve's a_y reached the node
        readings = np.column_stack([readings, ay])

    # the batch on the same inputs: the same numbers, in rclpy's bytes
    vehicle = ArticulatedParameters.from_parameters(values)
    assert vehicle.tractor_imu == imu
    # (with the IMU, the codes the node paired: on a loaded machine an a_y can come stale, and
    # such a sample leaves the IMU's row out in the node and in the batch alike)
    ref = estimate_whole_vehicle(vehicle, stamps, readings, speed,
                                 observer=ObserverParameters.from_parameters(values), imu=imu,
                                 imu_codes=codes if imu else None)
    front = ref.load_n[:2]
    for k, t in enumerate(stamps.tolist()):
        assert_same_bytes(api.JOINT_STATE, raw.data[api.WHEEL_LOADS][k],
                          joint_bytes(t, WHEELS, ref.load_n[:, k]))
        for u, topic in enumerate(api.UNIT_LOAD_TRANSFER):
            assert_same_bytes(api.VECTOR3_STAMPED, raw.data[topic][k], vector_bytes(
                t, ref.ltr[u, k], ref.ltr_quasi_static[u, k]))
        for side, topic in enumerate(api.LOAD):
            assert_same_bytes(api.WRENCH, raw.data[topic][k], serialize_message(
                wrench_msg(t, api.WHEEL_FRAMES[side], front[side, k])))
    # the road: the front wheels' own per sample, the fused profile per point passed by the
    # last axle (stamped with the sample at which the front axle passed it)
    w = vehicle.axles[0].wheel_half_track_m
    for k, t in enumerate(stamps.tolist()):
        for side, topic in enumerate(api.ROAD):
            assert_same_bytes(api.POINT, raw.data[topic][k], point_bytes(
                t, ref.distance_m[k], w if side == 0 else -w, ref.road_m[side, k]))
    f = ref.fused
    reach = max(a.position_m for a in vehicle.axles)
    assert np.all(f.distance_m + reach <= ref.distance_m[-1]) and np.isin(f.stamps_ns,
                                                                          stamps).all()
    assert f.stamps_ns.size > 0.9 * (ref.distance_m[-1] - reach) / FUSED_SPACING_M
    for side, topic in enumerate(api.ROAD_FUSED):
        assert len(raw.data[topic]) == f.stamps_ns.size
        for k, t in enumerate(f.stamps_ns.tolist()):
            assert_same_bytes(api.POINT, raw.data[topic][k], point_bytes(
                t, f.distance_m[k], w if side == 0 else -w, (f.left_m, f.right_m)[side][k]))
    # /load_transfer: the front axle's two wheels, right minus left over their sum
    got = np.array([(m.vector.x, m.vector.y) for m in (deserialize_message(
        d, Vector3Stamped) for d in raw.data[api.LOAD_TRANSFER])])
    np.testing.assert_allclose(got[:, 0], (front[1] - front[0]) / front.sum(axis=0),
                               rtol=0, atol=1e-12)
    assert np.all(np.abs(got[:, 1]) < np.abs(got[:, 0]).max())   # low-passed
    # the static loads ~10 Hz: the model's statics, summing to the gross weight
    statics = [deserialize_message(d, JointState) for d in raw.data[api.STATIC_WHEEL_LOADS]]
    assert abs(len(statics) - 10 * DURATION_S) <= 2
    assert all(list(m.name) == list(WHEELS) for m in statics)
    np.testing.assert_array_equal(statics[0].effort, ref.static_n[:, 0])
    assert sum(statics[0].effort) == pytest.approx(40.2e3 * 9.80665, rel=2e-3)
    left = [deserialize_message(d, WrenchStamped) for d in raw.data[api.STATIC_LOAD[0]]]
    assert len(left) == len(statics) and left[0].wrench.force.z == ref.static_n[0, 0]

    # against the plant's truth (independent): after SETTLED_S
    true = {stamp_to_ns(m.header.stamp): m for m in truth.messages[api.TRUE_WHEEL_LOADS]}
    assert list(true[stamps[0]].name) == list(WHEELS)
    true_loads = np.array([true[t].effort for t in stamps.tolist()]).T
    late = (stamps - stamps[0]) * 1e-9 >= SETTLED_S
    err = ref.load_n[:, late] - true_loads[:, late]
    dyn = true_loads[:, late] - true_loads[:, late].mean(axis=1, keepdims=True)
    ratio = np.sqrt((err ** 2).mean(axis=1) / (dyn ** 2).mean(axis=1))
    assert np.all(ratio < LOAD_TOLERANCE), ratio


class Feeder(Node):
    def __init__(self, context):
        super().__init__('feeder', context=context)
        self.deflections = self.create_publisher(JointState, api.DEFLECTIONS, sensor_qos(100))
        self.twist = self.create_publisher(message_class(api.TWIST_STAMPED), api.TWIST,
                                           sensor_qos(100))
        self.statuses: list = []
        self.create_subscription(message_class('diagnostic_msgs/msg/DiagnosticArray'),
                                 api.DIAGNOSTICS, self.statuses.append, reliable_qos(100))


def deflections(stamp_ns: int, names, values) -> JointState:
    msg = JointState(name=list(names), position=[float(v) for v in values])
    msg.header.stamp, msg.header.frame_id = ns_to_stamp(stamp_ns), api.BASE_FRAME
    return msg


def test_bad_messages_are_counted_and_skipped(ros_context):
    values = file_values()
    observer = Observer(context=ros_context, parameter_overrides=overrides(values))
    names = observer.whole.names
    feeder = Feeder(ros_context)
    loads = Collector(ros_context, [api.WHEEL_LOADS])
    executor = make_executor(ros_context, observer, feeder, loads)
    t0 = 1_700_000_000 * 10**9
    good = [0.0] * len(names)
    plan = [(t0 + k * 10**6, names, good) for k in range(5)]
    plan += [(t0 + 5 * 10**6, names[1:], good[1:]),                 # a joint missing
             (t0 + 6 * 10**6, names, [float('nan')] + good[1:]),    # non-finite
             (t0 + 2 * 10**6, names, good)]                         # the stamp goes back
    plan += [(t0 + k * 10**6, names, good) for k in range(7, 12)]
    plan += [(t0 + k * 10**6, names, good) for k in range(400, 403)]   # 0.39 s lost: a gap
    try:
        assert spin_until(executor, lambda: feeder.deflections.get_subscription_count() > 0 and
                          feeder.twist.get_subscription_count() > 0, 20.0)
        for stamp, n, v in plan:
            feeder.twist.publish(twist_msg(stamp, 15.0))
            feeder.deflections.publish(deflections(stamp, n, v))
            executor.spin_once(timeout_sec=0.002)

        def totals(name: str = 'observer: input') -> dict:
            out = {}
            for arr in feeder.statuses:
                for st in arr.status:
                    if st.name == name:
                        out.update({kv.key: kv.value for kv in st.values})
            return out

        assert spin_until(executor, lambda: loads.count(api.WHEEL_LOADS) == 13 and
                          totals().get('total.received') == str(len(plan)), 20.0), totals()
    finally:
        close(executor, observer, feeder, loads)
    got = totals()
    assert (got['total.names'], got['total.nonfinite'], got['total.time']) == ('1', '1', '1')
    assert got['total.published'] == '13'
    assert loads.stamps(api.WHEEL_LOADS) == [s for s, n, v in plan if n == names][:5] + [
        t0 + k * 10**6 for k in (*range(7, 12), *range(400, 403))]
    # the weights: MODEL.md's axle loads (docs/articulated.md "Statics and modes": 6.624,
    # 10.732, 8.004, 7.615, 7.225 t) and 40.2 t in all; every channel's gate count
    est = totals('observer: estimator')
    for axle, tonnes in zip(AXLES, (6.624, 10.732, 8.004, 7.615, 7.225)):
        assert float(est[f'static_load_{axle}_n']) == pytest.approx(tonnes * 1e3 * 9.80665,
                                                                     rel=1e-3)
    assert float(est['gross_weight_n']) == pytest.approx(40.2e3 * 9.80665, rel=1e-3)
    assert all(f'total.innovations_gated.{c}' in est for c in names)
    # the sensors' flags (estimation.sensor_health; docs/topics.md): nothing stuck or drifting
    assert {est[f'sensor.{c}'] for c in names} == {'ok'}
    assert {est[f'total.stuck.{c}'] for c in names} == {'0'}
    assert {est[f'total.drift.{c}'] for c in names} == {'0'}
    assert est['total.gaps'] == '1'       # the step over the lost samples restarted it


def imu_msg(stamp_ns: int, ay: float):
    msg = message_class(api.IMU_MSG)()
    msg.header.stamp, msg.header.frame_id = ns_to_stamp(stamp_ns), api.IMU_FRAME
    msg.linear_acceleration.y = float(ay)
    return msg


def test_an_imu_at_its_own_rate_is_held_and_counted(ros_context):
    """``vehicle.tractor_imu: true``, the IMU every 50 ms from the 5th sample of 10 ms steps
    and a 0.2 s hole: each sample fed the latest a_y at or before its stamp (0 before the
    first), the samples before it missing, those 0.1 s past the last message stale (counted
    here by hand), every sample estimated."""
    values = file_values(**{'vehicle.tractor_imu': True})
    observer = Observer(context=ros_context, parameter_overrides=overrides(values))
    assert observer.whole.names[-1] == 'tractor_imu_accel_y'
    joints = observer.whole.names[:-1]
    taken = record_inputs(observer)
    feeder = Feeder(ros_context)
    imu_pub = feeder.create_publisher(message_class(api.IMU_MSG), api.IMU, sensor_qos(100))
    loads = Collector(ros_context, [api.WHEEL_LOADS])
    executor = make_executor(ros_context, observer, feeder, loads)
    t0 = 1_700_000_000 * 10**9
    step = 10 * 10**6
    imu_at = [k for k in range(5, 60, 5) if not 25 < k < 45]      # the hole: 0.25 to 0.45 s
    try:
        assert spin_until(executor, lambda: imu_pub.get_subscription_count() > 0 and
                          feeder.deflections.get_subscription_count() > 0, 20.0)
        for k in imu_at:                 # every IMU message first: the node holds them
            imu_pub.publish(imu_msg(t0 + k * step, 0.1 * k))
        held = observer.whole.input.imu_hold.held
        assert spin_until(executor, lambda: len(held) == len(imu_at), 20.0)
        for k in range(60):
            feeder.twist.publish(twist_msg(t0 + k * step, 15.0))
            feeder.deflections.publish(deflections(t0 + k * step, joints, [0.0] * len(joints)))
            executor.spin_once(timeout_sec=0.002)
        assert spin_until(executor, lambda: loads.count(api.WHEEL_LOADS) == 60, 20.0)
        status = observer.whole.estimator_status('observer')
    finally:
        close(executor, observer, feeder, loads)
    want = []
    for k in range(60):                  # the rule, by hand
        last = [j for j in imu_at if j <= k]
        if not last:
            want.append((0.0, 2))
        else:
            want.append((0.1 * last[-1], 1 if (k - last[-1]) * step > 10**8 else 0))
    assert [s[3] for s in taken] == want
    missing = sum(c == 2 for _, c in want)
    stale = sum(c == 1 for _, c in want)
    assert (missing, stale) == (5, 9)       # k 0-4; k 36-44 (k 35 is 100 ms: still fresh)
    values = dict(status.values)
    assert (values['total.imu.missing'], values['total.imu.stale']) == ('5', '9')
    # the last period's counts and WARN (the 1 Hz timer may have closed a period before:
    # a sample without a fresh a_y has its own gain design, which takes time)
    period = [f'{values[f"imu.{k}"]} {k}' for k in ('stale', 'missing')
              if values[f'imu.{k}'] != '0']
    if period:
        assert f'tractor IMU: {", ".join(period)} samples' in status.message
        assert status.level == 1
