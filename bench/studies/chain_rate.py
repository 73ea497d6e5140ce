"""How the paper's chain converges with the sample rate: the differentiator chain (every
``observer.discretization`` of it: the paper's ``euler``, ``taylor``, ``implicit`` and Levant
and Livne's ``filtering``) on the benchmark's class C drive at 1 to 5 kHz.

``.venv/bin/python -m bench.studies.chain_rate [--duration S] [--rates HZ ...] [--noise M ...]``

Drive: :data:`bench.accuracy.scenarios` ``C20-1k-0um`` (ISO 8608 class C, road seed 1, 20 m/s, tire
envelope 0.25 m) sampled at each rate, without noise and with 10 um of deflection noise
(100 urad of roll), ``--duration`` s (default 10), scored by :func:`bench.accuracy.scenarios.score`
(load error in % of the true dynamic-load RMS, band-passed profile error in % of the band
RMS). Per scheme and rate: the package's default L (3000 m/s^3) and the best L of
:data:`L_GRID` (the chain's L is a setting a user tunes: the paper's scheme at its best).
The explicit schemes chatter by about ``lambda_0 L dt`` in z_2 (MODEL.md), so their error
falls with the step; under noise the differentiator's error is of order
``L^(2/3) eps^(1/3)`` at any rate.

What it found: docs/notes/chain_rate.md.
"""
from __future__ import annotations

import argparse
from dataclasses import replace
import sys
import time

from road_force_estimator.core.parameters import ObserverParameters

#: Sample rates (Hz) and the L grid (m/s^3) of the deflection differentiators.
RATES_HZ = (1000.0, 2000.0, 3000.0, 5000.0)
L_GRID = (1000.0, 2000.0, 3000.0, 5000.0, 10000.0)
SCHEMES = ('euler', 'taylor', 'implicit', 'filtering')


def measure(duration_s: float, rates, noises, log=None) -> dict:
    """``{(noise, rate): {scheme: {L: (load %, profile %)}}}``."""
    from bench.accuracy.run_benchmark import per_sample
    from bench.accuracy.scenarios import build_drive, scenario_by_name, score
    from road_force_estimator.estimation import estimate_batch

    out = {}
    for noise in noises:
        for rate in rates:
            t0 = time.perf_counter()
            sc = replace(scenario_by_name('C20-1k-0um'), rate_hz=rate, duration_s=duration_s,
                         skip_s=min(2.0, 0.25 * duration_s))
            drive = build_drive(sc, noise_deflection_m=noise)
            row = {}
            for scheme in SCHEMES:
                row[scheme] = {}
                for lq in L_GRID:
                    obs = ObserverParameters(discretization=scheme, lipschitz_deflection_mps3=lq)
                    est = estimate_batch(drive.stamps_ns, drive.q_m, drive.roll_rad,
                                         drive.speed_mps, drive.vehicle_observer, obs)
                    f = score(drive, per_sample(est, drive.stamps_ns))
                    row[scheme][lq] = (f['load_rms_pct_dyn'], f['profile_rms_pct_band'])
            out[(noise, rate)] = row
            if log:
                log(f'.. {noise * 1e6:g} um, {rate:g} Hz: {time.perf_counter() - t0:.0f} s')
    return out


def table(res: dict) -> list[str]:
    """Markdown: per noise level, rows = scheme, columns = rate: load error at the default
    L (3000) / at the best L of the grid (that L)."""
    lines = []
    for noise in sorted({k[0] for k in res}):
        rates = sorted(k[1] for k in res if k[0] == noise)
        lines += [f'Deflection noise {noise * 1e6:g} um: load error (% of the dynamic RMS) at '
                  'L = 3000 m/s^3 / at the best L of the grid (that L); profile error at the '
                  'best L in brackets', '',
                  '| scheme | ' + ' | '.join(f'{r / 1000:g} kHz' for r in rates) + ' |',
                  '|---|' + '---:|' * len(rates)]
        for scheme in SCHEMES:
            cells = []
            for rate in rates:
                by_l = res[(noise, rate)][scheme]
                best = min(by_l, key=lambda lq: by_l[lq][0])
                cells.append(f'{by_l[3000.0][0]:.1f} / {by_l[best][0]:.1f} ({best:g}) '
                             f'[{by_l[best][1]:.1f}]')
            lines.append(f'| {scheme} | ' + ' | '.join(cells) + ' |')
        lines.append('')
    return lines


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog='python -m bench.studies.chain_rate',
                                description=__doc__.splitlines()[0])
    p.add_argument('--duration', type=float, default=10.0, metavar='S')
    p.add_argument('--rates', type=float, nargs='+', default=list(RATES_HZ), metavar='HZ')
    p.add_argument('--noise', type=float, nargs='+', default=[0.0, 10e-6], metavar='M')
    p.add_argument('--filtering-order', type=int, default=None, metavar='N',
                   help="the 'filtering' scheme's n_f (1-3; default the package's, "
                        'estimation.differentiator.FILTERING_ORDER)')
    args = p.parse_args(argv)
    if args.filtering_order is not None:
        import road_force_estimator.estimation.chain.differentiator as differentiator
        if args.filtering_order not in (1, 2, 3):
            print('chain_rate: --filtering-order must be 1, 2 or 3', file=sys.stderr)
            return 2
        differentiator.FILTERING_ORDER = args.filtering_order
    if args.duration < 4.0 or any(r < 100.0 for r in args.rates):
        print('chain_rate: --duration >= 4 s and rates >= 100 Hz', file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    res = measure(args.duration, args.rates, args.noise,
                  log=lambda s: print(s, file=sys.stderr, flush=True))
    print('\n'.join(table(res)))
    print(f'({time.perf_counter() - t0:.0f} s, {args.duration:g} s drives)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
