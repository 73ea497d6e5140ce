"""`road_profile_iri`: IRI per segment of a road profile, as CSV on stdout.

    road_profile_iri PROFILE [--segment-length M]

PROFILE is a profile file (CSV, ERD, whitespace columns such as profile_1.txt), an LPA bag
folder, or a synthetic road spec (``iso8608:C:seed=1``). Output, one row per segment:
``start_m,end_m,iri_left_m_per_km,iri_right_m_per_km`` (golden quarter-car, ASTM E1926, see
:mod:`road_force_estimator.core.iri`). Segments start at the profile's first sample and are
``--segment-length`` long (default 100 m); a remainder shorter than half a segment joins the
last one. A one-track profile gives the same IRI left and right.
"""
from __future__ import annotations

import argparse
import math
import sys

from road_force_estimator.tools import cli

__all__ = ['build_parser', 'main']

PROG = 'road_profile_iri'
COLUMNS = ('start_m', 'end_m', 'iri_left_m_per_km', 'iri_right_m_per_km')


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``road_profile_iri``."""
    parser = cli.Parser(
        prog=PROG,
        description='International Roughness Index (ASTM E1926 golden quarter-car at 80 km/h, '
                    '250 mm slope average, 11 m initialisation) per segment of a road profile, '
                    'as CSV on stdout: ' + ','.join(COLUMNS) + '.',
        epilog='The quarter-car runs once over the whole profile; a segment IRI is the mean '
               'rectified slope inside it. A --segment-length longer than the profile gives '
               'the IRI of the whole profile.')
    parser.add_argument('profile', metavar='PROFILE',
                        help='profile file (.csv, .erd, .txt/.dat), LPA bag folder, or road '
                             'spec such as iso8608:C:seed=1')
    cli.add_segment_length(parser, 'segment length, m (default 100)')
    parser.add_argument('--length', type=float, default=None, metavar='M',
                        help='length of a synthetic road, m (default 1000)')
    return parser


def _number(value: float) -> str:
    return 'nan' if math.isnan(value) else f'{value:.6g}'


def main(argv: list[str] | None = None) -> int:
    """Run ``road_profile_iri``; returns the exit status (0 ok, 1 bad input, 2 usage)."""
    from road_force_estimator.bagio import BagReadError

    return cli.run_main(PROG, build_parser(), _main, argv,
                        {(ValueError, BagReadError, OSError): 1})


def _main(args: argparse.Namespace) -> int:
    """The command's work: the profile, its IRI table as CSV on stdout."""
    cli.check_positive('--segment-length', args.segment_length)
    cli.check_positive('--length', args.length, finite=False)
    from road_force_estimator.core.iri import iri_table
    from road_force_estimator.bagio import road_from_source

    profile = road_from_source(args.profile, length_m=args.length)
    table = iri_table(profile.distance_m, profile.elevation_m,
                      segment_length_m=args.segment_length)
    for note in getattr(profile, 'notes', ()):
        print(f'{PROG}: note: {note}', file=sys.stderr)
    lines = [','.join(COLUMNS)]
    for row in zip(*(table[c].tolist() for c in COLUMNS)):
        lines.append(f'{row[0]!r},{row[1]!r},{_number(row[2])},{_number(row[3])}')
    sys.stdout.write('\n'.join(lines) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
