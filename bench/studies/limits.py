"""What limits the zero-latency figures: two measurements behind the benchmark's verdicts.

    .venv/bin/python -m bench.studies.limits [--scenarios C10-1k-10um,C20-1k-10um,A20-1k-10um]

1. **Design grid.** The model observer designs its gains on a grid of operating points (noise
   level 2^(1/4), roughness 2^(1/2), speed 10 % apart). The zero-latency load error of the
   defaults, then with a grid of 2^(1/8) in noise and roughness and 5 % in speed
   apart: if the figures barely move, the small gap to the ``kf-model`` peer (tuned per noise
   level, given the true noise) is not the grid's.
2. **Where the profile error comes from.** The zero-latency road is ``u_i = z_s +- s sin(phi) -
   q_i + w_i``. The band-passed profile error of the defaults, then with the true body heave
   ``z_s`` put in, then with the true tire deflection ``w_i`` put in (from the plant), and the
   error of the estimated ``w_i`` per wavelength band (0.5-2, 2-8, 8-30 m) against the road's
   own RMS in that band.

Scores as ``bench.accuracy.scenarios.score`` (load % of the true dynamic-load RMS, profile % of the
band-passed truth's RMS).

What it found: docs/notes/limits.md.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np

DEFAULT_SCENARIOS = 'C10-1k-10um,C20-1k-10um,A20-1k-10um'


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--scenarios', default=DEFAULT_SCENARIOS,
                   help=f'comma-separated bench scenario names (default {DEFAULT_SCENARIOS})')
    return p


def _drive_with_plant(name: str):
    """The bench drive and the plant trajectory it was measured from."""
    import road_force_estimator.core.plant as plant
    from bench.accuracy import scenarios as sc

    kept = {}
    original = plant.simulate

    def keep(*args, **kwargs):
        kept['trajectory'] = original(*args, **kwargs)
        return kept['trajectory']

    plant.simulate = keep
    try:
        drive = sc.build_drive(sc.scenario_by_name(name))
    finally:
        plant.simulate = original
    return drive, kept['trajectory']


def design_grid(drive) -> list[tuple[str, float, int]]:
    """Zero-latency load error (%) and gain designs with the default and a finer grid."""
    from bench.accuracy import scenarios as sc
    from road_force_estimator.estimation.observer import schedule as mo
    from road_force_estimator.estimation import estimate_batch
    from road_force_estimator.core.parameters import ObserverParameters

    saved = (mo.NOISE_LEVEL_RATIO, mo.ROUGHNESS_LEVEL_RATIO, mo.SPEED_LEVEL_RATIO)
    out = []
    try:
        for label, ratios in (('default grid', saved),
                              ('finer grid', (2.0 ** 0.125, 2.0 ** 0.125, 1.05))):
            mo.NOISE_LEVEL_RATIO, mo.ROUGHNESS_LEVEL_RATIO, mo.SPEED_LEVEL_RATIO = ratios
            est = estimate_batch(drive.stamps_ns, drive.q_m, drive.roll_rad, drive.speed_mps,
                                 drive.vehicle_observer, ObserverParameters())
            out.append((label, sc.score(drive, est)['load_rms_pct_dyn'],
                        int(est.status.gain_designs)))
    finally:
        mo.NOISE_LEVEL_RATIO, mo.ROUGHNESS_LEVEL_RATIO, mo.SPEED_LEVEL_RATIO = saved
    return out


def profile_parts(drive, trajectory) -> dict[str, float]:
    """Profile error (%) of the defaults, with the true z_s, with the true w; w error by band."""
    from bench.accuracy import scenarios as sc
    from road_force_estimator.core import metrics
    from road_force_estimator.estimation import estimate_batch
    from road_force_estimator.core.parameters import ObserverParameters

    est = estimate_batch(drive.stamps_ns, drive.q_m, drive.roll_rad, drive.speed_mps,
                         drive.vehicle_observer, ObserverParameters())
    x = drive.truth['distance_m']
    road = drive.truth['road_m']
    k0 = drive.skip
    mask = (x >= x[k0] + 30.0) & (x <= x[-1] - 30.0)

    def pct(estimate) -> float:
        err, ref = sc.combined_rms(metrics.profile_errors(x, estimate, road, mask=mask))
        return 100.0 * err / ref

    zs_true = np.asarray(trajectory.body_heave_m, dtype=float)
    w_est = np.asarray(est.road_m) - np.asarray(est.wheel_heave_m)
    w_true = road - np.asarray(trajectory.wheel_heave_m, dtype=float)
    out = {'defaults': pct(est.road_m),
           'true body heave': pct(np.asarray(est.road_m)
                                  - np.asarray(est.body_heave_m)[:, None] + zs_true[:, None]),
           'true tire deflection': pct(np.asarray(est.wheel_heave_m) + w_true)}
    for lo, hi in ((0.5, 2.0), (2.0, 8.0), (8.0, 30.0)):
        err = metrics.profile_bandpass(x, w_est - w_true, short_m=lo, long_m=hi)[mask]
        ref = metrics.profile_bandpass(x, road, short_m=lo, long_m=hi)[mask]
        out[f'w error {lo:g}-{hi:g} m (um)'] = 1e6 * float(np.sqrt(np.mean(err ** 2)))
        out[f'road {lo:g}-{hi:g} m (um)'] = 1e6 * float(np.sqrt(np.mean(ref ** 2)))
    return out


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    names = [s for s in args.scenarios.split(',') if s]
    print('# bench.studies.limits: `python -m bench.studies.limits --scenarios '
          f'{",".join(names)}`\n')
    print('## Zero-latency load error (% of the dynamic-load RMS) and the design grid\n')
    print('| scenario | default grid | designs | finer grid | designs |')
    print('|---|---:|---:|---:|---:|')
    drives = {}
    for name in names:
        drives[name] = _drive_with_plant(name)
        (_, a, na), (_, b, nb) = design_grid(drives[name][0])
        print(f'| {name} | {a:.4f} | {na} | {b:.4f} | {nb} |')
    print('\n## Zero-latency profile error (% of the band RMS): where it comes from\n')
    rows = {name: profile_parts(*drives[name]) for name in names}
    keys = list(next(iter(rows.values())))
    print('| scenario | ' + ' | '.join(keys) + ' |')
    print('|---|' + '---:|' * len(keys))
    for name, parts in rows.items():
        print(f'| {name} | ' + ' | '.join(f'{parts[k]:.3g}' for k in keys) + ' |')
    return 0


if __name__ == '__main__':
    sys.exit(main())
