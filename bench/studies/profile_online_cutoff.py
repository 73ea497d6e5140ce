"""What limits the zero-latency profile on the noise-free drives (issue 21): the road's
long-wave cutoff, between the band's edge and the level's wander.

    .venv/bin/python -m bench.studies.profile_online_cutoff [--factors 1 0.3 0.1]
                                                   [--scenarios C20-1k-0um D20-1k-0um C20-stop]

The zero-latency road (:mod:`~.models.front_axle_rows`) integrates the
profile filter's body heave twice with a high-pass at ``w_c = 2 pi v / lambda_c`` (the body
heave's cutoff over :data:`~.models.front_axle.PROFILE_ONLINE_CUTOFF_RATIO`,
1 by default): a causal filter, so it starts with the body's rate at the start (not in the
data) and, near its cutoff, shifts the phase of the band's longest waves. ``--factors``
multiply that cutoff (0.1: ten times lower, waves ten times longer kept). Per factor the
benchmark's scenarios run (:mod:`bench.accuracy.scenarios`, as :mod:`bench.accuracy.run_benchmark`
builds them) for ``ours-online`` (zero latency, defaults) and once for ``kf-model`` (the
model-based Kalman filter, the target's peer; it does not depend on the factor), and the command
prints the profile error (% of the 0.5-30 m band's RMS) and the largest |error| of the road's level
(m, less its mean, after the scenario's convergence skip).

What it found: docs/notes/profile_online_cutoff.md.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--factors', type=float, nargs='+', default=[1.0, 0.3, 0.1],
                   help='the road cutoff times these factors (1 = the default)')
    p.add_argument('--scenarios', nargs='+', default=['C20-1k-0um', 'D20-1k-0um', 'C20-stop'])
    return p


def _level_error(drive, res) -> float:
    """Largest |estimated - true road| (m, less its mean) over both wheels after the
    scenario's convergence skip."""
    k = drive.skip
    err = np.asarray(res.road_m)[k:] - np.asarray(drive.truth['road_m'])[k:]
    return float(np.max(np.abs(err - np.mean(err, axis=0))))


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from bench.accuracy import tune
    from bench.accuracy.run_benchmark import METHODS
    from bench.accuracy.scenarios import build_drive, scenario_by_name, score
    from road_force_estimator.estimation.models import front_axle_rows as model_road

    tuned = tune.load_tuned()
    default = model_road.PROFILE_ONLINE_CUTOFF_RATIO
    drives = {name: build_drive(scenario_by_name(name)) for name in args.scenarios}
    peer = {name: score(d, METHODS['kf-model'].run(d, tuned))['profile_rms_pct_band']
            for name, d in drives.items()}
    print('| road cutoff factor | ' + ' | '.join(
        f'{n} profile % (kf-model {peer[n]:.3g}) | {n} level, m' for n in args.scenarios)
          + ' |')
    print('|---' * (1 + 2 * len(args.scenarios)) + '|')
    try:
        for f in args.factors:
            model_road.PROFILE_ONLINE_CUTOFF_RATIO = default / f
            cells = []
            for name, d in drives.items():
                d.cache.clear()                      # no estimate kept from another factor
                res = METHODS['ours-online'].run(d, tuned)
                cells += [f'{score(d, res)["profile_rms_pct_band"]:.3g}',
                          f'{_level_error(d, res):.3g}']
            print(f'| {f:g} | ' + ' | '.join(cells) + ' |')
    finally:
        model_road.PROFILE_ONLINE_CUTOFF_RATIO = default
    return 0


if __name__ == '__main__':
    sys.exit(main())
