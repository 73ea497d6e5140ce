"""Fuzzing the reader (issue 16's acceptance): 200 seeded random bit flips and 50 random
truncations of a small drive bag (the ``mcap`` library's writer: 8 KiB chunks, schemas and
channels inside them). Every read ends with a drive or one-line BagReadError, never another
exception; it reads at least as many deflections as the ``mcap`` library's readers recover
from the same bytes (chunks failing their CRC left out, ``bag_crafting.mcap_recovers``), and
every sample it accepts is one of the drive's. A handful run ``estimate_bag`` as processes:
exit 0 or 1, one line on stderr, no traceback.
"""
import numpy as np
import pytest

from bag_crafting import SAMPLES, mcap_recovers, rewrite_with_mcap, run_python, small_drive
from road_force_estimator import bagio
from road_force_estimator.interfaces import DEFLECTIONS

FLIPS, CUTS, SEED = 200, 50, 16


@pytest.fixture(scope='module')
def bag(tmp_path_factory):
    """``(folder, mcap path, original bytes, the undamaged drive)``."""
    root = tmp_path_factory.mktemp('fuzz')
    small_drive(root / 'ours')
    mcap = rewrite_with_mcap(root / 'ours', root / 'bag')
    return root / 'bag', mcap, mcap.read_bytes(), bagio.read_drive_bag(root / 'bag')


def cases(data: bytes):
    """``(name, damaged bytes)``: the flips, then the cuts."""
    rng = np.random.default_rng(SEED)
    for _ in range(FLIPS):
        at, bit = int(rng.integers(len(data))), int(rng.integers(8))
        out = bytearray(data)
        out[at] ^= 1 << bit
        yield f'flip byte {at} bit {bit}', bytes(out)
    for _ in range(CUTS):
        at = int(rng.integers(len(data)))
        yield f'cut at {at}', data[:at]


def read(folder):
    """``(deflections read, drive or None, error line or None)``."""
    try:
        d = bagio.read_drive_bag(folder)
    except bagio.BagReadError as err:
        return 0, None, str(err)
    return d.messages.get(DEFLECTIONS, 0), d, None


def test_flips_and_cuts(bag):
    folder, mcap, data, full = bag
    assert full.stamps_ns.size == SAMPLES and not full.issues
    worse = []
    for name, damaged in cases(data):
        mcap.write_bytes(damaged)
        got, d, error = read(folder)
        if error is not None:
            assert '\n' not in error, (name, error)
        want = mcap_recovers(damaged)
        if got < want:
            worse.append(f'{name}: read {got}, the mcap library {want}')
        if d is not None and d.stamps_ns.size:
            keep = np.isin(full.stamps_ns, d.stamps_ns)
            assert keep.sum() == d.stamps_ns.size, name      # no sample made up
            np.testing.assert_array_equal(d.q_m, full.q_m[keep], err_msg=name)
    mcap.write_bytes(data)
    assert not worse, worse


ESTIMATE = """
import sys
from road_force_estimator.tools.estimate_bag import main
sys.exit(main(sys.argv[1:]))
"""


def test_estimate_bag_processes(bag, tmp_path):
    folder, mcap, data, _ = bag
    chosen = [c for i, c in enumerate(cases(data)) if i in (3, 77, FLIPS + 1, FLIPS + 7)]
    chosen.append(('cut at 100', data[:100]))
    try:
        for k, (name, damaged) in enumerate(chosen):
            mcap.write_bytes(damaged)
            done = run_python(ESTIMATE, folder, '--output', tmp_path / str(k), '--no-figures',
                              '--mode', 'offline')
            assert done.returncode in (0, 1), (name, done.returncode, done.stderr)
            assert 'Traceback' not in done.stderr, (name, done.stderr)
            if done.returncode == 1:
                assert done.stderr.count('\n') == 1, (name, done.stderr)
            else:
                assert 'samples estimated' in done.stdout, (name, done.stdout)
    finally:
        mcap.write_bytes(data)
    assert done.returncode == 1                       # nothing usable in 100 bytes
