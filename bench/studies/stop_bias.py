"""A long drive with one short stop, offline (issue 21's risk left unmeasured in issue 19): the
stop's fitted acceleration bias goes on over the whole drive (``body_heave._rest_correction``),
so a stop early in a long drive could spoil the profile far from it.

    .venv/bin/python -m bench.studies.stop_bias [--duration 120] [--stop-at 5 50] [--standing 4]

Drives of ``--duration`` s (ISO 8608 class C, seed 1, 20 m/s, 1 kHz, 10 um / 0.1 mrad noise,
as :mod:`bench.accuracy.real_truck` builds them): without a stop, and with one stop starting at
each ``--stop-at`` (braking at 5 m/s^2, ``--standing`` s standing, pulling away at 5 m/s^2); each
with the deflections read from equilibrium and from the mechanical zero (``zero_load``, the
payload +40 % of real_truck (a), where the profile pass's acceleration carries a bias while the
static-load offset settles). Estimated offline (``estimate_recording``, the nominal file), the
profile error (% of the 0.5-30 m band's RMS, :func:`bench.accuracy.scenarios.score`) over the drive
and over each third of it (the last far from an early stop) and the load error (% of the
dynamic RMS).

What it found: docs/notes/stop_bias.md.
"""
from __future__ import annotations

import argparse
import sys
from types import SimpleNamespace

import numpy as np


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--duration', type=float, default=120.0, help='drive length, s')
    p.add_argument('--stop-at', type=float, nargs='+', default=[5.0, 50.0],
                   help='times (s) where a stop starts (braking)')
    p.add_argument('--standing', type=float, default=4.0, help='standing time, s')
    return p


def _profile(at: float | None, standing: float, duration: float):
    if at is None:
        return None
    return ((0.0, at, at + 4.0, at + 4.0 + standing, at + 8.0 + standing, duration),
            (20.0, 20.0, 0.0, 0.0, 20.0, 20.0))


def _third(drive, res, i: int) -> float:
    """The profile error over third ``i`` (0, 1, 2) of the drive (% of its band RMS)."""
    from dataclasses import replace

    from bench.accuracy.scenarios import score

    n = len(drive.t_s)
    a, b = i * n // 3, (i + 1) * n // 3
    part = replace(drive, t_s=drive.t_s[a:b], q_m=drive.q_m[a:b],
                   roll_rad=drive.roll_rad[a:b], speed_mps=drive.speed_mps[a:b],
                   truth={key: v[a:b] for key, v in drive.truth.items()},
                   scenario=replace(drive.scenario, skip_s=0.0 if i else drive.scenario.skip_s))
    cut = SimpleNamespace(wheel_load_n=np.asarray(res.wheel_load_n)[a:b],
                          road_m=np.asarray(res.road_m)[a:b], ltr=np.asarray(res.ltr)[a:b])
    return score(part, cut)['profile_rms_pct_band']


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from bench.accuracy.real_truck import (TruckDrive, build, estimate_ours, files_for,
                                           truth_vehicle)
    from bench.accuracy.scenarios import score

    payload = {'vehicle.sprung_mass': 7000.0, 'vehicle.roll_inertia': 4200.0,
               'vehicle.deflection_reference': 'zero_load'}
    print(f'{args.duration:g} s drives (class C, 20 m/s), offline, the nominal file; profile % '
          'of the 0.5-30 m band, whole drive (first / middle / last third), load % of the '
          'dynamic RMS')
    print('| stop | equilibrium: profile | equilibrium: load | zero_load +40 %: profile | '
          'zero_load +40 %: load |')
    print('|---|---|---|---|---|')
    for at in [None, *args.stop_at]:
        cells = []
        for truth in ({}, payload):
            drive = TruckDrive('s', 'stop-bias', 'one stop', truth,
                               speed_profile=_profile(at, args.standing, args.duration),
                               duration_s=args.duration)
            d, stamps = build(drive, args.duration)
            vehicle = files_for(drive, truth_vehicle(drive)[0])['nominal']
            _, res = estimate_ours('offline', d, stamps, vehicle)
            fig = score(d, res)
            thirds = ' / '.join(f'{_third(d, res, i):.3g}' for i in range(3))
            cells += [f'{fig["profile_rms_pct_band"]:.3g} ({thirds})',
                      f'{fig["load_rms_pct_dyn"]:.3g}']
        label = 'none' if at is None else f'at {at:g} s ({args.standing:g} s standing)'
        print(f'| {label} | ' + ' | '.join(cells) + ' |')
    return 0


if __name__ == '__main__':
    sys.exit(main())
