"""What estimate_bag's whole-vehicle path drops, counted (issues 30 and 32): a 3 s
simulate_bag drive of the 5-axle combination with the tractor IMU, written again by the
``mcap`` library with messages made bad by the test (serialized by ``rosbags``, not by us):
a twist with a non-finite speed, a twist stamped before the one before it, a deflection
message without one trailer joint, an IMU message stamped back in time, and the IMU's first
40 ms and a 0.3 s hole left out (the folder's ``metadata.yaml`` the simulation's). The
report's ``rejected``, the last ``/diagnostics`` statuses (decoded by the ``mcap`` library)
and estimate_fleet's ``summary.md`` carry the numbers the test put in; the IMU's samples
without a fresh a_y are the test's own count (the rule of docs/articulated.md); every other
deflection sample is estimated."""
import json
from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore

from road_force_estimator.tools import estimate_fleet
from road_force_estimator.tools.estimate_bag import main as estimate_bag

REPO = Path(__file__).resolve().parents[2]
CONFIG = REPO / 'config' / 'tractor_semitrailer.yaml'
BIN = Path(sys.executable).parent
STORE = get_typestore(Stores.ROS2_JAZZY)
RATE_HZ = 500
DROPPED_JOINT = 'trailer_2_left_suspension'
#: what the test puts in: topic -> reason -> count
PUT_IN = {'/imu/tractor': {'backwards_stamp': 1},
          '/suspension/deflections': {'missing_name': 1},
          '/vehicle/twist': {'backwards_stamp': 1, 'nonfinite': 1}}
WHOLE = 'estimate_bag: whole vehicle'


def stamp_of(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def set_stamp(msg, ns: int) -> None:
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(ns, 1_000_000_000)


def decoded(bag: Path) -> dict:
    """topic -> [message], decoded by the mcap library."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    out: dict = {}
    for path in sorted(bag.glob('*.mcap')):
        with open(path, 'rb') as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            for _, channel, _, msg in reader.iter_decoded_messages():
                out.setdefault(channel.topic, []).append(msg)
    return out


def spoil(src: Path, dst: Path) -> dict:
    """``src``'s messages written to ``dst`` by the mcap library, some made bad (above);
    returns the good deflection stamps and the IMU stamps that stay in order."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    dst.mkdir()
    seen: dict = {}
    t0 = None
    good, imu_kept, imu_stamps = [], [], []
    with src.open('rb') as f, (dst / f'{dst.name}_0.mcap').open('wb') as g:
        reader = make_reader(f)
        writer = Writer(g)
        writer.start(profile='ros2', library='test')
        ids: dict = {}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            topic, data = channel.topic, message.data
            i = seen[topic] = seen.get(topic, -1) + 1
            if topic in ('/vehicle/twist', '/suspension/deflections', '/imu/tractor'):
                msg = STORE.deserialize_cdr(data, schema.name)
                s = stamp_of(msg)
                t0 = s if t0 is None else t0
                if topic == '/vehicle/twist' and i == 100:
                    msg.twist.linear.x = float('nan')
                elif topic == '/vehicle/twist' and i == 200:
                    set_stamp(msg, s - 150 * 1_000_000_000 // RATE_HZ)
                elif topic == '/suspension/deflections':
                    if i == 300:
                        keep = [n != DROPPED_JOINT for n in msg.name]
                        msg.name = [n for n, k in zip(msg.name, keep) if k]
                        msg.position = msg.position[keep]
                        if len(msg.velocity):
                            msg.velocity = msg.velocity[keep]
                        if len(msg.effort):
                            msg.effort = msg.effort[keep]
                    else:
                        good.append(s)
                elif topic == '/imu/tractor':
                    if s - t0 < 40_000_000 or 1_000_000_000 <= s - t0 < 1_300_000_000:
                        continue
                    if i == 1000:
                        set_stamp(msg, s - 500_000_000)
                    else:
                        imu_kept.append(s)
                    imu_stamps.append(stamp_of(msg))
                data = bytes(STORE.serialize_cdr(msg, schema.name))
            if channel.id not in ids:
                sid = writer.register_schema(schema.name, schema.encoding, schema.data)
                ids[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, sid, dict(channel.metadata))
            writer.add_message(ids[channel.id], message.log_time, data,
                               message.publish_time, message.sequence)
        writer.finish()
    assert imu_stamps != sorted(imu_stamps)          # the IMU message is out of order
    return {'good': good, 'imu': imu_kept}


def imu_counts(samples: list, imu: list) -> tuple[int, int]:
    """(stale, missing): the samples whose latest a_y at or before them is older than
    0.1 s, and those with none yet (docs/articulated.md's rule, counted here)."""
    stale = missing = 0
    j = -1
    for s in samples:
        while j + 1 < len(imu) and imu[j + 1] <= s:
            j += 1
        if j < 0:
            missing += 1
        elif s - imu[j] > 100_000_000:
            stale += 1
    return stale, missing


@pytest.fixture(scope='module')
def drive(tmp_path_factory):
    folder = tmp_path_factory.mktemp('rejects')
    text = CONFIG.read_text()
    assert 'tractor_imu: false' in text
    params = folder / 'imu.yaml'
    params.write_text(text.replace('tractor_imu: false', 'tractor_imu: true'))
    sim = subprocess.run([str(BIN / 'simulate_bag'), '--params-file', str(params),
                          '--road', 'iso8608:C:seed=5', '--speed', '20', '--rate',
                          str(RATE_HZ), '--duration', '3', '--gnss-rate', '0',
                          '--no-progress', '--output', str(folder / 'sim')],
                         capture_output=True, text=True, timeout=300)
    assert sim.returncode == 0, sim.stderr
    (src,) = (folder / 'sim').glob('*.mcap')
    bag = folder / 'inputs' / 'spoilt'
    bag.parent.mkdir()
    put = spoil(src, bag)
    # estimate_fleet finds bag folders by their metadata.yaml: the simulation's, naming the
    # new file (its message counts are the simulation's)
    meta = (folder / 'sim' / 'metadata.yaml').read_text()
    assert meta.count('sim_0.mcap') == 2
    (bag / 'metadata.yaml').write_text(meta.replace('sim_0.mcap', 'spoilt_0.mcap'))
    out = folder / 'out'
    assert estimate_bag([str(bag), '--params-file', str(params), '--output', str(out),
                         '--mode', 'online', '--segment-length', '20', '--no-figures',
                         '--no-progress']) == 0
    return {'folder': folder, 'params': params, 'bag': bag, 'out': out, **put}


def test_the_report_counts_what_the_test_put_in(drive):
    report = json.loads((drive['out'] / 'report' / 'report.json').read_text())
    rejected = {t: r for t, r in report['rejected'].items() if t != 'estimator'}
    assert rejected == PUT_IN
    markdown = (drive['out'] / 'report' / 'report.md').read_text()
    for topic, reasons in PUT_IN.items():
        for reason, count in reasons.items():
            assert f'| `{topic}` | {reason} | {count} |' in markdown
    stale, missing = imu_counts(drive['good'], drive['imu'])
    assert missing == 20 and stale > 50
    imu = report['whole_vehicle_estimate']['tractor_imu']
    assert (imu['stale'], imu['missing']) == (stale, missing)
    # every topic read is counted, the IMU's too (which the front axle's reader never reads):
    # the messages in the spoilt bag, as the mcap library decodes them
    inputs = decoded(drive['bag'])
    for topic in ('/imu/tractor', '/suspension/deflections', '/vehicle/twist'):
        assert report['messages'][topic] == len(inputs[topic]), topic
        assert f'| `{topic}` | {len(inputs[topic])} |' in markdown


def test_the_last_statuses_count_them_and_every_good_sample_is_estimated(drive):
    est = decoded(drive['out'] / 'bag')
    last = {st.name: st for st in est['/diagnostics'][-1].status}
    whole = last[WHOLE]
    values = {kv.key: kv.value for kv in whole.values}
    for topic, reasons in PUT_IN.items():
        for reason, count in reasons.items():
            assert values[f'total.rejected.{topic}.{reason}'] == str(count)
    assert values['total.rejected_by_reader'] == '4'
    assert whole.level == 1 and '4 input messages rejected' in whole.message
    assert '/vehicle/twist: 1 backwards_stamp, 1 nonfinite' in whole.message
    front = next(st for name, st in last.items() if name.startswith('estimate_bag: estimator'))
    assert {kv.key: kv.value for kv in front.values}['total.rejected_by_reader'] == '4'
    stamps = [stamp_of(m) for m in est['/wheel_loads']]
    assert stamps == drive['good']
    assert np.isfinite([m.effort for m in est['/wheel_loads']]).all()
    # no earlier status carries the totals
    for arr in est['/diagnostics'][:-1]:
        for st in arr.status:
            assert not any(kv.key.startswith('total.rejected.') for kv in st.values)


def test_the_fleet_summary_carries_the_counts(drive):
    stale, missing = imu_counts(drive['good'], drive['imu'])
    out = drive['folder'] / 'fleet'
    args = [str(drive['bag']), '--params-file', str(drive['params']), '--output', str(out),
            '--segment-length', '20', '--no-figures', '--no-progress', '--workers', '1']
    for run in ('processed', 'skipped (already done)'):
        assert estimate_fleet.main(args) == 0
        summary = (out / 'summary.md').read_text()
        assert f'{run} 1' in summary
        section = summary.split('## Rejected inputs', 1)[1].split('\n## ', 1)[0]
        rows = {tuple(c.strip() for c in line.strip('|').split('|'))
                for line in section.splitlines() if line.startswith('| spoilt ')}
        want = {('spoilt', f'`{t}`', r, str(c)) for t, rs in PUT_IN.items()
                for r, c in rs.items()}
        want |= {('spoilt', '`/imu/tractor`', 'samples stale (a_y held)', str(stale)),
                 ('spoilt', '`/imu/tractor`', 'samples missing (a_y none)', str(missing))}
        assert want <= rows
        assert rows - want <= {r for r in rows if r[1] == '`estimator`'}
