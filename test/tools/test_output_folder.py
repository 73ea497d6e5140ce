"""Output folders of the offline commands: --force replaces only what the command wrote and
never its input; a write that fails (out of space: a real 3 MB tmpfs, and a writer raising
ENOSPC in-process) leaves nothing behind that looks complete.

References: the files on disk before and after (SHA-256 of every file), and the kernel's own
ENOSPC from a tmpfs mounted for the test.
"""
import errno
import hashlib
from pathlib import Path
import subprocess
import shutil

import pytest

from road_force_estimator import bagio
from road_force_estimator.tools import estimate_bag, output_folder, profile_to_bag, simulate_bag

ENOSPC_TEXT = 'out of space'


def run(main, argv, capsys):
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def tree(folder: Path) -> dict[str, str]:
    """Relative path -> SHA-256 of every file under ``folder``."""
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob('*')) if p.is_file()}


@pytest.fixture(scope='module')
def drive(tmp_path_factory):
    """6 s on ISO 8608 class C at 20 m/s, 1 kHz (its estimate bag: about 5 MB)."""
    folder = tmp_path_factory.mktemp('drive') / 'drive'
    assert simulate_bag.main(['--road', 'iso8608:C:seed=2', '--speed', '20', '--rate', '1000',
                              '--duration', '6', '--output', str(folder),
                              '--no-progress']) == 0
    return folder


@pytest.fixture
def tmpfs(tmp_path):
    """``tmpfs(size)``: a fresh tmpfs of ``size`` (mount(8) syntax) under tmp_path, unmounted
    at the end; the test is skipped (with the reason) when mounting is refused."""
    mounted = []

    def mount(size: str) -> Path:
        point = tmp_path / f'fs{len(mounted)}'
        point.mkdir()
        done = subprocess.run(['mount', '-t', 'tmpfs', '-o', f'size={size}', 'tmpfs',
                               str(point)], capture_output=True, text=True)
        if done.returncode != 0:
            pytest.skip(f'cannot mount a tmpfs here: {done.stderr.strip() or done.returncode}')
        mounted.append(point)
        return point

    yield mount
    for point in mounted:
        done = subprocess.run(['umount', str(point)], capture_output=True, text=True)
        if done.returncode != 0:                     # a file left open on it: a leak
            subprocess.run(['umount', '-l', str(point)], check=True)
            pytest.fail(f'{point} was busy at the end: {done.stderr.strip()}')


def one_line_no_traceback(err: str) -> bool:
    return err.count('\n') == 1 and 'Traceback' not in err


# ------------------------------------------------------------------------------------------
# --force: only what the command wrote, never the input

class TestForce:
    def test_estimate_bag_never_deletes_its_input(self, drive, tmp_path, capsys):
        out = tmp_path / 'x'
        out.mkdir()
        shutil.copytree(drive, out / 'bag')
        before = tree(out)
        for extra in ([], ['--force']):
            code, _, err = run(estimate_bag.main, [out / 'bag', '--output', out,
                                                   '--no-figures'] + extra, capsys)
            assert code == 1 and one_line_no_traceback(err), err
            assert 'input' in err
            assert tree(out) == before                  # the input is intact, nothing added

    def test_estimate_bag_force_replaces_its_own_output_only(self, drive, tmp_path, capsys):
        out = tmp_path / 'o'
        # --force on the first run too: the report quotes the command line
        argv = [drive, '--output', out, '--no-figures', '--mode', 'offline']
        assert run(estimate_bag.main, argv + ['--force'], capsys)[0] == 0
        marker = out / output_folder.MARKER_NAME
        assert marker.is_file()
        first = tree(out)
        assert run(estimate_bag.main, argv + ['--force'], capsys)[0] == 0
        assert tree(out) == first                       # replaced by the same bytes
        # A file the user put into the report: --force refuses, and names it.
        (out / 'report' / 'notes.txt').write_text('mine\n')
        before = tree(out)
        code, _, err = run(estimate_bag.main, argv + ['--force'], capsys)
        assert code == 1 and one_line_no_traceback(err) and 'notes.txt' in err, err
        assert tree(out) == before
        # Without the marker nothing is known to be ours: refused.
        (out / 'report' / 'notes.txt').unlink()
        marker.unlink()
        before = tree(out)
        code, _, err = run(estimate_bag.main, argv + ['--force'], capsys)
        assert code == 1 and one_line_no_traceback(err) and 'not written by' in err, err
        assert tree(out) == before

    def test_estimate_bag_beside_other_files_keeps_them(self, drive, tmp_path, capsys):
        out = tmp_path / 'o'
        out.mkdir()
        (out / 'keep.txt').write_text('mine\n')
        argv = [drive, '--output', out, '--no-figures']
        assert run(estimate_bag.main, argv, capsys)[0] == 0
        assert run(estimate_bag.main, argv + ['--force'], capsys)[0] == 0
        assert (out / 'keep.txt').read_text() == 'mine\n'
        assert sorted(p.name for p in out.iterdir()) == sorted(
            [output_folder.MARKER_NAME, 'bag', 'report', 'keep.txt'])

    def test_simulate_bag_force_replaces_its_own_bag_only(self, drive, tmp_path, capsys):
        argv = ['--road', 'flat:length=20', '--speed', 10, '--rate', 100, '--duration', 0.5]
        # A bag another command wrote (profile_to_bag's LPA bag): refused.
        lpa = tmp_path / 'lpa'
        assert run(profile_to_bag.main, ['flat', '--length', '10', '-o', lpa], capsys)[0] == 0
        before = tree(lpa)
        code, _, err = run(simulate_bag.main, argv + ['--output', lpa, '--force'], capsys)
        assert code == 1 and one_line_no_traceback(err) and 'not written by' in err, err
        assert tree(lpa) == before
        # The road it reads, given as the output: refused (never the input).
        code, _, err = run(simulate_bag.main, ['--road', lpa, '--speed', 10, '--rate', 100,
                                               '--duration', 0.5, '--output', lpa, '--force'],
                           capsys)
        assert code == 1 and one_line_no_traceback(err) and 'input' in err, err
        assert tree(lpa) == before
        # Its own bag, with a file added: refused; without it: replaced.
        own = tmp_path / 'd'
        assert run(simulate_bag.main, argv + ['--output', own], capsys)[0] == 0
        (own / 'notes.txt').write_text('mine\n')
        code, _, err = run(simulate_bag.main, argv + ['--output', own, '--force'], capsys)
        assert code == 1 and 'notes.txt' in err, err
        (own / 'notes.txt').unlink()
        assert run(simulate_bag.main, argv + ['--output', own, '--force'], capsys)[0] == 0
        assert sorted(p.name for p in own.iterdir()) == ['d_0.mcap', 'metadata.yaml']

    def test_profile_to_bag_force_replaces_its_own_outputs_only(self, drive, tmp_path, capsys):
        # A drive bag (simulate_bag's) is no LPA bag of profile_to_bag: refused.
        before = tree(drive)
        code, _, err = run(profile_to_bag.main, ['flat', '--length', '10', '-o', drive,
                                                 '--force'], capsys)
        assert code == 1 and one_line_no_traceback(err) and 'not written by' in err, err
        assert tree(drive) == before
        # A CSV that is not one it writes: refused; its own CSV: replaced.
        lpa = tmp_path / 'lpa'
        assert run(profile_to_bag.main, ['flat', '--length', '10', '-o', lpa], capsys)[0] == 0
        other = tmp_path / 'notes.csv'
        other.write_text('a,b\n1,2\n')
        code, _, err = run(profile_to_bag.main, [lpa, '-o', other, '--force'], capsys)
        assert code == 1 and one_line_no_traceback(err) and 'not written by' in err, err
        assert other.read_text() == 'a,b\n1,2\n'
        own = tmp_path / 'own.csv'
        assert run(profile_to_bag.main, [lpa, '-o', own], capsys)[0] == 0
        text = own.read_text()
        assert run(profile_to_bag.main, [lpa, '-o', own, '--force'], capsys)[0] == 0
        assert own.read_text() == text
        assert sorted(p.name for p in tmp_path.iterdir()) == ['lpa', 'notes.csv', 'own.csv']


# ------------------------------------------------------------------------------------------
# out of space: a real tmpfs

class TestOutOfSpaceOnTmpfs:
    def test_estimate_bag(self, drive, tmpfs, capsys):
        fs = tmpfs('3m')
        for extra in (['--no-figures'], []):
            code, _, err = run(estimate_bag.main, [drive, '--output', fs / 'out'] + extra,
                               capsys)
            assert code == 1 and one_line_no_traceback(err) and ENOSPC_TEXT in err, err
            assert list(fs.iterdir()) == []             # nothing left, not even DIR

    def test_estimate_bag_force_keeps_the_old_output_when_out_of_space(self, drive, tmp_path,
                                                                       tmpfs, capsys):
        fs = tmpfs('5m')
        short = tmp_path / 'short'
        assert simulate_bag.main(['--road', 'iso8608:C:seed=2', '--speed', '20', '--rate',
                                  '500', '--duration', '1', '--output', str(short),
                                  '--no-progress']) == 0
        out = fs / 'out'
        argv = ['--output', out, '--no-figures', '--force']
        assert run(estimate_bag.main, [short] + argv, capsys)[0] == 0
        before = tree(out)
        code, _, err = run(estimate_bag.main, [drive] + argv, capsys)
        assert code == 1 and ENOSPC_TEXT in err, err
        assert tree(out) == before                      # the old, complete output stays
        assert sorted(p.name for p in out.iterdir()) == sorted(
            [output_folder.MARKER_NAME, 'bag', 'report'])

    def test_simulate_bag(self, tmpfs, capsys):
        fs = tmpfs('3m')
        code, _, err = run(simulate_bag.main, ['--road', 'iso8608:C:seed=1', '--speed', 20,
                                               '--rate', 1000, '--duration', 6, '--output',
                                               fs / 'd', '--no-progress'], capsys)
        assert code == 1 and one_line_no_traceback(err) and ENOSPC_TEXT in err, err
        assert list(fs.iterdir()) == []

    def test_profile_to_bag(self, tmp_path, tmpfs, capsys):
        fs = tmpfs('256k')
        code, _, err = run(profile_to_bag.main, ['iso8608:C:seed=1', '--length', '5000', '-o',
                                                 fs / 'lpa'], capsys)
        assert code == 1 and one_line_no_traceback(err) and ENOSPC_TEXT in err, err
        assert list(fs.iterdir()) == []
        lpa = tmp_path / 'lpa'
        assert run(profile_to_bag.main, ['iso8608:C:seed=1', '--length', '5000', '-o', lpa],
                   capsys)[0] == 0
        code, _, err = run(profile_to_bag.main, [lpa, '-o', fs / 'p.csv'], capsys)
        assert code == 1 and one_line_no_traceback(err) and ENOSPC_TEXT in err, err
        assert list(fs.iterdir()) == []


# ------------------------------------------------------------------------------------------
# out of space: a writer raising ENOSPC in-process

def enospc(*_args, **_kwargs):
    raise OSError(errno.ENOSPC, 'No space left on device')


class TestOutOfSpaceInProcess:
    def test_report_fails_after_the_bag_was_written(self, drive, tmp_path, capsys,
                                                    monkeypatch):
        import road_force_estimator.report as report

        def half_report(folder, *args, **kwargs):
            Path(folder).mkdir(parents=True)
            (Path(folder) / 'loads.png').write_bytes(b'\x89PNG')
            enospc()

        monkeypatch.setattr(report, 'write_report', half_report)
        code, _, err = run(estimate_bag.main, [drive, '--output', tmp_path / 'o'], capsys)
        assert code == 1 and one_line_no_traceback(err) and ENOSPC_TEXT in err, err
        assert not (tmp_path / 'o').exists()            # no bag/ without report/

    def test_bag_writer_fails_midway(self, tmp_path, capsys, monkeypatch):
        real = bagio.write_drive_bag

        def half_bag(path, *args, **kwargs):
            real(path, *args, **kwargs)
            (Path(path) / 'metadata.yaml').unlink()     # a .mcap without metadata.yaml
            enospc()

        monkeypatch.setattr(bagio, 'write_drive_bag', half_bag)
        code, _, err = run(simulate_bag.main, ['--road', 'flat:length=20', '--speed', 10,
                                               '--rate', 100, '--duration', 0.5, '--output',
                                               tmp_path / 'd'], capsys)
        assert code == 1 and one_line_no_traceback(err) and ENOSPC_TEXT in err, err
        assert list(tmp_path.iterdir()) == []

    def test_lpa_writer_fails_midway(self, tmp_path, capsys, monkeypatch):
        def half_lpa(path, *args, **kwargs):
            Path(path).mkdir()
            (Path(path) / f'{Path(path).name}_0.mcap').write_bytes(b'\x89MCAP0\r\n')
            raise OSError(errno.EIO, 'Input/output error')

        monkeypatch.setattr(bagio, 'write_lpa_bag', half_lpa)
        code, _, err = run(profile_to_bag.main, ['flat', '--length', '10', '-o',
                                                 tmp_path / 'lpa'], capsys)
        assert code == 1 and one_line_no_traceback(err) and 'Input/output error' in err, err
        assert list(tmp_path.iterdir()) == []


def test_reasons():
    err = OSError(errno.ENOSPC, 'No space left on device')
    assert output_folder.os_reason(err).startswith(ENOSPC_TEXT)
    wrapped = bagio.BagWriteError('cannot create the bag')
    wrapped.__context__ = err
    assert output_folder.os_reason(wrapped).startswith(ENOSPC_TEXT)
    assert output_folder.os_reason(OSError(errno.EACCES, 'Permission denied')) == \
        'Permission denied'
    assert output_folder.os_reason(ValueError('x')) is None


def test_estimate_bag_in_the_fleet_writes_no_marker(drive, tmp_path):
    folder = tmp_path / 'staged'
    folder.mkdir()
    estimate_bag.run(drive, folder, figures=False, standalone=False)
    assert sorted(p.name for p in folder.iterdir()) == ['bag', 'report']

