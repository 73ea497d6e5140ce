"""bagio.playback: messages in log-time order as serialized bytes, recorded QoS, any writer.

Bags are written by our writer, by ``rosbags``' writer and by the ``mcap`` library (zstd and
lz4 chunks); the bytes played must be the bytes written, in log-time order.
"""
from __future__ import annotations

import numpy as np
import pytest

from bag_writers import (
    BASE_NS, FLOAT, POINT, WRITERS, expected, write_mcap, write_ours, write_rosbags)
from road_force_estimator.bagio import write_lpa_bag
from road_force_estimator.bagio.playback import PlaybackError, TopicQoS, open_playback
from road_force_estimator.core.road import flat_profile

@pytest.mark.parametrize('writer', sorted(WRITERS))
def test_every_message_in_log_time_order_as_written(tmp_path, writer):
    items = expected()
    WRITERS[writer](tmp_path / 'bag', items)
    playback = open_playback(tmp_path / 'bag')
    got = [(t, topic, data) for t, topic, _, data in playback.messages()]
    assert playback.broken == ''
    assert got == items
    assert {t.name: t.type for t in playback.topics.values()} == {
        '/lpa/left': POINT, '/lpa/right': POINT, '/ratio': FLOAT}
    # Topics and start offset.
    got = [(t, topic) for t, topic, _, _ in playback.messages(['/ratio'],
                                                               start_offset_ns=100 * 10**6)]
    assert got == [(t, topic) for t, topic, _ in items if topic == '/ratio'
                   and t >= BASE_NS + 100 * 10**6]


def test_messages_written_out_of_order_are_played_in_log_time_order(tmp_path):
    items = expected(200)
    shuffled = [items[i] for i in np.random.default_rng(1).permutation(len(items))]
    write_mcap(tmp_path / 'bag', shuffled, 'zstd')
    got = [t for t, _, _, _ in open_playback(tmp_path / 'bag').messages()]
    assert got == sorted(got) and len(got) == len(items)


def test_recorded_qos_or_the_interfaces_kind(tmp_path):
    write_ours(tmp_path / 'ours', expected(10))
    topics = open_playback(tmp_path / 'ours').topics
    assert topics['/lpa/left'].qos.reliability == 'reliable' and topics['/lpa/left'].qos.recorded
    assert topics['/ratio'].qos.reliability == 'best_effort'
    # rosbags records no QoS: INTERFACES.md's kind, reliable for a topic it does not list.
    write_rosbags(tmp_path / 'rb', expected(10))
    topics = open_playback(tmp_path / 'rb').topics
    assert topics['/lpa/left'].qos == TopicQoS('reliable')
    assert topics['/ratio'].qos == TopicQoS('reliable')
    assert not topics['/ratio'].qos.recorded
    assert TopicQoS.of_kind('sensor_data').reliability == 'best_effort'


def test_a_cut_bag_plays_up_to_the_break(tmp_path):
    items = expected(2000)
    write_mcap(tmp_path / 'bag', items, 'zstd')
    (path,) = (tmp_path / 'bag').glob('*.mcap')
    data = path.read_bytes()
    path.write_bytes(data[:len(data) // 2])
    playback = open_playback(tmp_path / 'bag')
    got = [(t, topic, d) for t, topic, _, d in playback.messages()]
    assert 100 < len(got) < len(items)
    assert got == items[:len(got)]
    assert 'cut or damaged' in playback.broken and 'played up to the break' in playback.broken


def test_our_lpa_bag_plays(tmp_path):
    write_lpa_bag(tmp_path / 'lpa', flat_profile(10.0, dx_m=0.5))
    playback = open_playback(tmp_path / 'lpa')
    got = list(playback.messages())
    assert len(got) == 42 and [g[1] for g in got[:2]] == ['/lpa/left', '/lpa/right']


@pytest.mark.parametrize('make, pattern', [
    (lambda p: None, 'no such bag folder or file'),
    (lambda p: p.mkdir(), 'no .mcap file'),
    (lambda p: (p.mkdir(), (p / 'x.mcap').write_bytes(b'not a bag')), 'not an MCAP file'),
])
def test_bad_bags_are_refused_with_one_line(tmp_path, make, pattern):
    make(tmp_path / 'bag')
    with pytest.raises(PlaybackError, match=pattern) as info:
        open_playback(tmp_path / 'bag')
    assert '\n' not in str(info.value)


def test_only_regular_files_inside_the_bag_folder_are_played(tmp_path):
    """The player takes the bag's files as the reader does (issue 16): a FIFO named .mcap
    does not hang it, and metadata.yaml cannot make it read a file outside the folder."""
    import os

    fifo_bag = tmp_path / 'fifo'
    fifo_bag.mkdir()
    os.mkfifo(fifo_bag / 'a.mcap')
    with pytest.raises(PlaybackError, match='FIFO'):
        open_playback(fifo_bag)
    write_lpa_bag(tmp_path / 'lpa', flat_profile(10.0))
    outside = tmp_path / 'lpa' / 'lpa_0.mcap'
    sneaky = tmp_path / 'sneaky'
    sneaky.mkdir()
    meta = (tmp_path / 'lpa' / 'metadata.yaml').read_text()
    (sneaky / 'metadata.yaml').write_text(meta.replace('- lpa_0.mcap', f'- ../lpa/{outside.name}'))
    with pytest.raises(PlaybackError, match='outside the bag folder'):
        open_playback(sneaky)
    # A metadata.yaml that cannot be parsed is read around, as the reader does.
    (tmp_path / 'lpa' / 'metadata.yaml').write_text(': [')
    assert len(list(open_playback(tmp_path / 'lpa').messages())) > 0
