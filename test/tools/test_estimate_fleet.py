"""estimate_fleet: many drives on Dask (local cluster, and real `dask scheduler` / `dask worker`
processes on 127.0.0.1), faults, resume, and segment geometry against Vincenty's direct
geodesic (written here, independently of the package)."""
import csv
import json
import math
import os
from pathlib import Path
import shutil
import socket
import subprocess
import sys
import time

import numpy as np
import pytest

from road_force_estimator.tools import estimate_bag
from road_force_estimator.tools import estimate_fleet
from road_force_estimator.tools import simulate_bag
from road_force_estimator.tools.estimate_fleet import FLEET_COLUMNS

pytestmark = pytest.mark.slow   # `pytest -m 'not slow'` skips it; scripts/test runs it

PY = sys.executable
DASK = str(Path(sys.executable).parent / 'dask')
SEGMENT_M = 25.0
SPEED = 20.0
#: The good drives: id -> (start latitude, start longitude, heading, seed); 4 s at 400 Hz.
DRIVES = {
    'd1': (48.1486, 17.1077, 30.0, 1),
    'd2': (40.0150, -105.2705, 135.0, 2),
    'd3': (-33.8688, 151.2093, 270.0, 3),
}
BAD = 'd0_corrupt'
TIMEOUT = 300


def vincenty_direct(lat1, lon1, azimuth, distance):
    """Point at ``distance`` (m) from (lat1, lon1) along the geodesic of initial ``azimuth``
    (deg clockwise from north) on WGS84 (Vincenty 1975)."""
    a, f = 6378137.0, 1 / 298.257223563
    b = a * (1 - f)
    alpha1 = math.radians(azimuth)
    tan_u1 = (1 - f) * math.tan(math.radians(lat1))
    cos_u1 = 1 / math.sqrt(1 + tan_u1**2)
    sin_u1 = tan_u1 * cos_u1
    sigma1 = math.atan2(tan_u1, math.cos(alpha1))
    sin_alpha = cos_u1 * math.sin(alpha1)
    cos2_alpha = 1 - sin_alpha**2
    u_sq = cos2_alpha * (a**2 - b**2) / b**2
    big_a = 1 + u_sq / 16384 * (4096 + u_sq * (-768 + u_sq * (320 - 175 * u_sq)))
    big_b = u_sq / 1024 * (256 + u_sq * (-128 + u_sq * (74 - 47 * u_sq)))
    sigma = distance / (b * big_a)
    for _ in range(200):
        cos_2sm = math.cos(2 * sigma1 + sigma)
        d_sigma = big_b * math.sin(sigma) * (cos_2sm + big_b / 4 * (
            math.cos(sigma) * (-1 + 2 * cos_2sm**2)
            - big_b / 6 * cos_2sm * (-3 + 4 * math.sin(sigma)**2) * (-3 + 4 * cos_2sm**2)))
        prev, sigma = sigma, distance / (b * big_a) + d_sigma
        if abs(sigma - prev) < 1e-14:
            break
    cos_2sm = math.cos(2 * sigma1 + sigma)
    sin_s, cos_s = math.sin(sigma), math.cos(sigma)
    lat2 = math.atan2(sin_u1 * cos_s + cos_u1 * sin_s * math.cos(alpha1),
                      (1 - f) * math.hypot(sin_alpha,
                                           sin_u1 * sin_s - cos_u1 * cos_s * math.cos(alpha1)))
    lam = math.atan2(sin_s * math.sin(alpha1), cos_u1 * cos_s - sin_u1 * sin_s * math.cos(alpha1))
    c = f / 16 * cos2_alpha * (4 + f * (4 - 3 * cos2_alpha))
    big_l = lam - (1 - c) * f * sin_alpha * (
        sigma + c * sin_s * (cos_2sm + c * cos_s * (-1 + 2 * cos_2sm**2)))
    return math.degrees(lat2), lon1 + math.degrees(big_l)


def metres_between(lat1, lon1, lat2, lon2):
    """Local flat-earth distance (m), good to well below a millimetre over a few metres."""
    m_per_deg_lat = 111132.954 - 559.822 * math.cos(2 * math.radians(lat1))
    m_per_deg_lon = 111412.84 * math.cos(math.radians(lat1))
    return math.hypot((lat2 - lat1) * m_per_deg_lat, (lon2 - lon1) * m_per_deg_lon)


def write_params(path, lat=48.1486, lon=17.1077, heading=0.0):
    path.write_text('/**:\n  ros__parameters:\n'
                    f'    simulator.gnss.start_latitude: {lat!r}\n'
                    f'    simulator.gnss.start_longitude: {lon!r}\n'
                    f'    simulator.gnss.heading: {heading!r}\n'
                    '    observer.lipschitz_deflection: 3000.0\n')
    return path


def read_csv(path):
    with open(path, newline='') as f:
        return list(csv.reader(f))


def mcap_messages(bag):
    """(topic, log time, bytes) of every message of a bag folder, with the mcap library."""
    from mcap.reader import make_reader
    out = []
    for f in sorted(Path(bag).glob('*.mcap')):
        with f.open('rb') as stream:
            for _, channel, message in make_reader(stream).iter_messages(log_time_order=False):
                out.append((channel.topic, message.log_time, bytes(message.data)))
    return out


def free_port():
    """A port nobody listens on (bound then closed at once)."""
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


@pytest.fixture(scope='module')
def drives(tmp_path_factory):
    """Three good drives (straight routes, /fix at 10 Hz) and a corrupt one, in one folder."""
    root = tmp_path_factory.mktemp('fleet_in')
    inputs = root / 'drives'
    inputs.mkdir()
    for name, (lat, lon, heading, seed) in DRIVES.items():
        params = write_params(root / f'{name}.yaml', lat, lon, heading)
        rc = simulate_bag.main(['--road', f'iso8608:C:seed={seed}', '--speed', str(SPEED),
                                '--rate', '400', '--duration', '4', '--seed', str(seed),
                                '--params-file', str(params), '--output',
                                str(inputs / name), '--no-progress'])
        assert rc == 0
    # The corrupt drive: a real bag whose .mcap is replaced by the same length of garbage.
    bad = inputs / BAD
    shutil.copytree(inputs / 'd1', bad)
    for f in bad.glob('*.mcap'):
        f.write_bytes(np.random.default_rng(7).bytes(f.stat().st_size))
    params = write_params(root / 'params.yaml')
    return {'inputs': inputs, 'params': params, 'root': root}


@pytest.fixture(scope='module')
def local_run(drives, tmp_path_factory):
    """estimate_fleet on a local cluster of 2 worker processes, figures on."""
    out = tmp_path_factory.mktemp('fleet_out') / 'out'
    rc = estimate_fleet.main([str(drives['inputs']), '--params-file', str(drives['params']),
                              '--output', str(out), '--workers', '2', '--segment-length',
                              str(SEGMENT_M), '--no-progress'])
    return {'rc': rc, 'out': out}


# ------------------------------------------------------------------------------------------
# (a) local cluster, a corrupt drive, equality with estimate_bag alone

def test_local_cluster_processes_good_drives_and_lists_the_corrupt_one(drives, local_run):
    out = local_run['out']
    assert local_run['rc'] == 1
    rows = read_csv(out / 'segments.csv')
    assert tuple(rows[0]) == FLEET_COLUMNS
    assert sorted({r[0] for r in rows[1:]}) == sorted(DRIVES)
    failures = read_csv(out / 'failures.csv')
    assert failures[0] == ['drive', 'reason'] and len(failures) == 2
    assert failures[1][0] == BAD and failures[1][1].strip()
    assert not (out / 'drives' / BAD).exists()
    assert not (out / 'drives' / estimate_fleet.TMP_NAME).exists()
    for name in DRIVES:
        folder = out / 'drives' / name
        assert sorted(p.name for p in folder.iterdir()) == ['bag', 'fleet.json', 'report']
        assert (folder / 'report' / 'overview.png').is_file()


def test_each_drive_equals_estimate_bag_run_alone(drives, local_run, tmp_path):
    out = local_run['out']
    table = read_csv(out / 'segments.csv')
    for name in DRIVES:
        alone = tmp_path / name
        rc = estimate_bag.main([str(drives['inputs'] / name), '--params-file',
                                str(drives['params']), '--output', str(alone),
                                '--segment-length', str(SEGMENT_M), '--no-figures',
                                '--no-progress'])
        assert rc == 0
        mine = mcap_messages(out / 'drives' / name / 'bag')
        theirs = mcap_messages(alone / 'bag')
        assert len(mine) > 1000 and mine == theirs
        alone_rows = read_csv(alone / 'report' / 'segments.csv')
        header = alone_rows[0]
        fleet_rows = [r for r in table[1:] if r[0] == name]
        assert len(fleet_rows) == len(alone_rows) - 1 == 3
        for fr, ar in zip(fleet_rows, alone_rows[1:]):
            for j, col in enumerate(FLEET_COLUMNS[1:], start=1):
                assert fr[j] == ar[header.index(col)], (name, col)
    # ... and estimate_bag alone refuses the corrupt drive too.
    rc = estimate_bag.main([str(drives['inputs'] / BAD), '--output', str(tmp_path / BAD),
                            '--no-figures', '--no-progress'])
    assert rc == 1


def test_parquet_equals_csv_and_summary_counts(local_run):
    import pyarrow.parquet as pq

    out = local_run['out']
    rows = read_csv(out / 'segments.csv')
    pt = pq.read_table(out / 'segments.parquet')
    assert tuple(pt.column_names) == FLEET_COLUMNS
    cols = pt.to_pydict()
    assert len(cols['drive']) == len(rows) - 1 == 9
    for i, r in enumerate(rows[1:]):
        assert cols['drive'][i] == r[0]
        assert cols['lift_offs'][i] == int(r[FLEET_COLUMNS.index('lift_offs')])
        for j, c in enumerate(FLEET_COLUMNS[1:], start=1):
            v = float(r[j])
            assert (math.isnan(v) and math.isnan(cols[c][i])) or cols[c][i] == v, c
    summary = (out / 'summary.md').read_text()
    assert 'processed 3, skipped (already done) 0, failed 1' in summary
    assert '(segments_map.png)' in summary
    assert (out / 'segments_map.png').read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    # in/mi = m/km x 63.36 (1 mile = 63 360 in): the drive's length-weighted mean IRI.
    r1 = [r for r in rows[1:] if r[0] == 'd1']
    x0 = np.array([float(r[1]) for r in r1])
    x1 = np.array([float(r[2]) for r in r1])
    iri = np.array([float(r[3]) for r in r1])
    mean = float(np.sum(iri * (x1 - x0)) / np.sum(x1 - x0))
    assert f'{mean:.3f} ({mean * 63360 / 1000:.2f})' in summary       # m/km (in/mi)


# ------------------------------------------------------------------------------------------
# (c) geometry

def test_segment_coordinates_follow_the_straight_route(local_run):
    rows = read_csv(local_run['out'] / 'segments.csv')
    idx = {c: j for j, c in enumerate(rows[0])}
    worst = 0.0
    for r in rows[1:]:
        lat0, lon0, heading, _ = DRIVES[r[0]]
        for end in ('start', 'end'):
            lat_ref, lon_ref = vincenty_direct(lat0, lon0, heading, float(r[idx[f'{end}_m']]))
            err = metres_between(lat_ref, lon_ref, float(r[idx[f'{end}_lat']]),
                                 float(r[idx[f'{end}_lon']]))
            worst = max(worst, err)
    assert worst < 2.0
    assert worst < 0.05        # in fact: the route and the estimate agree to centimetres


def test_geojson_is_a_feature_collection_in_lon_lat_order(local_run):
    out = local_run['out']
    rows = read_csv(out / 'segments.csv')
    idx = {c: j for j, c in enumerate(rows[0])}
    doc = json.loads((out / 'segments.geojson').read_text())   # strict JSON: no NaN token
    assert doc['type'] == 'FeatureCollection'
    assert len(doc['features']) == len(rows) - 1
    for feature, r in zip(doc['features'], rows[1:]):
        assert feature['type'] == 'Feature'
        assert feature['properties']['drive'] == r[0]
        assert feature['properties']['start_m'] == float(r[idx['start_m']])
        geometry = feature['geometry']
        assert geometry['type'] == 'LineString'
        coords = geometry['coordinates']
        assert len(coords) >= 2 and all(len(p) == 2 for p in coords)
        lat0, lon0, heading, _ = DRIVES[r[0]]
        # [lon, lat]: the first position is the segment start, longitude first.
        assert coords[0] == pytest.approx([float(r[idx['start_lon']]),
                                           float(r[idx['start_lat']])], abs=1e-8)
        assert coords[-1] == pytest.approx([float(r[idx['end_lon']]),
                                            float(r[idx['end_lat']])], abs=1e-8)
        assert abs(coords[0][0] - lon0) < 0.01 and abs(coords[0][1] - lat0) < 0.01
        # Every vertex lies on the route within the segment, in order of travel.
        start, end = float(r[idx['start_m']]), float(r[idx['end_m']])
        along = []
        for lon, lat in coords:
            d = metres_between(lat0, lon0, lat, lon)
            lat_ref, lon_ref = vincenty_direct(lat0, lon0, heading, d)
            assert metres_between(lat_ref, lon_ref, lat, lon) < 2.0
            along.append(d)
        assert np.all(np.diff(along) > 0)
        assert start - 2.0 < along[0] and along[-1] < end + 2.0
        assert len(coords) >= 2 + int((end - start) / SPEED * 10) - 2   # the 10 Hz fixes


# ------------------------------------------------------------------------------------------
# (d) resume: nothing to do the second time, --force recomputes the same numbers

def test_second_run_skips_everything_and_force_recomputes_the_same(drives, local_run,
                                                                   tmp_path):
    out = tmp_path / 'out'
    shutil.copytree(local_run['out'], out)
    good = [str(drives['inputs'] / name) for name in DRIVES]
    base = ['--params-file', str(drives['params']), '--output', str(out), '--segment-length',
            str(SEGMENT_M), '--no-progress']
    before = (out / 'segments.csv').read_text()
    bags = {name: mcap_messages(out / 'drives' / name / 'bag') for name in DRIVES}
    result = estimate_fleet.run_fleet(good, out, segment_length_m=SEGMENT_M,
                                      vehicle=estimate_bag.load_parameters(
                                          str(drives['params']))[0])
    assert [o.status for o in result.outcomes] == ['skipped'] * 3
    assert result.engine.startswith('none')          # no cluster was even started
    assert (out / 'segments.csv').read_text() == before
    assert len(read_csv(out / 'failures.csv')) == 1          # the header: nothing failed
    assert estimate_fleet.main(good + base) == 0
    assert (out / 'segments.csv').read_text() == before
    assert 'processed 0, skipped (already done) 3, failed 0' in (out / 'summary.md').read_text()
    # A stopped run: one drive's outputs lost, a half-built folder left behind.
    shutil.rmtree(out / 'drives' / 'd2')
    (out / 'drives' / estimate_fleet.TMP_NAME / 'd2-junk').mkdir(parents=True)
    assert estimate_fleet.main(good + base + ['--workers', '1']) == 0
    summary = (out / 'summary.md').read_text()
    assert 'processed 1, skipped (already done) 2, failed 0' in summary
    assert not (out / 'drives' / estimate_fleet.TMP_NAME).exists()
    assert (out / 'segments.csv').read_text() == before
    # --force: everything again, the same numbers and bags.
    assert estimate_fleet.main(good + base + ['--force', '--workers', '2',
                                              '--no-figures']) == 0
    assert 'processed 3, skipped (already done) 0, failed 0' in (out / 'summary.md').read_text()
    assert (out / 'segments.csv').read_text() == before
    for name in DRIVES:
        assert mcap_messages(out / 'drives' / name / 'bag') == bags[name]


# ------------------------------------------------------------------------------------------
# (b) a real Dask scheduler and workers as processes on 127.0.0.1

@pytest.fixture(scope='module')
def dask_cluster(tmp_path_factory):
    """`dask scheduler` and two `dask worker` processes (no nanny, so killing one loses it)."""
    folder = tmp_path_factory.mktemp('dask')
    sched_file = folder / 'scheduler.json'
    procs = []
    logs = []

    def start(args, name):
        log = (folder / f'{name}.log').open('w')
        logs.append(log)
        procs.append(subprocess.Popen(args, cwd=folder, stdout=log, stderr=subprocess.STDOUT))
        return procs[-1]

    try:
        start([DASK, 'scheduler', '--host', '127.0.0.1', '--port', '0', '--no-dashboard',
               '--scheduler-file', str(sched_file)], 'scheduler')
        deadline = time.monotonic() + 60
        address = None
        while time.monotonic() < deadline and procs[0].poll() is None:
            if sched_file.is_file():
                try:
                    address = json.loads(sched_file.read_text())['address']
                    break
                except (ValueError, KeyError):
                    pass
            time.sleep(0.05)
        assert address, (folder / 'scheduler.log').read_text()[-2000:]
        workers = [start([DASK, 'worker', address, '--host', '127.0.0.1', '--nthreads', '1',
                          '--no-nanny', '--no-dashboard', '--name', f'w{i}',
                          '--death-timeout', '60', '--local-directory', str(folder / f'w{i}')],
                         f'worker{i}') for i in range(2)]
        from distributed import Client
        with Client(address, timeout=30, set_as_default=False) as client:
            client.wait_for_workers(2, timeout=90)
            yield {'address': address, 'client': client, 'workers': workers}
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                p.terminate()
        for p in reversed(procs):
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(timeout=20)
        for log in logs:
            log.close()


def _fleet_command(drives, out, address, *extra):
    return [PY, '-m', 'road_force_estimator.tools.estimate_fleet', str(drives['inputs']),
            '--params-file', str(drives['params']), '--output', str(out), '--scheduler',
            address, '--segment-length', str(SEGMENT_M), '--no-progress', *extra]


def test_existing_scheduler_gives_the_same_tables(drives, local_run, dask_cluster, tmp_path):
    out = tmp_path / 'out'
    run = subprocess.run(_fleet_command(drives, out, dask_cluster['address'], '--no-figures'),
                         capture_output=True, text=True, timeout=TIMEOUT)
    assert run.returncode == 1, run.stderr[-3000:]
    assert 'scheduler tcp://127.0.0.1' in (out / 'summary.md').read_text()
    for name in ('segments.csv', 'failures.csv'):
        assert (out / name).read_text() == (local_run['out'] / name).read_text()


def test_a_lost_worker_task_is_retried(drives, local_run, dask_cluster, tmp_path):
    client = dask_cluster['client']
    alive = [p for p in dask_cluster['workers'] if p.poll() is None]
    if len(alive) < 2:
        pytest.fail('needs the two workers of the fixture')
    pids = client.run(os.getpid)                       # worker address -> pid
    out = tmp_path / 'out'
    fleet = subprocess.Popen(_fleet_command(drives, out, dask_cluster['address']),
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    killed = None
    try:
        deadline = time.monotonic() + 120
        while killed is None and fleet.poll() is None and time.monotonic() < deadline:
            for worker, keys in client.processing().items():
                if any(str(k).startswith('estimate_fleet-') for k in keys):
                    victim = [p for p in alive if p.pid == pids.get(worker)]
                    if victim:
                        victim[0].kill()
                        victim[0].wait(timeout=20)
                        killed = worker
                        break
            time.sleep(0.02)
        stdout, stderr = fleet.communicate(timeout=TIMEOUT)
    finally:
        if fleet.poll() is None:
            fleet.kill()
            fleet.wait(timeout=20)
    assert killed is not None, 'no drive task was seen running'
    assert fleet.returncode == 1, stderr[-3000:]
    for name in ('segments.csv', 'failures.csv'):
        assert (out / name).read_text() == (local_run['out'] / name).read_text()
    assert not (out / 'drives' / estimate_fleet.TMP_NAME).exists()


def test_unreachable_scheduler_is_a_one_line_error(drives, tmp_path):
    out = tmp_path / 'out'
    run = subprocess.run(_fleet_command(drives, out, f'tcp://127.0.0.1:{free_port()}'),
                         capture_output=True, text=True, timeout=60)
    assert run.returncode == 2
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and 'cannot reach the Dask scheduler' in lines[0]
    assert not out.exists()                            # nothing written, no local fallback


# ------------------------------------------------------------------------------------------
# bad invocations and the pieces, without a cluster

@pytest.mark.parametrize('args, text', [
    ([], 'required'),
    # --params-file is optional now (issue 18), as estimate_bag's; -p refuses unknown names.
    (['{inputs}', '--output', '{out}', '-p', 'observer.nope:=1'],
     "unknown parameter 'observer.nope'"),
    (['{root}/nope', '--params-file', '{params}', '--output', '{out}'], 'no such folder'),
    (['{root}', '--params-file', '{params}', '--output', '{out}', '--workers', '0'],
     '--workers'),
    (['{inputs}', '--params-file', '{params}', '--output', '{out}', '--workers', '2',
      '--scheduler', 'tcp://127.0.0.1:1'], '--workers'),
    (['{inputs}', '--params-file', '{params}', '--output', '{out}', '--segment-length', '0'],
     '--segment-length'),
    (['{inputs}', '--params-file', '{root}/missing.yaml', '--output', '{out}'],
     'missing.yaml'),
    (['{params}', '--params-file', '{params}', '--output', '{out}'], 'not a folder'),
])
def test_bad_invocations_exit_2_with_one_line(drives, tmp_path, capsys, args, text):
    fill = {'inputs': drives['inputs'], 'root': drives['root'], 'params': drives['params'],
            'out': tmp_path / 'out'}
    rc = estimate_fleet.main([a.format(**fill) for a in args])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and text in err[0], err
    assert not (tmp_path / 'out').exists()


def test_bad_params_file_is_refused(drives, tmp_path, capsys):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('/**:\n  ros__parameters:\n    vehicle.sprung_mass: -3.0\n')
    rc = estimate_fleet.main([str(drives['inputs']), '--params-file', str(bad), '--output',
                              str(tmp_path / 'out')])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and 'vehicle.sprung_mass' in err[0]


# ------------------------------------------------------------------------------------------
# one run per output folder; an output folder inside a bag folder given directly (issue 16)

def test_a_second_run_into_the_same_output_is_refused(drives, tmp_path, capsys):
    import fcntl

    out = tmp_path / 'out'
    out.mkdir()
    (out / 'drives' / estimate_fleet.TMP_NAME / 'd1-building').mkdir(parents=True)
    with (out / estimate_fleet.LOCK_NAME).open('a') as held:
        fcntl.flock(held, fcntl.LOCK_EX)          # the first run, still computing
        rc = estimate_fleet.main([str(drives['inputs']), '--params-file', str(drives['params']),
                                  '--output', str(out), '--no-progress'])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and 'another estimate_fleet run' in err[0], err
    assert '--wait' in err[0]
    # The first run's half-built drive is left alone, nothing is written.
    assert (out / 'drives' / estimate_fleet.TMP_NAME / 'd1-building').is_dir()
    assert sorted(p.name for p in out.iterdir()) == [estimate_fleet.LOCK_NAME, 'drives']


def test_output_inside_a_bag_folder_given_directly_is_not_recomputed(drives, tmp_path):
    bag = tmp_path / 'd1'
    shutil.copytree(drives['inputs'] / 'd1', bag)
    argv = [str(bag), '--params-file', str(drives['params']), '--output', str(bag / 'fleet'),
            '--segment-length', str(SEGMENT_M), '--no-figures', '--no-progress',
            '--workers', '1']
    assert estimate_fleet.main(argv) == 0
    assert 'processed 1, skipped (already done) 0' in (bag / 'fleet' / 'summary.md').read_text()
    assert estimate_fleet.main(argv) == 0
    assert 'processed 0, skipped (already done) 1' in (bag / 'fleet' / 'summary.md').read_text()


def test_a_default_local_run_prints_no_warning_even_with_the_dashboard_port_taken(drives,
                                                                                  tmp_path):
    """Issue 29: Dask's scheduler opened an HTTP server on 8787 although the local cluster has
    no dashboard, and warned on stderr when the port was taken. A default run (no options
    but the input and the output) now leaves stderr silent but for its progress bar."""
    taken = socket.socket()
    try:
        taken.bind(('127.0.0.1', 8787))
        taken.listen(1)
    except OSError:
        pass      # someone else holds it: the same condition
    good = tmp_path / 'one'
    shutil.copytree(drives['inputs'] / 'd1', good / 'd1')
    try:
        run = subprocess.run([PY, '-m', 'road_force_estimator.tools.estimate_fleet', str(good),
                              '--output', str(tmp_path / 'out'), '--workers', '1'],
                             capture_output=True, text=True, timeout=TIMEOUT)
    finally:
        taken.close()
    assert run.returncode == 0, run.stderr[-3000:]
    lines = [line for line in run.stderr.replace('\r', '\n').splitlines() if line.strip()]
    assert lines and all(line.startswith('estimate_fleet:') and 'drive' in line
                         for line in lines), run.stderr   # the progress bar, nothing else
    assert 'arn' not in run.stderr and 'in use' not in run.stderr
    assert '1 processed, 0 skipped, 0 failed' in run.stdout
