"""estimate_bag online on an articulated drive with the front axle's stage in blocks beside the
whole vehicle's (pipeline.plan's threshold lowered to 1: pipeline.blocks with
pipeline.whole_vehicle.BlockJoin) against the same drive in one block: every message of the
estimate bag the same (topic, log time, bytes; read by the mcap library), segments.csv,
report.md and report.json the same, at 0 and 10 ms, on a drive with 0.3 s of deflections and
twists lost (a gap), with the tractor IMU, in blocks of 1, 300 and 65536 samples, the whole
vehicle's samples spilled to files and read back 97 to 65536 at a time."""
import json
from pathlib import Path
import subprocess
import sys

from mcap.reader import make_reader
import pytest

from road_force_estimator.bagio import BagWriter, drive_blocks
from road_force_estimator.pipeline import plan
from road_force_estimator.tools.estimate_bag import main as estimate_bag

REPO = Path(__file__).resolve().parents[2]
CONFIG = REPO / 'config' / 'tractor_semitrailer.yaml'
BIN = Path(sys.executable).parent
LOST = (1.5e9, 1.8e9)          # ns after the first message: deflections and twists lost


def simulate(folder: Path, params: Path, duration_s: float) -> Path:
    """A simulate_bag drive of the combination (class C, 20 m/s, 1 kHz, no ground truth)."""
    sim = subprocess.run([str(BIN / 'simulate_bag'), '--params-file', str(params), '--road',
                          'iso8608:C:seed=5', '--speed', '20', '--rate', '1000',
                          '--duration', f'{duration_s:g}', '--no-ground-truth',
                          '--no-progress', '--output', str(folder)],
                         capture_output=True, text=True, timeout=600)
    assert sim.returncode == 0, sim.stderr
    return folder


def with_gap(bag: Path, out: Path) -> Path:
    """``bag`` written again (raw messages, read by the mcap library) without the
    deflections and twists of :data:`LOST`."""
    from mcap.reader import make_reader as reader

    rows = []
    topics = {}
    for path in sorted(bag.glob('*.mcap')):
        with open(path, 'rb') as f:
            r = reader(f)
            for schema, channel, msg in r.iter_messages(log_time_order=True):
                topics[channel.topic] = schema.name
                rows.append((channel.topic, msg.log_time, bytes(msg.data)))
    t0 = rows[0][1]
    with BagWriter(out) as w:
        for topic, kind in topics.items():
            w.add_topic(topic, kind)
        for topic, t, data in rows:
            if topic in ('/suspension/deflections', '/vehicle/twist') and \
                    LOST[0] <= t - t0 < LOST[1]:
                continue
            w.write_raw(topic, t, data)
    return out


def imu_params(folder: Path) -> Path:
    """The file's combination with the tractor IMU (plant and observer) and pendulum roll
    sensors through a curve."""
    text = CONFIG.read_text()
    for old, new in (('tractor_imu: false', 'tractor_imu: true'),
                     ('roll_sensor: "ideal"', 'roll_sensor: "pendulum"'),
                     ('lateral_profile: ""',
                      'lateral_profile: "curve:start=1,ramp=1,hold=2,ay=2"')):
        assert old in text
        text = text.replace(old, new)
    path = folder / 'imu.yaml'
    path.write_text(text)
    return path


def messages(bag: Path) -> dict:
    out: dict = {}
    for f in sorted(bag.glob('*.mcap')):
        with open(f, 'rb') as fh:
            for _, channel, msg in make_reader(fh).iter_messages(log_time_order=True):
                out.setdefault(channel.topic, []).append((msg.log_time, msg.data))
    return out


def run(bag: Path, params: Path, folder: Path, latency_s: float, monkeypatch) -> None:
    """estimate_bag into ``folder/est`` (run from ``folder``: the report's command line
    the same in both runs)."""
    folder.mkdir()
    monkeypatch.chdir(folder)
    assert estimate_bag([str(bag), '--params-file', str(params), '-p',
                         f'observer.latency:={latency_s}', '--output', 'est', '--mode',
                         'online', '--segment-length', '10', '--no-figures',
                         '--no-progress']) == 0


def in_pieces(monkeypatch, block: int, sink: int) -> list:
    """pipeline.plan's threshold lowered to 1, the drive read ``block`` samples at a time and
    the whole vehicle's sinks reading ``sink`` spilled samples at a time: the list that
    collects each ``run_blocks`` call's ``whole`` argument."""
    from road_force_estimator.pipeline import blocks, whole_vehicle
    from road_force_estimator.report import whole_vehicle as report

    calls = []
    original = blocks.run_blocks

    def counted(*args, **kw):
        calls.append(kw.get('whole'))
        return original(*args, **kw)

    monkeypatch.setattr(blocks, 'run_blocks', counted)
    monkeypatch.setattr(plan, 'STREAM_MIN_SAMPLES', 1)
    monkeypatch.setattr(drive_blocks, 'BLOCK_SAMPLES', block)
    monkeypatch.setattr(whole_vehicle, 'SINK_ROWS', sink)
    monkeypatch.setattr(report, 'SUM_ROWS', sink)
    return calls


def same_messages(one: Path, other: Path) -> dict:
    """The two bags' messages by topic (read by the mcap library), asserted the same."""
    a, b = messages(one), messages(other)
    assert sorted(a) == sorted(b)
    for topic in a:
        assert a[topic] == b[topic], topic
    return a


def assert_fails_out_of_space(bag: Path, params: Path, out: Path, mode: str, capsys) -> None:
    """estimate_bag on a disk that fills: exit 1, one line saying so, the output folder
    empty or absent."""
    code = estimate_bag([str(bag), '--params-file', str(params), '--output', str(out),
                         '--mode', mode, '--no-progress', '--no-figures'])
    err = capsys.readouterr().err
    assert code == 1 and 'out of space' in err and err.count('\n') == 1, err
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize('drive, latency_s, block, sink', [
    ('gap', 0.0, 300, 257), ('gap', 0.01, 1, 1000), ('gap', 0.0, 1 << 16, 1 << 16),
    ('imu', 0.01, 300, 97)])
def test_in_blocks_the_outputs_are_one_blocks(drives, tmp_path, monkeypatch, drive,
                                              latency_s, block, sink):
    """``block``: the samples the drive is read in; ``sink``: the whole vehicle's spilled
    samples its sinks read at a time (its bag topics, statuses, report sums and the front
    wheels joined to the front axle's pieces)."""
    bag, params = drives[drive]
    run(bag, params, tmp_path / 'one', latency_s, monkeypatch)
    calls = in_pieces(monkeypatch, block, sink)
    run(bag, params, tmp_path / 'str', latency_s, monkeypatch)
    assert len(calls) == 1 and calls[0].source.n > 2500    # in blocks, the samples spilled
    one, streamed = tmp_path / 'one' / 'est', tmp_path / 'str' / 'est'
    a = same_messages(one / 'bag', streamed / 'bag')
    assert len(a['/wheel_loads']) > 2500
    assert len(a['/road_profile/fused/left']) > 0
    for name in ('segments.csv', 'report.md'):
        assert (one / 'report' / name).read_text() == \
            (streamed / 'report' / name).read_text(), name
    ja = json.loads((one / 'report' / 'report.json').read_text())
    assert ja == json.loads((streamed / 'report' / 'report.json').read_text())
    wv = ja['whole_vehicle_estimate']
    assert wv['gaps'] == (1 if drive == 'gap' else 0)
    if drive == 'imu':
        assert wv['tractor_imu']['fresh'] > 2500


def test_a_full_disk_while_spilling_leaves_nothing(drives, tmp_path, monkeypatch, capsys):
    """The whole vehicle's samples go to temporary files in the output folder (core.spill):
    a full disk there is one line, exit 1, and nothing left behind."""
    import errno

    from road_force_estimator.core import spill

    def full(self, rows):
        raise OSError(errno.ENOSPC, 'No space left on device')

    bag, params = drives['gap']
    monkeypatch.setattr(plan, 'STREAM_MIN_SAMPLES', 1)
    monkeypatch.setattr(spill.SpillColumn, 'append', full)
    assert_fails_out_of_space(bag, params, tmp_path / 'o', 'online', capsys)


def test_in_blocks_the_detail_figures_are_one_blocks(drives, tmp_path, monkeypatch):
    """Figures on: the detail window's figures (the estimator resumed over the window's
    blocks, each piece given the whole vehicle's front wheels again) are one block's bytes;
    the profile and overview show that window only (the report's note says so)."""
    from road_force_estimator.pipeline import blocks
    from road_force_estimator.tools.estimate_bag import load_parameters, run as estimate

    bag, params = drives['gap']
    vehicle, observer = load_parameters(str(params))
    kw = dict(vehicle=vehicle, observer=observer, mode='online', segment_length_m=10.0)
    one = estimate(bag, tmp_path / 'one', **kw)
    monkeypatch.setattr(plan, 'STREAM_MIN_SAMPLES', 1)
    monkeypatch.setattr(drive_blocks, 'BLOCK_SAMPLES', 700)
    streamed = estimate(bag, tmp_path / 'str', **kw)
    assert blocks.FIGURES_NOTE in streamed.summary['notes']
    names = ('states.png', 'body.png', 'wheels.png', 'loads.png')
    assert set(names) <= set(one.summary['figures']) & set(streamed.summary['figures'])
    for name in names:
        assert (tmp_path / 'one' / 'report' / name).read_bytes() == \
            (tmp_path / 'str' / 'report' / name).read_bytes(), name
