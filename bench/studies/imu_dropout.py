"""The tractor IMU falling silent (issues 30 and 32): the whole vehicle's load error through
a curve when the IMU's a_y is not fresh for a stretch, with the held a_y fed (what every mode
did before) and with the IMU's row left out of those samples (and the pendulums' roll rows:
:func:`road_force_estimator.estimation.whole_vehicle.imu_left_out`), beside the fresh IMU.

Run from the repository root::

    .venv/bin/python -m bench.studies.imu_dropout [--sensors ideal pendulum]
        [--silent 4 20] [--duration 30] [--modes 0ms 10ms offline]

Drive: the family's ``C20-curve3`` (class C, 20 m/s, 1 kHz, a curve ramping to 3 m/s^2 from
5 s, 10 um / 0.1 mrad of noise, road seed 1) with ``vehicle.tractor_imu`` and the roll
sensors' physics stated in the plant and the file (``ideal`` or ``pendulum``). The IMU's
messages between the ``--silent`` times (s) are dropped; each sample is paired by the node's
rule (:func:`road_force_estimator.estimation.imu_hold.pair_imu`: stale after 0.1 s).
``--silent 0 1e9``: an IMU that never speaks (every sample ``missing``, fed 0). Printed per
sensor, mode and treatment: each axle's wheel-load RMS error after 2 s (% of its true dynamic
RMS).

What it found: docs/notes/imu_dropout.md.
"""
from __future__ import annotations

import argparse
from dataclasses import replace
import sys
import time

import numpy as np

MODES = {'0ms': (0.0, False), '10ms': (0.01, False), 'offline': (0.0, True)}
SETTLE_S = 2.0


def run(sensor: str, silent: tuple, duration_s: float, modes: list[str]) -> list[str]:
    """The table's rows for one roll sensor."""
    from bench.accuracy.articulated_observer import error_pct, simulate
    from bench.studies.articulated_drives import family
    from road_force_estimator.core.parameters import ObserverParameters
    from road_force_estimator.estimation.imu_hold import pair_imu
    from road_force_estimator.estimation.whole_vehicle import estimate_whole_vehicle

    (case,) = [c for c in family() if c.name == 'C20-curve3']
    case = replace(case, values={**case.values, 'vehicle.tractor_imu': True,
                                 'vehicle.roll_sensor': sensor,
                                 'simulator.roll_sensor': sensor})
    d = simulate(case, duration_s, 1e-5, imu=True)
    t = d['t']
    dropped = (t >= t[0] + silent[0]) & (t < t[0] + silent[1])
    held, codes = pair_imu(d['stamps'], d['stamps'][~dropped], d['ay'][~dropped])
    stale = int(np.count_nonzero(codes))
    rows = []
    for mode in modes:
        latency, offline = MODES[mode]
        obs = replace(ObserverParameters(), latency_s=latency)
        for label, ay, c in (('fresh IMU', d['ay'], None), ('held a_y fed', held, None),
                             ('left out', held, codes)):
            wv = estimate_whole_vehicle(d['vehicle'], d['stamps'],
                                        np.column_stack([d['y'], ay]), d['speed'],
                                        observer=obs, offline=offline, imu=True, imu_codes=c)
            pct = error_pct(t, wv.load_n - (d['load'] - d['dynamic']), d['dynamic'], SETTLE_S)
            rows.append(f'| {sensor} | {mode} | {label} | '
                        + ' | '.join(f'{p:.2f}' for p in pct) + f' | {stale} |')
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--sensors', nargs='+', default=['ideal', 'pendulum'],
                    choices=['ideal', 'pendulum'])
    ap.add_argument('--silent', nargs=2, type=float, default=[4.0, 20.0],
                    metavar=('FROM_S', 'TO_S'))
    ap.add_argument('--duration', type=float, default=30.0)
    ap.add_argument('--modes', nargs='+', default=list(MODES), choices=list(MODES))
    args = ap.parse_args(argv)
    from bench.studies.articulated_drives import CONFIG
    from road_force_estimator.core.articulated_setup import ArticulatedDrive
    from road_force_estimator.core.parameters import load_params_file

    axles = ArticulatedDrive.from_values(load_params_file(CONFIG)).vehicle.axle_names
    t0 = time.perf_counter()
    print(f'C20-curve3, {args.duration:g} s, the IMU silent from {args.silent[0]:g} to '
          f'{args.silent[1]:g} s: wheel-load RMS error after {SETTLE_S:g} s per axle (% of '
          'the true dynamic RMS)\n')
    print('| roll sensors | mode | a_y not fresh | ' + ' | '.join(axles)
          + ' | samples not fresh |')
    print('|' + '---|' * 3 + '---:|' * (len(axles) + 1))
    for sensor in args.sensors:
        for row in run(sensor, tuple(args.silent), args.duration, args.modes):
            print(row, flush=True)
    print(f'\n({time.perf_counter() - t0:.0f} s)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
