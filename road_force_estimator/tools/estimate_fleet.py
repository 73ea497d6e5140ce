"""`estimate_fleet`: many recorded drives on Dask distributed, one table and a map.

    estimate_fleet INPUT... --params-file FILE --output DIR [--mode online|offline]
                   [--segment-length M] [--scheduler ADDRESS] [--workers N] [--force]
                   [--no-figures] [--no-progress]

Each INPUT is a drive bag folder or a folder holding bag folders (any folder with a
``metadata.yaml``, searched recursively; the search does not enter a bag folder, nor DIR).
A drive's id is its bag folder's path relative to the INPUT that holds it (its folder name
when given directly); ids must be unique.

Every drive is one Dask task (:func:`process_drive`) that runs exactly what ``estimate_bag``
runs (:func:`tools.estimate_bag.run` with the same parameters, mode and segment
length), so ``DIR/drives/<id>/bag`` and ``DIR/drives/<id>/report`` are what ``estimate_bag
INPUT --params-file FILE --output DIR/drives/<id> --mode ... --segment-length ...`` writes. By
default the tasks run on a local cluster of ``--workers`` processes (one thread each, bound to
127.0.0.1, no dashboard); with ``--scheduler tcp://HOST:PORT`` on an existing cluster (``dask
scheduler`` / ``dask worker``), which must see the same file system paths (inputs and DIR). A
scheduler that cannot be reached is an error (exit status 2), never a silent local fallback.

Faults. A drive that cannot be processed (not a bag, corrupt, no usable sample: the reason
``estimate_bag`` gives) goes to ``failures.csv`` and the others go on. A task whose worker dies
is run again elsewhere (Dask's ``allowed-failures`` for lost workers, plus :data:`RETRIES`).
Each drive is built in ``DIR/drives/.fleet-tmp/`` and renamed into place only when complete,
with ``fleet.json`` (a key: SHA-256 of the input bag's files, the parameters, the mode, the
segment length and the figures switch); a drive whose stored key matches is skipped unless
``--force``, so a run that was stopped resumes where it stopped.

Outputs in DIR: ``drives/<id>/`` (``bag/``, ``report/``, ``fleet.json``), ``segments.parquet``
and ``segments.csv`` (:data:`FLEET_COLUMNS`, one row per segment of every drive done, drives in
id order; coordinates NaN without ``/fix``), ``segments.geojson`` (one LineString per segment,
``[lon, lat]``, a ``null`` geometry for a segment without coordinates:
:mod:`road_force_estimator.report.fleet_map`), ``segments_map.png`` (segments coloured by IRI, when
any has coordinates), ``failures.csv`` (``drive,reason``) and ``summary.md``.

Exit status: 0 when every drive succeeded (processed or skipped), 1 when some failed (the rest
are written), 2 for a bad invocation (bad option, missing input, no drive found, bad parameter
file, unreachable scheduler); each error with one line on stderr.
"""
from __future__ import annotations

import argparse
from contextlib import contextmanager
import csv
from dataclasses import dataclass, field
import hashlib
import io
import json
import math
import os
from pathlib import Path
import shutil
import sys
import tempfile
import time
from typing import Any, Iterator, Sequence
import uuid

import numpy as np

__all__ = [
    'PROG', 'FLEET_COLUMNS', 'STAMP_NAME', 'TMP_NAME', 'KEY_FORMAT', 'RETRIES',
    'CONNECT_TIMEOUT_S', 'WORKER_WAIT_S', 'FleetError', 'DriveInput', 'DriveTask',
    'DriveOutcome', 'FleetResult', 'find_drives', 'input_sha256', 'drive_key',
    'read_segments_csv', 'process_drive', 'load_done', 'run_fleet', 'write_outputs',
    'build_parser', 'main',
]

PROG = 'estimate_fleet'
#: Columns of segments.csv / segments.parquet, in order (INTERFACES.md "Many drives").
FLEET_COLUMNS = (
    'drive', 'start_m', 'end_m', 'iri_left_m_per_km', 'iri_right_m_per_km', 'dlc_left',
    'dlc_right', 'peak_load_left_n', 'peak_load_right_n', 'max_abs_ltr', 'lift_offs',
    'start_lat', 'start_lon', 'end_lat', 'end_lon',
)
#: Per-drive file written with the outputs: the key of what was computed, the polylines.
STAMP_NAME = 'fleet.json'
#: Folder under DIR/drives where drives are built before being renamed into place.
TMP_NAME = '.fleet-tmp'
#: Bump when the per-drive outputs change meaning: every stored key then misses.
KEY_FORMAT = 1
#: Extra attempts of a task that raised (lost workers are retried by the scheduler too).
RETRIES = 2
#: Time allowed to reach a --scheduler (s).
CONNECT_TIMEOUT_S = 10.0
#: Time allowed for a --scheduler to have at least one worker (s).
WORKER_WAIT_S = 120.0
#: Number of roughest segments listed in summary.md.
ROUGHEST = 10

_INT_COLUMNS = ('lift_offs',)


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


@dataclass
class FleetResult:
    """A fleet run: one outcome per drive (id order), the engine used, the wall time (s).

    ``timings`` (s): ``prepare`` (finding the drives, checking those already done),
    ``engine_start`` (starting or reaching the cluster), ``processing`` (first task submitted
    to last result back), ``write`` (tables, GeoJSON, map, summary).
    """

    outcomes: list[DriveOutcome]
    engine: str
    seconds: float
    settings: dict
    timings: dict[str, float] = field(default_factory=dict)

    def count(self, status: str) -> int:
        return sum(1 for o in self.outcomes if o.status == status)

    @property
    def exit_code(self) -> int:
        return 1 if self.count('failed') else 0


# ----------------------------------------------------------------------------------------------
# drives, keys

def _is_inside(path: Path, folder: Path) -> bool:
    try:
        path.relative_to(folder)
        return True
    except ValueError:
        return False


def find_drives(inputs: Sequence[str | Path], *, exclude: Sequence[str | Path] = ()
                ) -> list[DriveInput]:
    """The drives under ``inputs`` (see the module notes), sorted by id.

    Raises
    ------
    FleetError
        An input that does not exist or is not a folder, an input without any bag folder,
        two drives with the same id, or an id that is a parent folder of another.
    """
    skip = [Path(p).resolve() for p in exclude]
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
            drives.append(DriveInput(root.name, root))
            continue
        found = 0
        seen: set[Path] = set()
        for folder, dirs, files in os.walk(root, followlinks=True):
            here = Path(folder)
            real = here.resolve()
            if real in seen or any(_is_inside(real, s) for s in skip):
                dirs[:] = []
                continue
            seen.add(real)
            if 'metadata.yaml' in files:
                drives.append(DriveInput(here.relative_to(root).as_posix(), here))
                found += 1
                dirs[:] = []
            else:
                dirs.sort()
        if not found:
            raise FleetError(f'{given}: no bag folder (a folder with metadata.yaml) found')
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


def input_sha256(path: str | Path, *, chunk: int = 1 << 20) -> str:
    """SHA-256 (hex) of a bag folder's content: every file's relative path, size and bytes,
    in sorted path order (a single file: its bytes)."""
    path = Path(path)
    h = hashlib.sha256()
    files = [path] if path.is_file() else sorted(
        (p for p in path.rglob('*') if p.is_file()), key=lambda p: p.relative_to(path).as_posix())
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


def drive_key(input_digest: str, settings: dict) -> str:
    """The key of a drive's outputs: SHA-256 of the input digest, the settings (parameters,
    mode, segment length, figures) and :data:`KEY_FORMAT`, as canonical JSON."""
    doc = {'format': KEY_FORMAT, 'input_sha256': input_digest, 'settings': settings}
    text = json.dumps(doc, sort_keys=True, separators=(',', ':'), allow_nan=True)
    return hashlib.sha256(text.encode()).hexdigest()


def read_segments_csv(path: str | Path) -> dict[str, np.ndarray]:
    """A report's ``segments.csv`` as ``{column: array}`` (floats; ``lift_offs`` int64).

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
    out: dict[str, np.ndarray] = {}
    for name in FLEET_COLUMNS[1:]:
        j = header.index(name)
        values = [r[j] if j < len(r) else '' for r in body]
        if name in _INT_COLUMNS:
            out[name] = np.array([int(float(v)) if v not in ('', 'nan') else 0 for v in values],
                                 dtype=np.int64)
        else:
            out[name] = np.array([float(v) if v != '' else math.nan for v in values],
                                 dtype=float)
    return out


# ----------------------------------------------------------------------------------------------
# one drive (runs on a worker)

def _one_line(err: BaseException) -> str:
    text = str(err).strip().splitlines()
    return text[0] if text else type(err).__name__


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
    drive = getattr(result, 'drive', None)
    if drive is None:
        from road_force_estimator.bagio import read_drive_bag
        drive = read_drive_bag(input_path)
    return drive.fixes


def process_drive(task: DriveTask) -> DriveOutcome:
    """Estimate one drive into ``DIR/drives/<id>`` (the Dask task; never raises for a bad
    drive: the outcome says ``failed`` with the reason)."""
    from road_force_estimator.tools import estimate_bag
    from road_force_estimator.report.fleet_map import segment_lines

    t0 = time.perf_counter()
    out = Path(task.output_dir)
    tmp_root = out / 'drives' / TMP_NAME
    final = out / 'drives' / task.drive_id
    settings = task.settings
    try:
        digest = task.input_sha256 or input_sha256(task.input_path)
        key = drive_key(digest, settings)
        tmp_root.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=_safe_name(task.drive_id) + '-', dir=tmp_root))
        try:
            result = estimate_bag.run(
                task.input_path, tmp, vehicle=task.vehicle, observer=task.observer,
                mode=settings['mode'], segment_length_m=settings['segment_length_m'],
                figures=settings['figures'], force=False, progress=False)
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
                            input_path=task.input_path)
    except Exception as err:  # noqa: BLE001 - one bad drive never stops the fleet
        from road_force_estimator.bagio import BagReadError, BagWriteError
        # estimate_bag's own reasons as they are; anything else with its type (a bug).
        plain = type(err) in (estimate_bag.InputError, BagReadError, BagWriteError, ValueError)
        plain = plain or isinstance(err, OSError)
        reason = _one_line(err) if plain else f'{type(err).__name__}: {_one_line(err)}'
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
                        input_path=str(drive.path))


# ----------------------------------------------------------------------------------------------
# the engine

def default_workers() -> int:
    """Worker processes of the local cluster: the CPUs this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def _probe(address: str) -> None:
    """Fail at once when a ``tcp://HOST:PORT`` (or ``HOST:PORT``) scheduler does not accept a
    connection (Dask itself would retry until its timeout); other protocols go to Dask."""
    import socket
    from urllib.parse import urlsplit

    text = address if '://' in address else 'tcp://' + address
    parts = urlsplit(text)
    if parts.scheme != 'tcp':
        return
    try:
        host, port = parts.hostname, parts.port
    except ValueError as err:
        raise FleetError(f'--scheduler {address!r}: {err}') from None
    if not host or port is None:
        raise FleetError(f'--scheduler {address!r}: expected tcp://HOST:PORT')
    try:
        with socket.create_connection((host, port), timeout=CONNECT_TIMEOUT_S):
            pass
    except OSError as err:
        reason = err.strerror or type(err).__name__
        if isinstance(err, socket.timeout):
            reason = f'no answer within {CONNECT_TIMEOUT_S:g} s'
        raise FleetError(f'cannot reach the Dask scheduler at {address}: {reason}') from None


@contextmanager
def _client(scheduler: str | None, workers: int) -> Iterator[tuple[Any, str]]:
    """A Dask client: on ``scheduler``, or on a local cluster of ``workers`` processes."""
    import logging

    from distributed import Client, LocalCluster

    if scheduler:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
        except (OSError, TimeoutError, ValueError) as err:
            raise FleetError(f'cannot reach the Dask scheduler at {scheduler} within '
                             f'{CONNECT_TIMEOUT_S:g} s ({_one_line(err)})') from None
        try:
            try:
                client.wait_for_workers(1, timeout=WORKER_WAIT_S)
            except (TimeoutError, OSError) as err:
                raise FleetError(f'the Dask scheduler at {scheduler} has no worker after '
                                 f'{WORKER_WAIT_S:g} s ({_one_line(err)})') from None
            n = len(client.scheduler_info().get('workers', {}))
            yield client, f'scheduler {scheduler} ({n} workers at start)'
        finally:
            client.close()
        return
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                           host='127.0.0.1', dashboard_address=None,
                           silence_logs=logging.ERROR)
    try:
        client = Client(cluster, set_as_default=False)
        try:
            yield client, f'local cluster of {workers} worker process' + \
                ('es' if workers > 1 else '')
        finally:
            client.close()
    finally:
        cluster.close()


def run_fleet(inputs: Sequence[str | Path], output: str | Path, *, vehicle=None, observer=None,
              mode: str = 'online', segment_length_m: float = 100.0, figures: bool = True,
              scheduler: str | None = None, workers: int | None = None, force: bool = False,
              progress: bool = False, params_file: str | None = None) -> FleetResult:
    """Process every drive under ``inputs`` into ``output`` (see the module notes).

    Parameters
    ----------
    inputs : sequence of paths
        Bag folders or folders of bag folders.
    output : path
        DIR.
    vehicle, observer : parameters (defaults when None), as ``estimate_bag`` loads them.
    mode : 'online' or 'offline'
    segment_length_m : float
        Report segment length (m), > 0.
    figures : bool
        Draw each drive's report figures (as ``estimate_bag``; False = ``--no-figures``).
    scheduler : str, optional
        Address of an existing Dask scheduler; None = a local cluster.
    workers : int, optional
        Local cluster size (default :func:`default_workers`, at most the drives to do).
    force : bool
        Recompute drives already done.
    progress : bool
        A progress bar over drives on stderr.
    params_file : str, optional
        Shown in summary.md.

    Raises
    ------
    FleetError
        A bad invocation (nothing processed).
    """
    from road_force_estimator.tools.estimate_bag import MODES
    from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters

    t0 = time.perf_counter()
    vehicle = VehicleParameters() if vehicle is None else vehicle
    observer = ObserverParameters() if observer is None else observer
    if mode not in MODES:
        raise FleetError(f'--mode {mode!r}: must be one of {", ".join(MODES)}')
    if not (isinstance(segment_length_m, (int, float)) and math.isfinite(segment_length_m)
            and segment_length_m > 0.0):
        raise FleetError(f'--segment-length {segment_length_m!r}: must be > 0 m')
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int)
                                or workers < 1):
        raise FleetError(f'--workers {workers!r}: must be an integer >= 1')
    if scheduler and workers is not None:
        raise FleetError('--workers sets the size of the local cluster; the cluster at '
                         '--scheduler has its own workers')
    out = Path(output).resolve()
    drives = find_drives(inputs, exclude=[out])
    if scheduler:
        _probe(scheduler)
    try:
        out.mkdir(parents=True, exist_ok=True)
        (out / 'drives').mkdir(exist_ok=True)
    except OSError as err:
        raise FleetError(f'cannot create {output}: {err.strerror or err}') from None
    shutil.rmtree(out / 'drives' / TMP_NAME, ignore_errors=True)   # left by a stopped run
    settings = {'mode': mode, 'segment_length_m': float(segment_length_m),
                'figures': bool(figures),
                'parameters': {**vehicle.to_parameters(), **observer.to_parameters()}}

    outcomes: dict[str, DriveOutcome] = {}
    tasks: list[DriveTask] = []
    for d in drives:
        digest = ''
        if not force and (out / 'drives' / d.drive_id / STAMP_NAME).is_file():
            try:
                digest = input_sha256(d.path)
            except OSError:
                digest = ''
            done = load_done(out, d, drive_key(digest, settings)) if digest else None
            if done is not None:
                outcomes[d.drive_id] = done
                continue
        tasks.append(DriveTask(d.drive_id, str(d.path), str(out), vehicle, observer, settings,
                               digest))

    timings = {'prepare': time.perf_counter() - t0, 'engine_start': 0.0, 'processing': 0.0}
    engine = 'none (every drive already done)'
    if tasks or scheduler:
        n_local = min(workers or default_workers(), max(len(tasks), 1))
        t1 = time.perf_counter()
        with _client(scheduler, n_local) as (client, engine):
            t2 = time.perf_counter()
            timings['engine_start'] = t2 - t1
            if tasks:
                _run_tasks(client, tasks, outcomes, total=len(drives), progress=progress)
            timings['processing'] = time.perf_counter() - t2
        shutil.rmtree(out / 'drives' / TMP_NAME, ignore_errors=True)
    ordered = [outcomes[d.drive_id] for d in drives]
    t3 = time.perf_counter()
    result = FleetResult(ordered, engine, t3 - t0, settings, timings)
    write_outputs(out, result, params_file=params_file)
    timings['write'] = time.perf_counter() - t3
    result.seconds = time.perf_counter() - t0
    return result


def _run_tasks(client, tasks: list[DriveTask], outcomes: dict[str, DriveOutcome], *,
               total: int, progress: bool) -> None:
    from distributed import as_completed
    from tqdm import tqdm

    run_id = uuid.uuid4().hex[:8]
    futures = {}
    for i, task in enumerate(tasks):
        fut = client.submit(process_drive, task, key=f'{PROG}-{run_id}-{i}', pure=False,
                            retries=RETRIES)
        futures[fut.key] = (fut, task)
    done_before = total - len(tasks)
    failed = 0
    with tqdm(total=total, initial=done_before, desc=PROG, unit='drive', file=sys.stderr,
              disable=not progress, dynamic_ncols=True) as bar:
        for fut in as_completed([f for f, _ in futures.values()], loop=client.loop):
            task = futures[fut.key][1]
            try:
                outcome = fut.result()
            except Exception as err:  # noqa: BLE001 - a task lost beyond its retries
                outcome = DriveOutcome(task.drive_id, 'failed',
                                       reason=f'{type(err).__name__}: {_one_line(err)}',
                                       input_path=task.input_path)
            outcomes[task.drive_id] = outcome
            failed += outcome.status == 'failed'
            bar.set_postfix(failed=failed, refresh=False)
            bar.update(1)
            fut.release()


# ----------------------------------------------------------------------------------------------
# the tables, the map, the summary

def _fleet_table(outcomes: Sequence[DriveOutcome]) -> dict[str, np.ndarray]:
    done = [o for o in outcomes if o.status != 'failed' and o.table is not None]
    table: dict[str, np.ndarray] = {'drive': np.array(
        [o.drive_id for o in done for _ in range(len(o.table['start_m']))], dtype=object)}
    for name in FLEET_COLUMNS[1:]:
        dtype = np.int64 if name in _INT_COLUMNS else float
        parts = [np.asarray(o.table[name], dtype=dtype) for o in done]
        table[name] = np.concatenate(parts) if parts else np.zeros(0, dtype=dtype)
    return table


def _cell(value) -> str:
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, str):
        return value
    v = float(value)
    return 'nan' if math.isnan(v) else repr(v)


def _atomic_write(path: Path, data: bytes | str) -> None:
    tmp = path.with_name(f'.{path.name}.{uuid.uuid4().hex[:8]}.tmp')
    if isinstance(data, str):
        tmp.write_text(data, encoding='utf-8')
    else:
        tmp.write_bytes(data)
    os.replace(tmp, path)


def _csv_text(header: Sequence[str], rows) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator='\n')
    w.writerow(header)
    for row in rows:
        w.writerow([_cell(v) for v in row])
    return buf.getvalue()


def _write_parquet(path: Path, table: dict[str, np.ndarray], settings: dict) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    fields = [pa.field('drive', pa.string())] + [
        pa.field(c, pa.int64() if c in _INT_COLUMNS else pa.float64())
        for c in FLEET_COLUMNS[1:]]
    meta = {b'road_force_estimator.settings': json.dumps(settings, sort_keys=True).encode()}
    schema = pa.schema(fields, metadata=meta)
    arrays = [pa.array(table['drive'].tolist(), type=pa.string())] + [
        pa.array(table[c], type=f.type) for c, f in zip(FLEET_COLUMNS[1:], fields[1:])]
    tmp = path.with_name(f'.{path.name}.{uuid.uuid4().hex[:8]}.tmp')
    pq.write_table(pa.Table.from_arrays(arrays, schema=schema), tmp)
    os.replace(tmp, path)


def _mean_iri(o: DriveOutcome, side: str) -> float:
    t = o.table
    v = np.asarray(t[f'iri_{side}_m_per_km'], dtype=float)
    w = np.asarray(t['end_m'], dtype=float) - np.asarray(t['start_m'], dtype=float)
    ok = np.isfinite(v) & (w > 0)
    return float(np.sum(v[ok] * w[ok]) / np.sum(w[ok])) if ok.any() else math.nan


def _f(value: float, fmt: str = '.2f') -> str:
    return 'n/a' if value is None or not math.isfinite(value) else format(value, fmt)


def _md(text: str) -> str:
    return str(text).replace('|', '\\|').replace('\n', ' ')


def _summary_md(result: FleetResult, table: dict[str, np.ndarray], map_written: bool,
                params_file: str | None) -> str:
    from road_force_estimator.report.fleet_map import IN_PER_MI_PER_M_PER_KM as K

    s = result.settings
    n = len(result.outcomes)
    seg = s['segment_length_m']
    lines = [
        '# Fleet summary (`estimate_fleet`)', '',
        f'- Drives: {n}; processed {result.count("processed")}, skipped (already done) '
        f'{result.count("skipped")}, failed {result.count("failed")}'
        + (' (see `failures.csv`)' if result.count('failed') else '') + '.',
        f'- Segments in the tables: {len(table["start_m"])} (`segments.csv`, '
        '`segments.parquet`, `segments.geojson`).',
        f'- Mode: {s["mode"]}; segment length {seg:g} m ({seg / 1609.344:.4g} mi); report '
        f'figures: {"yes" if s["figures"] else "no"}; parameters: '
        f'{params_file or "package defaults"}.',
        f'- Engine: {result.engine}; wall time {result.seconds:.1f} s (engine start '
        f'{result.timings.get("engine_start", 0.0):.1f} s, processing '
        f'{result.timings.get("processing", 0.0):.1f} s).',
        f'- IRI in m/km (= mm/m); in/mi = m/km x {K:g}.', '']
    if map_written:
        lines += ['## Map', '', 'Segments coloured by IRI (mean of left and right), on '
                  'longitude/latitude (WGS84):', '',
                  '[![segments coloured by IRI](segments_map.png)](segments_map.png)', '']
    else:
        lines += ['## Map', '', 'No segment has coordinates (no drive with `/fix`): no map.', '']
    lines += ['## Drives', '',
              '| drive | status | segments | distance (km) | IRI left m/km (in/mi) | '
              'IRI right m/km (in/mi) | peak load (kN) | max abs LTR | lift-offs | GNSS | '
              'time (s) |',
              '|---|---|---:|---:|---:|---:|---:|---:|---:|---|---:|']
    for o in result.outcomes:
        if o.status == 'failed' or o.table is None:
            lines.append(f'| {_md(o.drive_id)} | failed | | | | | | | | | '
                         f'{o.seconds:.1f} |')
            continue
        t = o.table
        k = len(t['start_m'])
        dist = (float(t['end_m'][-1] - t['start_m'][0]) / 1000.0) if k else 0.0
        il, ir = _mean_iri(o, 'left'), _mean_iri(o, 'right')
        peak = np.fmax(t['peak_load_left_n'], t['peak_load_right_n']) if k else np.zeros(0)
        peak_kn = float(np.nanmax(peak)) / 1000.0 if k and np.isfinite(peak).any() else math.nan
        ltr = float(np.nanmax(t['max_abs_ltr'])) if k and np.isfinite(t['max_abs_ltr']).any() \
            else math.nan
        gnss = 'yes' if k and np.isfinite(t['start_lat']).any() else 'no'
        lines.append(
            f'| {_md(o.drive_id)} | {o.status} | {k} | {dist:.3f} | {_f(il)} ({_f(il * K, ".0f")})'
            f' | {_f(ir)} ({_f(ir * K, ".0f")}) | {_f(peak_kn, ".1f")} | {_f(ltr, ".3f")} | '
            f'{int(np.sum(t["lift_offs"])) if k else 0} | {gnss} | {o.seconds:.1f} |')
    lines.append('')
    lines.append('IRI per drive: length-weighted mean of its segments. Time: the processing of '
                 'the drive (for a skipped drive, in the run that made it).')
    lines.append('')
    mean = 0.5 * (table['iri_left_m_per_km'] + table['iri_right_m_per_km'])
    order = [int(j) for j in np.argsort(-np.where(np.isfinite(mean), mean, -np.inf))
             if np.isfinite(mean[j])][:ROUGHEST]
    if order:
        lines += [f'## Roughest segments (top {len(order)} by mean IRI)', '',
                  '| drive | start (m) | end (m) | IRI left m/km (in/mi) | '
                  'IRI right m/km (in/mi) | start lat, lon | end lat, lon |',
                  '|---|---:|---:|---:|---:|---|---|']
        for j in order:
            def pos(a, b):
                la, lo = table[a][j], table[b][j]
                return f'{la:.6f}, {lo:.6f}' if np.isfinite(la) and np.isfinite(lo) else 'n/a'
            il, ir = table['iri_left_m_per_km'][j], table['iri_right_m_per_km'][j]
            lines.append(
                f'| {_md(table["drive"][j])} | {table["start_m"][j]:.1f} | '
                f'{table["end_m"][j]:.1f} | {_f(il)} ({_f(il * K, ".0f")}) | {_f(ir)} '
                f'({_f(ir * K, ".0f")}) | {pos("start_lat", "start_lon")} | '
                f'{pos("end_lat", "end_lon")} |')
        lines.append('')
    failed = [o for o in result.outcomes if o.status == 'failed']
    if failed:
        lines += ['## Failures', '', '| drive | reason |', '|---|---|']
        lines += [f'| {_md(o.drive_id)} | {_md(o.reason)} |' for o in failed]
        lines.append('')
    warned = [o for o in result.outcomes if o.warnings]
    if warned:
        lines += ['## Warnings (processed up to the break)', '']
        lines += [f'- {_md(o.drive_id)}: {_md(w)}' for o in warned for w in o.warnings]
        lines.append('')
    return '\n'.join(lines)


def write_outputs(output: str | Path, result: FleetResult, *,
                  params_file: str | None = None) -> dict[str, np.ndarray]:
    """Write the fleet tables, GeoJSON, map, failures and summary into ``output``; returns the
    fleet table (:data:`FLEET_COLUMNS`)."""
    from road_force_estimator.report.fleet_map import plot_segments_map, segments_geojson

    out = Path(output)
    table = _fleet_table(result.outcomes)
    rows = zip(*(table[c].tolist() for c in FLEET_COLUMNS))
    _atomic_write(out / 'segments.csv', _csv_text(FLEET_COLUMNS, rows))
    _write_parquet(out / 'segments.parquet', table, result.settings)
    lines = [line for o in result.outcomes if o.status != 'failed' and o.table is not None
             for line in (o.lines or [None] * len(o.table['start_m']))]
    doc = segments_geojson(table, lines, FLEET_COLUMNS)
    _atomic_write(out / 'segments.geojson',
                  json.dumps(doc, allow_nan=False, separators=(',', ':')) + '\n')
    failed = [(o.drive_id, o.reason) for o in result.outcomes if o.status == 'failed']
    _atomic_write(out / 'failures.csv', _csv_text(('drive', 'reason'), failed))
    png = out / 'segments_map.png'
    mean = 0.5 * (table['iri_left_m_per_km'] + table['iri_right_m_per_km'])
    tmp_png = out / f'.segments_map.{uuid.uuid4().hex[:8]}.png'
    if plot_segments_map(tmp_png, lines, mean,
                         title=f'IRI per {result.settings["segment_length_m"]:g} m segment, '
                               f'{len({d for d in table["drive"]})} drives'):
        os.replace(tmp_png, png)
        map_written = True
    else:
        map_written = False
        png.unlink(missing_ok=True)
    _atomic_write(out / 'summary.md', _summary_md(result, table, map_written, params_file))
    return table


# ----------------------------------------------------------------------------------------------
# command line

class _UsageError(Exception):
    """A bad command line (exit status 2)."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, no usage dump
        raise _UsageError(message)


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``estimate_fleet``."""
    from road_force_estimator.tools.estimate_bag import MODES

    p = _Parser(prog=PROG, description='Run estimate_bag over many drive bags on Dask '
                'distributed and gather their segments into one table (CSV, Parquet, '
                'GeoJSON), a map and a summary.')
    p.add_argument('inputs', nargs='+', metavar='INPUT',
                   help='drive bag folder, or a folder holding bag folders (searched '
                        'recursively for metadata.yaml)')
    p.add_argument('--params-file', required=True, metavar='FILE',
                   help='ROS 2 parameter file (/**: ros__parameters:), as for estimate_bag')
    p.add_argument('--output', '-o', required=True, metavar='DIR', help='output folder')
    p.add_argument('--mode', choices=MODES, default='online',
                   help='online: what the observer node publishes (default); offline: '
                        'non-causal, the whole recording')
    p.add_argument('--segment-length', type=float, default=100.0, metavar='M',
                   help='segment length, m (default 100; 160.9344 = 0.1 mile)')
    p.add_argument('--scheduler', metavar='ADDRESS',
                   help='an existing Dask scheduler, e.g. tcp://10.0.0.5:8786 (default: a '
                        'local cluster)')
    p.add_argument('--workers', type=int, metavar='N',
                   help='worker processes of the local cluster (default: the CPUs)')
    p.add_argument('--force', action='store_true', help='recompute drives already done')
    p.add_argument('--no-figures', action='store_true',
                   help='reports without figures (much faster for short drives)')
    p.add_argument('--no-progress', action='store_true', help='no progress bar')
    return p


def main(argv: list[str] | None = None) -> int:
    """Run ``estimate_fleet``; the exit status (0 all done, 1 some drives failed, 2 bad
    invocation)."""
    from road_force_estimator.tools.estimate_bag import load_parameters

    try:
        args = build_parser().parse_args(argv)
        try:
            vehicle, observer = load_parameters(args.params_file)
        except (ValueError, OSError) as err:
            raise FleetError(_one_line(err)) from None
        result = run_fleet(args.inputs, args.output, vehicle=vehicle, observer=observer,
                           mode=args.mode, segment_length_m=args.segment_length,
                           figures=not args.no_figures, scheduler=args.scheduler,
                           workers=args.workers, force=args.force,
                           progress=not args.no_progress, params_file=args.params_file)
    except SystemExit as done:          # --help
        return int(done.code or 0)
    except _UsageError as err:
        print(f'{PROG}: error: {err}', file=sys.stderr)
        return 2
    except FleetError as err:
        print(f'{PROG}: {err}', file=sys.stderr)
        return 2
    n = len(result.outcomes)
    print(f'{PROG}: {n} drive{"s" if n != 1 else ""}: {result.count("processed")} processed, '
          f'{result.count("skipped")} skipped, {result.count("failed")} failed '
          f'({result.seconds:.1f} s, {result.engine}); summary: '
          f'{Path(args.output) / "summary.md"}')
    for o in result.outcomes:
        if o.status == 'failed':
            print(f'{PROG}: failed: {o.drive_id}: {o.reason}', file=sys.stderr)
    return result.exit_code


if __name__ == '__main__':
    sys.exit(main())
