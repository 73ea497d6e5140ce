"""What limits the offline IRI on C20-200-10um (issue 21): the profile smoother's roughness
factor, between that drive's IRI and the profile elsewhere.

    .venv/bin/python -m bench.studies.profile_offline_roughness [--factors 1 0.5 0.25]
                                                       [--scenarios C20-200-10um ...]

The offline profile pass (:meth:`~.smoothing.smoother.Smoother._profile`)
designs its smoother for the load pass's roughness times
:data:`~road_force_estimator.estimation.models.front_axle.PROFILE_OFFLINE_GD_RATIO` (1 by default).
``--factors`` multiply that ratio. Per factor the benchmark's scenarios run (as
:mod:`bench.accuracy.run_benchmark` builds them) for ``ours-offline`` and once for ``kf-model-rts``
(the target's peer; it does not depend on the factor); the command prints, per scenario, the
profile error (% of the 0.5-30 m band's RMS) and the mean IRI error per 100 m (%), and how many
scenarios' profile is no worse than the peer's.

What it found: docs/notes/profile_offline_roughness.md.
"""
from __future__ import annotations

import argparse
import sys

#: The drive the IRI target misses and those the profile target is checked on.
DEFAULT_SCENARIOS = ['C20-200-10um', 'C20-1k-10um', 'C10-1k-10um', 'A20-1k-10um',
                     'D20-1k-10um', 'C20-1k-50um', 'B20-pothole', 'profile_1', 'C20-stop']


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--factors', type=float, nargs='+', default=[1.0, 0.5, 0.25],
                   help='PROFILE_OFFLINE_GD_RATIO times these factors (1 = the default)')
    p.add_argument('--scenarios', nargs='+', default=DEFAULT_SCENARIOS)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from bench.accuracy import tune
    from bench.accuracy.run_benchmark import METHODS
    from bench.accuracy.scenarios import build_drive, scenario_by_name, score
    from road_force_estimator.estimation.models import front_axle as model

    tuned = tune.load_tuned()
    default = model.PROFILE_OFFLINE_GD_RATIO
    drives = {name: build_drive(scenario_by_name(name)) for name in args.scenarios}
    peer = {name: score(d, METHODS['kf-model-rts'].run(d, tuned)) for name, d in drives.items()}
    print('| factor | ' + ' | '.join(
        f'{n}: profile % / IRI % (kf-model-rts {peer[n]["profile_rms_pct_band"]:.3g} / '
        f'{peer[n]["iri_err_pct_mean"]:.3g})' for n in args.scenarios)
          + ' | profile no worse than the peer |')
    print('|---' * (2 + len(args.scenarios)) + '|')
    try:
        for f in args.factors:
            model.PROFILE_OFFLINE_GD_RATIO = default * f
            cells, wins = [], 0
            for name, d in drives.items():
                d.cache.clear()                      # no estimate kept from another factor
                fig = score(d, METHODS['ours-offline'].run(d, tuned))
                wins += fig['profile_rms_pct_band'] <= peer[name]['profile_rms_pct_band']
                cells.append(f'{fig["profile_rms_pct_band"]:.3g} / {fig["iri_err_pct_mean"]:.3g}')
            print(f'| {f:g} | ' + ' | '.join(cells) + f' | {wins} of {len(drives)} |')
    finally:
        model.PROFILE_OFFLINE_GD_RATIO = default
    return 0


if __name__ == '__main__':
    sys.exit(main())
