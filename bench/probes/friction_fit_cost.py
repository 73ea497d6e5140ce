"""The offline v_f fit (the whole vehicle's or the front axle's): the CPU seconds it adds.

    .venv/bin/python -m bench.probes.friction_fit_cost [--duration 20] [--repeats 1] [--front-axle]

The friction-lag study's offline drive (``bench.studies.friction_lag --whole-vehicle``:
class C, 20 m/s, 10 um, seed 1, the tractor-semitrailer file with 1.5 kN of tanh friction per
spring and a 3 ms sensor lag; the plant's v_f 0.005 m/s, the file's 0.01; read from the
equilibrium) through :func:`road_force_estimator.estimation.whole_vehicle.fit_friction_velocity`
(five zero-latency runs over the first 20 s): per repeat the v_f taken, the CPU seconds
(``time.process_time``: this process, not the machine's other load), the wall seconds and the
CPU microseconds a sample of a run. Numbers depend on the machine.

``--front-axle``: the front axle's fit instead
(:func:`road_force_estimator.estimation.offline.fit_friction_velocity`, five zero-latency
:class:`~road_force_estimator.estimation.estimator.BatchRun` runs over the first 20 s) on the
friction-lag study's front-axle drive ``friction+lag, truth v_f 0.005``
(``bench.studies.friction_lag``: class C, 20 m/s, road seed 1, 1.5 kN of tanh friction per
spring and a 3 ms sensor lag; the plant's v_f 0.005 m/s, the file's 0.01).
"""
from __future__ import annotations

import argparse
import sys
import time


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog='python -m bench.probes.friction_fit_cost',
                                description=__doc__.splitlines()[0])
    p.add_argument('--duration', type=float, default=20.0, metavar='S', help='s of drive')
    p.add_argument('--repeats', type=int, default=1, metavar='N')
    p.add_argument('--front-axle', action='store_true',
                   help="the front axle's fit (estimation.offline.fit_friction_velocity)")
    args = p.parse_args(argv)
    fit, stamps = _front_axle(args.duration) if args.front_axle else _whole_vehicle(
        args.duration)

    from road_force_estimator.estimation.friction_fit import FIT_GRID, fit_end

    samples = fit_end(stamps, stamps.size) * len(FIT_GRID)
    print('| repeat | v_f taken (m/s) | CPU s | wall s | CPU us a sample |')
    print('|---:|---:|---:|---:|---:|')
    for k in range(args.repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        fitted = fit()
        cpu, wall = time.process_time() - c0, time.perf_counter() - t0
        print(f'| {k + 1} | {fitted.leaf_spring_friction_velocity_mps:g} | {cpu:.1f} | '
              f'{wall:.1f} | {cpu / samples * 1e6:.0f} |')
    print(f'\n({args.duration:g} s drive, {samples} samples over {len(FIT_GRID)} runs)')
    return 0


def _whole_vehicle(duration_s: float):
    """The whole vehicle's fit (a call) and the drive's stamps (ns)."""
    from bench.accuracy import articulated_wim as wim
    from road_force_estimator.core.parameters import ObserverParameters
    from road_force_estimator.estimation.whole_vehicle import fit_friction_velocity

    both = {**wim.TANH, **wim.LAG}
    drive = wim.simulate('C', duration_s, 1e-5,
                         {**both, 'vehicle.leaf_spring_friction_velocity': 0.005})
    vehicle = wim.file_vehicle(both)
    return (lambda: fit_friction_velocity(vehicle, ObserverParameters(), drive['stamps'],
                                          drive['y'], drive['speed'])), drive['stamps']


def _front_axle(duration_s: float):
    """The front axle's fit (a call) and the drive's stamps (ns)."""
    import numpy as np

    from bench.studies import friction_lag
    from road_force_estimator.core.parameters import ObserverParameters
    from road_force_estimator.estimation.offline import fit_friction_velocity

    drive = friction_lag.build(friction_lag.BOTH, 0.005, duration_s, 1)
    stamps = np.asarray(drive.stamps_ns, np.int64)
    restart = np.zeros(stamps.size, bool)
    restart[:1] = True
    return (lambda: fit_friction_velocity(friction_lag.BOTH, ObserverParameters(), stamps,
                                          drive.q_m, drive.roll_rad, drive.speed_mps,
                                          restart)), stamps


if __name__ == '__main__':
    sys.exit(main())
