"""Old (before the memory work) against new :mod:`.body_heave`: the same bits but for the fit.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -m bench.body_heave_bits [--samples 3600000]

The old ``zero_phase``, ``in_distance`` and ``offline_profile`` are read from the checkout's
git history (``body_heave.py`` at :data:`OLD_COMMIT`, ``old_*`` here). On the two runs of
:mod:`bench.body_heave_memory` (3.6 M samples), runs of 200 003 samples (several chunks)
and short runs (1 .. 200 samples; steady, with a stop, a speed that changes without one,
backwards, uneven steps; ``level`` None or an array), each result is compared:

* bit for bit, where no whole-run polynomial is fitted (``zero_phase``, ``in_distance`` with
  ``degree=-1``, ``offline_profile``'s path without a stop) and, with the new fit replaced by
  ``np.polyval(np.polyfit(tt, z, degree), tt)`` (the old one), everywhere: so all but the fit
  keeps its bits;
* with the new fit, as ``max |new - old| / RMS(old)`` and relative to the RMS of what the
  trend is taken off (the double integral in time; ``zero_phase``'s output on the steady path):
  the latter is the figure that stays small (the old result is that less a trend ~1e5 larger).
  In distance it is ~1e-9 (3.6 M samples): the high-pass at ``2 dx / lambda ~ 4e-6`` of the
  grid's rate amplifies rounding; the old code itself moves by as much (1e-11 .. 1e-9 of it)
  when its polyfit trend is scaled by ``1 + 1e-15``;
* exceptions: the same type and message.

Also the fit alone: ``max |polynomial_values - polyval(polyfit)| / RMS(z)`` on random data and
on the runs' ``zero_phase`` output. Exits non-zero on a bit difference.
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path
import subprocess
import sys
import types

import numpy as np

from bench.body_heave_memory import DT, inputs
from road_force_estimator.estimation import body_heave
from road_force_estimator.estimation.body_heave import (SPEED_FLOOR_MPS, rest_stretches)

__all__ = ['old_zero_phase', 'old_in_distance', 'old_offline_profile', 'main']


#: The last commit before the memory work: its body_heave.py is the old code compared with.
OLD_COMMIT = '690ec1b'
ROOT = Path(__file__).resolve().parents[1]


def _old_module() -> types.ModuleType:
    """body_heave.py as it was at :data:`OLD_COMMIT` (from the checkout's git history)."""
    src = subprocess.run(
        ['git', 'show', f'{OLD_COMMIT}:road_force_estimator/estimation/body_heave.py'],
        capture_output=True, text=True, check=True, cwd=ROOT).stdout
    mod = types.ModuleType('old_body_heave')
    exec(compile(src, 'old_body_heave.py', 'exec'), mod.__dict__)
    return mod


_OLD = _old_module()
old_zero_phase = _OLD.zero_phase
old_in_distance = _OLD.in_distance
old_offline_profile = _OLD.offline_profile


def _polyfit_trend(z, degree):
    """The old fit, shaped as the new one's coefficients (for the bit-for-bit check)."""
    tt = np.linspace(-1.0, 1.0, z.size)
    return ('polyfit', np.polyval(np.polyfit(tt, z, degree), tt))


def _polyfit_values(coef, m, i=0, j=None):
    return coef[1][i:m if j is None else j]


class _OldFit:
    """Within it, :mod:`.body_heave` fits with ``np.polyfit`` (as the old code)."""

    def __enter__(self):
        self.saved = body_heave.polynomial_fit, body_heave.polynomial_values
        body_heave.polynomial_fit, body_heave.polynomial_values = _polyfit_trend, _polyfit_values

    def __exit__(self, *exc):
        body_heave.polynomial_fit, body_heave.polynomial_values = self.saved


def _call(fn, *args, **kw):
    try:
        return np.asarray(fn(*args, **kw), dtype=float)
    except Exception as e:                          # compared as type and message
        return (type(e).__name__, str(e))


def _same(a, b) -> bool:
    if isinstance(a, tuple) or isinstance(b, tuple):
        return a == b
    return a.shape == b.shape and a.tobytes() == b.tobytes()


def _rel(a, b) -> float:
    if isinstance(a, tuple) or isinstance(b, tuple):
        return 0.0 if a == b else math.inf
    rms = float(np.sqrt(np.mean(b * b))) if b.size else 0.0
    d = float(np.max(np.abs(a - b))) if b.size else 0.0
    return d / rms if rms > 0 else d


def short_runs(seed: int = 2):
    """``(name, accel, level, t, v)`` of the short runs (see the module notes)."""
    rng = np.random.default_rng(seed)
    for m in (1, 2, 5, 7, 8, 9, 12, 15, 16, 17, 20, 31, 33, 50, 64, 100, 129, 200):
        a = rng.standard_normal(m)
        lev = 1e-3 * rng.standard_normal(m)
        t = DT * np.arange(m)
        k = np.arange(m)
        stop = np.where((k >= 0.3 * m) & (k < 0.3 * m + max(16, 0.4 * m)), 0.0, 20.0)
        ramp = np.linspace(20.0, 2.0, m)
        jitter = np.concatenate([[0.0], np.cumsum(DT * (0.5 + rng.random(m - 1)))])
        yield f'steady-{m}', a, lev, t, np.full(m, 20.0)
        yield f'stop-{m}', a, lev, t, stop
        yield f'stop-nolevel-{m}', a, None, t, stop
        yield f'ramp-{m}', a, lev, t, ramp
        yield f'back-stop-{m}', a, lev, jitter, -stop


def long_runs(n: int):
    for case in ('steady', 'stop'):
        a, lev, t, v = inputs(case, n)
        yield f'{case}-{n}', a, lev, t, v


def compare(name, a, lev, t, v) -> tuple[bool, float]:
    """Every comparison of one run: (all bits where expected, the largest relative
    difference with the new fit)."""
    ok, worst = True, 0.0
    speed = float(np.median(np.abs(v))) if v.size else 0.0
    w = 2.0 * math.pi * max(speed, SPEED_FLOOR_MPS) / 100.0
    same = [('zero_phase', old_zero_phase, body_heave.zero_phase, (a, DT, w), {})]
    fitted = []
    for deg in (-1, 0, 3):
        args, kw = (a, t, v, 1e4), {'level': lev, 'degree': deg}
        (same if deg < 0 else fitted).append((f'in_distance deg {deg}', old_in_distance,
                                              body_heave.in_distance, args, kw))
    args = (a, lev, t, v, DT, speed, 100.0, 100.0, 3)
    fitted.append(('offline_profile', old_offline_profile, body_heave.offline_profile, args,
                   {}))
    if v.size >= 8 and float(np.percentile(np.abs(v), 5.0)) < 0.5 * speed and \
            not rest_stretches(v):
        same.append(fitted.pop())                   # its path fits nothing
    for what, old, new, args, kw in [*same, *fitted]:
        with_fit = any(what == f[0] for f in fitted)
        ref = _call(old, *args, **kw)
        with _OldFit():
            got = _call(new, *args, **kw)
        bits = _same(got, ref)
        ok &= bits
        line = f'{name:>22} {what:<18} bits {"same" if bits else "DIFFER"}'
        if with_fit:
            got = _call(new, *args, **kw)
            r = _rel(got, ref)
            line += f'; new fit: {r:.1e} of RMS'
            if not isinstance(ref, tuple) and ref.size >= 8:
                # the scale of what the fit takes the trend off: the double integral in time
                # (in distance), zero_phase's output (steady)
                steady = what == 'offline_profile' and not (
                    float(np.percentile(np.abs(v), 5.0)) < 0.5 * speed and rest_stretches(v))
                zz = (old_zero_phase(a, DT, w / 100.0) if steady else
                      body_heave._cumtrapz(body_heave._cumtrapz(a, t), t))
                r = float(np.max(np.abs(got - ref)) / np.sqrt(np.mean(zz * zz)))
                line += f', {r:.1e} of RMS(z before the trend is off)'
            worst = max(worst, r)
        print(line)
    return ok, worst


def fit_error(seed: int = 3) -> float:
    """The largest ``max |polynomial_values - polyval(polyfit)| / RMS(z)`` over random data."""
    rng = np.random.default_rng(seed)
    worst = 0.0
    for m in (5, 6, 9, 37, 99, 1000, 65535, 65537, 200_003, 3_600_000):
        for deg in range(0, 6):
            if m <= deg + 1:
                continue
            tt = np.linspace(-1.0, 1.0, m)
            z = rng.standard_normal(m) + 3.0 * tt ** 3 - tt + 0.5
            ref = np.polyval(np.polyfit(tt, z, deg), tt)
            got = body_heave.polynomial_values(body_heave.polynomial_fit(z, deg), m)
            r = float(np.max(np.abs(got - ref)) / np.sqrt(np.mean(z * z)))
            worst = max(worst, r)
        print(f'fit alone: m = {m:>8}: worst so far {worst:.1e} of RMS(z)')
    return worst


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--samples', type=int, default=3_600_000)
    a = p.parse_args(argv)
    ok, worst = True, 0.0
    runs = [*short_runs(), *long_runs(200_003), *long_runs(a.samples)]
    for run in runs:
        o, w = compare(*run)
        ok, worst = ok and o, max(worst, w)
    for run in long_runs(a.samples):
        zs = body_heave.zero_phase(run[1], DT, 2.0 * math.pi * 20.0 / 1e4)
        tt = np.linspace(-1.0, 1.0, zs.size)
        ref = np.polyval(np.polyfit(tt, zs, 3), tt)
        got = body_heave.polynomial_values(body_heave.polynomial_fit(zs, 3), zs.size)
        print(f'fit alone on {run[0]} zero_phase: '
              f'{np.max(np.abs(got - ref)) / np.sqrt(np.mean(zs * zs)):.1e} of RMS(z)')
    fe = fit_error()
    print(f'bits: {"all the same" if ok else "DIFFER"}; results with the new fit within '
          f'{worst:.1e} of RMS(z before the trend is off); the fit alone within {fe:.1e} '
          'of RMS(z)')
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
