"""The offline commands under signals (issue 28): SIGINT is one line and exit status 130,
SIGTERM one line and 143, and neither leaves a temporary folder behind; what a SIGKILLed run
left is removed by the next run that writes there. Each command runs in its own process
(``python -m road_force_estimator.tools.<command>``) and is signalled while it works."""
from __future__ import annotations

import os
from pathlib import Path
import signal
import subprocess
import sys
import time

import pytest

from road_force_estimator.tools import simulate_bag

TIMEOUT_S = 120.0
MESSAGES = {signal.SIGINT: (130, 'interrupted (SIGINT)'),
            signal.SIGTERM: (143, 'terminated (SIGTERM)')}


def start(command: str, *args: str) -> subprocess.Popen:
    env = dict(os.environ, PYTHONUNBUFFERED='1')
    return subprocess.Popen([sys.executable, '-m', f'road_force_estimator.tools.{command}',
                             *args, '--no-progress'], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def wait_for(condition, process: subprocess.Popen, timeout_s: float = TIMEOUT_S) -> None:
    """Poll ``condition()`` every 2 ms until true; fail if the process ends first."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        if process.poll() is not None:
            out, err = process.communicate()
            pytest.fail(f'ended ({process.returncode}) before the moment to signal: {err}')
        if time.monotonic() > deadline:
            process.kill()
            pytest.fail('the moment to signal never came')
        time.sleep(0.002)


def finish(process: subprocess.Popen) -> tuple[int, str, str]:
    try:
        out, err = process.communicate(timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        process.kill()
        out, err = process.communicate()
        pytest.fail(f'did not end after the signal: {err[-2000:]}')
    return process.returncode, out, err


def stages(folder: Path) -> list[Path]:
    return sorted(folder.glob('.*.tmp-*'))


@pytest.fixture(scope='module')
def drive(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp('signals') / 'drive'
    assert simulate_bag.main(['--road', 'iso8608:C:seed=1', '--speed', '20', '--rate', '1000',
                              '--duration', '20', '--output', str(path), '--no-progress']) == 0
    return path


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
def test_estimate_bag_stopped_while_it_writes_leaves_nothing(drive, tmp_path, sig):
    out = tmp_path / 'est'
    process = start('estimate_bag', str(drive), '--output', str(out))
    wait_for(lambda: bool(stages(out)), process)      # the bag and report being written
    process.send_signal(sig)
    code, stdout, stderr = finish(process)
    status, word = MESSAGES[sig]
    assert code == status
    assert stderr == f'estimate_bag: {word}; nothing half-written is left\n'
    assert not out.exists()           # DIR was made for the run: it goes too


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
def test_simulate_bag_stopped_while_it_simulates(tmp_path, sig):
    out = tmp_path / 'sim'
    process = start('simulate_bag', '--road', 'iso8608:C:seed=2', '--speed', '20', '--rate',
                    '1000', '--duration', '600', '--output', str(out))
    # the plant runs (tens of seconds for 600 s): signal once its modules are loaded
    time.sleep(3.0)
    assert process.poll() is None
    process.send_signal(sig)
    code, stdout, stderr = finish(process)
    status, word = MESSAGES[sig]
    assert (code, stderr) == (status, f'simulate_bag: {word}; nothing half-written is left\n')
    assert list(tmp_path.iterdir()) == []


def test_what_a_killed_run_left_is_removed_by_the_next(drive, tmp_path):
    out = tmp_path / 'est'
    process = start('estimate_bag', str(drive), '--output', str(out))
    wait_for(lambda: bool(stages(out)), process)
    process.kill()                                    # SIGKILL: no clean-up possible
    finish(process)
    left = stages(out)
    assert len(left) == 1 and (left[0] / '.lock').is_file()
    # a run still alive keeps its folder: a lock held by another process
    (tmp_path / '.other.tmp-live').mkdir()
    ((tmp_path / '.other.tmp-live') / '.lock').write_text('')
    holder = subprocess.Popen([sys.executable, '-c', (
        'import fcntl, os, sys, time\n'
        f'fd = os.open({str(tmp_path / ".other.tmp-live" / ".lock")!r}, os.O_RDONLY)\n'
        'fcntl.flock(fd, fcntl.LOCK_EX)\nprint("held", flush=True)\ntime.sleep(600)\n')],
        stdout=subprocess.PIPE, text=True)
    try:
        from road_force_estimator.tools.output_folder import remove_stale_stages
        assert holder.stdout.readline() == 'held\n'
        assert remove_stale_stages(tmp_path, '.other.tmp-') == []
        assert (tmp_path / '.other.tmp-live').is_dir()
    finally:
        holder.kill()
        holder.wait()
    assert remove_stale_stages(tmp_path, '.other.tmp-') == [tmp_path / '.other.tmp-live']
    code, stdout, stderr = finish(start('estimate_bag', str(drive), '--output', str(out)))
    assert code == 0, stderr
    assert stages(out) == []
    assert sorted(p.name for p in out.iterdir()) == [
        '.written-by-road-force-estimator.json', 'bag', 'report']


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
def test_estimate_fleet_stopped_while_drives_are_built(drive, tmp_path, sig):
    import shutil
    for name in ('a', 'b'):
        shutil.copytree(drive, tmp_path / 'in' / name)
    out = tmp_path / 'out'
    env = dict(os.environ, PYTHONUNBUFFERED='1')
    process = subprocess.Popen(
        [sys.executable, '-m', 'road_force_estimator.tools.estimate_fleet', str(tmp_path / 'in'),
         '--output', str(out), '--workers', '2', '--no-progress'], env=env,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    wait_for(lambda: any((out / 'drives' / '.fleet-tmp').glob('*/*')), process)
    if sig == signal.SIGINT:
        os.killpg(process.pid, sig)          # Ctrl-C: the whole group, the workers too
    else:
        process.send_signal(sig)             # systemd / a launcher: the command only
    code, stdout, stderr = finish(process)
    status, word = MESSAGES[sig]
    assert (code, stderr) == (status, f'estimate_fleet: {word}; nothing half-written is left\n')
    # no drive half-built; one that was complete before the signal stays, whole
    for entry in (out / 'drives').iterdir():
        assert entry.name in ('a', 'b') and (entry / 'fleet.json').is_file(), entry


def test_a_failure_reason_keeps_a_file_name_with_a_newline(tmp_path):
    """Issue 28: a newline in a bag path cut the reason in failures.csv."""
    import csv

    from road_force_estimator.tools.fleet_drives import DriveTask, process_drive
    from road_force_estimator.tools.fleet_outputs import _csv_text

    bag = tmp_path / 'in' / 'truck\nmonday'
    bag.mkdir(parents=True)
    (bag / 'metadata.yaml').write_text('rosbag2_bagfile_information:\n  storage_identifier: '
                                       'sqlite3\n')
    outcome = process_drive(DriveTask('truck\nmonday', str(bag), str(tmp_path / 'out'), None,
                                      None, {'mode': 'online', 'segment_length_m': 100.0,
                                             'figures': False}))
    assert outcome.status == 'failed'
    assert outcome.reason == (f"{tmp_path}/in/truck\\nmonday: storage 'sqlite3': only MCAP "
                              'bags are read here')
    rows = list(csv.reader(_csv_text(('drive', 'reason'),
                                     [(outcome.drive_id, outcome.reason)]).splitlines(True)))
    assert rows == [['drive', 'reason'], ['truck\nmonday', outcome.reason]]
