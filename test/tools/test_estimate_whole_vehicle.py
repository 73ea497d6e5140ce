"""estimate_bag and estimate_fleet with ``vehicle.model: articulated`` (issue 32, INTERFACES.md
"The whole vehicle"): a short simulated 5-axle drive estimated online and offline; the
estimate bag read by the mcap library (mcap + mcap-ros2-support, not the package's reader),
its loads against :func:`estimate_whole_vehicle` on the inputs the mcap library decodes from
the drive bag (online bit for bit) and against the drive's own ``/ground_truth/wheel_loads``,
the report's columns against the bag's static loads and the test's own statics."""
import csv
import json
from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest

from articulated_reference import defaults, statics
from road_force_estimator.tools.estimate_bag import load_parameters, main as estimate_bag

REPO = Path(__file__).resolve().parents[2]
CONFIG = REPO / 'config' / 'tractor_semitrailer.yaml'
BIN = Path(sys.executable).parent
AXLES = ('front', 'drive', 'trailer_1', 'trailer_2', 'trailer_3')
WHEELS = tuple(f'{a}_{s}_wheel' for a in AXLES for s in ('left', 'right'))
RATE_HZ = 1000
DURATION_S = 3


def decoded(bag: Path) -> dict:
    """topic -> [(log time ns, message)], decoded by the mcap library and mcap-ros2-support."""
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


@pytest.fixture(scope='module')
def runs(tmp_path_factory):
    """The drive bag (3 s at 1 kHz, class C, 20 m/s, no GNSS) and estimate_bag's output
    folders online and offline (segments of 20 m)."""
    folder = tmp_path_factory.mktemp('whole_vehicle')
    bag = folder / 'drive'
    sim = subprocess.run([str(BIN / 'simulate_bag'), '--params-file', str(CONFIG), '--road',
                          'iso8608:C:seed=5', '--speed', '20', '--rate', str(RATE_HZ),
                          '--duration', str(DURATION_S), '--gnss-rate', '0', '--no-progress',
                          '--output', str(bag)], capture_output=True, text=True, timeout=300)
    assert sim.returncode == 0, sim.stderr
    outs = {}
    for mode in ('online', 'offline'):
        outs[mode] = folder / f'est_{mode}'
        code = estimate_bag([str(bag), '--params-file', str(CONFIG), '--output',
                             str(outs[mode]), '--mode', mode, '--segment-length', '20',
                             '--no-figures', '--no-progress'])
        assert code == 0
    return bag, outs, {m: decoded(o / 'bag') for m, o in outs.items()}


def inputs(bag: Path, names):
    """The drive's readings in the estimator's channel order and the twist's speed held at
    each sample (the first twist's before it), decoded by the mcap library."""
    topics = decoded(bag)
    rows = topics['/suspension/deflections']
    stamps = np.array([stamp(m) for _, m in rows], np.int64)
    readings = np.array([[m.position[list(m.name).index(n)] for n in names] for _, m in rows])
    twist = topics['/vehicle/twist']
    t_ns = np.array([stamp(m) for _, m in twist], np.int64)
    v = np.array([m.twist.linear.x for _, m in twist])
    held = np.searchsorted(t_ns, stamps, side='right') - 1
    return stamps, readings, v[np.maximum(held, 0)]


def test_the_bag_has_the_whole_vehicles_topics(runs):
    _, _, bags = runs
    n = DURATION_S * RATE_HZ + 1
    for topics in bags.values():
        for topic in ('/wheel_loads', '/load_transfer/tractor', '/load_transfer/trailer',
                      '/load_transfer/combination', '/wheel_load/left', '/wheel_load/right',
                      '/load_transfer'):
            assert len(topics[topic]) == n, topic
        for _, msg in topics['/wheel_loads'][:3] + topics['/wheel_loads/static'][:3]:
            assert tuple(msg.name) == WHEELS and len(msg.effort) == 10
            assert len(msg.position) == 0 and len(msg.velocity) == 0
        # ~10 Hz: the first sample of every 100 ms
        for topic in ('/wheel_loads/static', '/wheel_load/static/left'):
            assert len(topics[topic]) == 10 * DURATION_S + 1, topic
        assert all(t == stamp(m) for t, m in topics['/wheel_loads'])
        last = topics['/diagnostics'][-1][1]
        whole = [s for s in last.status if s.name == 'estimate_bag: whole vehicle']
        assert len(whole) == 1
        values = {kv.key: float(kv.value) for kv in whole[0].values
                  if not kv.key.startswith('sensor.')}
        words = {kv.key: kv.value for kv in whole[0].values if kv.key.startswith('sensor.')}
        assert len(words) == 12 and set(words.values()) == {'ok'}    # (a clean drive)
        static = np.array(topics['/wheel_loads/static'][-1][1].effort)
        assert values['gross_weight_n'] == pytest.approx(static.sum(), abs=0.1)
        assert values['total.gaps'] == 0 and values['gaps'] == 0     # (a drive without)
        for j, a in enumerate(AXLES):
            assert values[f'static_load_{a}_n'] == pytest.approx(static[2 * j:2 * j + 2].sum(),
                                                                 abs=0.1)
        # each unit's largest |LTR| of the status's period (the samples after the previous
        # status), as the observer node's key, from the bag's own /load_transfer/<unit>
        before, at = (stamp(m) for _, m in topics['/diagnostics'][-2:])
        for unit in ('tractor', 'trailer', 'combination'):
            period = [abs(m.vector.x) for _, m in topics[f'/load_transfer/{unit}']
                      if before < stamp(m) <= at]
            assert values[f'max_abs_ltr_{unit}'] == pytest.approx(max(period), abs=1e-4)


@pytest.mark.parametrize('mode', ['online', 'offline'])
def test_the_loads_are_estimate_whole_vehicles_on_the_same_inputs(runs, mode):
    from road_force_estimator.estimation.whole_vehicle import (
        WholeVehicleEstimator, estimate_whole_vehicle)
    bag, _, bags = runs
    vehicle, observer = load_parameters(str(CONFIG))
    names = WholeVehicleEstimator(vehicle, observer).channel_names
    stamps, readings, speed = inputs(bag, names)
    want = estimate_whole_vehicle(vehicle, stamps, readings, speed, observer=observer,
                                  offline=mode == 'offline')
    topics = bags[mode]
    got = np.array([m.effort for _, m in topics['/wheel_loads']]).T
    np.testing.assert_array_equal([stamp(m) for _, m in topics['/wheel_loads']], want.stamps_ns)
    np.testing.assert_array_equal(got, want.load_n)       # bit for bit
    for u, unit in enumerate(('tractor', 'trailer', 'combination')):
        rows = topics[f'/load_transfer/{unit}']
        np.testing.assert_array_equal([m.vector.x for _, m in rows], want.ltr[u])
        np.testing.assert_array_equal([m.vector.y for _, m in rows], want.ltr_quasi_static[u])
    for side, word in enumerate(('left', 'right')):
        np.testing.assert_array_equal(
            [m.wrench.force.z for _, m in topics[f'/wheel_load/{word}']], want.load_n[side])
    # the front axle's /load_transfer: its two wheels' right minus left over their sum
    left, right = want.load_n[0], want.load_n[1]
    np.testing.assert_allclose([m.vector.x for _, m in topics['/load_transfer']],
                               (right - left) / (right + left), rtol=0, atol=1e-12)
    first = np.searchsorted(want.stamps_ns, [stamp(m) for _, m in
                                             topics['/wheel_loads/static']])
    np.testing.assert_array_equal([m.effort for _, m in topics['/wheel_loads/static']],
                                  want.static_n[:, first].T)
    if mode == 'online':
        from road_force_estimator.estimation.fused_stream import FUSED_SPACING_M
        # the road as the node publishes it: the front wheels' own per sample (y = +- the
        # front wheels' half track) and the streamed fused points, bit for bit
        w = vehicle.axles[0].wheel_half_track_m
        f = want.fused
        assert f.stamps_ns.size > 0.9 * (want.distance_m[-1] - 12.22) / FUSED_SPACING_M
        for side, word in enumerate(('left', 'right')):
            rows = topics[f'/road_profile/{word}']
            np.testing.assert_array_equal([stamp(m) for _, m in rows], want.stamps_ns)
            np.testing.assert_array_equal([m.point.x for _, m in rows], want.distance_m)
            np.testing.assert_array_equal([m.point.z for _, m in rows], want.road_m[side])
            assert {m.point.y for _, m in rows} == {w if side == 0 else -w}
            rows = topics[f'/road_profile/fused/{word}']
            np.testing.assert_array_equal([stamp(m) for _, m in rows], f.stamps_ns)
            np.testing.assert_array_equal([t for t, _ in rows], f.stamps_ns)
            np.testing.assert_array_equal([m.point.x for _, m in rows], f.distance_m)
            np.testing.assert_array_equal([m.point.z for _, m in rows],
                                          (f.left_m, f.right_m)[side])
            assert {m.point.y for _, m in rows} == {w if side == 0 else -w}


#: Largest per-wheel RMS load error, % of the true dynamic load's RMS, after the first second
#: (the observer's start): offline measured 2-3 %, online 14-28 % (zero latency) on such drives.
TOLERANCE_PCT = {'offline': 8.0, 'online': 40.0}


@pytest.mark.parametrize('mode', ['online', 'offline'])
def test_the_loads_follow_the_drives_ground_truth(runs, mode):
    bag, _, bags = runs
    truth = decoded(bag)['/ground_truth/wheel_loads']
    assert tuple(truth[0][1].name) == WHEELS
    t_stamps = np.array([stamp(m) for _, m in truth])
    true = np.array([m.effort for _, m in truth])
    est = bags[mode]['/wheel_loads']
    e_stamps = np.array([stamp(m) for _, m in est])
    loads = np.array([m.effort for _, m in est])
    common, ie, it = np.intersect1d(e_stamps, t_stamps, return_indices=True)
    late = common >= common[0] + 1_000_000_000
    err = loads[ie][late] - true[it][late]
    dyn = true[it][late] - true[it][late].mean(axis=0)
    pct = 100.0 * np.sqrt((err ** 2).mean(axis=0)) / np.sqrt((dyn ** 2).mean(axis=0))
    assert np.all(pct < TOLERANCE_PCT[mode]), pct


def read_csv(path: Path) -> dict:
    with path.open(newline='') as f:
        rows = list(csv.reader(f))
    return {c: [r[j] for r in rows[1:]] for j, c in enumerate(rows[0])}


def per_axle_columns() -> list:
    cols = []
    for a in AXLES:
        cols += [f'peak_load_{a}_left_n', f'peak_load_{a}_right_n', f'dlc_{a}_left',
                 f'dlc_{a}_right', f'static_load_{a}_n']
    return cols + ['gross_weight_n', 'max_abs_ltr_trailer_quasi_static']


@pytest.mark.parametrize('mode', ['online', 'offline'])
def test_segments_csv_has_every_axles_columns_and_the_gross_weight(runs, mode):
    _, outs, bags = runs
    table = read_csv(outs[mode] / 'report' / 'segments.csv')
    for c in ('peak_load_left_n', 'dlc_left', 'static_load_left_n', 'max_abs_ltr_quasi_static',
              *per_axle_columns()):
        assert c in table, c
    assert len(table['start_m']) == 3                 # 60 m in 20 m segments
    static = np.array([m.effort for _, m in bags[mode]['/wheel_loads/static']])
    gross = static.sum(axis=1)
    assert np.ptp(gross) < 1e-6 * gross[0]            # the statics hold the whole drive
    for i in range(3):
        assert float(table['gross_weight_n'][i]) == pytest.approx(gross[0], abs=0.5)
        axles = [float(table[f'static_load_{a}_n'][i]) for a in AXLES]
        assert sum(axles) == pytest.approx(gross[0], abs=3.0)
        # against the test's own statics (MODEL.md's tables; 2 %: issue 32's axle figure)
        np.testing.assert_allclose(axles, statics(defaults())['wheel'], rtol=0.02)
        loads = np.array([m.effort for _, m in bags[mode]['/wheel_loads']])
        for w, name in enumerate(WHEELS):
            axle, side = name.rsplit('_', 2)[0], name.rsplit('_', 2)[1]
            peak = float(table[f'peak_load_{axle}_{side}_n'][i])
            assert 0.0 < peak <= loads[:, w].max() + 0.5
        assert 0.0 <= float(table['max_abs_ltr_trailer_quasi_static'][i]) < 1.0
    summary = json.loads((outs[mode] / 'report' / 'report.json').read_text())
    est = summary['whole_vehicle_estimate']
    assert est['gross_weight_n'] == pytest.approx(gross[0], rel=1e-9)
    assert set(est['accuracy']['load_rms_pct_dynamic']) == set(WHEELS)
    assert '## The whole vehicle (estimate)' in (outs[mode] / 'report' / 'report.md').read_text()


def test_estimate_fleet_gets_every_axles_columns(runs, tmp_path):
    import shutil

    import pyarrow.parquet as pq
    bag, outs, _ = runs
    inputs_dir = tmp_path / 'in'
    inputs_dir.mkdir()
    for name in ('a', 'b'):
        shutil.copytree(bag, inputs_dir / name)
    fleet = subprocess.run([str(BIN / 'estimate_fleet'), str(inputs_dir), '--params-file',
                            str(CONFIG), '--output', str(tmp_path / 'fleet'), '--workers', '1',
                            '--mode', 'offline', '--segment-length', '20', '--no-figures',
                            '--no-progress'], capture_output=True, text=True, timeout=600)
    assert fleet.returncode == 0, fleet.stderr
    table = read_csv(tmp_path / 'fleet' / 'segments.csv')
    assert table['drive'] == ['a'] * 3 + ['b'] * 3
    own = read_csv(outs['offline'] / 'report' / 'segments.csv')
    parquet = pq.read_table(tmp_path / 'fleet' / 'segments.parquet').to_pydict()
    for c in per_axle_columns():
        assert table[c][:3] == own[c] and table[c][3:] == own[c], c
        np.testing.assert_allclose(parquet[c], [float(v) for v in own[c]] * 2, atol=0.5)


def test_offline_the_fused_profile_is_published_and_is_the_reports_road(runs):
    """Offline: ``/road_profile/fused/left|right`` (INTERFACES.md) at the front axle's stamps,
    one point per sample the last axle has passed (x = the front axle's distance, frame
    ``road``), and the same elevations on ``/road_profile/*`` there; the report's
    IRI-filtered cross-correlation against the drive's own ``/ground_truth/road_profile/*``
    over the 20-40 m segment (every axle has passed it, the start's second is behind) is the
    fused road's (measured 0.991-0.997; the front-axle estimator's own road, the package's
    defaults on this truck's beam axle, gave 0.71-0.73 over a 6 s drive). Online the fused
    profile is the streamed one (test_the_loads_are_estimate_whole_vehicles_on_the_same_inputs)
    and the report counts its points."""
    from road_force_estimator.core.articulated_setup import ArticulatedDrive
    from road_force_estimator.core.parameters import load_params_file
    _, outs, bags = runs
    topics = bags['offline']
    xi = max(a.position_m for a in ArticulatedDrive.from_values(
        load_params_file(CONFIG)).vehicle.axles)
    loads = [stamp(m) for _, m in topics['/wheel_loads']]
    road = {stamp(m): m for _, m in topics['/road_profile/left']}
    for side, word in enumerate(('left', 'right')):
        rows = topics[f'/road_profile/fused/{word}']
        stamps = [stamp(m) for _, m in rows]
        x = np.array([m.point.x for _, m in rows])
        assert stamps == loads[:len(stamps)] and len(stamps) > 0.5 * len(loads)
        assert np.all(np.diff(x) > 0.0) and x[-1] <= 20.0 * DURATION_S - xi + 0.05
        assert {m.header.frame_id for _, m in rows} == {'road'}
        assert all((m.point.y > 0.0) == (side == 0) for _, m in rows[:5])
        if side == 0:
            np.testing.assert_array_equal([m.point.z for _, m in rows],
                                          [road[s].point.z for s in stamps])
    acc = json.loads((outs['offline'] / 'report' / 'report.json').read_text())['accuracy']
    seg = acc['profile_xcorr_segments']
    k = seg['start_m'].index(20.0)
    assert min(seg['left'][k], seg['right'][k]) >= 0.98
    fused = json.loads((outs['offline'] / 'report' / 'report.json').read_text())[
        'whole_vehicle_estimate']['fused_profile']
    assert fused['axles'] == 5 and fused['points'] == len(topics['/road_profile/fused/left'])
    online = json.loads((outs['online'] / 'report' / 'report.json').read_text())[
        'whole_vehicle_estimate']['fused_profile']
    assert online['points'] == len(bags['online']['/road_profile/fused/left'])


def test_a_file_stating_friction_and_lag_is_estimated(tmp_path):
    """A drive with 1.5 kN of tanh friction per spring and a 3 ms lag on every sensor, and the
    same file for estimate_bag (it used to be refused): accepted, and its /wheel_loads are
    estimate_whole_vehicle's on the inputs the mcap library decodes, bit for bit."""
    from road_force_estimator.estimation.whole_vehicle import (
        WholeVehicleEstimator, estimate_whole_vehicle)
    text = CONFIG.read_text(encoding='utf-8')
    for old, new in (('leaf_spring_friction: [0.0, 0.0]',
                      'leaf_spring_friction: [1500.0, 1500.0]'),
                     ('sensor_time_constant: [0.0, 0.0]',
                      'sensor_time_constant: [0.003, 0.003]')):
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    params = tmp_path / 'friction_lag.yaml'
    params.write_text(text, encoding='utf-8')
    bag = tmp_path / 'drive'
    sim = subprocess.run([str(BIN / 'simulate_bag'), '--params-file', str(params), '--road',
                          'iso8608:C:seed=5', '--speed', '20', '--rate', str(RATE_HZ),
                          '--duration', '2', '--gnss-rate', '0', '--no-progress',
                          '--output', str(bag)], capture_output=True, text=True, timeout=300)
    assert sim.returncode == 0, sim.stderr
    out = tmp_path / 'est'
    assert estimate_bag([str(bag), '--params-file', str(params), '--output', str(out),
                         '--mode', 'online', '--no-figures', '--no-progress']) == 0
    vehicle, observer = load_parameters(str(params))
    assert vehicle.axles[1].leaf_spring_friction_n == (1500.0, 1500.0)
    assert vehicle.axles[1].sensor_time_constant_s == 0.003
    names = WholeVehicleEstimator(vehicle, observer).channel_names
    stamps, readings, speed = inputs(bag, names)
    want = estimate_whole_vehicle(vehicle, stamps, readings, speed, observer=observer)
    got = np.array([m.effort for _, m in decoded(out / 'bag')['/wheel_loads']]).T
    np.testing.assert_array_equal(got, want.load_n)


def test_a_stuck_sensor_is_named_in_the_report_and_the_diagnostics(tmp_path):
    """A drive whose trailer_1_right_suspension the plant holds for 1.5 s from 1 s
    (``simulator.sensor_faults``; where it struck read from the bag's metadata.yaml): the
    report's Sensors (report.json) and the whole vehicle's /diagnostics status (decoded by the
    mcap library) name it stuck, its flag raised within 1 s of the hold, once; no other
    sensor flagged."""
    import yaml
    text = CONFIG.read_text(encoding='utf-8')
    old = 'sensor_faults: ""'
    assert text.count(old) == 1
    params = tmp_path / 'stuck.yaml'
    params.write_text(text.replace(
        old, 'sensor_faults: "stuck@trailer_1_right_suspension:start=1,duration=1.5"'),
        encoding='utf-8')
    bag = tmp_path / 'drive'
    sim = subprocess.run([str(BIN / 'simulate_bag'), '--params-file', str(params), '--road',
                          'iso8608:C:seed=5', '--speed', '20', '--rate', str(RATE_HZ),
                          '--duration', str(DURATION_S), '--gnss-rate', '0', '--no-progress',
                          '--output', str(bag)], capture_output=True, text=True, timeout=300)
    assert sim.returncode == 0, sim.stderr
    info = yaml.safe_load((bag / 'metadata.yaml').read_text(encoding='utf-8'))
    custom = info['rosbag2_bagfile_information']['custom_data']
    (fault,) = json.loads(custom['road_force_estimator.sensor_faults'])
    assert fault['channel'] == 'trailer_1_right_suspension'
    out = tmp_path / 'est'
    assert estimate_bag([str(bag), '--params-file', str(params), '--output', str(out),
                         '--mode', 'online', '--no-figures', '--no-progress']) == 0
    rows = decoded(bag)['/suspension/deflections']
    t0 = stamp(rows[0][1])
    began_s = (stamp(rows[fault['window'][0]][1]) - t0) * 1e-9
    sensors = json.loads((out / 'report' / 'report.json').read_text())['sensors']
    flagged = {n: v for n, v in sensors.items() if v['stuck_flags'] or v['drift_flags']}
    assert set(flagged) == {'trailer_1_right_suspension'}
    assert flagged['trailer_1_right_suspension']['stuck_flags'] == 1
    assert 0 < flagged['trailer_1_right_suspension']['first_stuck_s'] - began_s <= 1.0
    assert len(sensors) == 12                      # every channel of the whole vehicle
    statuses = [{kv.key: kv.value for kv in st.values}
                for _, m in decoded(out / 'bag')['/diagnostics'] for st in m.status
                if st.name.endswith('whole vehicle')]
    assert any(s['sensor.trailer_1_right_suspension'] == 'stuck' for s in statuses)
    last = statuses[-1]
    assert last['total.stuck.trailer_1_right_suspension'] == '1'
    assert {last[f'total.stuck.{n}'] for n in sensors
            if n != 'trailer_1_right_suspension'} == {'0'}
