"""Regenerate the sample LPA profile bags of this folder (see README.md).

    python bags/make_sample_bags.py [--output FOLDER]

Each bag is an ISO 8608 road synthesized by road_force_estimator.core.road.iso8608_profile
(geometric-mean Gd(n0), default left/right coherence model), limited to the wavelengths an LPA
records (0.5-50 m), sampled every 0.1 m over 1 km, and written by
road_force_estimator.bagio.write_lpa_bag (/lpa/left, /lpa/right; stamps at 20 m/s).
The output is byte-for-byte reproducible.
"""
from __future__ import annotations

import argparse
from pathlib import Path
import sys

from road_force_estimator.bagio import write_lpa_bag
from road_force_estimator.core.road import iso8608_profile

#: (folder, ISO 8608 class, seed) of each bag.
BAGS = (('lpa_iso8608_b', 'B', 21), ('lpa_iso8608_c', 'C', 22))
LENGTH_M = 1000.0
DX_M = 0.1
#: Wavelengths an LPA records, 0.5-50 m, as spatial frequencies (cycles/m).
BAND_CPM = (1.0 / 50.0, 1.0 / 0.5)
SURVEY_SPEED_MPS = 20.0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--output', default=str(Path(__file__).resolve().parent),
                        help='folder to write the bags into (default: this folder)')
    args = parser.parse_args(argv)
    for folder, road_class, seed in BAGS:
        profile = iso8608_profile(road_class, LENGTH_M, seed=seed, dx_m=DX_M, band_cpm=BAND_CPM)
        path = Path(args.output) / folder
        write_lpa_bag(path, profile, survey_speed_mps=SURVEY_SPEED_MPS, overwrite=True)
        print(f'{path}: {profile.name}, {len(profile)} samples, {profile.length_m:g} m',
              file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
