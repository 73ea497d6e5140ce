"""Does the per-axle model fit name the axle or sensor that does not fit (issue 32)?

Run from the repository root::

    .venv/bin/python -m bench.studies.axle_fit [--duration 30] [--roads A C] [--only NAME ...]
        [--limits | --family] [--online LATENCY]

MODEL.md's combination (``config/tractor_semitrailer.yaml``) at 20 m/s, 1 kHz, ISO 8608 roads
seed 1, 10 um on every deflection and 10 um / 0.45 m on the rolls, simulated by the core
plant with one parameter off the file's (the estimator keeps the file's), estimated offline
by :func:`road_force_estimator.estimation.whole_vehicle.estimate_whole_vehicle` and judged
by :func:`road_force_estimator.estimation.axle_fit.assess_axles` (its ``axle_fit``). Per
drive: each axle's worst misfit bound ``|H - 1| - 3 se`` (%), what the verdict names, and
whether that is the plant's fault.
The clean drives also through the family's curve (to 3 m/s^2) and stop. ``--limits``: half
the faults, and a sensor offset, to show where the threshold lies (not judged); ``--family``:
the family's other roads and speeds (B20, D20 clean and with a fault, C10, C30, more noise)
and its stick drives (friction on every spring that the file does not state: not judged).
``--online LATENCY`` (s): the drives estimated online instead
(:class:`road_force_estimator.estimation.axle_fit.OnlineAxleFit`, as the node: a verdict
over the last 800 m every 400 m, so give ``--duration 60`` or more; below 10 ms the causal
road's statistic at its own threshold); per drive every verdict's culprits, and the last
verdict's misfits; right when every verdict names the plant's fault.
"""
from __future__ import annotations

import argparse
import sys


from bench.accuracy.articulated_wim import CURVE, STICK, file_vehicle, simulate

#: The family's stop (bench.studies.articulated_drives): braking at 3 m/s^2 to a stop, 5 s
#: standing, 1 m/s^2 back to 20 m/s.
STOP = ((0.0, 10.0, 10.0 + 20.0 / 3.0, 15.0 + 20.0 / 3.0, 35.0 + 20.0 / 3.0),
        (20.0, 20.0, 0.0, 0.0, 20.0))


def cases(vehicle) -> list[tuple[str, dict, tuple, tuple | None]]:
    """(name, the plant's values over the file's, the culprits the verdict should name,
    speed profile)."""
    axles = {a.name: a for a in vehicle.axles}

    def scaled(axle: str, key: str, field: str, factor: float) -> dict:
        value = getattr(axles[axle], field)
        new = [factor * v for v in value] if isinstance(value, tuple) else factor * value
        return {f'vehicle.axle.{axle}.{key}': new}

    return [
        ('clean', {}, (), None),
        ('trailer_2 spring +20 %', scaled('trailer_2', 'suspension_stiffness',
                                          'suspension_stiffness_npm', 1.2), ('trailer_2',),
         None),
        ('drive damping -30 %', scaled('drive', 'suspension_damping',
                                       'suspension_damping_nspm', 0.7), ('drive',), None),
        ('trailer_1 left sensor gain +10 %',
         {'simulator.axle.trailer_1.sensor_scale_error': [0.1, 0.0]},
         ('trailer_1_left_suspension',), None),
        ('front axle mass +30 %', scaled('front', 'mass', 'mass_kg', 1.3), ('front',), None),
        ('trailer_3 spring -20 %', scaled('trailer_3', 'suspension_stiffness',
                                          'suspension_stiffness_npm', 0.8), ('trailer_3',),
         None),
        ('trailer_2 tire +20 %', scaled('trailer_2', 'tire_stiffness', 'tire_stiffness_npm',
                                        1.2), ('trailer_2',), None),
        ('drive friction 1.5 kN (file none)',
         {'vehicle.axle.drive.leaf_spring_friction': [1500.0, 1500.0]}, ('drive',), None),
        ('trailer payload 25 t (file 29 t)', {'vehicle.trailer.mass': 25000.0}, (), None),
        ('clean, curve to 3 m/s^2', {'simulator.lateral_profile': CURVE}, (), None),
        ('clean, stop', {}, (), STOP),
    ]


def limits(vehicle) -> list[tuple[str, dict, None, None]]:
    """Half the faults above, and a sensor offset (``--limits``): not judged."""
    axles = {a.name: a for a in vehicle.axles}
    return [
        ('trailer_2 spring +10 %', {'vehicle.axle.trailer_2.suspension_stiffness': [
            1.1 * k for k in axles['trailer_2'].suspension_stiffness_npm]}, None, None),
        ('drive damping -15 %', {'vehicle.axle.drive.suspension_damping': [
            0.85 * c for c in axles['drive'].suspension_damping_nspm]}, None, None),
        ('trailer_1 left sensor gain +5 %',
         {'simulator.axle.trailer_1.sensor_scale_error': [0.05, 0.0]}, None, None),
        ('front axle mass +15 %', {'vehicle.axle.front.mass': 1.15 * axles['front'].mass_kg},
         None, None),
        ('drive left sensor offset 1 mm', {'simulator.axle.drive.sensor_offset': [1e-3, 0.0]},
         None, None),
    ]


def family(vehicle) -> list[tuple[str, dict, tuple | None, None]]:
    """The rest of the family's roads and speeds, and its stick drives (``--family``; the
    road class and speed in the name; the stick friction on every spring is in no file: not
    judged)."""
    stiff = {'vehicle.axle.trailer_2.suspension_stiffness': [
        1.2 * k for k in {a.name: a for a in vehicle.axles}['trailer_2'].suspension_stiffness_npm]}
    return [
        ('B20', {}, (), None), ('D20', {}, (), None),
        ('D20, trailer_2 spring +20 %', stiff, ('trailer_2',), None),
        ('C10', {'simulator.speed': 10.0}, (), None),
        ('C30', {'simulator.speed': 30.0}, (), None),
        ('C20, 30 um of noise', {'simulator.noise.deflection': 3e-5}, (), None),
        ('A20-stick', STICK, None, None), ('C20-stick', STICK, None, None),
    ]


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog='python -m bench.studies.axle_fit',
                                description=__doc__.splitlines()[0])
    p.add_argument('--duration', type=float, default=30.0, help='each drive (s)')
    p.add_argument('--roads', nargs='+', default=['C', 'A'], help='ISO 8608 classes')
    p.add_argument('--only', nargs='+', help='the drives whose name starts so')
    p.add_argument('--noise', type=float, default=1e-5, help='deflection noise (m)')
    p.add_argument('--limits', action='store_true',
                   help='smaller faults instead, not judged (where the threshold lies)')
    p.add_argument('--family', action='store_true',
                   help="the family's other drives instead (the road class in the name)")
    p.add_argument('--online', type=float, default=None, metavar='LATENCY',
                   help='online at this observer.latency (s) instead of offline')
    return p


def main(argv=None) -> int:
    from road_force_estimator.core.parameters import ObserverParameters
    from road_force_estimator.estimation.axle_fit import (
        CAUSAL_THRESHOLD, ONLINE_MIN_LATENCY_S, ONLINE_THRESHOLD, THRESHOLD)
    from road_force_estimator.estimation.whole_vehicle import estimate_whole_vehicle

    args = build_parser().parse_args(argv)
    vehicle = file_vehicle({})
    names = vehicle.axle_names
    online = args.online is not None
    threshold = (THRESHOLD if not online else CAUSAL_THRESHOLD
                 if args.online < ONLINE_MIN_LATENCY_S else ONLINE_THRESHOLD)
    mode = (f"online at {1e3 * args.online:g} ms (the last verdict's misfits; every verdict "
            'named)') if online else 'offline'
    gain = '||H| - 1|' if threshold == CAUSAL_THRESHOLD else '|H - 1|'
    print(f'Per-axle model fit, {args.duration:g} s drives, {mode}; misfit bound {gain} - 3 '
          f'se (%) per axle (worst wheel and band), threshold '
          f'{100 * threshold:g} %\n')
    print('| road | drive | ' + ' | '.join(names) + ' | named | right |')
    print('|---|---|' + '---:|' * len(names) + '---|---|')
    right = total = 0
    which = limits if args.limits else family if args.family else cases
    for road in (['-'] if args.family else args.roads):
        for name, values, expected, profile in which(vehicle):
            if args.only and not any(name.startswith(o) for o in args.only):
                continue
            drive = simulate(name[0] if args.family else road, args.duration, args.noise,
                             values, speed_profile=profile)
            est = estimate_whole_vehicle(
                vehicle, drive['stamps'], drive['y'], drive['speed'], offline=not online,
                observer=ObserverParameters(latency_s=args.online) if online else None)
            fit = est.axle_fit
            if fit is None:
                print(f'| {road} | {name} | no verdict |', flush=True)
                right += False
                total += expected is not None
                continue
            verdicts = [f.culprits for _, f in est.axle_fits] if online else [fit.culprits]
            ok = all(v == expected for v in verdicts)
            right += ok
            total += expected is not None
            cells = ' | '.join(f'{100 * m:.1f}' for m in fit.axle_misfit)
            word = '-' if expected is None else 'yes' if ok else 'NO'
            named = '; '.join(', '.join(v) or 'none' for v in verdicts)
            print(f'| {road} | {name} | {cells} | {named} | {word} |', flush=True)
    if total:
        print(f'\n{right} of {total} verdicts right')
    return 0


if __name__ == '__main__':
    sys.exit(main())
