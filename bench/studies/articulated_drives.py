"""The benchmark's articulated drive family and its truth (issue 31: the drives and the truth;
the estimates come with the articulated observer).

Run from the repository root::

    .venv/bin/python -m bench.studies.articulated_drives [--duration 60] [--write DIR] [--only
NAME...]

Each drive is MODEL.md's 5-axle 40 t combination (``config/tractor_semitrailer.yaml``) at
1 kHz with the simulator's default sensors, over ISO 8608 roads (seed 1, the default 0.25 m
tire envelope): classes A-D at 20 m/s, class C at 10 and 30 m/s, a stop (20 m/s, braking at
3 m/s^2 to standstill, 5 s standing, back to 20 m/s at 1 m/s^2), a curve (a_y entered over
3 s, 3 m/s^2 held 6 s; on class B and class C), the payload case (the trailer unladen) and
friction that sticks (1.5 kN per spring on every axle, the stick element, loaded while
parked; on class A and class C). ``--write DIR`` writes each drive's bag
(``DIR/<name>``, what ``simulate_bag`` writes for it).

Printed, from the plant's truth: the road's IRI (m/km, left / right, over the front axle's
stretch), the static axle loads and the gross weight (t), the peak dynamic wheel load of each
axle (kN: the largest |F_n - F_c| of its two wheels), the trailer's peak |LTR| and peak
|quasi-static LTR| (:mod:`road_force_estimator.core.unit_loads`), and the wheel samples at
zero load (lift-off).

What it found: docs/notes/articulated_drives.md.
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass, field
import pathlib
import sys
import time

import numpy as np

REPO = pathlib.Path(__file__).resolve().parents[2]
CONFIG = REPO / 'config' / 'tractor_semitrailer.yaml'

UNLADEN = {'vehicle.trailer.mass': 7500.0, 'vehicle.trailer.pitch_inertia': 120000.0,
           'vehicle.trailer.roll_inertia': 9000.0, 'vehicle.trailer.cg_height': 1.3,
           'vehicle.trailer.cg_height_above_roll_axis': 0.6}
STICK = {'vehicle.leaf_spring_friction_model': 'stick',
         'vehicle.leaf_spring_friction': [1500.0, 1500.0],
         'simulator.leaf_spring_friction_start': 1.0}
CURVE = 'curve:start=5,ramp=3,hold=6,ay=3'


@dataclass(frozen=True)
class Case:
    """One drive: its name, road class, speed (m/s) and parameter overrides."""

    name: str
    road: str
    speed_mps: float = 20.0
    values: dict = field(default_factory=dict)
    speed_profile: tuple | None = None


def family() -> list[Case]:
    """The drives, in the table's order."""
    stop = ((0.0, 10.0, 10.0 + 20.0 / 3.0, 15.0 + 20.0 / 3.0, 35.0 + 20.0 / 3.0),
            (20.0, 20.0, 0.0, 0.0, 20.0))
    return [Case('A20', 'A'), Case('B20', 'B'), Case('C20', 'C'), Case('D20', 'D'),
            Case('C10', 'C', 10.0), Case('C30', 'C', 30.0),
            Case('C20-stop', 'C', speed_profile=stop),
            Case('B20-curve3', 'B', values={'simulator.lateral_profile': CURVE}),
            Case('C20-curve3', 'C', values={'simulator.lateral_profile': CURVE}),
            Case('C20-unladen', 'C', values=UNLADEN),
            Case('A20-stick', 'A', values=STICK), Case('C20-stick', 'C', values=STICK)]


def run_case(case: Case, duration_s: float, write: pathlib.Path | None) -> dict:
    """Simulate one drive; its truth figures (and its bag with ``write``)."""
    import tempfile

    from road_force_estimator.bagio import road_from_source
    from road_force_estimator.core.articulated_plant import simulate_articulated
    from road_force_estimator.core.articulated_setup import ArticulatedDrive
    from road_force_estimator.core.iri import iri
    from road_force_estimator.core.parameters import GRAVITY_MPS2, load_params_file
    from road_force_estimator.core.unit_loads import unit_load_transfer

    values = load_params_file(CONFIG)
    values.update({'simulator.road': f'iso8608:{case.road}:seed=1',
                   'simulator.speed': case.speed_mps, 'simulator.duration': duration_s,
                   **case.values})
    with tempfile.TemporaryDirectory() as tmp:
        if case.speed_profile is not None:
            path = pathlib.Path(tmp) / 'speed.csv'
            path.write_text('time_s,speed_mps\n' + ''.join(
                f'{t:.6f},{v:.6f}\n' for t, v in zip(*case.speed_profile)))
            values['simulator.speed_profile'] = str(path)
        drive = ArticulatedDrive.from_values(values)
        if write is not None:
            _write(drive, write / case.name)
    sim = drive.sim
    road = road_from_source(sim.road, length_m=drive.road_length_m)
    tr = simulate_articulated(drive.vehicle, road, speed_mps=sim.speed_mps, rate_hz=sim.rate_hz,
                              duration_s=duration_s, speed_profile=drive.speed_profile,
                              lateral_acceleration=drive.lateral,
                              tire_envelope_m=sim.tire_envelope_length_m,
                              friction_start=sim.leaf_spring_friction_start, model=drive.model)
    st = drive.model.statics()
    x = tr.distance_m
    stretch = (road.distance_m >= x[0]) & (road.distance_m <= x[-1])
    loads = tr.wheel_load_n
    dyn = np.abs(loads - st.output_wheel_load_n.reshape(-1))
    ltr = unit_load_transfer([a.body for a in drive.vehicle.axles], st.output_wheel_load_n,
                             1.0 / sim.rate_hz, loads)
    return {'name': case.name, 'iri': iri(road.distance_m[stretch], road.elevation_m[stretch]),
            'axle_t': st.axle_load_kg / 1000.0, 'gross_t': st.gross_weight_kg / 1000.0,
            'peak_kn': dyn.reshape(len(tr), -1, 2).max(axis=(0, 2)) / 1000.0,
            'ltr_trailer': float(np.max(np.abs(ltr[:, 2]))),
            'ltr_trailer_qs': float(np.max(np.abs(ltr[:, 3]))),
            'lift_off': int(np.count_nonzero(loads <= 0.0)), 'samples': len(tr),
            'km': (x[-1] - x[0]) / 1000.0, 'g': GRAVITY_MPS2,
            'axles': drive.vehicle.axle_names}


def _write(drive, out: pathlib.Path) -> None:
    """The drive's bag, as simulate_bag writes it."""
    from road_force_estimator.tools import articulated_simulation as articulated
    from road_force_estimator.tools.simulate_bag import PROG, gnss_fixes, twist_speed

    result = articulated.simulate(drive, route=gnss_fixes, prog=PROG)
    custom = articulated.custom_data(drive, result, PROG)
    articulated.write(out, drive, result, custom, twist_speed=twist_speed)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--duration', type=float, default=60.0, help='each drive (s)')
    parser.add_argument('--write', type=pathlib.Path, metavar='DIR',
                        help="write each drive's bag into DIR/<name>")
    parser.add_argument('--only', nargs='*', metavar='NAME', help='these drives only')
    args = parser.parse_args(argv)
    cases = [c for c in family() if not args.only or c.name in args.only]
    if args.write is not None:
        args.write.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    rows = [run_case(c, args.duration, args.write) for c in cases]
    axles = rows[0]['axles']
    print(f'Articulated drive family, {args.duration:g} s each at 1 kHz '
          f'({time.perf_counter() - start:.0f} s):\n')
    head = ' | '.join(f'{a} (kN)' for a in axles)
    print(f'| drive | IRI left / right (m/km) | gross (t) | peak dynamic wheel load: {head} | '
          'trailer max abs LTR / quasi-static | lift-off samples |')
    print('|---|---:|---:|' + '---:|' * len(axles) + '---:|---:|')
    for r in rows:
        peaks = ' | '.join(f'{p:.1f}' for p in r['peak_kn'])
        print(f'| {r["name"]} | {r["iri"][0]:.2f} / {r["iri"][1]:.2f} | {r["gross_t"]:.2f} | '
              f'{peaks} | {r["ltr_trailer"]:.3f} / {r["ltr_trailer_qs"]:.3f} | '
              f'{r["lift_off"]} |')
    print('\nStatic axle loads (t):\n')
    print('| drive | ' + ' | '.join(axles) + ' | gross |')
    print('|---|' + '---:|' * (len(axles) + 1))
    seen = set()
    for r in rows:
        key = tuple(np.round(r['axle_t'], 6))
        if key in seen:
            continue
        seen.add(key)
        print(f'| {r["name"]} | ' + ' | '.join(f'{t:.2f}' for t in r['axle_t'])
              + f' | {r["gross_t"]:.2f} |')
    return 0


if __name__ == '__main__':
    sys.exit(main())
