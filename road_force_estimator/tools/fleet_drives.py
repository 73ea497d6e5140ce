"""estimate_fleet's drives: finding them, their resume keys, and one drive's task.

A drive's id is its bag folder's path relative to the INPUT that holds it (its folder name
when given directly); :func:`find_drives` finds them (see
:mod:`road_force_estimator.tools.estimate_fleet`). :func:`process_drive` (the Dask task) runs
:func:`road_force_estimator.tools.estimate_bag.run` into ``DIR/drives/.fleet-tmp/`` and
renames the complete folder into ``DIR/drives/<id>`` with :data:`STAMP_NAME`, which holds the
key (:func:`drive_key`: SHA-256 of :func:`input_sha256` of the input bag, the parameters, the
mode, the segment length and the figures switch); :func:`load_done` finds a drive already done
with the same key.
"""
from __future__ import annotations

from contextlib import contextmanager
import csv
from dataclasses import dataclass, field
import hashlib
import json
import math
import os
from pathlib import Path
import re
import shutil
import tempfile
import time
from typing import Any, Callable, Iterator, Sequence
import uuid

import numpy as np

from road_force_estimator.tools.cli import one_line
from road_force_estimator.tools.output_folder import os_reason

__all__ = [
    'FLEET_COLUMNS', 'INT_COLUMNS', 'STAMP_NAME', 'TMP_NAME', 'LOCK_NAME', 'KEY_FORMAT',
    'FleetError', 'DriveInput', 'DriveTask', 'DriveOutcome', 'find_drives', 'input_sha256',
    'drive_key', 'read_segments_csv', 'process_drive', 'load_done', 'output_lock',
    'report_counts',
]

#: Columns of segments.csv / segments.parquet, in order (INTERFACES.md "Many drives").
FLEET_COLUMNS = (
    'drive', 'start_m', 'end_m', 'iri_left_m_per_km', 'iri_right_m_per_km', 'dlc_left',
    'dlc_right', 'peak_load_left_n', 'peak_load_right_n', 'max_abs_ltr', 'lift_offs',
    'start_lat', 'start_lon', 'end_lat', 'end_lon', 'static_load_left_n', 'static_load_right_n',
    'max_abs_ltr_quasi_static',
)
#: The integer columns of :data:`FLEET_COLUMNS` (the others are floats, but ``drive``).
INT_COLUMNS = ('lift_offs',)
#: Per-drive file written with the outputs: the key of what was computed, the polylines.
STAMP_NAME = 'fleet.json'
#: Folder under DIR/drives where drives are built before being renamed into place.
TMP_NAME = '.fleet-tmp'
#: Lock file in DIR held (flock) by the run writing DIR.
LOCK_NAME = '.fleet-lock'
#: Bump when the per-drive outputs change meaning: every stored key then misses.
KEY_FORMAT = 1


class FleetError(Exception):
    """A bad invocation (exit status 2): the message is the one-line reason."""


@dataclass(frozen=True)
class DriveInput:
    """One drive: ``drive_id`` (its path relative to its INPUT) and ``path`` (absolute)."""

    drive_id: str
    path: Path


@dataclass(frozen=True)
class DriveTask:
    """Everything a worker needs for one drive (picklable).

    ``settings``: ``mode``, ``segment_length_m``, ``figures`` and ``parameters`` (dotted
    names, as :meth:`VehicleParameters.to_parameters`); ``input_sha256`` when already known.
    """

    drive_id: str
    input_path: str
    output_dir: str
    vehicle: Any
    observer: Any
    settings: dict
    input_sha256: str = ''


@dataclass
class DriveOutcome:
    """What became of one drive.

    ``status``: ``'processed'``, ``'skipped'`` (already done) or ``'failed'`` (``reason``);
    ``table``: the drive's segment table (``report/segments.csv``), ``lines``: its segments'
    polylines (``[[lon, lat], ...]`` or None); ``seconds``: wall time of the processing (for a
    skipped drive, of the run that made it); ``warnings``: breaks found in the input bag.
    """

    drive_id: str
    status: str
    reason: str = ''
    seconds: float = 0.0
    table: dict[str, np.ndarray] | None = None
    lines: list | None = None
    warnings: list[str] = field(default_factory=list)
    input_path: str = ''
    #: per sensor: the report's counts (``report.json`` ``sensors``: innovations gated,
    #: stuck and drift flags; :func:`road_force_estimator.report.summary.sensor_summary`)
    sensors: dict = field(default_factory=dict)
    #: the messages rejected, topic -> reason -> count (``report.json`` ``rejected``: the
    #: readers' and the estimator's; :func:`road_force_estimator.report.summary.rejections`)
    rejected: dict = field(default_factory=dict)
    #: an articulated drive's tractor IMU: its samples fed a ``fresh``, ``stale`` (held) or
    #: ``missing`` a_y (``report.json`` ``whole_vehicle_estimate.tractor_imu``), else {}
    tractor_imu: dict = field(default_factory=dict)
    #: an articulated drive's model fit per axle (``report.json``
    #: ``whole_vehicle_estimate.model_fit``: ``verdict``, ``culprits``, ``misfit`` per axle,
    #: online the verdicts), else {} (no verdict: a front-axle drive, too short)
    model_fit: dict = field(default_factory=dict)
    #: offline, where the file states tanh friction: the friction's ``v_f`` taken
    #: (``report.json`` ``friction_velocity``, an articulated drive's
    #: ``whole_vehicle_estimate.friction_velocity``: ``taken_mps``, ``file_mps``, ...), else {}
    friction_velocity: dict = field(default_factory=dict)


def _is_inside(path: Path, folder: Path) -> bool:
    try:
        path.relative_to(folder)
        return True
    except ValueError:
        return False


#: A temporary folder of the offline commands (:mod:`.output_folder`): ``.<name>.tmp-*``.
_STAGE = re.compile(r'^\..+\.tmp-[^/]+$')


def _links_out(folder: Path, root: Path) -> list[str]:
    """The entries of a bag folder that are links leading out of ``root`` (names)."""
    out = []
    try:
        entries = list(folder.iterdir())
    except OSError:
        return out
    for entry in entries:
        if entry.is_symlink() and not _is_inside(entry.resolve(), root):
            out.append(entry.name)
    return sorted(out)


def _walk(given, root: Path, skip: list[Path], skipped: list[str]) -> list[DriveInput]:
    """The bag folders under ``root`` (an INPUT resolved): links are followed only while they
    stay inside it, temporary folders of unfinished writes are left out; both named in
    ``skipped``."""
    drives = []
    seen: set[Path] = set()
    for folder, dirs, files in os.walk(root, followlinks=True):
        here = Path(folder)
        real = here.resolve()
        if real in seen or any(_is_inside(real, s) for s in skip):
            dirs[:] = []
            continue
        seen.add(real)
        rel = here.relative_to(root).as_posix()
        if 'metadata.yaml' in files:
            outside = _links_out(here, root)
            if outside:
                skipped.append(f'{given}/{rel}: not a drive of {given}: '
                               f'{", ".join(outside[:3])} link{"s" if len(outside) > 1 else ""} '
                               f'out of it (not followed)')
            else:
                drives.append(DriveInput(rel, here))
            dirs[:] = []
            continue
        keep = []          # real folders before links to them: a drive keeps its real path
        for d in sorted(dirs, key=lambda d: ((here / d).is_symlink(), d)):
            sub = here / d
            if _STAGE.match(d):
                skipped.append(f'{given}/{(Path(rel) / d).as_posix()}: the temporary folder '
                               'of an unfinished write (not a drive)')
            elif sub.is_symlink() and not _is_inside(sub.resolve(), root):
                skipped.append(f'{given}/{(Path(rel) / d).as_posix()}: a link out of {given} '
                               f'(to {sub.resolve()}): not followed')
            else:
                keep.append(d)
        dirs[:] = keep
    return drives


def find_drives(inputs: Sequence[str | Path], *, exclude: Sequence[str | Path] = (),
                skipped: list[str] | None = None) -> list[DriveInput]:
    """The drives under ``inputs`` (see the module notes), sorted by id.

    The search stays inside each INPUT: a link that leads out of it (to ``/``, to ``..``) is
    not followed, a bag folder holding such a link is not taken, and the temporary folders
    of unfinished writes (``.<name>.tmp-*``) are no drives; each is named in ``skipped``
    (one line each) when a list is given.

    Raises
    ------
    FleetError
        An input that does not exist or is not a folder, an input without any bag folder,
        two drives with the same id, or an id that is a parent folder of another.
    """
    skip = [Path(p).resolve() for p in exclude]
    skipped = [] if skipped is None else skipped
    drives: list[DriveInput] = []
    for given in inputs:
        top = Path(given)
        if not top.exists():
            raise FleetError(f'{given}: no such folder')
        if not top.is_dir():
            raise FleetError(f'{given}: not a folder (expected a bag folder or a folder of bag '
                             'folders)')
        root = top.resolve()
        if (top / 'metadata.yaml').is_file():
            outside = _links_out(root, root)
            if outside:
                raise FleetError(f'{given}: {", ".join(outside[:3])} link out of the bag '
                                 'folder: not read')
            drives.append(DriveInput(root.name, root))
            continue
        found = _walk(given, root, skip, skipped)
        if not found:
            raise FleetError(f'{given}: no bag folder (a folder with metadata.yaml) found')
        drives += found
    ids: dict[str, Path] = {}
    for d in drives:
        if d.drive_id in ids:
            raise FleetError(f'drive id {d.drive_id!r} is given twice ({ids[d.drive_id]} and '
                             f'{d.path}): ids must be unique')
        if d.drive_id.split('/')[0].startswith('.fleet-'):
            raise FleetError(f'drive id {d.drive_id!r}: names starting with ".fleet-" are '
                             'reserved')
        ids[d.drive_id] = d.path
    names = sorted(ids)
    for a, b in zip(names, names[1:]):
        if b.startswith(a + '/'):
            raise FleetError(f'drive id {a!r} is a folder above drive {b!r}: their outputs '
                             'would nest')
    return sorted(drives, key=lambda d: d.drive_id)


def input_sha256(path: str | Path, *, chunk: int = 1 << 20,
                 exclude: Sequence[str | Path] = ()) -> str:
    """SHA-256 (hex) of a bag folder's content: every file's relative path, size and bytes,
    in sorted path order (a single file: its bytes); files inside an ``exclude`` folder (the
    fleet's output folder, when it lies inside the bag folder) are left out."""
    path = Path(path)
    skip = [Path(p).resolve() for p in exclude]
    h = hashlib.sha256()
    files = [path] if path.is_file() else sorted(
        (p for p in path.rglob('*')
         if p.is_file() and not any(_is_inside(p.resolve(), s) for s in skip)),
        key=lambda p: p.relative_to(path).as_posix())
    for f in files:
        rel = f.name if f == path else f.relative_to(path).as_posix()
        h.update(f'{rel}\0{f.stat().st_size}\0'.encode())
        with f.open('rb') as stream:
            while True:
                block = stream.read(chunk)
                if not block:
                    break
                h.update(block)
    return h.hexdigest()


@contextmanager
def output_lock(output_dir: str | Path, *, wait: bool = False,
                on_wait: Callable[[], None] | None = None) -> Iterator[Path]:
    """Hold DIR/:data:`LOCK_NAME` (``fcntl.flock``, exclusive) for one run writing DIR.

    Raises
    ------
    FleetError
        Another run holds it (unless ``wait``: then ``on_wait()`` is called and the lock is
        waited for), or it cannot be created.
    """
    import fcntl

    lock = Path(output_dir) / LOCK_NAME
    try:
        stream = lock.open('a+')
    except OSError as err:
        raise FleetError(f'cannot create {lock}: {err.strerror or err}') from None
    with stream:
        try:
            fcntl.flock(stream, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            if not wait:
                stream.seek(0)
                holder = stream.read(40).strip()
                raise FleetError(
                    f'another estimate_fleet run{f" (pid {holder})" if holder else ""} is '
                    f'writing {output_dir}: wait for it to end, or give --wait to wait for '
                    'it') from None
            if on_wait is not None:
                on_wait()
            fcntl.flock(stream, fcntl.LOCK_EX)
        except OSError as err:                 # a file system without locks
            raise FleetError(f'cannot lock {lock}: {err.strerror or err}') from None
        stream.seek(0)
        stream.truncate()
        stream.write(f'{os.getpid()}\n')
        stream.flush()
        try:
            yield lock
        finally:
            fcntl.flock(stream, fcntl.LOCK_UN)


def drive_key(input_digest: str, settings: dict) -> str:
    """The key of a drive's outputs: SHA-256 of the input digest, the settings (parameters,
    mode, segment length, figures, units; not ``run_info``, the command line shown in the
    reports) and :data:`KEY_FORMAT`, as canonical JSON."""
    settings = {k: v for k, v in settings.items() if k != 'run_info'}
    doc = {'format': KEY_FORMAT, 'input_sha256': input_digest, 'settings': settings}
    text = json.dumps(doc, sort_keys=True, separators=(',', ':'), allow_nan=True)
    return hashlib.sha256(text.encode()).hexdigest()


def read_segments_csv(path: str | Path) -> dict[str, np.ndarray]:
    """A report's ``segments.csv`` as ``{column: array}`` (floats; ``lift_offs`` int64):
    :data:`FLEET_COLUMNS`, then the columns an articulated drive adds (INTERFACES.md "The
    whole vehicle": every column of the file that a drive's :data:`~.core.segments.
    SEGMENT_COLUMNS` does not name), in the file's order.

    Raises
    ------
    ValueError
        A column of :data:`FLEET_COLUMNS` (other than ``drive``) is missing.
    """
    with Path(path).open(newline='') as f:
        rows = list(csv.reader(f))
    if not rows:
        raise ValueError(f'{path}: empty segment table')
    header, body = rows[0], rows[1:]
    missing = [c for c in FLEET_COLUMNS[1:] if c not in header]
    if missing:
        raise ValueError(f'{path}: no column {", ".join(missing)}')
    from road_force_estimator.core.segments import SEGMENT_COLUMNS

    out: dict[str, np.ndarray] = {}
    extra = [c for c in header if c not in SEGMENT_COLUMNS and c not in FLEET_COLUMNS]
    for name in list(FLEET_COLUMNS[1:]) + extra:
        j = header.index(name)
        values = [r[j] if j < len(r) else '' for r in body]
        if name in INT_COLUMNS:
            out[name] = np.array([int(float(v)) if v not in ('', 'nan') else 0 for v in values],
                                 dtype=np.int64)
        else:
            out[name] = np.array([float(v) if v != '' else math.nan for v in values],
                                 dtype=float)
    return out


# ----------------------------------------------------------------------------------------------
# one drive (runs on a worker)

def _safe_name(drive_id: str) -> str:
    return ''.join(c if c.isalnum() or c in '-_.' else '_' for c in drive_id)[:60] or 'drive'


def _install(tmp: Path, final: Path, tmp_root: Path) -> None:
    """Move the complete folder ``tmp`` to ``final``, replacing what was there."""
    final.parent.mkdir(parents=True, exist_ok=True)
    old = None
    if final.exists():
        old = tmp_root / f'old-{uuid.uuid4().hex}'
        os.rename(final, old)
    os.rename(tmp, final)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def _fixes_of(result, input_path: str):
    """The drive's fixes: those the run read (its ``drive``: a :class:`.bagio.Drive` or,
    in blocks, a :class:`.bagio.drive_blocks.DriveRecord`), else read again."""
    drive = result.drive
    if drive is None:
        from road_force_estimator.bagio import read_drive_bag
        drive = read_drive_bag(input_path)
    return drive.fixes


def worker_memory_limit() -> float | None:
    """The memory limit (bytes) of the Dask worker this task runs in, None outside one or
    without a limit: what :func:`.estimate_bag.run` is given (the pipeline's block plan)."""
    try:
        from distributed import get_worker
        worker = get_worker()
    except (ImportError, ValueError):
        return None
    manager = getattr(worker, 'memory_manager', None)     # a Dask object, not ours
    limit = getattr(manager, 'memory_limit', None)
    return float(limit) if limit else None


def process_drive(task: DriveTask) -> DriveOutcome:
    """Estimate one drive into ``DIR/drives/<id>`` (the Dask task; never raises for a bad
    drive: the outcome says ``failed`` with the reason)."""
    from road_force_estimator.tools import estimate_bag
    from road_force_estimator.report import segment_lines

    t0 = time.perf_counter()
    out = Path(task.output_dir)
    tmp_root = out / 'drives' / TMP_NAME
    final = out / 'drives' / task.drive_id
    settings = task.settings
    try:
        digest = task.input_sha256 or input_sha256(task.input_path, exclude=[out])
        key = drive_key(digest, settings)
        tmp_root.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=_safe_name(task.drive_id) + '-', dir=tmp_root))
        try:
            result = estimate_bag.run(
                task.input_path, tmp, vehicle=task.vehicle, observer=task.observer,
                mode=settings['mode'], segment_length_m=settings['segment_length_m'],
                figures=settings['figures'], force=False, progress=False, standalone=False,
                units=settings.get('units', 'si'), run_info=settings.get('run_info'),
                memory_limit_bytes=worker_memory_limit())
            table = read_segments_csv(tmp / 'report' / 'segments.csv')
            fixes = _fixes_of(result, task.input_path)
            est = result.estimates
            rows = np.flatnonzero(np.asarray(est.valid, dtype=bool))
            lines = segment_lines(
                table['start_m'], table['end_m'], table['start_lat'], table['start_lon'],
                table['end_lat'], table['end_lon'],
                stamps_ns=np.asarray(est.stamp_ns, dtype=np.int64)[rows],
                distance_m=np.asarray(est.distance_m, dtype=float)[rows],
                fix_stamps_ns=None if fixes is None else fixes.stamps_ns,
                fix_latitude_deg=None if fixes is None else fixes.latitude_deg,
                fix_longitude_deg=None if fixes is None else fixes.longitude_deg)
            seconds = time.perf_counter() - t0
            stamp = {'format': KEY_FORMAT, 'drive': task.drive_id, 'input': task.input_path,
                     'key': key, 'input_sha256': digest, 'settings': settings,
                     'seconds': seconds, 'warnings': list(result.warnings), 'lines': lines}
            (tmp / STAMP_NAME).write_text(json.dumps(stamp, allow_nan=True) + '\n')
            _install(tmp, final, tmp_root)
        finally:
            if tmp.exists():
                shutil.rmtree(tmp, ignore_errors=True)
        return DriveOutcome(task.drive_id, 'processed', seconds=seconds, table=table,
                            lines=lines, warnings=list(result.warnings),
                            input_path=task.input_path, **report_counts(result.summary))
    except Exception as err:  # noqa: BLE001 - one bad drive never stops the fleet
        from road_force_estimator.bagio import BagReadError, BagWriteError
        # estimate_bag's own reasons as they are; anything else with its type (a bug).
        plain = type(err) in (estimate_bag.InputError, BagReadError, BagWriteError, ValueError)
        plain = plain or isinstance(err, OSError)
        reason = one_line(err) if plain else f'{type(err).__name__}: {one_line(err)}'
        if isinstance(err, OSError) and os_reason(err):
            reason = f'cannot write {final}: {os_reason(err)}'
        return DriveOutcome(task.drive_id, 'failed', reason=reason,
                            seconds=time.perf_counter() - t0, input_path=task.input_path)


def load_done(output_dir: str | Path, drive: DriveInput, key: str) -> DriveOutcome | None:
    """The outcome of a drive already done with this ``key`` (``skipped``), else None."""
    folder = Path(output_dir) / 'drives' / drive.drive_id
    try:
        stamp = json.loads((folder / STAMP_NAME).read_text())
        if stamp.get('key') != key or not (folder / 'bag' / 'metadata.yaml').is_file():
            return None
        table = read_segments_csv(folder / 'report' / 'segments.csv')
        lines = stamp.get('lines')
        if not isinstance(lines, list) or len(lines) != len(table['start_m']):
            return None
    except (OSError, ValueError):
        return None
    return DriveOutcome(drive.drive_id, 'skipped', seconds=float(stamp.get('seconds', 0.0)),
                        table=table, lines=lines, warnings=list(stamp.get('warnings', [])),
                        input_path=str(drive.path),
                        **report_counts(_report_summary(folder)))


def report_counts(summary: dict) -> dict[str, dict]:
    """The counts of a drive's report summary (``report.json``) that the fleet's tables
    carry, as :class:`DriveOutcome`'s fields: ``sensors``, ``rejected``, ``tractor_imu``,
    ``model_fit``, ``friction_velocity`` ({} each where the summary has none)."""
    def part(value) -> dict:
        return dict(value) if isinstance(value, dict) else {}

    whole = part(summary.get('whole_vehicle_estimate'))
    return {'sensors': part(summary.get('sensors')), 'rejected': part(summary.get('rejected')),
            'tractor_imu': part(whole.get('tractor_imu')),
            'model_fit': part(whole.get('model_fit')),
            'friction_velocity': part(whole.get('friction_velocity')
                                      or summary.get('friction_velocity'))}


def _report_summary(folder: Path) -> dict:
    """A drive's ``report/report.json`` ({} without one)."""
    try:
        summary = json.loads((folder / 'report' / 'report.json').read_text())
    except (OSError, ValueError):
        return {}
    return summary if isinstance(summary, dict) else {}
