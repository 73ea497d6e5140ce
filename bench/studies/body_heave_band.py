"""The in-band error of the online body-heave high-pass (estimation/body_heave.py): the
8-pole complementary filter ``H = 1 - G`` at wavelengths inside the 0.5-30 m profile band.

``.venv/bin/python -m bench.studies.body_heave_band [--cutoff M] [--speed V] [--rate HZ]``

Per wavelength: ``|G(j Omega)|`` from the transfer function ``G = (n w^(n-1) s + w^n) / (s +
w)^n`` (n = 8, ``w = 2 pi v / lambda_c``, ``Omega = 2 pi v / lambda``), its first-order
estimate ``n (w / Omega)^(n-1)`` (the module's formula), and the error measured on the
discrete filter itself: :func:`road_force_estimator.estimation.body_heave.step` fed the
acceleration of a sine of that wavelength at the speed and rate given, its ``z_s`` fitted
(least squares, after 60 s of settling) by amplitude and phase against the sine: the
magnitude of the complex relative error ``|z_fit / z_true - 1|``.

What it found: docs/notes/body_heave_band.md.
"""
from __future__ import annotations

import argparse
import math
import sys

import numpy as np

WAVELENGTHS_M = (0.5, 1.0, 3.0, 10.0, 20.0, 30.0)


def transfer_error(ratio: float, n: int = 8) -> float:
    """``|G(j Omega)|`` at ``ratio = w / Omega``."""
    num = abs(complex(ratio ** n, n * ratio ** (n - 1)))
    return num / (1.0 + ratio * ratio) ** (n / 2.0)


def measured_error(wavelength_m: float, cutoff_m: float, speed: float, rate: float) -> float:
    """The discrete filter's complex relative error on a sine of ``wavelength_m``."""
    from road_force_estimator.estimation import body_heave

    omega = 2.0 * math.pi * speed / wavelength_m
    dt = 1.0 / rate
    settle = 60.0
    t = np.arange(0.0, settle + 20.0 * wavelength_m / speed + 1.0, dt)
    z = np.sin(omega * t)
    accel = (-omega * omega * z).tolist()
    wc = body_heave.cutoff_per_speed(cutoff_m)
    state = body_heave.start(accel[0])
    out = np.empty(t.size)
    out[0] = 0.0
    step = body_heave.step
    for k in range(1, t.size):
        state = step(state, accel[k], dt, speed, wc)
        out[k] = state[-2]
    late = t >= settle
    basis = np.column_stack([np.sin(omega * t[late]), np.cos(omega * t[late])])
    (a, b), *_ = np.linalg.lstsq(basis, out[late], rcond=None)
    return abs(complex(a, b) - 1.0)      # z_fit = a sin + b cos = Im((a + j b) e^(j w t))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog='python -m bench.studies.body_heave_band',
                                description=__doc__.splitlines()[0])
    p.add_argument('--cutoff', type=float, default=100.0, metavar='M',
                   help='observer.profile_cutoff_wavelength (m)')
    p.add_argument('--speed', type=float, default=20.0, metavar='V', help='m/s')
    p.add_argument('--rate', type=float, default=1000.0, metavar='HZ')
    args = p.parse_args(argv)
    if not (args.cutoff > 0 and args.speed > 1.0 and args.rate >= 100.0):
        print('body_heave_band: --cutoff > 0, --speed > 1 m/s, --rate >= 100 Hz',
              file=sys.stderr)
        return 2
    print(f'cutoff {args.cutoff:g} m, {args.speed:g} m/s, {args.rate:g} Hz')
    print('| wavelength (m) | |G| (transfer function, %) | 8 (w/Omega)^7 (%) | '
          'measured on body_heave.step (%) |')
    print('|---:|---:|---:|---:|')
    for lam in WAVELENGTHS_M:
        r = lam / args.cutoff
        print(f'| {lam:g} | {100 * transfer_error(r):.4g} | {100 * 8 * r ** 7:.4g} | '
              f'{100 * measured_error(lam, args.cutoff, args.speed, args.rate):.4g} |')
    return 0


if __name__ == '__main__':
    sys.exit(main())
