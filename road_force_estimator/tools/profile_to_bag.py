"""`profile_to_bag`: a road profile to an LPA bag, and an LPA bag back to CSV.

    profile_to_bag INPUT --output DIR [--survey-speed V] [--track-width T] [--length M]
    profile_to_bag BAG --output FILE.csv [--exact]

INPUT is a profile file (CSV ``distance_m,left_m,right_m`` or ``distance_m,elevation_m``, UMTRI
ERD, or whitespace columns such as profile_1.txt) or a synthetic road spec
(``iso8608:C:seed=1``, ``flat``; ``--length`` sets its length). It becomes the LPA bag DIR:
``/lpa/left`` and ``/lpa/right`` (geometry_msgs/PointStamped, INTERFACES.md). When INPUT is a
bag folder (an LPA bag, or a bag of estimates: its ``/road_profile/fused/*`` when present, else
``/road_profile/*``), the profile it holds is written to the CSV file ``--output`` instead,
rounded to what a profiler measures (1 mm of distance, 0.1 um of elevation), or with
``--exact`` every number exactly (shortest round-trip form), so CSV -> bag -> CSV loses
nothing.

The output is built beside its place and renamed into it when complete (:mod:`.output_folder`);
``--force`` replaces only an LPA bag (``custom_data`` kind ``lpa_profile``, nothing else in the
folder) or a CSV file starting with the header this command writes, never INPUT.
"""
from __future__ import annotations

import argparse
from pathlib import Path
import sys

from road_force_estimator.tools import cli, output_folder

__all__ = ['build_parser', 'main', 'write_exact_csv', 'write_rounded_csv']

PROG = 'profile_to_bag'
_CSV_HEADER = 'distance_m,left_m,right_m\n'


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``profile_to_bag``."""
    from road_force_estimator.bagio import (
        DEFAULT_SURVEY_SPEED_MPS,
        DEFAULT_TRACK_WIDTH_M,
    )
    parser = cli.Parser(
        prog=PROG,
        description='Convert a road profile (CSV, ERD, text columns or a synthetic '
                    'iso8608:<class>[:seed=N] road) into an LPA bag (rosbag2 MCAP folder with '
                    '/lpa/left and /lpa/right), or an LPA bag back into a CSV profile.',
        epilog='Direction: an INPUT that is a bag folder (it holds metadata.yaml or .mcap '
               'files) is converted to the CSV file --output; anything else to the bag folder '
               '--output. The CSV has the header distance_m,left_m,right_m, numbers rounded '
               'to 1 mm of distance and 0.1 um of elevation (--exact: exact).')
    parser.add_argument('input', metavar='INPUT',
                        help='profile file (.csv, .erd, .txt/.dat), road spec such as '
                             'iso8608:C:seed=1, or an LPA bag folder or bag of estimates')
    cli.add_output(parser, 'bag folder to create, or CSV file when INPUT is a bag',
                   metavar='PATH')
    parser.add_argument('--survey-speed', type=cli.finite_float,
                        default=DEFAULT_SURVEY_SPEED_MPS,
                        metavar='V', help='survey speed for the bag stamps, m/s (default '
                                          f'{DEFAULT_SURVEY_SPEED_MPS:g})')
    parser.add_argument('--track-width', type=cli.finite_float, default=DEFAULT_TRACK_WIDTH_M,
                        metavar='T', help='lateral distance between the wheel paths, m: '
                                          f'y = +-T/2 (default {DEFAULT_TRACK_WIDTH_M:g})')
    parser.add_argument('--length', type=cli.finite_float, default=None, metavar='M',
                        help='length of a synthetic road, m (default 1000)')
    parser.add_argument('--exact', action='store_true',
                        help='bag to CSV: every number exactly (shortest round-trip form), '
                             'so that CSV -> bag -> CSV loses nothing')
    cli.add_force(parser, 'replace an LPA bag folder or CSV file this command wrote')
    return parser


def _is_bag(path: Path) -> bool:
    return path.is_dir() and ((path / 'metadata.yaml').is_file() or any(path.glob('*.mcap')))


def write_exact_csv(path: str | Path, profile) -> None:
    """Write ``distance_m,left_m,right_m`` with every float in its shortest exact form."""
    with Path(path).open('w', newline='') as f:
        f.write(_CSV_HEADER)
        for x, (zl, zr) in zip(profile.distance_m.tolist(), profile.elevation_m.tolist()):
            f.write(f'{x!r},{zl!r},{zr!r}\n')


def write_rounded_csv(path: str | Path, profile) -> None:
    """Write ``distance_m,left_m,right_m`` rounded to 1 mm of distance and 0.1 um of
    elevation (:data:`road_force_estimator.core.units.DECIMALS`)."""
    from road_force_estimator.core.units import rounded

    with Path(path).open('w', newline='') as f:
        f.write('distance_m,left_m,right_m\n')
        for x, (zl, zr) in zip(profile.distance_m.tolist(), profile.elevation_m.tolist()):
            f.write(f'{rounded(x, "distance_m")},{rounded(zl, "elevation_m")},'
                    f'{rounded(zr, "elevation_m")}\n')


def _run(args: argparse.Namespace) -> list[str]:
    """Convert (see the module notes); the lines to print. The output is built beside its
    place and renamed into it when complete (:mod:`.output_folder`); ``--force`` replaces
    only an LPA bag or a CSV this command writes, never the input."""
    from road_force_estimator import bagio
    from road_force_estimator.bagio import road_from_source

    source = Path(args.input).expanduser()
    output = Path(args.output).expanduser()
    inputs = [source] if source.exists() else []
    if _is_bag(source):
        target = output_folder.FileOutput(output, PROG, force=args.force, owned=_csv_written_here,
                                          inputs=inputs)
        target.check()
        notes: list[str] = []
        profile = bagio.read_profile_bag(source, issues=notes)
        with target.staged() as tmp:
            (write_exact_csv if args.exact else write_rounded_csv)(tmp, profile)
        return notes + [f'wrote {len(profile)} samples to {output}']
    cli.check_positive('--length', args.length, finite=False)
    target = output_folder.BagOutput(output, PROG, force=args.force, owned=_lpa_written_here,
                                     inputs=inputs)
    target.check()
    profile = road_from_source(args.input, length_m=args.length)
    with target.staged() as bag:
        bagio.write_lpa_bag(bag, profile, survey_speed_mps=args.survey_speed,
                            track_width_m=args.track_width)
    return list(getattr(profile, 'notes', ())) + [
        f'wrote {len(profile)} samples ({profile.distance_m[0]:g} m to '
        f'{profile.distance_m[-1]:g} m) to {output}']


def _lpa_written_here(custom: dict[str, str]) -> bool:
    """A bag's ``custom_data`` says it is an LPA bag (what this command writes)."""
    return custom.get('road_force_estimator.kind') == 'lpa_profile'


def _csv_written_here(path: Path) -> bool:
    """A file begins with the header :func:`write_exact_csv` writes."""
    try:
        with path.open('rb') as f:
            return f.readline(64) == _CSV_HEADER.encode()
    except OSError:
        return False


def main(argv: list[str] | None = None) -> int:
    """Run ``profile_to_bag``; returns the exit status (0 ok, 1 bad input, 2 usage)."""
    from road_force_estimator.bagio import BagReadError, BagWriteError

    return cli.run_main(PROG, build_parser(), _main, argv,
                        {(ValueError, BagReadError, BagWriteError, OSError): 1})


def _main(args: argparse.Namespace) -> int:
    """The command's work (:func:`_run`) and its notes on stderr."""
    for line in _run(args):
        print(f'{PROG}: {line}', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
