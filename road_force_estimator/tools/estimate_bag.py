"""`estimate_bag`: the estimator over a recorded drive bag, without DDS.

    estimate_bag INPUT [--params-file FILE] [-p NAME:=VALUE]... --output DIR
                 [--mode online|offline] [--units si|us] [--segment-length M]
                 [--reference-profile SOURCE [--reference-offset M]]
                 [--export-profile FILE.erd|FILE.csv|FILE.txt]
                 [--no-figures] [--force] [--no-progress]

Reads the measurement bag INPUT (``/suspension/deflections``, ``/vehicle/twist``, and when
present the ground truth and ``/fix``) with :func:`bagio.read_drive_bag`,
which rejects and counts what cannot be trusted (NaN, missing joint names, duplicate or
backward stamps, undecodable messages) and reads a truncated or corrupt bag up to its break.
Then it estimates:

``online`` (default)
    Exactly what the ``observer`` node publishes: every accepted sample goes through
    :meth:`estimation.estimator.Estimator.update`, in order, with the latest speed;
    samples recorded before the first ``/vehicle/twist`` take the first speed (the node holds
    them until a speed arrives). The numbers equal :func:`~.estimator.estimate_batch`'s.
``offline``
    :func:`estimation.offline.estimate_recording`: non-causal, the whole recording.

A drive of 2^21 samples or more without ground truth (fewer in a Dask worker with a memory
limit) is estimated block by block in either mode (:mod:`.estimate_stream`: a 4-hour drive at
1 kHz under 2 GB).

It writes ``DIR/bag`` (the observer's topics, :func:`~.bagio.write_estimate_bag`, with a
``/diagnostics`` message per second of the drive) and the report ``DIR/report/``
(:mod:`road_force_estimator.report`). Both are built in a temporary folder in DIR and renamed
into place when complete, with ``DIR/.written-by-road-force-estimator.json`` listing the files
written (:mod:`.output_folder`): a failure (out of space) leaves nothing behind, and
``--force`` replaces only what estimate_bag wrote there, never INPUT nor other files.
``--export-profile FILE`` also writes the estimated profile, read back from ``DIR/bag``, as
ProVAL and pavement-management systems read it (:mod:`.profile_export`).

Exit status: 0 on success (skipped messages are counted in the report, never fatal), 1 for
bad input (not a bag, no usable sample, no speed, no sample the estimator accepts: every speed
out of range, say), an output that may not be replaced or cannot be written, or bad
parameters, 2 for a bad command line; each with one line on stderr.
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass, field
import math
from pathlib import Path
import sys
from types import SimpleNamespace
from typing import Any

import numpy as np

from road_force_estimator.tools import cli, output_folder
from road_force_estimator.tools.cli import MODES

__all__ = ['PROG', 'MODES', 'EstimateResult', 'build_parser', 'load_parameters', 'drive_speed',
           'estimate_online', 'run', 'main']

PROG = 'estimate_bag'


class InputError(Exception):
    """Bad input (exit status 1)."""


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``estimate_bag``."""
    p = cli.Parser(prog=PROG, description='Run the estimator over a recorded drive bag and write '
                'the bag of estimates (DIR/bag) and a report (DIR/report).')
    p.add_argument('input', metavar='INPUT', help='drive bag folder (rosbag2 MCAP)')
    cli.add_params_file(p, 'ROS 2 parameter file (/**: ros__parameters:) with vehicle.* and '
                           'observer.*; default: the package defaults')
    cli.add_overrides(p)
    cli.add_output(p, 'output folder')
    cli.add_mode(p)
    cli.add_units(p)
    cli.add_segment_length(p, 'report segment length, m (default 100 m; 0.1 mi = 160.9344 m '
                              'with --units us)', default=None)
    p.add_argument('--reference-profile', metavar='SOURCE',
                   help='profile to compare the estimate with when the bag has no ground '
                        'truth: LPA bag, CSV or ERD')
    p.add_argument('--reference-offset', type=cli.finite_float, metavar='M',
                   help='distance along the reference profile where the drive starts, m from '
                        'its start (default: found by correlation within +-10 m)')
    p.add_argument('--no-figures', action='store_true', help='report without figures')
    p.add_argument('--export-profile', metavar='FILE',
                   help='also write the estimated profile (both wheel paths, metres, evenly '
                        'spaced) to FILE: .erd (UMTRI ERD, as ProVAL reads it), .csv '
                        '(distance_m,left_m,right_m) or .txt (columns distance left right)')
    cli.add_force(p, 'replace DIR/bag and DIR/report (and the --export-profile file) written '
                     'by an earlier estimate_bag')
    cli.add_no_progress(p)
    return p


def load_parameters(path: str | None, overrides=()):
    """``(VehicleParameters, ObserverParameters)`` from a parameter file (defaults if None)
    and ``-p NAME:=VALUE`` overrides."""
    return cli.load_estimator_parameters(path, ('observer', PROG), overrides)


def drive_speed(drive) -> tuple[np.ndarray, int]:
    """Speed per sample (m/s) and how many samples took the first twist's speed.

    Samples before the first accepted ``/vehicle/twist`` get its speed (the observer node
    holds them until a speed arrives and estimates them with it).

    Raises
    ------
    InputError
        No usable twist at all.
    """
    speed = np.array(drive.speed_mps, dtype=float)
    if len(drive.twist_speed_mps) == 0:
        raise InputError('no usable /vehicle/twist message: the speed is unknown')
    early = ~np.isfinite(speed)
    speed[early] = float(drive.twist_speed_mps[0])
    return speed, int(np.count_nonzero(early))


class _Stages:
    """A one-line progress display of the stages of :func:`run` (stderr, TTY only)."""

    NAMES = ('read', 'estimate', 'write bag', 'report')

    def __init__(self, enabled: bool) -> None:
        self.bar = cli.progress_bar(enabled, total=len(self.NAMES), desc=PROG, leave=False,
                                    bar_format='{desc} ({n}/{total} stages done)')
        self.started = False

    def next(self, name: str) -> None:
        if self.started:
            self.bar.update(1)
        self.started = True
        self.bar.set_description_str(f'{PROG}: {name}')

    def close(self) -> None:
        self.bar.close()


def estimate_online(stamps_ns, q_m, roll_rad, speed_mps, vehicle, observer, *,
                    progress: bool = False):
    """The observer node's numbers: :func:`~.estimator.estimate_batch`, which runs
    :meth:`Estimator.update`'s steps per sample, in order, then ``flush`` (bit-identical to
    them: test_estimator); row k holds the estimate of sample k (with a latency it came with a
    later input or from ``flush``), rejected rows hold the previous one with ``valid`` False.

    Returns
    -------
    EstimateArrays
    """
    from road_force_estimator.estimation import estimate_batch

    with cli.sample_progress(len(stamps_ns), progress, f'{PROG}: online') as bar:
        return estimate_batch(stamps_ns, q_m, roll_rad, speed_mps, vehicle, observer,
                              progress=bar.update)


def _diagnostics(est, summary_counts: dict[str, int], mode: str, model_fit=None):
    """One estimator status per second of the drive (data time), the last with the totals;
    ``model_fit``: the drive's (ratio, verdict) or None."""
    from road_force_estimator.estimation.diagnostics import batch_diagnostics

    per_second = batch_diagnostics(est.stamp_ns, est.valid, est.converged, est.lift_off, est.ltr,
                                   est.residual_nm, summary_counts,
                                   f'{PROG}: estimator ({mode})', PROG,
                                   speed_contradicted=getattr(est, 'speed_contradicted', None),
                                   model_fit=model_fit)
    return [(stamp, [st.as_dict() for st in statuses]) for stamp, statuses in per_second]


@dataclass
class EstimateResult:
    """What :func:`run` did: the summary of the report, the paths, the estimates, the bag's
    messages that were written (``written``), warnings (breaks in the bag) and the drive read
    (:class:`~.bagio.Drive`)."""

    summary: dict[str, Any]
    bag: Path
    report: Path
    estimates: Any = None
    written: dict[str, int] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    drive: Any = None
    #: what the reader took (an articulated drive: its front axle), one line each
    notes: list[str] = field(default_factory=list)


def run(input_path: str | Path, output: str | Path, *, vehicle=None, observer=None,
        mode: str = 'online', segment_length_m: float = 100.0, reference=None,
        reference_offset_m: float | None = None, figures: bool = True, force: bool = False,
        progress: bool = False, standalone: bool = True, units: str = 'si',
        run_info: dict[str, Any] | None = None) -> EstimateResult:
    """Estimate one drive bag and write ``output/bag`` and ``output/report``.

    ``units`` ('si' or 'us') are those of the report's text; ``run_info`` (the parameter file,
    the overrides, the command line) is shown in it.

    Both are built in a temporary folder in ``output`` and renamed into place with the marker
    :data:`~.output_folder.MARKER_NAME` when complete (:mod:`.output_folder`); ``force``
    replaces only what estimate_bag wrote there, never the input. ``standalone`` False:
    ``output`` is a fresh folder that the caller builds and renames itself (estimate_fleet),
    written directly and without the marker.

    Raises
    ------
    InputError
        Not a drive bag, no usable sample or speed, output exists without ``force``.
    OutputError
        An output that may not be replaced, or a write that failed (out of space: nothing is
        left behind).
    """
    from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters

    vehicle = VehicleParameters() if vehicle is None else vehicle
    observer = ObserverParameters() if observer is None else observer
    if mode not in MODES:
        raise InputError(f'mode {mode!r}: must be one of {", ".join(MODES)}')
    if not (segment_length_m > 0.0 and math.isfinite(segment_length_m)):
        raise InputError(f'segment length {segment_length_m!r} m: must be > 0')
    input_path = Path(input_path)
    output = Path(output)
    target = output_folder.FolderOutput(output, ('bag', 'report'), PROG,
                                        force=force and standalone, inputs=[input_path])
    target.check()
    stages = _Stages(progress)
    options = dict(mode=mode, reference=reference, reference_offset_m=reference_offset_m,
                   segment_length_m=segment_length_m, figures=figures, units=units,
                   run_info=run_info)
    try:
        write = _writer(input_path, output, vehicle, observer, options, progress, stages)
        if not standalone:
            return _whole_vehicle(write(output), input_path, output)
        with target.staged() as stage:
            return _whole_vehicle(write(stage), input_path, stage)
    finally:
        stages.close()


def _whole_vehicle(result: EstimateResult, input_path: Path, folder: Path) -> EstimateResult:
    """An articulated drive: the note of what was estimated, and the truth of every axle
    in the report (:mod:`~.report.whole_vehicle`)."""
    from road_force_estimator import bagio
    from road_force_estimator.bagio.articulated_drive import read_articulated_truth
    from road_force_estimator.bagio.vehicle_layout import front_axle_joints, is_articulated

    custom = bagio.bag_custom_data(input_path)
    if result.drive is not None and getattr(result.drive, 'notes', ()):
        result.notes += list(result.drive.notes)
    elif is_articulated(custom):
        result.notes.append(front_axle_joints(custom, None)[1])
    truth = read_articulated_truth(input_path) if is_articulated(custom) or result.notes \
        else None
    if truth is not None and len(truth.stamps_ns):
        from road_force_estimator.report.whole_vehicle import append_to_report
        append_to_report(folder / 'report', truth, result.summary)
    return result


def _writer(input_path: Path, output: Path, vehicle, observer, options: dict, progress: bool,
            stages):
    """``write(folder) -> EstimateResult``: a long drive block by block
    (:mod:`.estimate_stream`), else estimated in one piece now and written by :func:`_write`."""
    from road_force_estimator.tools import estimate_stream

    if estimate_stream.use_stream(input_path, options['mode'], options['reference'], observer):
        api = SimpleNamespace(prog=PROG, error=InputError, result=EstimateResult)
        return lambda folder: estimate_stream.run_stream(
            folder, output, input_path, vehicle, observer, options, stages, api, progress)
    drive, est, extra = _estimate(input_path, vehicle, observer, options['mode'], progress,
                                  stages, options['segment_length_m'])
    return lambda folder: _write(folder, output, input_path, drive, est, extra, vehicle,
                                 observer, options, stages)


def check_spacing(segment_length_m: float, stamps_ns, speed_mps) -> None:
    """Raise :class:`InputError` when the segments are shorter than the drive's sample
    spacing (:func:`.core.segments.check_segment_length`): refused before the work."""
    from road_force_estimator.core.segments import check_segment_length, sample_spacing
    from road_force_estimator.estimation.acceptance import MAX_SPEED_MPS

    try:
        check_segment_length(segment_length_m,
                             sample_spacing(stamps_ns, speed_mps, MAX_SPEED_MPS))
    except ValueError as err:
        raise InputError(str(err)) from None


def _estimate(input_path: Path, vehicle, observer, mode: str, progress: bool, stages,
              segment_length_m: float = 100.0):
    """Read the bag and estimate: ``(drive, estimates, notes for the report)``.

    Raises
    ------
    InputError
        Not a drive bag, no usable sample or speed, no sample estimated.
    """
    from road_force_estimator import bagio
    from road_force_estimator.estimation import estimate_recording

    stages.next('reading the bag')
    try:
        drive = bagio.read_drive_bag(input_path)
    except bagio.BagReadError as err:
        raise InputError(str(err)) from None
    if len(drive.stamps_ns) == 0:
        raise InputError(f'{input_path}: no usable /suspension/deflections message'
                         + (f' ({drive.issues[0]})' if drive.issues else ''))
    speed, early = drive_speed(drive)
    check_spacing(segment_length_m, drive.stamps_ns, speed)
    args = (drive.stamps_ns, drive.q_m, drive.roll_rad, speed, vehicle, observer)
    stages.next(f'estimating ({mode})')
    if mode == 'online':
        est = estimate_online(*args, progress=progress)
    else:
        est = estimate_recording(*args, fixes=drive.fixes)
    if est.status.accepted == 0:
        raise InputError(f'{input_path}: no sample could be estimated: '
                         f'{_why_none_estimated(drive, speed, est.status)}')
    extra = {}
    if mode == 'online':          # the distance is the speed's online: the report says why
        from road_force_estimator.estimation.odometer import distance_speed
        est.distance_source = distance_speed(observer.distance_source, drive.stamps_ns,
                                             speed, drive.fixes, offline=False)[1]
    if early:
        extra['samples before the first twist (given its speed)'] = early
    return drive, est, extra


def _why_none_estimated(drive, speed: np.ndarray, status) -> str:
    """Why every one of the drive's samples was rejected (one phrase)."""
    from road_force_estimator.estimation.acceptance import (
        MAX_DEFLECTION_M, MAX_ROLL_RAD, MAX_SPEED_MPS)

    n = len(speed)
    finite = np.isfinite(speed)
    if not np.any(finite & (np.abs(speed) <= MAX_SPEED_MPS)):
        worst = speed[finite][np.argmax(np.abs(speed[finite]))] if finite.any() else math.nan
        return (f'every speed out of range ({worst:g} m/s; the limit is |v| <= '
                f'{MAX_SPEED_MPS:g} m/s)')
    if np.all(speed < 0.0):
        return f'every speed negative (e.g. {speed[0]:g} m/s)'
    q = np.asarray(drive.q_m, dtype=float)
    roll = np.asarray(drive.roll_rad, dtype=float)
    if not np.any(np.all(np.abs(q) <= MAX_DEFLECTION_M, axis=1)):
        return f'every deflection out of range (|q| <= {MAX_DEFLECTION_M:g} m)'
    if not np.any(np.abs(roll) <= MAX_ROLL_RAD):
        return f'every roll angle out of range (|phi| <= {MAX_ROLL_RAD:g} rad)'
    return (f'all {n} samples rejected ({status.rejected_range} out of range, '
            f'{status.rejected_nonfinite} non-finite, {status.rejected_time} with a bad stamp)')


def _write(folder: Path, output: Path, input_path: Path, drive, est, extra: dict, vehicle,
           observer, options: dict, stages) -> EstimateResult:
    """Write ``folder/bag`` and ``folder/report``; the result names them in ``output``."""
    from road_force_estimator import bagio
    from road_force_estimator.estimation.fit_check import ADVICE, MISMATCH
    from road_force_estimator.report import raw_road, write_report

    mode = options['mode']
    bag_dir, report_dir = folder / 'bag', folder / 'report'
    for p in (bag_dir, report_dir):
        if p.exists():
            raise InputError(f'{p} exists (use --force to replace it)')
    st = est.status
    counts = {'samples': int(len(drive.stamps_ns)), 'estimated': int(st.accepted),
              'rejected_by_reader': int(drive.rejected_total),
              'rejected_by_estimator': int(st.rejected), 'resets': int(st.resets)}
    fit = getattr(est, 'odometer', None)          # a GNSS fit was made (offline)
    if fit is not None and not fit.problem:
        counts.update(odometer_scale=fit.scale, odometer_scale_std=fit.scale_sigma,
                      odometer_fixes_rejected=fit.rejected)
    folder.mkdir(parents=True, exist_ok=True)
    custom = {'road_force_estimator.mode': mode,
              'road_force_estimator.input': input_path.name,
              'road_force_estimator.writer_command': PROG}
    fit = _model_fit(est, drive, vehicle, observer)
    if fit is not None:
        extra['model fit'] = (f'{fit[1]} (residual band RMS {fit[0]:.3g} x sigma_M)'
                              + (f': {ADVICE}' if fit[1] == MISMATCH else ''))
    stages.next('writing the bag')
    written = bagio.write_estimate_bag(
        bag_dir, est, track_width_m=vehicle.track_width_m,
        diagnostics=_diagnostics(est, counts, mode, fit), custom_data=custom)
    if written.get('nonfinite'):
        extra['estimates not written (non-finite)'] = written['nonfinite']
    stages.next('writing the report' + (' and figures' if options['figures'] else ''))
    summary = write_report(report_dir, est, drive, vehicle, observer,
                           input_name=input_path.name, extra=extra,
                           raw_road=raw_road(drive, reader=bagio.road_from_source), **options)
    warnings = [f'{input_path}: {issue}' for issue in drive.issues]
    return EstimateResult(summary, output / 'bag', output / 'report', est, written, warnings,
                          drive)


def _model_fit(est, drive, vehicle, observer):
    """The drive's model-fit verdict (:func:`.model_fit.assess`), or None when the method
    is not the model's or there are too few samples."""
    from road_force_estimator.estimation.fit_check import assess

    if getattr(est.status, 'method', '') != 'model':
        return None
    ratio, word = assess(est, vehicle, observer, drive.speed_mps)
    return None if not math.isfinite(ratio) else (ratio, word)


def _headline(result: EstimateResult, units: str = 'si') -> list[str]:
    from road_force_estimator.core.units import units as unit_system

    u = unit_system(units)
    s = result.summary
    lines = [f'report: {result.report / "report.md"}', f'bag: {result.bag}',
             f'samples estimated: {s["samples"]["estimated"]} ({s["mode"]}), rejected: '
             f'{s["rejected_total"]}, restarts: {s["resets"]}']
    acc = s.get('accuracy') or {}
    if 'load_rms_pct_dynamic_both' in acc:
        lines.append(f'wheel-load error: {acc["load_rms_pct_dynamic_both"]:.2f} % of the true '
                     f'dynamic-load RMS ({np.mean(acc["load_rms_pct_static"]):.2f} % of the '
                     'static load)')
    if 'profile_rms_pct_band_both' in acc:
        lines.append(f'profile error (0.5-30 m band): {acc["profile_rms_pct_band_both"]:.2f} %')
    iri = s['iri_m_per_km']
    if iri['estimated']:
        est = '/'.join(u.iri_text(v) for v in iri['estimated'])
        text = f'IRI of the whole drive, left/right: {est} {u.iri_unit}'
        if iri['true']:
            what = 'reference' if s.get('reference_profile') else 'true'
            text += f' ({what} {"/".join(u.iri_text(v) for v in iri["true"])})'
        lines.append(text)
    return lines


def main(argv: list[str] | None = None) -> int:
    """Run ``estimate_bag``; the exit status (0 ok, 1 bad input, 2 bad command line)."""
    from road_force_estimator.bagio import BagReadError, BagWriteError

    return cli.run_main(PROG, build_parser(), lambda args: _main(args, argv), argv,
                        {(InputError, ValueError, BagReadError, BagWriteError, OSError): 1})


def _main(args: argparse.Namespace, argv: list[str] | None) -> int:
    """The command's work: options, parameters, reference, :func:`run`, the headline."""
    segment_length_m = cli.segment_length(args)
    vehicle, observer = load_parameters(args.params_file, args.overrides)
    reference = None
    if args.reference_offset is not None and not args.reference_profile:
        raise cli.UsageError('--reference-offset needs --reference-profile')
    if args.reference_profile:
        from road_force_estimator.bagio import road_from_source
        reference = road_from_source(args.reference_profile)
        for note in getattr(reference, 'notes', ()):      # e.g. an ERD file's feet converted
            print(f'{PROG}: note: {args.reference_profile}: {note}', file=sys.stderr)
    export = None
    if args.export_profile:       # checked before the drive is estimated
        from road_force_estimator.tools import profile_export
        export = profile_export.target(args.export_profile, force=args.force,
                                       inputs=[Path(args.input)])
    result = run(args.input, args.output, vehicle=vehicle, observer=observer,
                 mode=args.mode, segment_length_m=segment_length_m, reference=reference,
                 reference_offset_m=args.reference_offset, figures=not args.no_figures,
                 force=args.force, progress=not args.no_progress, units=args.units,
                 run_info={'params_file': args.params_file, 'overrides': list(args.overrides),
                           'command': cli.command_line(PROG, argv)})
    for line in result.warnings:
        print(f'{PROG}: warning: {line}; processed up to the break', file=sys.stderr)
    for line in result.notes:
        print(f'{PROG}: note: {line}', file=sys.stderr)
    for line in _headline(result, args.units):
        print(f'{PROG}: {line}')
    if export is not None:
        print(f'{PROG}: ' + profile_export.export_profile(
            result.bag, export, cutoff_wavelength_m=observer.profile_cutoff_wavelength_m))
    return 0


if __name__ == '__main__':
    sys.exit(main())
