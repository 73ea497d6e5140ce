"""The articulated plant's integration error against scipy's solve_ivp on MODEL.md's equations.

Run from the repository root::

    .venv/bin/python -m bench.studies.articulated_accuracy [--substeps 1 2]

The drive and the reference are those of ``test/core/test_articulated_plant.py`` (the
equations rewritten in ``test/articulated_reference.py``, not imported from the package):
MODEL.md's 5-axle combination on an ISO class C road, braking from 15 m/s at 3 m/s^2 to a
stop while in a 2 m/s^2 curve, 10 s at 1 kHz. Printed per RK4 step count: the RMS and the
largest error of the wheel loads, and the RMS error relative to the dynamic-load RMS (the
test's bound: 1e-4), overall and for the worst wheel.

What it found: docs/notes/articulated_accuracy.md.
"""
from __future__ import annotations

import argparse
import pathlib
import sys
import time

import numpy as np

REPO = pathlib.Path(__file__).resolve().parents[2]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--substeps', type=int, nargs='*', default=[1, 2])
    args = parser.parse_args(argv)
    sys.path[:0] = [str(REPO / 'test'), str(REPO / 'test' / 'core')]
    from test_articulated_plant import _drive, _reference_run

    for n in args.substeps:
        start = time.perf_counter()
        tr, env, tk, vk, curve = _drive(substeps=n)
        loads, st = _reference_run(tr, env, tk, vk, curve)
        dyn = loads - np.repeat(st['wheel'] / 2, 2)
        err = tr.wheel_load_n - loads
        rms = np.sqrt(np.mean(err ** 2))
        per = np.sqrt(np.mean(err ** 2, axis=0)) / np.sqrt(np.mean(dyn ** 2, axis=0))
        print(f'{n} RK4 step(s) per sample: load error RMS {rms:.3g} N, max '
              f'{np.max(np.abs(err)):.3g} N; RMS / dynamic RMS '
              f'{rms / np.sqrt(np.mean(dyn ** 2)):.2e} (worst wheel {per.max():.2e}); '
              f'dynamic-load RMS {np.sqrt(np.mean(dyn ** 2)) / 1e3:.2f} kN '
              f'({time.perf_counter() - start:.0f} s)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
