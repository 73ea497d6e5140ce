"""Reading bad bags (bagio.reader): truncated and corrupt files, missing metadata,
undeclared channels read without a crash, every break described."""

from mcap_walk import top_level_records
import numpy as np
import pytest

from bag_samples import BASE_NS, T, header, make_trajectory
from road_force_estimator import bagio
from road_force_estimator.bagio import BagReadError
from road_force_estimator.serde import TYPESTORE


class TestBrokenFiles:
    @pytest.fixture
    def drive(self, tmp_path):
        trajectory, q, roll = make_trajectory(n=3000)
        bagio.write_drive_bag(tmp_path / 'd', trajectory, q, roll)
        (mcap,) = (tmp_path / 'd').glob('*.mcap')
        return tmp_path / 'd', mcap, bagio.read_drive_bag(tmp_path / 'd')

    def assert_prefix(self, d, full):
        m = d.stamps_ns.size
        assert 0 < m < full.stamps_ns.size
        np.testing.assert_array_equal(d.stamps_ns, full.stamps_ns[:m])
        np.testing.assert_array_equal(d.q_m, full.q_m[:m])

    def test_truncated_file_is_read_up_to_the_break(self, drive):
        folder, mcap, full = drive
        data = mcap.read_bytes()
        assert len(data) > 2**20          # more than one chunk
        for cut in (0.3, 0.6, 0.9):                  # inside the first or second chunk
            mcap.write_bytes(data[:int(cut * len(data))])
            d = bagio.read_drive_bag(folder)
            self.assert_prefix(d, full)
            assert len(d.issues) == 1 and 'ends inside the chunk' in d.issues[0], d.issues
        mcap.write_bytes(data[:int(0.99 * len(data))])   # inside the index: every message
        d = bagio.read_drive_bag(folder)
        np.testing.assert_array_equal(d.q_m, full.q_m)
        assert len(d.issues) == 1 and 'bytes missing' in d.issues[0], d.issues
        # Cut exactly at a record boundary inside the data: no end-of-data record.
        mcap.write_bytes(data[:8 + 9 + int.from_bytes(data[9:17], 'little')])
        with pytest.raises(BagReadError, match='no /suspension/deflections'):
            bagio.read_drive_bag(folder)

    def assert_subset(self, d, full):
        keep = np.isin(full.stamps_ns, d.stamps_ns)
        assert keep.sum() == d.stamps_ns.size
        np.testing.assert_array_equal(d.q_m, full.q_m[keep])
        np.testing.assert_array_equal(d.roll_rad, full.roll_rad[keep])
        return keep

    def test_a_chunk_that_fails_its_crc_is_skipped_and_reading_goes_on(self, drive):
        folder, mcap, full = drive
        data = bytearray(mcap.read_bytes())
        chunks = [at for op, at, _ in top_level_records(bytes(data)) if op == 0x06]
        assert len(chunks) >= 2
        at = (chunks[0] + chunks[1]) // 2             # inside the first chunk's messages
        data[at:at + 300] = b'\xff' * 300
        mcap.write_bytes(bytes(data))
        d = bagio.read_drive_bag(folder)
        keep = self.assert_subset(d, full)
        assert 0 < keep.sum() < keep.size and keep[-1]   # a gap, then the rest of the drive
        assert len(d.issues) == 1 and 'CRC' in d.issues[0], d.issues

    def test_a_corrupt_record_ends_the_read_with_a_message(self, drive):
        folder, mcap, full = drive
        data = bytearray(mcap.read_bytes())
        second = [at for op, at, _ in top_level_records(bytes(data)) if op == 0x06][1]
        data[second] = 0x33                            # not an MCAP opcode
        data[-1] ^= 0xFF                               # no footer: no chunk index either
        mcap.write_bytes(bytes(data))
        d = bagio.read_drive_bag(folder)
        self.assert_prefix(d, full)
        assert len(d.issues) == 1 and 'corrupt record (op 0x33)' in d.issues[0], d.issues

    def test_the_chunk_index_overrules_a_corrupt_chunk_head(self, drive):
        folder, mcap, full = drive
        data = bytearray(mcap.read_bytes())
        second = [at for op, at, _ in top_level_records(bytes(data)) if op == 0x06][1]
        data[second] = 0x33                            # not an MCAP opcode
        mcap.write_bytes(bytes(data))
        d = bagio.read_drive_bag(folder)
        np.testing.assert_array_equal(d.stamps_ns, full.stamps_ns)
        np.testing.assert_array_equal(d.q_m, full.q_m)
        assert len(d.issues) == 1 and 'chunk index is used' in d.issues[0], d.issues

    @pytest.mark.parametrize('compression', ['zstd', 'lz4'])
    def test_compressed_chunks_of_other_writers(self, tmp_path, compression):
        """A bag folder holding only an .mcap written by the mcap library with compressed
        chunks (as rosbag2's zstd presets do): read whole, then cut inside a chunk."""
        from mcap.writer import CompressionType, Writer

        folder = tmp_path / 'foreign'
        folder.mkdir()
        path = folder / 'foreign_0.mcap'
        msgtype = 'geometry_msgs/msg/PointStamped'
        point = T[msgtype]
        with path.open('wb') as f:
            writer = Writer(f, compression=CompressionType[compression.upper()],
                            chunk_size=64 * 1024)
            writer.start(profile='ros2', library='test')
            sid = writer.register_schema(msgtype, 'ros2msg', TYPESTORE.generate_msgdef(
                msgtype, ros_version=2)[0].encode())
            cids = [writer.register_channel(t, 'cdr', sid, {'offered_qos_profiles': ''})
                    for t in ('/lpa/left', '/lpa/right')]
            for i in range(4000):
                for side, cid in enumerate(cids):
                    msg = point(header=header(BASE_NS + i, 'road'),
                                point=T['geometry_msgs/msg/Point'](x=0.1 * i, y=1.0 - 2 * side,
                                                                   z=1e-3 * i + side))
                    writer.add_message(cid, BASE_NS + i, bytes(TYPESTORE.serialize_cdr(
                        msg, msgtype)), BASE_NS + i)
            writer.finish()
        issues = []
        p = bagio.read_lpa_bag(folder, issues=issues)
        assert len(p) == 4000 and p.elevation_m[-1].tolist() == [1e-3 * 3999, 1e-3 * 3999 + 1]
        assert issues == ['no metadata.yaml: reading the .mcap files found in the folder']
        data = path.read_bytes()
        path.write_bytes(data[:len(data) // 2])
        issues = []
        p = bagio.read_lpa_bag(folder, issues=issues)
        assert 100 < len(p) < 4000
        np.testing.assert_array_equal(p.distance_m, 0.1 * np.arange(len(p)))
        assert any('ends inside the chunk' in line for line in issues), issues

    def test_missing_metadata_and_missing_files(self, drive, tmp_path):
        folder, mcap, full = drive
        (folder / 'metadata.yaml').unlink()
        d = bagio.read_drive_bag(folder)
        np.testing.assert_array_equal(d.q_m, full.q_m)
        assert any('no metadata.yaml' in line for line in d.issues)
        mcap.unlink()
        with pytest.raises(BagReadError, match='not an MCAP bag'):
            bagio.read_drive_bag(folder)
        with pytest.raises(BagReadError, match='no such bag'):
            bagio.read_drive_bag(tmp_path / 'nowhere')
        (tmp_path / 'empty').mkdir()
        (tmp_path / 'empty' / 'x.mcap').write_bytes(b'')
        issues = []
        assert list(bagio.iter_messages(tmp_path / 'empty', issues=issues)) == []
        assert any('not an MCAP file' in line for line in issues), issues
