"""estimate_bag on a drive estimated block by block (pipeline.blocks, issue 21) against the
same drive in one block (pipeline.one_block): the same messages in the estimate bag (read with
the mcap library), the same segments.csv, report.json and report.md."""
import dataclasses
import json

from mcap.reader import make_reader
import numpy as np
import pytest

from road_force_estimator.bagio import BagWriter, drive_blocks
from road_force_estimator.serde import TYPESTORE
from road_force_estimator.bagio.mcap_file import McapFile
from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
from road_force_estimator.core.plant import simulate
from road_force_estimator.core.road import iso8608_profile
from road_force_estimator.interfaces import DEFLECTION_JOINTS
from road_force_estimator.estimation.smoothing import smoother
from road_force_estimator.pipeline import blocks, plan, window_figures
from road_force_estimator.tools import estimate_bag

import bag_samples

BASE = 1_700_000_000 * 10**9


def joint_state(stamp_ns, q, roll):
    """A /suspension/deflections message (:mod:`bag_samples`)."""
    return bag_samples.joint_state(int(stamp_ns), DEFLECTION_JOINTS, [q[0], q[1], roll])


def twist(stamp_ns, v):
    return bag_samples.twist(int(stamp_ns), v)


def header(stamp_ns, frame):
    return bag_samples.header(int(stamp_ns), frame)


def navsatfix(stamp_ns, lat, lon):
    T = TYPESTORE.types
    return T['sensor_msgs/msg/NavSatFix'](
        header=header(stamp_ns, 'gnss'),
        status=T['sensor_msgs/msg/NavSatStatus'](status=0, service=1),
        latitude=lat, longitude=lon, altitude=0.0, position_covariance=np.zeros(9),
        position_covariance_type=0)


@pytest.fixture(scope='module')
def drive(tmp_path_factory):
    """4 s at 1 kHz of a simulated drive with defects (NaN, duplicate and backward stamps,
    samples before the first twist, a 0.2 s gap, a lift-off-free road), a twist at 100 Hz,
    GNSS at 10 Hz; small chunks."""
    tr = simulate(VehicleParameters(), iso8608_profile('C', 120.0, seed=4), speed_mps=20.0,
                  rate_hz=1000.0, duration_s=4.0, tire_envelope_m=0.25)
    stamps = BASE + np.round(tr.t_s * 1e9).astype(np.int64)
    stamps[2500:] += 200_000_000
    rng = np.random.default_rng(5)
    q = tr.q_m + 1e-5 * rng.standard_normal(tr.q_m.shape)
    folder = tmp_path_factory.mktemp('drive') / 'd'
    old = McapFile.CHUNK_BYTES
    McapFile.CHUNK_BYTES = 1 << 13
    try:
        with BagWriter(folder) as bag:
            for topic, kind in (('/vehicle/twist', 'geometry_msgs/msg/TwistStamped'),
                                ('/suspension/deflections', 'sensor_msgs/msg/JointState'),
                                ('/fix', 'sensor_msgs/msg/NavSatFix')):
                bag.add_topic(topic, kind, 'sensor_data')
            for k, s in enumerate(stamps.tolist()):
                if k >= 30 and k % 10 == 0:
                    bag.write('/vehicle/twist', s, twist(s, 20.0 + 0.01 * (k % 7)))
                if k % 100 == 0:
                    bag.write('/fix', s, navsatfix(s, 48.1 + 1.8e-4 * k * 1e-3, 11.5))
                qk = (np.nan, q[k, 1]) if k in (40, 41, 1700) else q[k]
                bag.write('/suspension/deflections', s, joint_state(s, qk, tr.roll_rad[k]))
                if k in (900, 2000):
                    bag.write('/suspension/deflections', s, joint_state(s, 1.01 * q[k], 0.0))
                if k == 1200:
                    b = int(stamps[k - 5])
                    bag.write('/suspension/deflections', s, joint_state(b, q[k], 0.0))
    finally:
        McapFile.CHUNK_BYTES = old
    return folder


def messages(bag):
    out = {}
    for f in sorted(bag.glob('*.mcap')):
        with open(f, 'rb') as fh:
            for _, channel, msg in make_reader(fh).iter_messages(log_time_order=True):
                out.setdefault(channel.topic, []).append((msg.log_time, msg.data))
    return out


@pytest.mark.parametrize('latency_s, segment_m, block', [
    (0.0, 6.5, 700), (0.01, 7.0, 333), (0.0, 100.0, 1 << 16)])
def test_streamed_equals_one_piece(drive, tmp_path, monkeypatch, latency_s, segment_m, block):
    observer = dataclasses.replace(ObserverParameters(), latency_s=latency_s)
    kw = dict(observer=observer, segment_length_m=segment_m, figures=False)
    one = estimate_bag.run(drive, tmp_path / 'one', **kw)
    assert one.estimates is not None
    monkeypatch.setattr(plan, 'STREAM_MIN_SAMPLES', 1)
    monkeypatch.setattr(drive_blocks, 'BLOCK_SAMPLES', block)
    streamed = estimate_bag.run(drive, tmp_path / 'str', **kw)
    assert_same_outputs(one, streamed, tmp_path)


def assert_same_outputs(one, streamed, tmp_path):
    """The streamed run's bag messages (mcap library), report files and marker are the
    one-piece run's."""
    track = streamed.estimates                            # never held whole
    assert not hasattr(track, 'wheel_load_n')
    rows = np.flatnonzero(one.estimates.valid)
    np.testing.assert_array_equal(track.stamp_ns, one.estimates.stamp_ns[rows])
    np.testing.assert_array_equal(track.distance_m, one.estimates.distance_m[rows])
    a, b = messages(tmp_path / 'one' / 'bag'), messages(tmp_path / 'str' / 'bag')
    assert sorted(a) == sorted(b)
    for topic in a:
        assert a[topic] == b[topic], topic
    for name in ('segments.csv', 'report.md'):
        assert (tmp_path / 'one' / 'report' / name).read_text() == \
            (tmp_path / 'str' / 'report' / name).read_text(), name
    ja = json.loads((tmp_path / 'one' / 'report' / 'report.json').read_text())
    jb = json.loads((tmp_path / 'str' / 'report' / 'report.json').read_text())
    assert ja == jb
    assert ja['rejected']['/suspension/deflections'] == {
        'backwards_stamp': 1, 'duplicate_stamp': 2, 'nonfinite': 3}
    assert ja['notes']['samples before the first twist (given its speed)'] == 30
    assert ja['segments'] >= (8 if ja['segment_length_m'] < 10 else 1)
    assert np.isfinite(ja['iri_m_per_km']['estimated']).all()
    assert ja['fixes'] == 41
    rows = (tmp_path / 'str' / 'report' / 'segments.csv').read_text().splitlines()
    assert 'nan' not in rows[1].split(',')[12]                # start_lat from the fixes
    assert written(tmp_path / 'one') == written(tmp_path / 'str')


def written(folder):
    marker = json.loads((folder / '.written-by-road-force-estimator.json').read_text())
    return [f for f in marker['files'] if not f.endswith('.mcap')]


def small_windows(monkeypatch, window=700, overlap=300):
    """The offline smoother's runs in windows of ``window`` samples (overlap ``overlap``),
    in one piece and streamed alike: every smoother ``eager`` (the stream's rule, a run
    longer than ``window + overlap`` in windows). By default one piece windows only runs of
    WINDOWED_RUNS windows' work (``window + 2 overlap`` each): a run in between (the drive's
    1500 samples after the gap, with 900 / 300) would be whole in one piece and in windows
    streamed, ~0.4 N apart with windows this short (issue 28's xfail)."""
    monkeypatch.setattr(smoother, 'window_samples', lambda *a, **k: (window, overlap))
    init = smoother.Smoother.__init__
    monkeypatch.setattr(smoother.Smoother, '__init__',
                        lambda self, *a, **k: init(self, *a, **{**k, 'eager': True}))


@pytest.mark.parametrize('windows, segment_m, block, gnss', [
    (True, 6.5, 700, False), (False, 7.0, 333, False), (True, 100.0, 1 << 16, True)])
def test_streamed_offline_equals_one_piece(drive, tmp_path, monkeypatch, windows, segment_m,
                                           block, gnss):
    """Offline (the model's smoother): the streamed drive's rows come run by run and, in
    windows, window by window (smoother.smoothed_rows, as smooth): the same bytes."""
    if windows:
        small_windows(monkeypatch)
    observer = dataclasses.replace(ObserverParameters(),
                                   distance_source='gnss' if gnss else 'speed')
    kw = dict(observer=observer, segment_length_m=segment_m, figures=False, mode='offline')
    one = estimate_bag.run(drive, tmp_path / 'one', **kw)
    monkeypatch.setattr(plan, 'STREAM_MIN_SAMPLES', 1)
    monkeypatch.setattr(drive_blocks, 'BLOCK_SAMPLES', block)
    streamed = estimate_bag.run(drive, tmp_path / 'str', **kw)
    assert_same_outputs(one, streamed, tmp_path)
    assert ('odometer' in streamed.summary) == gnss


def test_short_drives_stay_in_one_piece(drive, tmp_path):
    """Below STREAM_MIN_SAMPLES (and with a reference, or offline with a differentiator
    scheme) one piece, as before."""
    obs = ObserverParameters()
    assert not plan.plan_drive(drive, 'online', obs).blocks
    assert not plan.plan_drive(drive, 'offline', obs).blocks
    assert plan.plan_drive(drive, 'online', obs, min_samples=1).blocks
    assert plan.plan_drive(drive, 'offline', obs, min_samples=1).blocks
    assert not plan.plan_drive(drive, 'online', obs, object(), min_samples=1).blocks
    implicit = dataclasses.replace(obs, discretization='implicit')
    assert not plan.plan_drive(drive, 'offline', implicit, min_samples=1).blocks


def test_a_streamed_drive_without_twist_is_refused(tmp_path, monkeypatch, capsys):
    folder = tmp_path / 'notwist'
    with BagWriter(folder) as bag:
        bag.add_topic('/suspension/deflections', 'sensor_msgs/msg/JointState')
        for k in range(20):
            bag.write('/suspension/deflections', k, joint_state(k, (0.0, 0.0), 0.0))
    monkeypatch.setattr(plan, 'STREAM_MIN_SAMPLES', 1)
    code = estimate_bag.main([str(folder), '--output', str(tmp_path / 'o'), '--no-progress'])
    err = capsys.readouterr().err
    assert code == 1 and 'speed' in err and err.count('\n') == 1
    assert not (tmp_path / 'o' / 'bag').exists()


def test_streamed_detail_figures_equal_one_piece(drive, tmp_path, monkeypatch):
    """The detail figures come from the estimator resumed at a snapshot before the window:
    the same pictures as in one piece; the profile and overview show the window only."""
    one = estimate_bag.run(drive, tmp_path / 'one', segment_length_m=10.0)
    monkeypatch.setattr(plan, 'STREAM_MIN_SAMPLES', 1)
    monkeypatch.setattr(drive_blocks, 'BLOCK_SAMPLES', 500)
    streamed = estimate_bag.run(drive, tmp_path / 'str', segment_length_m=10.0)
    assert streamed.summary['figures'] == one.summary['figures']
    assert len(one.summary['figures']) == 6
    for name in ('states.png', 'body.png', 'wheels.png', 'loads.png'):
        assert (tmp_path / 'one' / 'report' / name).read_bytes() == \
            (tmp_path / 'str' / 'report' / name).read_bytes(), name
    assert blocks.FIGURES_NOTE in streamed.summary['notes']


@pytest.mark.parametrize('guess', [True, False])
def test_streamed_offline_detail_figures_equal_one_piece(drive, tmp_path, monkeypatch, guess):
    """Offline the detail window's pieces are kept as they pass (OfflineWindow's guess of
    the window), or, when the guess missed, the drive is estimated again: the same
    pictures as in one piece either way."""
    small_windows(monkeypatch, 900, 300)
    kw = dict(segment_length_m=10.0, mode='offline')
    one = estimate_bag.run(drive, tmp_path / 'one', **kw)
    monkeypatch.setattr(plan, 'STREAM_MIN_SAMPLES', 1)
    monkeypatch.setattr(drive_blocks, 'BLOCK_SAMPLES', 500)
    if not guess:           # a wrong guess of the drive's end: the window estimated again
        monkeypatch.setattr(window_figures.OfflineWindow, 'keep', lambda self, p, a: None)
    streamed = estimate_bag.run(drive, tmp_path / 'str', **kw)
    assert streamed.summary['figures'] == one.summary['figures']
    assert len(one.summary['figures']) == 6
    for name in ('states.png', 'body.png', 'wheels.png', 'loads.png'):
        assert (tmp_path / 'one' / 'report' / name).read_bytes() == \
            (tmp_path / 'str' / 'report' / name).read_bytes(), name


def test_a_full_disk_while_spilling_leaves_nothing(drive, tmp_path, monkeypatch, capsys):
    """Offline, the columns that wait for the end go to temporary files in the output
    folder (core.spill): a full disk there is one line, exit 1, and nothing left behind."""
    import errno

    from road_force_estimator.core import spill

    def full(self, rows):
        raise OSError(errno.ENOSPC, 'No space left on device')

    monkeypatch.setattr(plan, 'STREAM_MIN_SAMPLES', 1)
    monkeypatch.setattr(spill.SpillColumn, 'append', full)
    out = tmp_path / 'o'
    code = estimate_bag.main([str(drive), '--output', str(out), '--mode', 'offline',
                              '--no-progress', '--no-figures'])
    err = capsys.readouterr().err
    assert code == 1 and 'out of space' in err and err.count('\n') == 1, err
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize('mode', ['online', 'offline'])
def test_a_cut_bag_streams_as_one_piece(drive, tmp_path, monkeypatch, mode):
    """A bag cut off at 60 % of its file (a recorder that lost power; metadata.yaml still
    lists every message): both paths read it up to the break, say so once, and write the
    same estimates and report."""
    import shutil

    cut = tmp_path / 'cut'
    shutil.copytree(drive, cut)
    (mcap,) = cut.glob('*.mcap')
    data = mcap.read_bytes()
    mcap.write_bytes(data[:int(0.6 * len(data))])
    kw = dict(segment_length_m=10.0, figures=False, mode=mode)
    one = estimate_bag.run(cut, tmp_path / 'one', **kw)
    monkeypatch.setattr(plan, 'STREAM_MIN_SAMPLES', 1)
    monkeypatch.setattr(drive_blocks, 'BLOCK_SAMPLES', 500)
    streamed = estimate_bag.run(cut, tmp_path / 'str', **kw)
    assert 0 < one.summary['samples']['input'] < 3000
    assert one.warnings and one.warnings == streamed.warnings
    a, b = messages(tmp_path / 'one' / 'bag'), messages(tmp_path / 'str' / 'bag')
    assert sorted(a) == sorted(b) and all(a[t] == b[t] for t in a)
    ja = json.loads((tmp_path / 'one' / 'report' / 'report.json').read_text())
    jb = json.loads((tmp_path / 'str' / 'report' / 'report.json').read_text())
    assert ja == jb


@pytest.fixture(scope='module')
def truth_drive(tmp_path_factory):
    """4 s at 1 kHz of a simulated drive with its ground truth (simulate_bag's topics), small
    chunks."""
    from road_force_estimator import bagio

    tr = simulate(VehicleParameters(), iso8608_profile('C', 120.0, seed=6), speed_mps=20.0,
                  rate_hz=1000.0, duration_s=4.0, tire_envelope_m=0.25)
    rng = np.random.default_rng(7)
    q = tr.q_m + 1e-5 * rng.standard_normal(tr.q_m.shape)
    folder = tmp_path_factory.mktemp('truth') / 'd'
    old = McapFile.CHUNK_BYTES
    McapFile.CHUNK_BYTES = 1 << 13
    try:
        bagio.write_drive_bag(folder, tr, q, tr.roll_rad)
    finally:
        McapFile.CHUNK_BYTES = old
    return folder


def _csv_without_true_iri(path):
    rows = [line.split(',') for line in path.read_text().splitlines()]
    keep = [i for i, name in enumerate(rows[0]) if not name.startswith('true_iri')]
    return [[r[i] for i in keep] for r in rows]


@pytest.mark.parametrize('mode', ['online', 'offline'])
def test_a_drive_with_ground_truth_goes_in_blocks(truth_drive, tmp_path, monkeypatch, mode):
    """Ground truth no longer keeps a drive in one block: the same estimate bag, the same
    segments (but the truth's IRI), the load and LTR accuracy of one block (to the sums'
    last bits) and a note of what a drive in blocks leaves out."""
    kw = dict(segment_length_m=10.0, figures=False, mode=mode)
    one = estimate_bag.run(truth_drive, tmp_path / 'one', **kw)
    monkeypatch.setattr(plan, 'STREAM_MIN_SAMPLES', 1)
    monkeypatch.setattr(drive_blocks, 'BLOCK_SAMPLES', 700)
    many = estimate_bag.run(truth_drive, tmp_path / 'str', **kw)
    assert not hasattr(many.estimates, 'wheel_load_n')          # went in blocks
    a, b = messages(tmp_path / 'one' / 'bag'), messages(tmp_path / 'str' / 'bag')
    assert sorted(a) == sorted(b)
    for topic in a:
        assert a[topic] == b[topic], topic
    assert _csv_without_true_iri(tmp_path / 'one' / 'report' / 'segments.csv') == \
        _csv_without_true_iri(tmp_path / 'str' / 'report' / 'segments.csv')
    ja, jb = one.summary, many.summary
    assert ja['has_ground_truth'] and jb['has_ground_truth']
    assert ja['messages'] == jb['messages'] and ja['rejected'] == jb['rejected']
    assert set(jb['accuracy']) < set(ja['accuracy'])
    for key, value in jb['accuracy'].items():
        np.testing.assert_allclose(value, ja['accuracy'][key], rtol=1e-9, err_msg=key)
    assert jb['accuracy']['samples_judged'] > 3000
    from road_force_estimator.report.streamed import TRUTH_NOTE
    assert TRUTH_NOTE in jb['notes']


def test_streamed_detail_figures_with_truth_equal_one_block(truth_drive, tmp_path,
                                                            monkeypatch):
    """The detail figures of a drive with truth in blocks show its truth as one block's."""
    one = estimate_bag.run(truth_drive, tmp_path / 'one', segment_length_m=10.0)
    monkeypatch.setattr(plan, 'STREAM_MIN_SAMPLES', 1)
    monkeypatch.setattr(drive_blocks, 'BLOCK_SAMPLES', 500)
    many = estimate_bag.run(truth_drive, tmp_path / 'str', segment_length_m=10.0)
    assert many.summary['figures'] == one.summary['figures']
    for name in ('states.png', 'body.png', 'wheels.png', 'loads.png'):
        assert (tmp_path / 'one' / 'report' / name).read_bytes() == \
            (tmp_path / 'str' / 'report' / name).read_bytes(), name
