"""LPA profile bags (bagio.lpa): round trips, bags that rosbag2 (Jazzy), mcap and rosbags
read, bad samples dropped and counted."""

import numpy as np
import pytest
import yaml

from bag_samples import BASE_NS, T, header, jazzy_type_hash, make_trajectory
from road_force_estimator import bagio
from road_force_estimator.bagio import (
    BagReadError,
    BagWriter,
)
from road_force_estimator.core.road import RoadProfile


class TestLpaBag:
    def profile(self):
        rng = np.random.default_rng(5)
        x = 12.0 + 0.05 * np.arange(3001)
        return RoadProfile(x, np.cumsum(rng.normal(0.0, 3e-4, (x.size, 2)), axis=0),
                           name='test road')

    def test_round_trip_is_exact(self, tmp_path):
        p = self.profile()
        bagio.write_lpa_bag(tmp_path / 'lpa', p, survey_speed_mps=10.0, track_width_m=1.8)
        issues = []
        q = bagio.read_lpa_bag(tmp_path / 'lpa', issues=issues)
        assert issues == []
        np.testing.assert_array_equal(q.distance_m, p.distance_m)
        np.testing.assert_array_equal(q.elevation_m, p.elevation_m)
        assert q.name == 'test road'
        # Stamps at the survey speed, y = +-T/2, frame road (read with the generic reader).
        msgs = list(bagio.iter_messages(tmp_path / 'lpa', ['/lpa/right']))
        assert len(msgs) == 3001
        topic, log_ns, msg = msgs[20]
        assert log_ns == BASE_NS + 100_000_000          # 1 m at 10 m/s
        assert msg.header.frame_id == 'road' and msg.point.y == -0.9
        assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == log_ns

    def test_metadata_is_what_jazzy_rosbag2_reads(self, tmp_path):
        bagio.write_lpa_bag(tmp_path / 'lpa', self.profile())
        meta = yaml.safe_load((tmp_path / 'lpa' / 'metadata.yaml').read_text())
        info = meta['rosbag2_bagfile_information']
        assert info['version'] == 9 and info['storage_identifier'] == 'mcap'
        assert isinstance(info['custom_data'], dict)      # never null: yaml-cpp wants a map
        for name in info['relative_file_paths']:
            assert (tmp_path / 'lpa' / name).is_file() and name.endswith('.mcap')
        assert info['message_count'] == 2 * 3001
        topics = {t['topic_metadata']['name']: t for t in info['topics_with_message_count']}
        assert set(topics) == {'/lpa/left', '/lpa/right'}
        for t in topics.values():
            meta = t['topic_metadata']
            assert meta['type'] == 'geometry_msgs/msg/PointStamped'
            assert meta['serialization_format'] == 'cdr'
            assert meta['type_description_hash'] == jazzy_type_hash(meta['type'])
            (qos,) = meta['offered_qos_profiles']
            assert qos['reliability'] == 'reliable' and qos['history'] == 'keep_last'
            assert t['message_count'] == 3001
        # The mcap library validates every CRC and finds the rosbag2 metadata record, which
        # Jazzy's MCAP plugin decodes as the same bag information.
        from mcap.reader import make_reader
        (mcap,) = (tmp_path / 'lpa').glob('*.mcap')
        with mcap.open('rb') as f:
            reader = make_reader(f, validate_crcs=True)
            assert reader.get_header().profile == 'ros2'
            assert sum(1 for _ in reader.iter_messages()) == 2 * 3001
            (record,) = list(reader.iter_metadata())
            assert record.name == 'rosbag2'
            assert yaml.safe_load(record.metadata['serialized_metadata']) == info
            stats = reader.get_summary().statistics
            assert stats.message_count == 2 * 3001 and stats.chunk_count >= 1

    def test_one_track_and_dropped_samples(self, tmp_path):
        point = T['geometry_msgs/msg/PointStamped']
        with BagWriter(tmp_path / 'b') as bag:
            bag.add_topic('/lpa/left', 'geometry_msgs/msg/PointStamped')
            for i, (x, z) in enumerate([(0.0, 1.0), (1.0, 2.0), (1.0, 9.0), (0.5, 9.0),
                                        (2.0, np.nan), (3.0, 4.0)]):
                bag.write('/lpa/left', BASE_NS + i, point(
                    header=header(BASE_NS + i, 'road'),
                    point=T['geometry_msgs/msg/Point'](x=x, y=1.0, z=z)))
        issues = []
        p = bagio.read_lpa_bag(tmp_path / 'b', issues=issues)
        assert p.distance_m.tolist() == [0.0, 1.0, 3.0]
        assert p.elevation_m.tolist() == [[1.0, 1.0], [2.0, 2.0], [4.0, 4.0]]
        text = ' | '.join(issues)
        assert 'only /lpa/left' in text and '(nonfinite)' in text
        assert '1 samples dropped (duplicate_stamp)' in text          # x = 1.0 again
        assert '1 samples dropped (backwards_stamp)' in text          # x = 0.5
        with pytest.raises(BagReadError, match='not an LPA bag'):
            bagio.read_lpa_bag(self.drive_bag(tmp_path))

    def drive_bag(self, tmp_path):
        trajectory, q, roll = make_trajectory(n=10)
        bagio.write_drive_bag(tmp_path / 'drive', trajectory, q, roll)
        return tmp_path / 'drive'
