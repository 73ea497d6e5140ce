"""The stick friction carried from the measured deflections (issue 30): the front axle's load
error with MODEL.md's elastic-plastic element in the plant and stated in the file, against
the same drive without friction (plant and file), online (zero latency), at 10 ms and
offline.

Run from the repository root::

    .venv/bin/python -m bench.studies.stick_friction [--duration 20] [--classes A C]
        [--cases free lag noise2 parked] [--whole-vehicle]

Drives: the file's front axle at 20 m/s, 1 kHz, ISO 8608 road (seed 3), tire envelope
0.25 m, 1.5 kN of ``stick`` friction per spring (``k_f`` = 8 k), 10 um / 0.1 mrad of noise
(seed 5). Cases: ``free`` (the sliders free at the start), ``lag`` (a 3 ms first-order lag on
every sensor, stated in the file), ``noise2`` (2 um of deflection noise), ``parked`` (every
slider holding +F_f at the start, ``simulator.leaf_spring_friction_start: 1``; the observer's
operator starts at 0). Printed per case and mode: the wheel-load RMS error after 2 s (N)
with stick friction and without, and their ratio.

``--whole-vehicle``: the same on MODEL.md's tractor and semi-trailer
(``config/tractor_semitrailer.yaml``, :mod:`bench.accuracy.articulated_wim`'s drives: 20 m/s,
1 kHz, ISO 8608 seed 1, 10 um, 1.5 kN of ``stick`` friction on every spring, the sliders free
at the start), cases ``free`` and ``lag`` only: per axle (front, drive, trailer_1..3) the
dynamic-load error after 5 s (% of the true dynamic RMS) with stick friction, and its ratio
to the same drive without friction (the same lag).

What it found: docs/notes/stick_friction.md.
"""
from __future__ import annotations

import argparse
from dataclasses import replace
import sys

import numpy as np

from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
from road_force_estimator.core.plant import simulate
from road_force_estimator.core.road import iso8608_profile
from road_force_estimator.core.sensors import SensorModel
from road_force_estimator.estimation import estimate_batch
from road_force_estimator.estimation.offline import estimate_recording

STICK = replace(VehicleParameters(), leaf_spring_friction_n=(1500.0, 1500.0),
                leaf_spring_friction_model='stick')
MODES = (('online', 0.0), ('10 ms', 0.01), ('offline', 0.0))
SKIP_S = 2.0
#: case -> (sensor lag (s), deflection noise (m), parked start (x F_f))
CASES = {'free': (0.0, 1e-5, 0.0), 'lag': (0.003, 1e-5, 0.0), 'noise2': (0.0, 2e-6, 0.0),
         'parked': (0.0, 1e-5, 1.0)}


def drive(vehicle: VehicleParameters, road_class: str, duration_s: float, noise_m: float,
          parked: float) -> tuple:
    """The plant's truth, stamps and readings."""
    tr = simulate(vehicle, iso8608_profile(road_class, 20.0 * duration_s + 50.0, seed=3),
                  speed_mps=20.0, rate_hz=1000.0, duration_s=duration_s, tire_envelope_m=0.25,
                  friction_start=parked)
    q, phi = SensorModel(deflection_std_m=noise_m, roll_std_rad=10.0 * noise_m, seed=5,
                         time_constant_s=vehicle.sensor_time_constant_s,
                         rate_hz=1000.0).measure(tr.q_m, tr.roll_rad)
    return tr, np.round(np.asarray(tr.t_s) * 1e9).astype(np.int64), q, phi


def load_error_n(vehicle: VehicleParameters, d: tuple, mode: str, latency_s: float) -> float:
    """The wheel-load RMS error (N) after SKIP_S of one mode's estimate."""
    tr, stamps, q, phi = d
    if mode == 'offline':
        est = estimate_recording(stamps, q, phi, 20.0, vehicle, ObserverParameters())
    else:
        est = estimate_batch(stamps, q, phi, 20.0, vehicle,
                             ObserverParameters(latency_s=latency_s))
    ok = np.asarray(tr.t_s) >= SKIP_S
    err = np.asarray(est.wheel_load_n)[ok] - np.asarray(tr.wheel_load_n)[ok]
    return float(np.sqrt(np.mean(err ** 2)))


def whole_vehicle(duration_s: float, classes, cases) -> list[str]:
    """The ``--whole-vehicle`` table (Markdown rows)."""
    from bench.accuracy import articulated_wim as wim

    stick = {'vehicle.leaf_spring_friction_model': 'stick',
             'vehicle.leaf_spring_friction': [1500.0, 1500.0]}
    lines = [f'Whole vehicle, 1.5 kN stick friction per spring stated in the file, '
             f'{duration_s:g} s at 20 m/s: dynamic-load error after 5 s per axle (front, drive, '
             'trailer_1..3; % of the true dynamic RMS) with stick friction, and / without\n',
             '| class | case | ' + ' | '.join(m for m, _, _ in wim.MODES) + ' |',
             '|---|---|' + '---|' * len(wim.MODES)]
    for road in classes:
        for case in cases:
            lag = {'vehicle.sensor_time_constant': [0.003, 0.003]} if case == 'lag' else {}
            ds = wim.simulate(road, duration_s, 1e-5, {**stick, **lag})
            dn = wim.simulate(road, duration_s, 1e-5, lag)
            cells = []
            for _, latency, offline in wim.MODES:
                a = wim.dynamic_pct(ds, wim.estimate(ds['vehicle'], ds, latency, offline))
                b = wim.dynamic_pct(dn, wim.estimate(dn['vehicle'], dn, latency, offline))
                cells.append(', '.join(f'{v:.1f}' for v in a) + ' / '
                             + ', '.join(f'{v:.2f}' for v in a / b))
            lines.append(f'| {road} | {case} | ' + ' | '.join(cells) + ' |')
            print(lines[-1], flush=True)
    return lines


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--duration', type=float, default=20.0, help='each drive (s)')
    p.add_argument('--classes', nargs='+', default=['A', 'C'])
    p.add_argument('--cases', nargs='+', default=list(CASES), choices=list(CASES))
    p.add_argument('--whole-vehicle', action='store_true',
                   help="the tractor and semi-trailer's per-axle table (cases free, lag)")
    args = p.parse_args(argv)
    if args.whole_vehicle:
        cases = [c for c in args.cases if c in ('free', 'lag')] or ['free', 'lag']
        print('\n'.join(whole_vehicle(args.duration, args.classes, cases)))
        return 0
    print(f'Front axle, 1.5 kN stick friction per spring stated in the file, {args.duration:g} s '
          'at 20 m/s: wheel-load RMS error after 2 s (N), stick / without friction (ratio)\n')
    print('| class | case | ' + ' | '.join(m for m, _ in MODES) + ' |')
    print('|---|---|' + '---|' * len(MODES))
    for road in args.classes:
        for case in args.cases:
            lag, noise, parked = CASES[case]
            stick = replace(STICK, sensor_time_constant_s=(lag, lag))
            none = replace(stick, leaf_spring_friction_n=(0.0, 0.0))
            ds = drive(stick, road, args.duration, noise, parked)
            dn = drive(none, road, args.duration, noise, 0.0)
            cells = []
            for mode, latency in MODES:
                a, b = load_error_n(stick, ds, mode, latency), load_error_n(none, dn, mode,
                                                                            latency)
                cells.append(f'{a:.0f} / {b:.0f} ({a / b:.2f})')
            print(f'| {road} | {case} | ' + ' | '.join(cells) + ' |', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
