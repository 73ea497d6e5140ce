"""The whole vehicle's inputs read block by block (bagio/drive_blocks.py ``joints``,
``imu``; issue 32): the same samples, readings, speeds, IMU pairs and rejection counts as the
drive read whole (:func:`read_articulated_readings`, then the pipeline's rules: the samples
before the first twist the first held speed, :func:`pair_imu`). The bag: an articulated drive
of 2000 samples written by our writer, then again by the ``mcap`` library with messages made
bad by the test (serialized by ``rosbags``): the first 40 twists left out, a twist non-finite
and one stamped back, a deflection message without a trailer joint, the IMU at a fifth of
the rate from 0.1 s with a hole and one message stamped back."""
from pathlib import Path

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore

from road_force_estimator.bagio.articulated_drive import write_articulated_drive_bag
from road_force_estimator.bagio.articulated_readings import read_articulated_readings
from road_force_estimator.bagio.drive_blocks import DriveBlocks
from road_force_estimator.core.articulated_setup import ArticulatedDrive
from road_force_estimator.core.parameters import load_params_file
from road_force_estimator.estimation.imu_hold import pair_imu
from road_force_estimator.estimation.models.articulated import channel_names

CONFIG = Path(__file__).resolve().parents[2] / 'config' / 'tractor_semitrailer.yaml'
STORE = get_typestore(Stores.ROS2_JAZZY)
M = 2000
#: what the test puts in: topic -> reason -> count
PUT_IN = {'/imu/tractor': {'backwards_stamp': 1},
          '/suspension/deflections': {'missing_name': 1},
          '/vehicle/twist': {'backwards_stamp': 1, 'nonfinite': 1}}


def _stamp(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def _set_stamp(msg, ns: int) -> None:
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(ns, 1_000_000_000)


@pytest.fixture(scope='module')
def bag(tmp_path_factory) -> tuple[Path, tuple]:
    from mcap.reader import make_reader
    from mcap.writer import Writer

    folder = tmp_path_factory.mktemp('wv_blocks')
    names = channel_names(ArticulatedDrive.from_values(load_params_file(CONFIG)).model)
    rng = np.random.default_rng(7)
    stamps = 10 ** 18 + np.arange(M, dtype=np.int64) * 1_000_000
    imu = np.zeros((M, 6))
    imu[:, 1] = rng.standard_normal(M)
    write_articulated_drive_bag(folder / 'src', stamps_ns=stamps,
                                speed_mps=20.0 + 0.01 * rng.standard_normal(M),
                                readings=1e-3 * rng.standard_normal((M, len(names))),
                                names=names, truth=None, imu=imu)
    (src,) = (folder / 'src').glob('*.mcap')
    dst = folder / 'spoilt'
    dst.mkdir()
    seen: dict = {}
    with src.open('rb') as f, (dst / 'spoilt_0.mcap').open('wb') as g:
        reader = make_reader(f)
        writer = Writer(g, chunk_size=16_000)      # many chunks: many blocks
        writer.start(profile='ros2', library='test')
        ids: dict = {}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            topic, data = channel.topic, message.data
            i = seen[topic] = seen.get(topic, -1) + 1
            if topic in ('/vehicle/twist', '/suspension/deflections', '/imu/tractor'):
                msg = STORE.deserialize_cdr(data, schema.name)
                s = _stamp(msg) - int(stamps[0])
                if topic == '/vehicle/twist':
                    if i < 40:
                        continue
                    if i == 700:
                        msg.twist.linear.x = float('nan')
                    elif i == 900:
                        _set_stamp(msg, _stamp(msg) - 150_000_000)
                elif topic == '/suspension/deflections' and i == 1300:
                    keep = [n != 'trailer_2_left_suspension' for n in msg.name]
                    msg.name = [n for n, k in zip(msg.name, keep) if k]
                    msg.position = msg.position[keep]
                    msg.velocity = msg.velocity[keep] if len(msg.velocity) else msg.velocity
                    msg.effort = msg.effort[keep] if len(msg.effort) else msg.effort
                elif topic == '/imu/tractor':
                    if s < 100_000_000 or i % 5 or 1_000_000_000 <= s < 1_300_000_000:
                        continue
                    if i == 1500:
                        _set_stamp(msg, _stamp(msg) - 500_000_000)
                data = bytes(STORE.serialize_cdr(msg, schema.name))
            if channel.id not in ids:
                sid = writer.register_schema(schema.name, schema.encoding, schema.data)
                ids[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, sid, dict(channel.metadata))
            writer.add_message(ids[channel.id], message.log_time, data,
                               message.publish_time, message.sequence)
        writer.finish()
    listed = folder / 'listed'               # the same file with the source's metadata.yaml
    listed.mkdir()
    (listed / 'listed_0.mcap').write_bytes((dst / 'spoilt_0.mcap').read_bytes())
    meta = (folder / 'src' / 'metadata.yaml').read_text()
    (listed / 'metadata.yaml').write_text(meta.replace(src.name, 'listed_0.mcap'))
    return {'spoilt': dst, 'listed': listed}, tuple(names)


@pytest.mark.parametrize('kind', ['spoilt', 'listed'])
@pytest.mark.parametrize('block_samples', [1, 300, 1 << 16])
def test_blocks_are_the_drive_read_whole(bag, block_samples, kind):
    """Every block size, with and without a metadata.yaml (the IMU waited for as it lists
    it, or always): the blocks joined are the whole read's samples, readings, speeds (the
    40 early samples given the first held speed), a_y and codes, and its counts (the test's
    own: what it put in)."""
    paths, names = bag
    path = paths[kind]
    whole = read_articulated_readings(path, names, imu=True)
    speed = np.array(whole.speed_mps)
    held = np.isfinite(speed)
    assert np.count_nonzero(~held) == 40
    speed[~held] = speed[np.argmax(held)]
    ay, codes = pair_imu(whole.stamps_ns, whole.imu_stamps_ns, whole.imu_ay_mps2)
    reader = DriveBlocks(path, block_samples, joints=names, imu=True)
    blocks = list(reader)
    if block_samples == 1:
        assert len(blocks) > 3
    got = {f: np.concatenate([getattr(b, f) for b in blocks]) for f in
           ('stamps_ns', 'readings', 'speed_mps', 'imu_ay_mps2', 'imu_codes')}
    assert got['stamps_ns'].size == M - 1
    np.testing.assert_array_equal(got['stamps_ns'], whole.stamps_ns)
    np.testing.assert_array_equal(got['readings'], whole.readings)
    np.testing.assert_array_equal(got['speed_mps'], speed)
    np.testing.assert_array_equal(got['imu_ay_mps2'], ay)
    np.testing.assert_array_equal(got['imu_codes'], codes)
    assert set(codes.tolist()) == {0, 1, 2}
    assert reader.early == 40
    counts = {t: {k: c for k, c in r.items() if c} for t, r in reader.rejected.items()}
    assert {t: r for t, r in counts.items() if r} == PUT_IN
    assert whole.rejected == reader.rejected
