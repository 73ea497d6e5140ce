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

The drive goes through :func:`road_force_estimator.pipeline.run.run_drive`: one block, or
block by block from 2^21 samples or from a memory limit
(:mod:`road_force_estimator.pipeline.plan`; a 4-hour drive at 1 kHz under 2 GB).

It writes ``DIR/bag`` (the observer's topics, :func:`~.bagio.write_estimate_bag`, with a
``/diagnostics`` message per second of the drive) and the report ``DIR/report/``
(:mod:`road_force_estimator.report`). Both are built in a temporary folder in DIR and renamed
into place when complete, with ``DIR/.written-by-road-force-estimator.json`` listing the files
written (:mod:`.output_folder`): a failure (out of space) leaves nothing behind, and
``--force`` replaces only what estimate_bag wrote there, never INPUT nor other files.
With ``vehicle.model: articulated`` parameters (``config/tractor_semitrailer.yaml``) the whole
vehicle is estimated beside the front axle (:mod:`road_force_estimator.pipeline.whole_vehicle`,
one block): ``/wheel_loads``, ``/wheel_loads/static``, ``/load_transfer/tractor|trailer|
combination`` in the bag, the front axle's loads and load transfer from its wheels, the axle
loads and gross vehicle weight in ``/diagnostics``, the per-axle columns in ``segments.csv`` and
the section in the report (INTERFACES.md "The whole vehicle").

``--export-profile FILE`` also writes the estimated profile, read back from ``DIR/bag``, as
ProVAL and pavement-management systems read it (:mod:`.profile_export`).

Exit status: 0 on success (skipped messages are counted in the report, never fatal), 1 for
bad input (not a bag, no usable sample, no speed, no sample the estimator accepts: every speed
out of range, say), an output that may not be replaced or cannot be written, or bad
parameters, 2 for a bad command line; each with one line on stderr.
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path
import sys
from typing import Any

import numpy as np

from road_force_estimator.pipeline.one_block import drive_speed
from road_force_estimator.pipeline.result import PROG, EstimateResult, InputError, check_spacing
from road_force_estimator.tools import cli, output_folder
from road_force_estimator.tools.cli import MODES

__all__ = ['PROG', 'MODES', 'EstimateResult', 'InputError', 'build_parser', 'load_parameters',
           'drive_speed', 'check_spacing', 'estimate_online', 'run', 'main']


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


class _Stages:
    """A one-line progress display of the stages of :func:`run` (stderr, TTY only)."""

    NAMES = ('read', 'estimate', 'write bag', 'report')

    def __init__(self, enabled: bool, whole_vehicle: bool = False) -> None:
        self.enabled = enabled
        self.bar = cli.progress_bar(enabled, total=len(self.NAMES) + whole_vehicle,
                                    desc=PROG, leave=False,
                                    bar_format='{desc} ({n}/{total} stages done)')
        self.started = False

    def samples(self, total: int, desc: str):
        """A progress bar over ``total`` samples (:func:`.cli.sample_progress`)."""
        return cli.sample_progress(total, self.enabled, desc)

    def next(self, name: str) -> None:
        if self.started:
            self.bar.update(1)
        self.started = True
        self.bar.set_description_str(f'{PROG}: {name}')

    def close(self) -> None:
        self.bar.close()


def estimate_online(stamps_ns, q_m, roll_rad, speed_mps, vehicle, observer, *,
                    progress: bool = False):
    """:func:`.pipeline.one_block.estimate_online` (the observer node's numbers,
    :func:`~.estimator.estimate_batch`) with a progress bar when ``progress``."""
    from road_force_estimator.pipeline import one_block

    with cli.sample_progress(len(stamps_ns), progress, f'{PROG}: online') as bar:
        return one_block.estimate_online(stamps_ns, q_m, roll_rad, speed_mps, vehicle,
                                         observer, progress=bar.update)


def run(input_path: str | Path, output: str | Path, *, vehicle=None, observer=None,
        mode: str = 'online', segment_length_m: float = 100.0, reference=None,
        reference_offset_m: float | None = None, figures: bool = True, force: bool = False,
        progress: bool = False, standalone: bool = True, units: str = 'si',
        run_info: dict[str, Any] | None = None,
        memory_limit_bytes: float | None = None) -> EstimateResult:
    """Estimate one drive bag and write ``output/bag`` and ``output/report``.

    ``units`` ('si' or 'us') are those of the report's text; ``run_info`` (the parameter file,
    the overrides, the command line) is shown in it.

    Both are built in a temporary folder in ``output`` and renamed into place with the marker
    :data:`~.output_folder.MARKER_NAME` when complete (:mod:`.output_folder`); ``force``
    replaces only what estimate_bag wrote there, never the input. ``standalone`` False:
    ``output`` is a fresh folder that the caller builds and renames itself (estimate_fleet),
    written directly and without the marker. ``memory_limit_bytes``: the memory the run may
    take (:func:`.pipeline.plan.stream_threshold`; None: none given).

    Raises
    ------
    InputError
        Not a drive bag, no usable sample or speed, output exists without ``force``.
    OutputError
        An output that may not be replaced, or a write that failed (out of space: nothing is
        left behind).
    """
    from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
    from road_force_estimator.pipeline.run import run_drive

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
    from road_force_estimator.pipeline.whole_vehicle import is_whole_vehicle
    stages = _Stages(progress, is_whole_vehicle(vehicle))     # + the whole vehicle's stage
    options = dict(mode=mode, reference=reference, reference_offset_m=reference_offset_m,
                   segment_length_m=segment_length_m, figures=figures, units=units,
                   run_info=run_info)
    try:
        if not standalone:
            return run_drive(output, output, input_path, vehicle, observer, options, stages,
                             progress=progress, memory_limit_bytes=memory_limit_bytes)
        with target.staged() as stage:
            return run_drive(stage, output, input_path, vehicle, observer, options, stages,
                             progress=progress, memory_limit_bytes=memory_limit_bytes)
    finally:
        stages.close()


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


def _friction_notes(summary: dict) -> list[str]:
    """A line where the offline fit changed the tanh friction's ``v_f`` (the front axle's
    ``friction_velocity``, the whole vehicle's ``whole_vehicle_estimate.friction_velocity``:
    :func:`.report.summary.friction_velocity_note`)."""
    from road_force_estimator.report.summary import friction_velocity_note

    out = []
    for who, s in (('', summary), ("the whole vehicle's ",
                                   summary.get('whole_vehicle_estimate') or {})):
        fv = s.get('friction_velocity')
        note = friction_velocity_note(fv) if fv else None
        if note:
            out.append(who + note)
    return out


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
    for line in _friction_notes(result.summary):
        print(f'{PROG}: note: {line}', file=sys.stderr)
    for line in _headline(result, args.units):
        print(f'{PROG}: {line}')
    if export is not None:
        print(f'{PROG}: ' + profile_export.export_profile(
            result.bag, export, cutoff_wavelength_m=observer.profile_cutoff_wavelength_m))
    return 0


if __name__ == '__main__':
    sys.exit(main())
