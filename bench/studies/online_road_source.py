"""Where the whole vehicle's online road errs, from the wheels or from the bodies (issue 32):
every axle's road by band against the plant's true paths, and the IRI-filtered cross
correlation with the error kept to one band at a time.

Run from the repository root::

    .venv/bin/python -m bench.studies.online_road_source [--only C20 A20] [--online 0 0.01]
        [--blend 2 4]

Each drive is :mod:`bench.accuracy.articulated_observer`'s (25 s, 10 um of noise), estimated
online (:func:`road_force_estimator.estimation.whole_vehicle.estimate_whole_vehicle`) with
every wheel's road from the wheels (:class:`~road_force_estimator.estimation.models.
articulated_rows.WheelRoads`) and from the bodies (:class:`~road_force_estimator.estimation.
models.articulated_rows.BodyRoads`), after 5 s and away from the last 60 m. Printed: per axle
the band errors (% of the true band's RMS, both paths) and the road's wander (the largest
mean over a second of the road less the truth, m, both paths, the whole drive); for the front
axle the cross
correlation (the lower path) of the road and of the truth plus the error band-passed to one
band (zero phase); ``--blend L``: the bodies' road plus the difference high-passed at L m
(causal second-order Butterworth at the drive's 20 m/s, the front axle only).
"""
from __future__ import annotations

import argparse
import math

import numpy as np

BANDS = ((0.1, 0.5), (0.5, 1.0), (1.0, 3.0), (3.0, 10.0), (10.0, 30.0), (30.0, 100.0))
XC_BANDS = ((0.5, 1.0), (1.0, 3.0), (3.0, 30.0))
SPEED_MPS, RATE_HZ = 20.0, 1000.0


def _band_pct(x, paths, truth, mask, lo, hi) -> float:
    from road_force_estimator.core import metrics
    pe = metrics.profile_errors(x, paths, truth, mask=mask, short_m=lo, long_m=hi)
    return math.sqrt(float(np.mean(np.square(pe.rms_pct))))


def _xcorr(x, paths, truth, mask) -> float:
    from road_force_estimator.core import profile_correlation as pc
    xs = x[mask]
    return min(pc.cross_correlation(x, paths[:, s], x, truth[:, s], start_m=float(xs[0]),
                                    end_m=float(xs[-1])).rating for s in (0, 1))


def main(argv: list[str] | None = None) -> int:
    from scipy import signal

    from bench.accuracy.articulated_observer import simulate
    from bench.studies.articulated_drives import family
    from road_force_estimator.core.parameters import ObserverParameters
    from road_force_estimator.estimation.models import articulated_rows
    from road_force_estimator.estimation.whole_vehicle import estimate_whole_vehicle

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--only', nargs='*', default=['C20', 'A20'], metavar='NAME')
    parser.add_argument('--online', nargs='+', type=float, default=[0.0, 0.01],
                        metavar='LATENCY_S')
    parser.add_argument('--blend', nargs='*', type=float, default=[2.0, 4.0], metavar='M')
    args = parser.parse_args(argv)
    keep = articulated_rows.ROAD_FROM_BODIES
    print('| drive | mode | road | axle | ' + ' | '.join(f'{lo:g}-{hi:g} m' for lo, hi in BANDS)
          + ' | wander (m) |')
    print('|---|---|---|---|' + '---:|' * (len(BANDS) + 1))
    xc_lines = []
    try:
        for case in [c for c in family() if c.name in args.only]:
            drive = simulate(case, 25.0, 1e-5)
            for latency in args.online:
                roads = {}
                for source in ('wheels', 'bodies'):
                    articulated_rows.ROAD_FROM_BODIES = (source == 'bodies',) * 2
                    wv = estimate_whole_vehicle(drive['vehicle'], drive['stamps'], drive['y'],
                                                drive['speed'],
                                                observer=ObserverParameters(latency_s=latency))
                    x = wv.distance_m
                    mask = (drive['t'] >= drive['t'][0] + 5.0) & (x < x[-1] - 60.0)
                    for j, name in enumerate(wv.axle_names):
                        got = [_band_pct(x, wv.road_m[2 * j:2 * j + 2].T,
                                         drive['road'][:, 2 * j:2 * j + 2], mask, lo, hi)
                               for lo, hi in BANDS]
                        e = wv.road_m[2 * j:2 * j + 2].T - drive['road'][:, 2 * j:2 * j + 2]
                        k = int(RATE_HZ)
                        n = e.shape[0] // k * k
                        wander = float(np.max(np.abs(e[:n].reshape(-1, k, 2).mean(axis=1))))
                        print(f'| {case.name} | {latency * 1e3:g} ms | {source} | {name} | '
                              + ' | '.join(f'{g:.2f}' for g in got) + f' | {wander:.3f} |')
                    roads[source] = wv.road_m[:2].T.copy()
                truth = drive['road'][:, :2]
                for source, p in roads.items():
                    e = p - truth
                    per = []
                    for lo, hi in XC_BANDS:
                        b, a = signal.butter(2, [2.0 * SPEED_MPS / hi / RATE_HZ,
                                                 2.0 * SPEED_MPS / lo / RATE_HZ], 'band')
                        per.append(_xcorr(x, truth + signal.filtfilt(b, a, e, axis=0), truth,
                                          mask))
                    xc_lines.append(f'| {case.name} | {latency * 1e3:g} ms | {source} | '
                                    f'{_xcorr(x, p, truth, mask):.4f} | '
                                    + ' | '.join(f'{v:.4f}' for v in per) + ' |')
                for L in args.blend:
                    b, a = signal.butter(2, 2.0 * SPEED_MPS / L / RATE_HZ, 'high')
                    p = roads['bodies'] + signal.lfilter(b, a, roads['wheels'] - roads['bodies'],
                                                         axis=0)
                    xc_lines.append(f'| {case.name} | {latency * 1e3:g} ms | blend {L:g} m | '
                                    f'{_xcorr(x, p, truth, mask):.4f} | | | |')
    finally:
        articulated_rows.ROAD_FROM_BODIES = keep
    print('\nFront axle, IRI-filtered cross correlation: the road, then the truth plus the '
          'error kept to one band\n')
    print('| drive | mode | road | xcorr | ' + ' | '.join(f'error {lo:g}-{hi:g} m only'
                                                       for lo, hi in XC_BANDS) + ' |')
    print('|---|---|---|---:|' + '---:|' * len(XC_BANDS))
    print('\n'.join(xc_lines))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
