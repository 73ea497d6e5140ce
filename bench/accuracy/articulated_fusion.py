"""The fused profile of the articulated observer (issue 32's acceptance): the offline roads of
every axle fused by distance (:func:`road_force_estimator.estimation.articulated.fuse_roads`)
against the front axle's own road, on the articulated drive family.

Run from the repository root::

    .venv/bin/python -m bench.accuracy.articulated_fusion [--duration 25]
        [--only C20 A20 C20-stop] [--cutoff-factor 3] [--online 0 0.01]

Each drive is :mod:`bench.accuracy.articulated_observer`'s (MODEL.md's 5-axle combination at
1 kHz, road seed 1, 10 um of noise), estimated offline with the package's settings; the
wheel heave's double integral band-limited at ``--cutoff-factor`` x
``observer.profile_cutoff_wavelength`` (:data:`road_force_estimator.estimation.models.
articulated_rows.ROAD_CUTOFF_FACTOR`, the package's by default). Printed per drive, for the
front axle's road and the fused profile against the front axle's two true wheel paths, over
the points every axle has passed, after ``--settle`` s and away from the last 60 m: the
0.5-30 m band's RMS error (both paths, % of the true band's RMS), the fused one over the
front axle's (issue 32: <= 0.7), the 30-100 m band's error the same way (<= 10 %) and the
IRI-filtered cross correlation (:func:`road_force_estimator.core.profile_correlation.
cross_correlation`, the lower of the two paths; >= 0.99).

``--online LATENCY...`` judges the road online instead, per latency (s; 0: zero latency):
:func:`road_force_estimator.estimation.whole_vehicle.estimate_whole_vehicle` with
``offline=False`` (the node's numbers), the front axle's own per-sample road and the fused
profile streamed (every point once the last axle has passed it, ``WholeVehicleArrays.
fused``), with the same figures.
"""
from __future__ import annotations

import argparse
import math
import sys

import numpy as np

BANDS = ((0.5, 30.0), (30.0, 100.0))


def figures(drive: dict, x: np.ndarray, paths: np.ndarray, settle_s: float,
            at: np.ndarray | None = None) -> tuple:
    """``(0.5-30 m error %, 30-100 m error %, cross correlation)`` of both wheel paths
    ``paths`` (n, 2) at the front axle's distances ``x`` (the drive's samples ``at``, by
    default its first n)."""
    from road_force_estimator.core import metrics
    from road_force_estimator.core import profile_correlation as pc

    at = np.arange(x.size) if at is None else np.asarray(at)
    mask = (drive['t'][at] >= drive['t'][0] + settle_s) & (x < x[-1] - 60.0)
    truth = drive['road'][at, :2]
    out = []
    for lo, hi in BANDS:
        pe = metrics.profile_errors(x, paths, truth, mask=mask, short_m=lo, long_m=hi)
        out.append(math.sqrt(float(np.mean(np.square(pe.rms_pct)))))
    xs = x[mask]
    xc = [pc.cross_correlation(x, paths[:, s], x, truth[:, s], start_m=float(xs[0]),
                               end_m=float(xs[-1])).rating for s in (0, 1)]
    return out[0], out[1], min(xc)


def run(case, args) -> list[str]:
    """The table's lines of one drive."""
    from bench.accuracy.articulated_observer import simulate
    from road_force_estimator.estimation.articulated import estimate_articulated, fuse_roads

    drive = simulate(case, args.duration, args.noise)
    est = estimate_articulated(drive['vehicle'], drive['stamps'], drive['y'], drive['speed'],
                               offline=True)
    own = figures(drive, est.distance_m, est.road_m[:2].T, args.settle)
    fused = fuse_roads(est, [a.position_m for a in drive['vehicle'].axles])
    fus = figures(drive, fused.distance_m, np.column_stack([fused.left, fused.right]),
                  args.settle)
    return [f'| {case.name} | front axle | {own[0]:.2f} | | {own[1]:.1f} | {own[2]:.4f} |',
            f'| {case.name} | fused ({fused.axles} axles) | {fus[0]:.2f} | '
            f'{fus[0] / own[0]:.2f} | {fus[1]:.1f} | {fus[2]:.4f} |']


def run_online(case, args, drive=None) -> list[str]:
    """The table's lines of one drive online, per latency of ``args.online``."""
    from bench.accuracy.articulated_observer import simulate
    from road_force_estimator.core.parameters import ObserverParameters
    from road_force_estimator.estimation.whole_vehicle import estimate_whole_vehicle

    drive = simulate(case, args.duration, args.noise) if drive is None else drive
    out = []
    for latency in args.online:
        wv = estimate_whole_vehicle(drive['vehicle'], drive['stamps'], drive['y'],
                                    drive['speed'],
                                    observer=ObserverParameters(latency_s=latency))
        mode = f'{latency * 1e3:g} ms'
        own = figures(drive, wv.distance_m, wv.road_m[:2].T, args.settle)
        f = wv.fused
        fus = figures(drive, f.distance_m, np.column_stack([f.left_m, f.right_m]),
                      args.settle, np.searchsorted(drive['stamps'], f.stamps_ns))
        out += [f'| {case.name} | {mode} | front axle | {own[0]:.2f} | | {own[1]:.1f} | '
                f'{own[2]:.4f} |',
                f'| {case.name} | {mode} | fused ({len(wv.axle_names)} axles) | {fus[0]:.2f} | '
                f'{fus[0] / own[0]:.2f} | {fus[1]:.1f} | {fus[2]:.4f} |']
    return out


def main(argv: list[str] | None = None) -> int:
    from bench.studies.articulated_drives import family
    from road_force_estimator.estimation.models import articulated_rows

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--duration', type=float, default=25.0, help='each drive (s)')
    parser.add_argument('--only', nargs='*', default=['C20', 'A20', 'C20-stop'],
                        metavar='NAME')
    parser.add_argument('--noise', type=float, default=1e-5, help='deflection noise (m)')
    parser.add_argument('--settle', type=float, default=5.0, help='judged after (s)')
    parser.add_argument('--cutoff-factor', type=float, default=None,
                        help="the road integral's cutoff over the observer's (default: the "
                        "package's ROAD_CUTOFF_FACTOR)")
    parser.add_argument('--online', nargs='+', type=float, default=None, metavar='LATENCY_S',
                        help='the road online at these latencies (s) instead of offline')
    args = parser.parse_args(argv)
    if args.cutoff_factor is not None:
        articulated_rows.ROAD_CUTOFF_FACTOR = args.cutoff_factor
    out = []
    for case in [c for c in family() if c.name in args.only]:
        out += run(case, args) if args.online is None else run_online(case, args)
    if args.online is not None:
        print(f'The road online, {args.duration:g} s drives at 1 kHz, {args.noise * 1e6:g} um '
              f"noise, judged after {args.settle:g} s: band errors in % of the true band's "
              'RMS (both wheel paths)\n')
        print('| drive | mode | road | 0.5-30 m | x front axle | 30-100 m | IRI-filtered xcorr |')
        print('|---|---|---|---:|---:|---:|---:|')
        print('\n'.join(out))
        return 0
    print(f'The fused profile offline, {args.duration:g} s drives at 1 kHz, '
          f'{args.noise * 1e6:g} um noise, judged after {args.settle:g} s, road cutoff '
          f"{articulated_rows.ROAD_CUTOFF_FACTOR:g} x the observer's: band errors in % of the "
          "true band's RMS (both wheel paths)\n")
    print('| drive | road | 0.5-30 m | x front axle | 30-100 m | IRI-filtered xcorr |')
    print('|---|---|---:|---:|---:|---:|')
    print('\n'.join(out))
    return 0


if __name__ == '__main__':
    sys.exit(main())
