"""estimate_bag with the tractor IMU (``vehicle.tractor_imu: true``, issues 30 and 32): a
simulate_bag drive of the 5-axle combination through a curve to 3 m/s^2 with pendulum roll
sensors (``phi + a_y / g``), estimated with the IMU's a_y (``/imu/tractor``) in every mode and
without it. Judged against the drive's own ``/ground_truth/wheel_loads`` and the test's
statics (articulated_reference), every bag read by the ``mcap`` library; online the loads
are :func:`estimate_whole_vehicle` on the inputs the mcap library decodes, the IMU paired by
the rule stated in docs/articulated.md (the latest a_y at or before each sample), bit for
bit. A bag written again by the ``mcap`` library with the IMU at 100 Hz, starting late and
with a hole: every sample without a fresh a_y counted (the test's own count), no crash."""
import json
from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest

from articulated_reference import defaults, statics
from road_force_estimator.tools.estimate_bag import main as estimate_bag

REPO = Path(__file__).resolve().parents[2]
CONFIG = REPO / 'config' / 'tractor_semitrailer.yaml'
BIN = Path(sys.executable).parent
DURATION_S = 6
CURVE = 'curve:start=1,ramp=2,hold=3,ay=3'
SETTLED_S = 2.0
MODES = {'0ms': ('online', 0.0), '10ms': ('online', 0.01), 'offline': ('offline', 0.0)}
#: the worst axle's load error allowed with the IMU (% of the true dynamic RMS, after 2 s):
#: bench.studies.roll_sensors measures 10.66 / 2.01 / 1.69 % on the 20 s class C curve
#: (in process and through estimate_bag, ``--parts bag``); this 6 s drive 10.8 / 1.7 / 1.4
TOLERANCE_PCT = {'0ms': 14.0, '10ms': 3.0, 'offline': 3.0}


def params_file(folder: Path, imu: bool) -> Path:
    """The file's combination with pendulum roll sensors (the plant's and the observer's),
    the curve, the plant's IMU and the observer's ``vehicle.tractor_imu`` as ``imu``."""
    text = CONFIG.read_text()
    for old, new in (('tractor_imu: false', f'tractor_imu: {str(imu).lower()}'),
                     ('roll_sensor: "ideal"', 'roll_sensor: "pendulum"'),
                     ('lateral_profile: ""', f'lateral_profile: "{CURVE}"')):
        assert old in text
        text = text.replace(old, new)
    path = folder / f'{"imu" if imu else "no_imu"}.yaml'
    path.write_text(text)
    return path


def decoded(bag: Path) -> dict:
    """topic -> [(log time ns, message)], decoded by the mcap library."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    out: dict = {}
    for path in sorted(bag.glob('*.mcap')):
        with open(path, 'rb') as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            for _, channel, message, msg in reader.iter_decoded_messages():
                out.setdefault(channel.topic, []).append((message.log_time, msg))
    return out


def stamp(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def run(bag: Path, params: Path, out: Path, mode: str) -> dict:
    kind, latency = MODES[mode]
    code = estimate_bag([str(bag), '--params-file', str(params), '-p',
                         f'observer.latency:={latency}', '--output', str(out), '--mode', kind,
                         '--segment-length', '20', '--no-figures', '--no-progress'])
    assert code == 0
    return decoded(out / 'bag')


def worst_axle_pct(est: dict, truth: dict) -> float:
    """The worst axle's load error after SETTLED_S (% of its true dynamic RMS about the
    test's statics, RMS over both wheels)."""
    got = {stamp(m): m.effort for _, m in est['/wheel_loads']}
    true = {stamp(m): m.effort for _, m in truth['/ground_truth/wheel_loads']}
    stamps = sorted(set(got) & set(true))
    t0 = stamps[0]
    use = [s for s in stamps if s - t0 >= SETTLED_S * 1e9]
    e = np.array([got[s] for s in use]).T
    t = np.array([true[s] for s in use]).T
    static = np.repeat(statics(defaults())['wheel'] / 2.0, 2)[:, None]
    err = ((e - t) ** 2).reshape(5, 2, -1).mean(axis=(1, 2))
    dyn = ((t - static) ** 2).reshape(5, 2, -1).mean(axis=(1, 2))
    return float(100.0 * np.sqrt(err / dyn).max())


@pytest.fixture(scope='module')
def drive(tmp_path_factory):
    folder = tmp_path_factory.mktemp('imu')
    bag = folder / 'drive'
    sim = subprocess.run([str(BIN / 'simulate_bag'), '--params-file',
                          str(params_file(folder, True)), '--road', 'iso8608:C:seed=5',
                          '--speed', '20', '--rate', '1000', '--duration', str(DURATION_S),
                          '--gnss-rate', '0', '--no-progress', '--output', str(bag)],
                         capture_output=True, text=True, timeout=300)
    assert sim.returncode == 0, sim.stderr
    return folder, bag, decoded(bag)


def test_the_imu_makes_the_pendulum_readable_in_every_mode(drive):
    folder, bag, truth = drive
    assert len(truth['/imu/tractor']) == len(truth['/suspension/deflections'])
    with_imu, without = {}, {}
    for mode in MODES:
        est = run(bag, params_file(folder, True), folder / f'imu_{mode}', mode)
        with_imu[mode] = worst_axle_pct(est, truth)
        without[mode] = worst_axle_pct(run(bag, params_file(folder, False),
                                           folder / f'no_imu_{mode}', mode), truth)
        # every sample paired with the IMU message of its own stamp: none stale or missing
        report = json.loads((folder / f'imu_{mode}' / 'report' / 'report.json').read_text())
        n = len(truth['/suspension/deflections'])
        assert report['whole_vehicle_estimate']['tractor_imu'] == {
            'max_age_s': 0.1, 'fresh': n, 'stale': 0, 'missing': 0}
        last = {}
        for _, arr in est['/diagnostics']:
            for st in arr.status:
                if st.name == 'estimate_bag: whole vehicle':
                    last = {kv.key: kv.value for kv in st.values}
        assert last['total.imu.stale'] == '0' and last['total.imu.missing'] == '0'
    for mode in MODES:
        assert with_imu[mode] < TOLERANCE_PCT[mode], (mode, with_imu)
        # without the IMU the pendulum is read as plain roll: the curve's a_y / g mistaken
        assert without[mode] > 20.0 and with_imu[mode] < 0.35 * without[mode], (
            mode, with_imu, without)


def test_online_loads_are_the_estimator_on_the_decoded_inputs(drive):
    """estimate_bag online = estimate_whole_vehicle(imu=True) on the readings, speed and IMU
    the mcap library decodes, each sample given the latest IMU a_y at or before its stamp."""
    from road_force_estimator.core.articulated_setup import ArticulatedDrive
    from road_force_estimator.core.parameters import ObserverParameters, load_params_file
    from road_force_estimator.estimation.whole_vehicle import (
        WholeVehicleEstimator, estimate_whole_vehicle)

    folder, bag, truth = drive
    vehicle = ArticulatedDrive.from_values(load_params_file(params_file(folder, True))).vehicle
    assert vehicle.tractor_imu and vehicle.roll_sensor == 'pendulum'
    names = WholeVehicleEstimator(vehicle).channel_names
    rows = truth['/suspension/deflections']
    stamps = np.array([stamp(m) for _, m in rows], np.int64)
    readings = np.array([[m.position[list(m.name).index(n)] for n in names] for _, m in rows])
    tw = truth['/vehicle/twist']
    t_ns = np.array([stamp(m) for _, m in tw], np.int64)
    v = np.array([m.twist.linear.x for _, m in tw])
    speed = v[np.maximum(np.searchsorted(t_ns, stamps, side='right') - 1, 0)]
    imu = truth['/imu/tractor']
    i_ns = np.array([stamp(m) for _, m in imu], np.int64)
    ay = np.array([m.linear_acceleration.y for _, m in imu])
    held = np.searchsorted(i_ns, stamps, side='right') - 1
    assert np.all(held >= 0) and np.all(i_ns[held] == stamps)     # the plant's same stamps
    ref = estimate_whole_vehicle(vehicle, stamps, np.column_stack([readings, ay[held]]), speed,
                                 observer=ObserverParameters(), imu=True)
    est = run(bag, params_file(folder, True), folder / 'bits', '0ms')
    got = np.array([m.effort for _, m in est['/wheel_loads']]).T
    assert [stamp(m) for _, m in est['/wheel_loads']] == stamps.tolist()
    np.testing.assert_array_equal(got, ref.load_n)


def test_an_imu_at_its_own_rate_with_holes_is_counted(drive, tmp_path):
    """The drive written again by the mcap library, the IMU at 100 Hz from 0.25 s on and
    none from 2.0 to 2.5 s: the samples before its first message are missing, those whose
    latest message is more than 0.1 s old stale (the test's own count), the estimate goes
    on (every sample published, the loads finite and still far better than without)."""
    from mcap.reader import make_reader
    from mcap.writer import Writer
    from mcap_ros2.decoder import DecoderFactory

    folder, bag, truth = drive
    (src,) = bag.glob('*.mcap')
    dst = tmp_path / 'sparse'
    dst.mkdir()
    t0 = stamp(truth['/suspension/deflections'][0][1])
    kept = []
    with src.open('rb') as f, (dst / 'sparse_0.mcap').open('wb') as g:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        writer = Writer(g)
        writer.start(profile='ros2', library='test')
        ids: dict = {}
        for schema, channel, message, msg in reader.iter_decoded_messages(
                log_time_order=False):
            if channel.topic == '/imu/tractor':
                s = stamp(msg) - t0
                if s < 250_000_000 or s % 10_000_000 or 2_000_000_000 <= s < 2_500_000_000:
                    continue
                kept.append(stamp(msg))
            if channel.id not in ids:
                sid = writer.register_schema(schema.name, schema.encoding, schema.data)
                ids[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, sid, dict(channel.metadata))
            writer.add_message(ids[channel.id], message.log_time, message.data,
                               message.publish_time, message.sequence)
        writer.finish()
    samples = [stamp(m) for _, m in truth['/suspension/deflections']]
    missing = stale = 0
    j = -1
    for s in samples:                   # the rule, counted here sample by sample
        while j + 1 < len(kept) and kept[j + 1] <= s:
            j += 1
        if j < 0:
            missing += 1
        elif s - kept[j] > 100_000_000:
            stale += 1
    assert missing == 250 and stale > 300
    est = run(dst, params_file(folder, True), tmp_path / 'out', '10ms')
    report = json.loads((tmp_path / 'out' / 'report' / 'report.json').read_text())
    assert report['whole_vehicle_estimate']['tractor_imu'] == {
        'max_age_s': 0.1, 'fresh': len(samples) - missing - stale, 'stale': stale,
        'missing': missing}
    totals, warned = {}, False
    for _, arr in est['/diagnostics']:
        for st in arr.status:
            if st.name == 'estimate_bag: whole vehicle':
                totals = {kv.key: kv.value for kv in st.values}
                warned |= st.level == 1 and 'tractor IMU' in st.message
    assert totals['total.imu.missing'] == str(missing)
    assert totals['total.imu.stale'] == str(stale) and warned
    assert len(est['/wheel_loads']) == len(samples)
    assert np.isfinite([m.effort for _, m in est['/wheel_loads']]).all()
    assert worst_axle_pct(est, truth) < 10.0

