"""`calibrate_vehicle`: the truck's parameters from a drive over a surveyed road.

    calibrate_vehicle DRIVE --profile SOURCE [--static-load LEFT RIGHT] [--params-file FILE]
                      [--hold NAME...] [--free NAME...] [-p NAME:=VALUE]... --output FILE
                      [--start-offset M] [--search-range M] [--min-correlation R]
                      [--no-figures] [--force] [--no-progress]

DRIVE is a drive bag (``/suspension/deflections``, ``/vehicle/twist``; ground truth, if any,
is not used); SOURCE the survey of the same wheel paths (LPA bag, CSV, ERD, text, or a road
spec such as ``iso8608:C:seed=1``, :func:`road_force_estimator.core.road.road_from_source`).
``--static-load`` is the weighbridge load per wheel [left, right] (N): the force scale;
without it the mean tire stiffness is held at its nominal value and the report says that the
masses are known only up to a factor. ``--hold`` keeps parameters (e.g.
``vehicle.track_width``) at the values of the parameter file; ``-p`` overrides the file.
``vehicle.leaf_spring_friction`` and ``vehicle.sensor_time_constant`` are fitted when the
file's value is > 0; a 0 stays fixed (reported 'fixed') unless ``--free NAME`` asks: then the
fit starts from 500 N per side / 2 ms (reaching 50-5000 N / 0.2-20 ms), reported as nominal.
``vehicle.leaf_spring_friction_velocity`` (the tanh friction's v_f) is fitted where the file
states a tanh friction (the online node then takes the fitted value from FILE).
The survey is followed under the tire envelope ``simulator.tire_envelope_length``.

Writes FILE, a ``/**: ros__parameters:`` parameter file with every key of the input file (the
fitted ones replaced, the static load set when given), that the observer, ``estimate_bag``
and ``estimate_fleet`` read as they are, and the report ``<FILE stem>_report/`` next to it
(:mod:`road_force_estimator.report.calibration`). Exit status 0 on success, 1 for bad input
(one line on stderr: a drive too short, no overlap, a survey with gaps, a drive not on that
road...), 2 for a bad command line. The fit is :func:`road_force_estimator.estimation.
calibration.calibrate`.
"""
from __future__ import annotations

import argparse
from pathlib import Path
import sys

import numpy as np
import yaml

# The APIs this command uses (one place, for the lead to re-point).
from road_force_estimator.bagio import BagReadError, read_drive_bag, read_lpa_bag
from road_force_estimator.core.parameters import (
    ObserverParameters, SimulatorParameters, VehicleParameters, load_params_file,
    parse_override, read_params_document)
from road_force_estimator.bagio import road_from_source
from road_force_estimator.calibration.calibrate import CalibrationOptions, calibrate
from road_force_estimator.tools import cli
from road_force_estimator.tools.output_folder import staged_path

__all__ = ['PROG', 'build_parser', 'main', 'updated_document', 'report_folder']

PROG = 'calibrate_vehicle'


_UsageError = cli.UsageError
_Parser = cli.Parser


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``calibrate_vehicle``."""
    p = _Parser(prog=PROG, description='Calibrate the vehicle parameters from a drive over a '
                'road whose profile is known.',
                epilog="Values: defaults < --params-file < -p; --hold keeps the file's value.")
    p.add_argument('drive', metavar='DRIVE', help='drive bag folder (rosbag2 MCAP)')
    p.add_argument('--profile', required=True, metavar='SOURCE',
                   help='survey of the wheel paths: LPA bag, CSV, ERD or a road spec')
    p.add_argument('--static-load', nargs=2, type=cli.finite_float, metavar=('LEFT', 'RIGHT'),
                   help='weighbridge static wheel loads, N (the force scale)')
    p.add_argument('--params-file', metavar='FILE', help='nominal parameters (ROS 2 file)')
    p.add_argument('--hold', nargs='+', action='extend', default=[], metavar='NAME',
                   help='parameters kept at their nominal values (e.g. vehicle.track_width)')
    p.add_argument('--free', nargs='+', action='extend', default=[], metavar='NAME',
                   help='fit vehicle.leaf_spring_friction and/or vehicle.sensor_time_constant '
                        "even where the file's value is 0 (from 500 N / 2 ms; without it a 0 "
                        'stays fixed)')
    p.add_argument('-p', dest='overrides', action='append', default=[], metavar='NAME:=VALUE',
                   help='override a parameter of the file (repeatable)')
    p.add_argument('--output', '-o', required=True, metavar='FILE',
                   help='parameter file to write (the report goes next to it)')
    p.add_argument('--start-offset', type=cli.finite_float, metavar='M',
                   help="expected survey distance at the drive's start, m (default: the "
                        "survey's start)")
    p.add_argument('--search-range', type=cli.finite_float, default=50.0, metavar='M',
                   help='start offset searched +- this, m (default 50)')
    p.add_argument('--min-correlation', type=cli.finite_float, default=0.5, metavar='R',
                   help='refuse the alignment below this correlation (default 0.5)')
    p.add_argument('--no-figures', action='store_true', help='report without figures')
    p.add_argument('--force', action='store_true', help='replace an existing output')
    p.add_argument('--no-progress', action='store_true', help='no progress bar')
    return p


def _override(text: str) -> tuple[str, object]:
    """``-p NAME:=VALUE`` read as the other commands and the nodes read it
    (:func:`.parameters.parse_override`)."""
    name, sep, _ = text.partition(':=')
    if not sep or not name:
        raise _UsageError(f'-p {text!r}: expected NAME:=VALUE')
    return parse_override(text)


def _parameters(args) -> tuple[dict, object]:
    """(values by name: defaults < file < -p, the file's YAML document or None)."""
    values, doc = {}, None
    if args.params_file:
        values = load_params_file(args.params_file, node_names=('observer', PROG))
        doc = read_params_document(args.params_file)
    for text in args.overrides:
        name, value = _override(text)
        values[name] = value
    return values, doc


def _set_in(params: dict, name: str, value) -> bool:
    """Replace ``name`` (dotted or nested) in one ros__parameters mapping; True if found."""
    if name in params:
        params[name] = value
        return True
    head, _, rest = name.partition('.')
    if rest and isinstance(params.get(head), dict):
        return _set_in(params[head], rest, value)
    return False


def _insert(params: dict, name: str, value) -> None:
    head, _, rest = name.partition('.')
    if not rest:
        params[head] = value
        return
    if not isinstance(params.get(head), dict):
        params[head] = {}
    _insert(params[head], rest, value)


def updated_document(doc, values: dict) -> dict:
    """The parameter document with ``values`` (dotted names) replaced wherever they are, and
    added under ``/**`` where they are not; every other key is kept as it was."""
    doc = {'/**': {'ros__parameters': {}}} if not isinstance(doc, dict) else doc
    for name, value in values.items():
        found = False
        for body in doc.values():
            if isinstance(body, dict) and isinstance(body.get('ros__parameters'), dict):
                found |= _set_in(body['ros__parameters'], name, value)
        if not found:
            section = doc.setdefault('/**', {'ros__parameters': {}})
            _insert(section.setdefault('ros__parameters', {}), name, value)
    return doc


def report_folder(output: Path) -> Path:
    """Where the report of the parameter file ``output`` goes."""
    return output.with_name(output.stem + '_report')


def _survey(source: str):
    """The survey: an LPA bag folder through bagio, any other source through the core."""
    path = Path(source).expanduser()
    if path.is_dir() and (path / 'metadata.yaml').is_file():
        return read_lpa_bag(path)
    return road_from_source(source)


def _written_values(result, static) -> dict:
    """The fitted vehicle parameters (and the static load when given), by name."""
    fitted = {e.slot.name for e in result.parameters
              if e.slot.physical and e.status in ('fitted', 'scale')}
    params = result.vehicle.to_parameters()
    out = {name: params[name] for name in sorted(fitted)}
    if static is not None:
        out['vehicle.static_load'] = [float(static[0]), float(static[1])]
    return out


def _check_options(args) -> None:
    """Refuse the numbers no calibration can work with (a bad command line)."""
    if not args.search_range > 0.0:
        raise cli.UsageError(f'--search-range {args.search_range:g}: must be > 0 m')
    if not -1.0 < args.min_correlation <= 1.0:
        raise cli.UsageError(f'--min-correlation {args.min_correlation:g}: a correlation, in '
                             '(-1, 1]')
    if args.static_load is not None and not all(v > 0.0 for v in args.static_load):
        raise cli.UsageError(f'--static-load {args.static_load[0]:g} {args.static_load[1]:g}: '
                             'wheel loads, > 0 N')


def _run(args) -> tuple[object, Path, list[str]]:
    from tqdm import tqdm

    from road_force_estimator.report.calibration import write_report

    output = Path(args.output)
    _check_options(args)
    if output.exists() and not args.force:
        raise ValueError(f'{output} exists (use --force to replace it)')
    values, doc = _parameters(args)
    nominal = VehicleParameters.from_parameters(values)
    observer = ObserverParameters.from_parameters(values)
    sim = SimulatorParameters.from_parameters(values)
    drive = read_drive_bag(args.drive)
    if not np.any(np.isfinite(drive.speed_mps)):
        raise ValueError(f'{args.drive}: no usable /vehicle/twist: the speed is needed')
    survey = _survey(args.profile)
    options = CalibrationOptions(
        static_load_n=tuple(args.static_load) if args.static_load else None,
        hold=frozenset(args.hold), free=frozenset(args.free),
        tire_envelope_m=sim.tire_envelope_length_m,
        start_offset_m=args.start_offset, search_m=args.search_range,
        min_correlation=args.min_correlation)
    with tqdm(total=100, desc=PROG, unit='%', file=sys.stderr, leave=False,
              disable=args.no_progress or None, bar_format='{l_bar}{bar}| {postfix}') as bar:
        def progress(fraction: float, stage: str) -> None:
            bar.n = int(100 * fraction)
            bar.set_postfix_str(stage, refresh=True)

        result = calibrate(drive.stamps_ns, drive.q_m, drive.roll_rad, drive.speed_mps, survey,
                           nominal, observer, options, progress)
    written = _written_values(result, options.static_load_n)
    text = yaml.safe_dump(updated_document(doc, written), default_flow_style=None,
                          sort_keys=False)
    header = (f'# calibrate_vehicle: {args.drive} over {args.profile}; report in '
              f'{report_folder(output).name}/\n')
    output.parent.mkdir(parents=True, exist_ok=True)
    # Both built beside their places and renamed in when complete (a signal or a full disk
    # leaves what was there before).
    report = report_folder(output)
    with staged_path(report) as stage:
        files = write_report(result, stage, drive=str(args.drive), profile=str(args.profile),
                             output=str(output), figures=not args.no_figures)
    files = [report / Path(f).relative_to(stage) if Path(f).is_relative_to(stage) else f
             for f in files]
    with staged_path(output) as tmp:
        tmp.write_text(header + text)
    notes = [f'{len(result.parameters)} numbers, {result.used_samples} samples '
             f'({result.rejected_samples} missing or rejected'
             + (f'; {drive.rejected_total} messages rejected by the reader, calibrated on the '
                'good ones' if drive.rejected_total else '') + ')']
    return result, output, notes + [str(f) for f in files[:1]]


def main(argv: list[str] | None = None) -> int:
    """Run ``calibrate_vehicle``; the exit status (0 ok, 1 bad input, 2 bad command line)."""
    return cli.run_main(PROG, build_parser(), _main, argv,
                        {(ValueError, BagReadError, OSError): 1})


def _main(args: argparse.Namespace) -> int:
    """The command's work and its lines on stderr."""
    result, output, notes = _run(args)
    a = result.alignment
    print(f'{PROG}: aligned at {a.offset_m + result.fine_alignment[0]:.2f} m, odometer scale '
          f'{a.scale + result.fine_alignment[1]:.5f} (correlation {a.correlation:.2f}); '
          f'{notes[0]}', file=sys.stderr)
    if not result.scale_known:
        print(f'{PROG}: {result.scale_note}', file=sys.stderr)
    if result.not_identifiable:
        print(f'{PROG}: held at nominal (the drive cannot tell them apart): '
              f'{", ".join(result.not_identifiable)}', file=sys.stderr)
    print(f'{PROG}: wrote {output} and the report {report_folder(output)}', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
