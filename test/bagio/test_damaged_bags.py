"""Damaged and hostile bags (issue 16): the good data read, the fault named, never a
traceback, a hang, a crash or unbounded memory.

References: the ``mcap`` library's readers on the same bytes (``bag_crafting.mcap_recovers``),
and the undamaged bag read by this package.
"""
import struct

from mcap_walk import top_level_records
import pytest

from bag_crafting import (
    SAMPLES,
    run_python,
    chunk_record,
    mcap_recovers,
    rewrite_with_mcap,
    small_drive,
    with_extra_chunk,
)
from bag_samples import make_trajectory
from road_force_estimator import bagio
from road_force_estimator.bagio import BagReadError, mcap_scan
from road_force_estimator.interfaces import DEFLECTIONS

def chunks_of(data: bytes) -> list[int]:
    return [at for op, at, _ in top_level_records(data) if op == 0x06]


@pytest.fixture(scope='module')
def drives(tmp_path_factory):
    """``{writer: (folder, mcap bytes)}``: a small drive by our writer and by the mcap
    library (8 KiB chunks, schemas and channels inside them)."""
    root = tmp_path_factory.mktemp('drives')
    small_drive(root / 'ours')
    rewrite_with_mcap(root / 'ours', root / 'mcap')
    return {name: (root / name, next((root / name).glob('*.mcap')).read_bytes())
            for name in ('ours', 'mcap')}


def damaged(tmp_path, drives, writer, data):
    """A copy of the drive folder of ``writer`` whose .mcap holds ``data``."""
    folder, original = drives[writer]
    out = tmp_path / writer
    out.mkdir(parents=True)
    (out / 'metadata.yaml').write_bytes((folder / 'metadata.yaml').read_bytes())
    (out / next(folder.glob('*.mcap')).name).write_bytes(data)
    return out


@pytest.mark.parametrize('byte, bit', [(8, 7), (1, 0), (4, 2)])
def test_a_flipped_chunk_length_resumes_at_the_next_chunk(tmp_path, drives, byte, bit):
    """Before: the read ended at the flipped length (up to 8,411 of 10,001 samples lost)."""
    _, data = drives['mcap']
    chunks = chunks_of(data)
    assert len(chunks) >= 6
    broken = bytearray(data)
    broken[chunks[2] + byte] ^= 1 << bit
    d = bagio.read_drive_bag(damaged(tmp_path, drives, 'mcap', bytes(broken)))
    assert mcap_recovers(bytes(broken)) == SAMPLES
    assert d.messages[DEFLECTIONS] == SAMPLES and d.stamps_ns.size == SAMPLES
    assert any('chunk index' in line for line in d.issues), d.issues


def test_a_flipped_chunk_length_in_our_bags(tmp_path):
    trajectory, q, roll = make_trajectory(n=3000)
    bagio.write_drive_bag(tmp_path / 'd', trajectory, q, roll)
    (mcap,) = (tmp_path / 'd').glob('*.mcap')
    data = bytearray(mcap.read_bytes())
    assert len(chunks_of(bytes(data))) >= 2
    data[chunks_of(bytes(data))[0] + 6] ^= 0x10
    mcap.write_bytes(bytes(data))
    d = bagio.read_drive_bag(tmp_path / 'd')
    assert d.messages[DEFLECTIONS] == mcap_recovers(bytes(data)) == 3000
    assert len(d.issues) == 1 and 'chunk index is used' in d.issues[0], d.issues


def test_schemas_and_channels_of_a_damaged_first_chunk_come_from_the_summary(tmp_path, drives):
    """Before: "no /suspension/deflections topic" (the channels sat in the first chunk)."""
    _, data = drives['mcap']
    first, second = chunks_of(data)[:2]
    broken = bytearray(data)
    broken[(first + second) // 2] ^= 0x01             # the first chunk fails its CRC
    d = bagio.read_drive_bag(damaged(tmp_path, drives, 'mcap', bytes(broken)))
    expected = mcap_recovers(bytes(broken))
    assert 0 < expected < SAMPLES
    assert d.messages[DEFLECTIONS] == expected
    assert len(d.issues) == 1 and 'fails its CRC check' in d.issues[0], d.issues


TRUNCATE_WHILE_READING = """
import subprocess, sys
from pathlib import Path
from road_force_estimator import bagio
from road_force_estimator.bagio import reader
folder = Path(sys.argv[1])
(mcap,) = folder.glob('*.mcap')
add = reader.TopicReader.add_block
def cut_then_add(self, block):
    if mcap.stat().st_size > 100000:      # another process cuts the file under the reader
        subprocess.run(['truncate', '-s', '90000', str(mcap)], check=True)
    add(self, block)
reader.TopicReader.add_block = cut_then_add
try:
    bagio.read_drive_bag(folder)
except bagio.BagReadError as err:
    print(err)
    sys.exit(1)
"""


def test_a_file_cut_while_it_is_read_is_an_error_not_a_crash(tmp_path):
    """Before: SIGBUS (the file was memory-mapped): the process died without a message."""
    trajectory, q, roll = make_trajectory(n=3000)
    bagio.write_drive_bag(tmp_path / 'd', trajectory, q, roll)
    done = run_python(TRUNCATE_WHILE_READING, tmp_path / 'd')
    assert done.returncode == 1, (done.returncode, done.stderr)
    assert done.stderr == '' and done.stdout.count('\n') == 1
    assert 'changed while being read' in done.stdout and 'messages read before' in done.stdout


def test_an_empty_deflections_topic(tmp_path, drives):
    """A bag cut after its channel records. Before: "cannot reshape array of size 0"."""
    _, data = drives['ours']
    folder = damaged(tmp_path, drives, 'ours', data[:chunks_of(data)[0]])
    d = bagio.read_drive_bag(folder)
    assert d.messages[DEFLECTIONS] == 0 and d.stamps_ns.size == 0 and d.q_m.shape == (0, 2)
    assert len(d.issues) == 1 and 'without the MCAP end-of-data record' in d.issues[0]
    from road_force_estimator.tools.estimate_bag import main
    assert main([str(folder), '--output', str(tmp_path / 'o'), '--no-figures']) == 1


@pytest.mark.parametrize('text, why', [
    ('rosbag2_bagfile_information: [1, 2]\n', 'not a mapping'),
    ('[1, 2]\n', 'not a mapping'),
    ('rosbag2_bagfile_information: {relative_file_paths: 7}\n', 'not a list'),
])
def test_metadata_of_the_wrong_shape(tmp_path, drives, text, why):
    """Before: AttributeError traceback."""
    folder = damaged(tmp_path, drives, 'ours', drives['ours'][1])
    (folder / 'metadata.yaml').write_text(text)
    d = bagio.read_drive_bag(folder)
    assert d.stamps_ns.size == SAMPLES
    assert any(why in line and 'metadata.yaml' in line for line in d.issues), d.issues


def test_metadata_naming_files_outside_the_bag_folder(tmp_path, drives):
    """Before: ``../../x.mcap`` and absolute paths were read."""
    folder = damaged(tmp_path, drives, 'ours', drives['ours'][1])
    (mcap,) = folder.glob('*.mcap')
    outside = tmp_path / 'outside.mcap'
    outside.write_bytes(drives['mcap'][1])
    meta = (folder / 'metadata.yaml').read_text()
    for name in ('../outside.mcap', str(outside)):
        (folder / 'metadata.yaml').write_text(meta.replace(mcap.name, name))
        mcap.rename(tmp_path / 'away.mcap')
        with pytest.raises(BagReadError, match='outside the bag folder'):
            bagio.read_drive_bag(folder)
        (tmp_path / 'away.mcap').rename(mcap)
        d = bagio.read_drive_bag(folder)         # refused, named; the folder's own file read
        assert d.stamps_ns.size == SAMPLES
        assert any(f'{name}: outside the bag folder' in line for line in d.issues), d.issues


NOT_REGULAR = """
import os, sys
from pathlib import Path
from road_force_estimator import bagio
root = Path(sys.argv[1])
fifo = root / 'fifo'; fifo.mkdir(); os.mkfifo(fifo / 'a.mcap')
zero = root / 'zero'; zero.mkdir(); (zero / 'a.mcap').symlink_to('/dev/zero')
for folder in (fifo, zero, fifo / 'a.mcap', zero / 'a.mcap'):
    try:
        bagio.read_drive_bag(folder)
    except bagio.BagReadError as err:
        print(err)
"""


def test_only_regular_files_are_read(tmp_path):
    """Before: a FIFO named a.mcap hung forever; a link to /dev/zero read until MemoryError."""
    done = run_python(NOT_REGULAR, tmp_path, timeout=60)
    assert done.returncode == 0 and done.stderr == '', done.stderr
    lines = done.stdout.splitlines()
    assert len(lines) == 4, lines
    assert 'a FIFO' in lines[0] and 'a character device' in lines[1]
    assert 'a FIFO' in lines[2] and 'a character device' in lines[3]


READ_COUNT = """
import sys
from road_force_estimator import bagio
d = bagio.read_drive_bag(sys.argv[1])
print(d.messages['/suspension/deflections'])
print('|'.join(d.issues))
"""


def zero_stream(compression: str, total: int) -> bytes:
    """``total`` zero bytes compressed, a MiB at a time."""
    block = bytes(1 << 20)
    if compression == 'zstd':
        import zstandard
        c = zstandard.ZstdCompressor().compressobj()
        return b''.join(c.compress(block) for _ in range(total >> 20)) + c.flush()
    import lz4.frame
    c = lz4.frame.LZ4FrameCompressor()
    return c.begin() + b''.join(c.compress(block) for _ in range(total >> 20)) + c.flush()


@pytest.mark.parametrize('compression, total, declared', [
    ('zstd', 2 << 30, None), ('lz4', 1 << 30, None),   # honest sizes beyond the cap
    ('zstd', 2 << 30, 1000), ('lz4', 1 << 30, 1000),   # lying sizes: output stops there
])
def test_decompression_bombs_are_skipped_in_bounded_memory(tmp_path, drives, compression,
                                                           total, declared):
    """Before: peak RSS grew with the declared size (MemoryError under this cap)."""
    bomb = zero_stream(compression, total)
    assert len(bomb) < 8 << 20
    chunk = chunk_record(b'', compression=compression, compressed=bomb,
                         declared=total if declared is None else declared)
    folder = damaged(tmp_path, drives, 'mcap', with_extra_chunk(drives['mcap'][1], chunk))
    done = run_python(READ_COUNT, folder)
    assert done.returncode == 0 and done.stderr == '', done.stderr[-2000:]
    count, issues = done.stdout.splitlines()
    assert int(count) == SAMPLES
    assert 'skipped' in issues and ('MAX_CHUNK_BYTES' in issues or 'not 1000' in issues), issues
    assert mcap_scan.MAX_CHUNK_BYTES < total


def test_a_chunk_larger_than_the_cap_is_counted(tmp_path, drives, monkeypatch):
    """The cap is a module constant: lowered below the chunks' size, they are skipped."""
    monkeypatch.setattr(mcap_scan, 'MAX_CHUNK_BYTES', 1000)
    folder = damaged(tmp_path, drives, 'mcap', drives['mcap'][1])
    d = bagio.read_drive_bag(folder)
    assert d.messages.get(DEFLECTIONS, 0) == 0
    assert sum('MAX_CHUNK_BYTES' in line for line in d.issues) == len(chunks_of(
        drives['mcap'][1]))



@pytest.fixture(scope='module')
def lz4_drive(drives, tmp_path_factory):
    root = tmp_path_factory.mktemp('lz4')
    mcap = rewrite_with_mcap(drives['ours'][0], root / 'mcap', compression='lz4')
    return root / 'mcap', mcap.read_bytes()


def break_fields(data: bytes, how: str) -> bytes:
    """``data`` with one field of its third chunk (or what follows it) damaged."""
    at = chunks_of(data)[2]
    (length,) = struct.unpack_from('<Q', data, at + 1)
    out = bytearray(data)
    if how == 'records length':
        name_length = struct.unpack_from('<I', data, at + 37)[0]
        out[at + 41 + name_length + 6] ^= 0x40
    elif how == 'declared size':
        out[at + 25 + 5] ^= 0x08
    else:                             # a message index length, and the summary's CRC
        out[at + 9 + length + 5] ^= 0x20
        (start,) = struct.unpack_from('<Q', data, len(data) - 28)
        out[start + 20] ^= 0x01
    return bytes(out)


@pytest.mark.parametrize('how', ['records length', 'declared size', 'index length'])
def test_compressed_chunks_with_a_corrupt_field(tmp_path, lz4_drive, how):
    """The field's damage is overruled by the record's own length, the decompressed size or
    the summary (even one failing its CRC, as the mcap library reads it) and the CRC checks
    the result: nothing lost. Before: the chunk or the rest of the file was lost."""
    folder, data = lz4_drive
    broken = break_fields(data, how)
    out = tmp_path / 'b'
    out.mkdir()
    (out / 'metadata.yaml').write_bytes((folder / 'metadata.yaml').read_bytes())
    (out / next(folder.glob('*.mcap')).name).write_bytes(broken)
    d = bagio.read_drive_bag(out)
    assert mcap_recovers(broken) == SAMPLES
    assert d.messages[DEFLECTIONS] == SAMPLES and d.stamps_ns.size == SAMPLES, d.issues
    assert d.issues, 'the damage is named'


def test_a_cut_recording_resumes_at_the_next_chunk_head(tmp_path, drives):
    """No summary (the recording was cut): after a corrupt record the next chunk is found by
    its head. Before: the read ended at the corrupt record."""
    _, data = drives['mcap']
    chunks = chunks_of(data)
    cut = data[:(chunks[-2] + chunks[-1]) // 2]           # inside the last chunk but one
    whole = bagio.read_drive_bag(damaged(tmp_path / 'a', drives, 'mcap', cut))
    broken = bytearray(cut)
    (length,) = struct.unpack_from('<Q', cut, chunks[2] + 1)
    broken[chunks[2] + 9 + length + 8] ^= 0x80            # a message index length
    d = bagio.read_drive_bag(damaged(tmp_path / 'b', drives, 'mcap', bytes(broken)))
    assert d.messages[DEFLECTIONS] == whole.messages[DEFLECTIONS] > mcap_recovers(
        bytes(broken))
    assert any('found by its head' in line for line in d.issues), d.issues


def test_a_file_without_chunks(tmp_path, drives):
    """Every record at the top level (rosbag2's fastwrite preset): read whole, then cut and
    flipped, at least what the mcap library recovers."""
    mcap = rewrite_with_mcap(drives['ours'][0], tmp_path / 'flat', chunked=False)
    data = mcap.read_bytes()
    assert not chunks_of(data)
    full = bagio.read_drive_bag(tmp_path / 'flat')
    assert full.stamps_ns.size == SAMPLES and not full.issues
    for cut in (len(data) // 3, 2 * len(data) // 3):
        broken = bytearray(data[:cut])
        broken[cut // 2] ^= 0x04
        mcap.write_bytes(bytes(broken))
        d = bagio.read_drive_bag(tmp_path / 'flat')
        assert d.messages.get(DEFLECTIONS, 0) >= mcap_recovers(bytes(broken)) > 0
        assert d.issues
