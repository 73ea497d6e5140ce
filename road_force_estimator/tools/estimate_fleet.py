"""`estimate_fleet`: many recorded drives on Dask distributed, one table and a map.

    estimate_fleet INPUT... [--params-file FILE] [-p NAME:=VALUE]... --output DIR
                   [--mode online|offline] [--units si|us] [--segment-length M]
                   [--scheduler ADDRESS] [--workers N] [--force] [--wait] [--no-figures]
                   [--no-progress]

Each INPUT is a drive bag folder or a folder holding bag folders (any folder with a
``metadata.yaml``, searched recursively; the search does not enter a bag folder, nor DIR).
A drive's id is its bag folder's path relative to the INPUT that holds it (its folder name
when given directly); ids must be unique. The search stays inside each INPUT: a link that
leads out of it (to ``/``, to ``..``) is not followed and a bag folder holding one is not
taken, and the temporary folders that unfinished writes leave (``.<name>.tmp-*``) are no
drives; each is named on stderr (``skipped: ...``).

Every drive is one Dask task (:func:`~.fleet_drives.process_drive`) that runs exactly what
``estimate_bag`` runs (:func:`tools.estimate_bag.run` with the same parameters, mode and
segment length), so ``DIR/drives/<id>/bag`` and ``DIR/drives/<id>/report`` are what
``estimate_bag INPUT --params-file FILE --output DIR/drives/<id> --mode ... --segment-length
...`` writes. By default the tasks run on a local cluster of ``--workers`` processes (one
thread each, bound to 127.0.0.1, no dashboard); with ``--scheduler tcp://HOST:PORT`` on an
existing cluster (``dask scheduler`` / ``dask worker``), which must see the same file system
paths (inputs and DIR). A scheduler that cannot be reached is an error (exit status 2), never
a silent local fallback (:mod:`.fleet_dask`).

Faults. A drive that cannot be processed (not a bag, corrupt, no usable sample: the reason
``estimate_bag`` gives) goes to ``failures.csv`` and the others go on. A task whose worker dies
is run again elsewhere (Dask's ``allowed-failures`` for lost workers, plus
:data:`~.fleet_dask.RETRIES`). Each drive is built in ``DIR/drives/.fleet-tmp/`` and renamed
into place only when complete, with ``fleet.json`` (a key: SHA-256 of the input bag's files,
the parameters, the mode, the segment length and the figures switch); a drive whose stored key
matches is skipped unless ``--force``, so a run that was stopped resumes where it stopped
(:mod:`.fleet_drives`). The input key leaves DIR out when DIR lies inside a bag folder.

One run at a time per DIR: a run holds ``DIR/.fleet-lock`` (``flock``); a second run into the
same DIR refuses (exit status 2), or with ``--wait`` waits for the first to end.

Outputs in DIR (:mod:`.fleet_outputs`): ``drives/<id>/`` (``bag/``, ``report/``,
``fleet.json``), ``segments.parquet`` and ``segments.csv`` (:data:`~.fleet_drives.FLEET_COLUMNS`,
one row per segment of every drive done, drives in id order; coordinates NaN without
``/fix``; with ``vehicle.model: articulated`` parameters the per-axle columns after them,
INTERFACES.md "The whole vehicle"), ``segments.geojson`` (one LineString per segment,
``[lon, lat]``, a ``null`` geometry for a segment without coordinates:
:mod:`road_force_estimator.report.fleet_map`),
``segments_map.png`` (segments coloured by IRI, when any has coordinates), ``failures.csv``
(``drive,reason``) and ``summary.md``.

Exit status: 0 when every drive succeeded (processed or skipped), 1 when some failed (the rest
are written), 2 for a bad invocation (bad option, missing input, no drive found, bad parameter
file, unreachable scheduler); each error with one line on stderr.
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path
import shutil
import sys
import time
from typing import Sequence

from road_force_estimator.tools import cli
from road_force_estimator.tools.fleet_dask import (
    CONNECT_TIMEOUT_S, RETRIES, WORKER_WAIT_S, dask_client, default_workers, probe_scheduler,
    run_tasks)
from road_force_estimator.tools.fleet_drives import (
    FLEET_COLUMNS, KEY_FORMAT, LOCK_NAME, STAMP_NAME, TMP_NAME, DriveInput, DriveOutcome,
    DriveTask, FleetError, drive_key, find_drives, input_sha256, load_done, output_lock,
    process_drive, read_segments_csv)
from road_force_estimator.tools.fleet_outputs import FleetResult, write_outputs

__all__ = [
    'PROG', 'FLEET_COLUMNS', 'STAMP_NAME', 'TMP_NAME', 'LOCK_NAME', 'KEY_FORMAT', 'RETRIES',
    'CONNECT_TIMEOUT_S', 'WORKER_WAIT_S', 'FleetError', 'DriveInput', 'DriveTask',
    'DriveOutcome', 'FleetResult', 'find_drives', 'input_sha256', 'drive_key',
    'read_segments_csv', 'process_drive', 'load_done', 'default_workers', 'dask_client',
    'run_fleet', 'write_outputs', 'build_parser', 'main',
]

PROG = 'estimate_fleet'


def run_fleet(inputs: Sequence[str | Path], output: str | Path, *, vehicle=None, observer=None,
              mode: str = 'online', segment_length_m: float = 100.0, figures: bool = True,
              scheduler: str | None = None, workers: int | None = None, force: bool = False,
              progress: bool = False, params_file: str | None = None, units: str = 'si',
              run_info: dict | None = None, wait: bool = False) -> FleetResult:
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
    units : 'si' or 'us'
        Units of summary.md and of the drives' reports.
    run_info : dict, optional
        The parameter file, overrides and command line, shown in the drives' reports.
    wait : bool
        When another run writes ``output`` (it holds DIR/:data:`LOCK_NAME`), wait for it to
        end instead of refusing (``--wait``).

    Raises
    ------
    FleetError
        A bad invocation (nothing processed).
    """
    from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters

    t0 = time.perf_counter()
    vehicle = VehicleParameters() if vehicle is None else vehicle
    observer = ObserverParameters() if observer is None else observer
    _check_options(mode, segment_length_m, scheduler, workers)
    out = Path(output).resolve()
    skipped: list[str] = []
    drives = find_drives(inputs, exclude=[out], skipped=skipped)
    for line in skipped:                  # links out of an INPUT, unfinished writes
        print(f'{PROG}: skipped: {cli.one_line(line)}', file=sys.stderr)
    if scheduler:
        probe_scheduler(scheduler)
    try:
        out.mkdir(parents=True, exist_ok=True)
        (out / 'drives').mkdir(exist_ok=True)
    except OSError as err:
        raise FleetError(f'cannot create {output}: {err.strerror or err}') from None

    def waiting() -> None:
        print(f'{PROG}: waiting for the other run writing {output} to end', file=sys.stderr)

    with output_lock(out, wait=wait, on_wait=waiting):
        shutil.rmtree(out / 'drives' / TMP_NAME, ignore_errors=True)   # left by a stopped run
        settings = {'mode': mode, 'segment_length_m': float(segment_length_m),
                    'figures': bool(figures), 'units': units, 'run_info': run_info or {},
                    'parameters': {**vehicle.to_parameters(), **observer.to_parameters()}}
        outcomes, tasks = _resume(out, drives, vehicle, observer, settings, force)
        timings = {'prepare': time.perf_counter() - t0, 'engine_start': 0.0, 'processing': 0.0}
        engine = 'none (every drive already done)'
        if tasks or scheduler:
            engine = _process(out, tasks, outcomes, timings, total=len(drives),
                              scheduler=scheduler, workers=workers, progress=progress)
        ordered = [outcomes[d.drive_id] for d in drives]
        t3 = time.perf_counter()
        result = FleetResult(ordered, engine, t3 - t0, settings, timings)
        write_outputs(out, result, params_file=params_file)
    timings['write'] = time.perf_counter() - t3
    result.seconds = time.perf_counter() - t0
    return result


def _check_options(mode: str, segment_length_m: float, scheduler: str | None,
                   workers: int | None) -> None:
    """Raise :class:`FleetError` for a bad mode, segment length or worker count."""
    if mode not in cli.MODES:
        raise FleetError(f'--mode {mode!r}: must be one of {", ".join(cli.MODES)}')
    if not (isinstance(segment_length_m, (int, float)) and math.isfinite(segment_length_m)
            and segment_length_m > 0.0):
        raise FleetError(f'--segment-length {segment_length_m!r}: must be > 0 m')
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int)
                                or workers < 1):
        raise FleetError(f'--workers {workers!r}: must be an integer >= 1')
    if scheduler and workers is not None:
        raise FleetError('--workers sets the size of the local cluster; the cluster at '
                         '--scheduler has its own workers')


def _resume(out: Path, drives: Sequence[DriveInput], vehicle, observer, settings: dict,
            force: bool) -> tuple[dict[str, DriveOutcome], list[DriveTask]]:
    """The drives already done with these settings (unless ``force``) and the tasks of the
    others."""
    outcomes: dict[str, DriveOutcome] = {}
    tasks: list[DriveTask] = []
    for d in drives:
        digest = ''
        if not force and (out / 'drives' / d.drive_id / STAMP_NAME).is_file():
            try:
                digest = input_sha256(d.path, exclude=[out])
            except OSError:
                digest = ''
            done = load_done(out, d, drive_key(digest, settings)) if digest else None
            if done is not None:
                outcomes[d.drive_id] = done
                continue
        tasks.append(DriveTask(d.drive_id, str(d.path), str(out), vehicle, observer, settings,
                               digest))
    return outcomes, tasks


def _process(out: Path, tasks: list[DriveTask], outcomes: dict[str, DriveOutcome],
             timings: dict[str, float], *, total: int, scheduler: str | None,
             workers: int | None, progress: bool) -> str:
    """Run ``tasks`` on the engine (outcomes into ``outcomes``, times into ``timings``); the
    engine's description."""
    n_local = min(workers or default_workers(), max(len(tasks), 1))
    t1 = time.perf_counter()
    try:
        with dask_client(scheduler, n_local) as (client, engine):
            t2 = time.perf_counter()
            timings['engine_start'] = t2 - t1
            if tasks:
                run_tasks(client, tasks, outcomes, total=total, progress=progress, name=PROG)
            timings['processing'] = time.perf_counter() - t2
    finally:       # also on SIGINT / SIGTERM: the drives being built go with the workers
        shutil.rmtree(out / 'drives' / TMP_NAME, ignore_errors=True)
    return engine


# ----------------------------------------------------------------------------------------------
# command line

def build_parser() -> argparse.ArgumentParser:
    """The command line of ``estimate_fleet``."""
    p = cli.Parser(prog=PROG, description='Run estimate_bag over many drive bags on Dask '
                   'distributed and gather their segments into one table (CSV, Parquet, '
                   'GeoJSON), a map and a summary.')
    p.add_argument('inputs', nargs='+', metavar='INPUT',
                   help='drive bag folder, or a folder holding bag folders (searched '
                        'recursively for metadata.yaml)')
    cli.add_params_file(p, 'ROS 2 parameter file (/**: ros__parameters:), as for estimate_bag; '
                           'default: the package defaults')
    cli.add_overrides(p)
    cli.add_output(p, 'output folder')
    cli.add_mode(p)
    cli.add_units(p)
    cli.add_segment_length(p, 'segment length, m (default 100 m; 0.1 mi = 160.9344 m with '
                              '--units us)', default=None)
    p.add_argument('--scheduler', metavar='ADDRESS',
                   help='an existing Dask scheduler, e.g. tcp://10.0.0.5:8786 (default: a '
                        'local cluster)')
    p.add_argument('--workers', type=int, metavar='N',
                   help='worker processes of the local cluster (default: the CPUs)')
    cli.add_force(p, 'recompute drives already done')
    p.add_argument('--wait', action='store_true',
                   help='when another run is writing DIR, wait for it to end (default: refuse)')
    p.add_argument('--no-figures', action='store_true',
                   help='reports without figures (much faster for short drives)')
    cli.add_no_progress(p)
    return p


def main(argv: list[str] | None = None) -> int:
    """Run ``estimate_fleet``; the exit status (0 all done, 1 some drives failed, 2 bad
    invocation)."""
    return cli.run_main(PROG, build_parser(), lambda args: _main(args, argv), argv,
                        {(FleetError,): 2})


def _main(args: argparse.Namespace, argv: list[str] | None) -> int:
    """The command's work: the parameters, :func:`run_fleet`, the one-line result."""
    from road_force_estimator.tools.estimate_bag import load_parameters

    segment_length_m = cli.segment_length(args)
    try:
        vehicle, observer = load_parameters(args.params_file, args.overrides)
    except (ValueError, OSError) as err:
        raise FleetError(cli.one_line(err)) from None
    run_info = {'params_file': args.params_file, 'overrides': list(args.overrides),
                'command': cli.command_line(PROG, argv)}
    result = run_fleet(args.inputs, args.output, vehicle=vehicle, observer=observer,
                       mode=args.mode, segment_length_m=segment_length_m, units=args.units,
                       run_info=run_info,
                       figures=not args.no_figures, scheduler=args.scheduler,
                       workers=args.workers, force=args.force,
                       progress=not args.no_progress, params_file=args.params_file,
                       wait=args.wait)
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
