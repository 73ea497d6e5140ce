"""`road_profile_iri`: IRI per segment of a road profile, as CSV on stdout.

    road_profile_iri PROFILE [--units si|us] [--segment-length M] [--length M]

PROFILE is a profile file (CSV, ERD, whitespace columns such as profile_1.txt), an LPA bag
folder, a bag of estimates (``estimate_bag``'s ``DIR/bag``: its ``/road_profile/fused/*`` when
present, else ``/road_profile/*``, the estimated road by the estimator's distance), or a
synthetic road spec (``iso8608:C:seed=1``). Output, one row per segment:
``start_m,end_m,iri_left_m_per_km,iri_right_m_per_km`` (``--units si``, the default: 100 m
segments) or ``start_ft,end_ft,iri_left_in_per_mi,iri_right_in_per_mi`` (``--units us``:
0.1-mile segments, 1 m/km = 63.36 in/mi), rounded to 1 mm of distance and 0.001 m/km
(0.01 in/mi) of IRI (golden quarter-car, ASTM E1926, see :mod:`road_force_estimator.core.iri`).
Segments start at the profile's first sample and are ``--segment-length`` long; a remainder
shorter than half a segment joins the last one. A one-track profile gives the same IRI left and
right. On stderr: the whole profile's IRI, what was converted on reading (an ERD file's feet),
and the IRI an ERD file's header stores (``IRILWP`` / ``IRIRWP``) beside the computed one.
"""
from __future__ import annotations

import argparse
from pathlib import Path
import sys

import numpy as np

from road_force_estimator.tools import cli

__all__ = ['build_parser', 'main', 'columns']

PROG = 'road_profile_iri'
COLUMNS = ('start_m', 'end_m', 'iri_left_m_per_km', 'iri_right_m_per_km')
US_COLUMNS = ('start_ft', 'end_ft', 'iri_left_in_per_mi', 'iri_right_in_per_mi')


def columns(units: str = 'si') -> tuple[str, ...]:
    """The CSV header of ``--units units``."""
    return US_COLUMNS if units == 'us' else COLUMNS


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``road_profile_iri``."""
    parser = cli.Parser(
        prog=PROG,
        description='International Roughness Index (ASTM E1926 golden quarter-car at 80 km/h, '
                    '250 mm slope average, 11 m initialisation) per segment of a road profile, '
                    'as CSV on stdout: ' + ','.join(COLUMNS) + ' (--units us: '
                    + ','.join(US_COLUMNS) + ').',
        epilog='The quarter-car runs once over the whole profile; a segment IRI is the mean '
               'rectified slope inside it. The IRI of the whole profile goes to stderr (and an '
               "ERD file's stored IRILWP / IRIRWP beside it).")
    parser.add_argument('profile', metavar='PROFILE',
                        help='profile file (.csv, .erd, .txt/.dat), LPA bag folder, bag of '
                             'estimates (/road_profile/*), or road spec such as '
                             'iso8608:C:seed=1')
    cli.add_units(parser)
    cli.add_segment_length(parser, 'segment length, m (default 100 m; 0.1 mi = 160.9344 m with '
                                   '--units us)', default=None)
    parser.add_argument('--length', type=cli.finite_float, default=None, metavar='M',
                        help='length of a synthetic road, m (default 1000)')
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``road_profile_iri``; returns the exit status (0 ok, 1 bad input, 2 usage)."""
    from road_force_estimator.bagio import BagReadError

    return cli.run_main(PROG, build_parser(), _main, argv,
                        {(ValueError, BagReadError, OSError): 1})


def _main(args: argparse.Namespace) -> int:
    """The command's work: the profile, its IRI table as CSV on stdout, the whole IRI."""
    segment_length_m = cli.segment_length(args)
    cli.check_positive('--length', args.length, finite=False)
    from road_force_estimator.bagio import road_from_source
    from road_force_estimator.core.iri import iri, iri_table
    from road_force_estimator.core.units import units

    u = units(args.units)
    profile = road_from_source(args.profile, length_m=args.length)
    from road_force_estimator.core.segments import check_segment_length
    steps = np.diff(profile.distance_m)
    check_segment_length(segment_length_m, float(np.median(steps)) if steps.size else 0.0,
                         'profile')
    table = iri_table(profile.distance_m, profile.elevation_m,
                      segment_length_m=segment_length_m)
    for note in getattr(profile, 'notes', ()):
        print(f'{PROG}: note: {note}', file=sys.stderr)
    lines = [','.join(columns(u.name))]
    for row in zip(*(table[c].tolist() for c in COLUMNS)):
        lines.append(','.join([u.length_text(row[0]), u.length_text(row[1]),
                               _iri(u, row[2]), _iri(u, row[3])]))
    sys.stdout.write('\n'.join(lines) + '\n')
    whole = iri(profile.distance_m, profile.elevation_m)
    x = profile.distance_m
    print(f'{PROG}: whole profile ({u.length_text(x[0])} to {u.length_text(x[-1])} '
          f'{u.length_unit}): IRI left/right {_iri(u, whole[0])}/{_iri(u, whole[1])} '
          f'{u.iri_unit}', file=sys.stderr)
    stored = _stored(args.profile)
    if stored is not None:
        print(f'{PROG}: the file stores (IRILWP / IRIRWP) '
              f'{_iri(u, stored["left_m_per_km"])}/{_iri(u, stored["right_m_per_km"])} '
              f'{u.iri_unit} (written {_raw(stored["left"])}/{_raw(stored["right"])} '
              f'{stored["unit"]}, the unit of its XUNITS); computed '
              f'{_iri(u, whole[0])}/{_iri(u, whole[1])} {u.iri_unit}', file=sys.stderr)
    return 0


def _iri(u, m_per_km) -> str:
    text = u.iri_text(m_per_km)
    return 'nan' if text == 'n/a' else text


def _raw(value) -> str:
    return 'n/a' if value is None else f'{value:g}'


def _stored(source: str):
    """The ERD header's stored IRI of ``source`` (None: not an ERD file or none stored)."""
    from road_force_estimator.core.road_files import erd_stored_iri

    path = Path(source)
    if path.suffix.lower() != '.erd' or not path.is_file():
        return None
    return erd_stored_iri(path)


if __name__ == '__main__':
    sys.exit(main())
