"""The articulated truck's statics and linearised modes (MODEL.md "The whole vehicle").

Run from the repository root::

    .venv/bin/python -m bench.studies.articulated_modes [--params-file
        config/tractor_semitrailer.yaml] [--stuck]

Prints the static loads (per axle and gross, in t of mass, and the kingpin's) from the
statics of the spring system, and every mode of the small-motion model about equilibrium
(:meth:`ArticulatedModel.modes`): named after the coordinate holding most of its kinetic
energy (``fifth_wheel`` when the coupling's spring holds most of its strain energy), its
undamped and damped frequency, damping ratio and pole's real part, and whether every pole is
stable. ``--stuck``: the stick friction's springs k_f in parallel (as while the sliders hold).

What it found: docs/notes/articulated_modes.md.
"""
from __future__ import annotations

import argparse
import pathlib
import sys

from road_force_estimator.core.articulated_setup import ArticulatedDrive
from road_force_estimator.core.parameters import GRAVITY_MPS2, load_params_file

REPO = pathlib.Path(__file__).resolve().parents[2]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--params-file', type=pathlib.Path,
                        default=REPO / 'config' / 'tractor_semitrailer.yaml')
    parser.add_argument('--stuck', action='store_true',
                        help="the stick friction's springs in parallel (sliders holding)")
    args = parser.parse_args(argv)
    drive = ArticulatedDrive.from_values(load_params_file(args.params_file))
    model = drive.model
    st = model.statics()
    print(f'{args.params_file.name}: {model.n_axles} axles, {model.n_dof} coordinates')
    print('| axle | body | position (m) | static load (t) | left / right (kN) |')
    print('|---|---|---:|---:|---:|')
    for a, t, w in zip(model.axles, st.axle_load_kg / 1000.0, st.output_wheel_load_n):
        print(f'| {a.name} | {a.body} | {a.position_m:g} | {t:.3f} | '
              f'{w[0] / 1e3:.2f} / {w[1] / 1e3:.2f} |')
    print(f'| gross vehicle weight | | | {st.gross_weight_kg / 1000.0:.3f} | |')
    print(f'| kingpin | | {model.vehicle.fifth_wheel.position_m:g} | '
          f'{st.kingpin_load_n / GRAVITY_MPS2 / 1000.0:.3f} | |')
    print()
    print('| mode | undamped (Hz) | damped (Hz) | damping ratio | Re(pole) (1/s) |')
    print('|---|---:|---:|---:|---:|')
    modes = model.modes(stuck=args.stuck)
    for m in modes:
        print(f'| {m.name} | {m.frequency_hz:.2f} | {m.damped_frequency_hz:.2f} | '
              f'{m.damping_ratio:.3f} | {m.real_part:.2f} |')
    worst = float(max(model.poles(stuck=args.stuck).real))
    print(f'\nall {2 * model.n_dof} poles stable: {worst < 0.0} (largest real part '
          f'{worst:.3f} 1/s); fastest |pole| {model.max_pole_magnitude():.1f} 1/s')
    return 0


if __name__ == '__main__':
    sys.exit(main())
