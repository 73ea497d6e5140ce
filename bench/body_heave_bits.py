"""Old (before the memory work) against new :mod:`.body_heave`: the same bits but for the fit.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -m bench.body_heave_bits [--samples 3600000]

The old ``zero_phase``, ``_rest_correction``, ``in_distance`` and ``offline_profile`` are kept
here verbatim (renamed ``old_*``). On the two runs of :mod:`bench.body_heave_memory` (3.6 M
samples), runs of 200 003 samples (several chunks) and short runs (1 .. 200 samples; steady,
with a stop, a speed that changes without one, backwards, uneven steps; ``level`` None or an
array), each result is compared:

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
import sys

import numpy as np

from bench.body_heave_memory import DT, inputs
from road_force_estimator.estimation import body_heave
from road_force_estimator.estimation.body_heave import (SPEED_FLOOR_MPS, ZERO_PHASE_ORDER,
                                                         _rest_edges, rest_stretches)

__all__ = ['old_zero_phase', 'old_in_distance', 'old_offline_profile', 'main']


def old_zero_phase(accel, dt_s: float, w: float, order: int = ZERO_PHASE_ORDER):
    """Band-limited double integral of an evenly sampled acceleration, without phase error.

    ``z = -|H_B(j Omega)|^2 a / Omega^2``: ``s^(n-2) / D(s)`` run forward and ``s^n / D(s)``
    backward (D the Butterworth denominator of even order n at ``w`` rad/s; bilinear at the
    sample rate, in second-order sections, each pass started in its steady state for the first
    / last value). A constant acceleration gives zero.

    Parameters
    ----------
    accel : array_like (m,)
        Acceleration (m/s^2).
    dt_s : float
        Step (s).
    w : float
        Cutoff (rad/s), > 0.
    order : int
        Even Butterworth order n >= 2.

    Returns
    -------
    ndarray (m,)
        Displacement (m); zeros when there are fewer than 8 samples.
    """
    import numpy as np
    from road_force_estimator.core.scipy_signal import signal as _signal
    signal = _signal()

    a = np.asarray(accel, dtype=float)
    if a.size < 8:
        return np.zeros_like(a)
    if order < 2 or order % 2:
        raise ValueError(f'order = {order!r}: must be an even integer >= 2')
    fs = 1.0 / dt_s
    _, poles, _ = signal.butter(order, w, btype='high', analog=True, output='zpk')
    out = a
    for n_zeros, reverse in ((order - 2, False), (order, True)):
        z, p, k = signal.bilinear_zpk(np.zeros(n_zeros), poles, 1.0, fs)
        sos = signal.zpk2sos(z, p, k)
        x = out[::-1] if reverse else out
        y, _ = signal.sosfilt(sos, x, zi=signal.sosfilt_zi(sos) * x[0])
        out = y[::-1] if reverse else y
    return np.ascontiguousarray(out)



def old_rest_correction(t, z, standing, level):
    """The rate error (m/s) of a double integral ``z`` (m) at the times t (s) from the
    standing steps: over each stretch of them (at least :data:`MIN_REST_SAMPLES` samples)
    ``z + level`` is constant but for the integral's error, fitted there by a quadratic in
    time; its derivative is the error there, linear in time between stretches (a constant
    acceleration bias), before the first and after the last going on with the acceleration
    bias fitted on it (held constant there, a bias the whole drive long, as the profile pass's
    under ``zero_load`` while its offset settles, made a kink of the rate at the stop: bench
    real_truck (f) 207 / 229 %, now 27 / 8.8 %). None without such a stretch."""
    import numpy as np

    knots_t, knots_c, bias = [], [], []
    for s0, s1 in _rest_edges(standing):
        rows = slice(s0, s1 + 1)                     # the samples at both ends of its steps
        tt = t[rows] - t[s0]
        scale = max(float(tt[-1]), 1e-9)
        p = np.polyfit(tt / scale, z[rows] + level[rows], 2)
        knots_t.append(t[rows])
        knots_c.append((p[1] + 2.0 * p[0] * tt / scale) / scale)
        bias.append(2.0 * p[0] / (scale * scale))    # the acceleration bias there (m/s^2)
    if not knots_t:
        return None
    kt, kc = np.concatenate(knots_t), np.concatenate(knots_c)
    c = np.interp(t, kt, kc)
    # before the first stretch and after the last the bias goes on as fitted there (between
    # two the rate's linear interpolation is a constant bias too)
    c = np.where(t < kt[0], kc[0] + bias[0] * (t - kt[0]), c)
    return np.where(t > kt[-1], kc[-1] + bias[-1] * (t - kt[-1]), c)



def old_in_distance(accel, t_s, v_mps, wavelength_m: float, *, level=None, degree: int = 3,
                order: int = ZERO_PHASE_ORDER):
    """Band-limited double integral of a body acceleration over a drive whose speed changes,
    without phase error, its long waves taken off in distance (offline, runs with stops).

    ``dd z_s`` (sampled in time) is integrated twice in time (trapezoid). Standing (``v = 0``
    at both ends of a step) the road under the tires is fixed, so ``z_s + level`` is constant
    (``level``: the rest of the road estimate, ``s sin(phi) - q_i + w_i`` averaged over the
    wheels; 0 when None: the body at rest): over each standing stretch the integral's error is
    fitted (a quadratic in time) and its rate error, interpolated linearly in time between
    stretches (a zero-velocity update, the smoother of a random-walk rate error) and going on
    with the acceleration bias fitted on the first / last stretch before / after them, taken
    off the rate. What the double integral leaves at long waves is then taken off in distance: on
    an even grid of ``x = integral |v| dt``, its least-squares polynomial of degree ``degree``
    in x and the zero-phase Butterworth high-pass ``|H_B|^2`` (order ``order`` per pass) at
    ``wavelength_m``; the trend so removed is interpolated back onto the samples (the short
    waves stay those of the samples). A filter run in time with one cutoff removes, through
    the slow stretches, waves of a few metres (``v / f_c``): this one's cutoff is a
    wavelength everywhere.

    Parameters
    ----------
    accel : array_like (m,)
        ``dd z_s`` (m/s^2).
    t_s : array_like (m,)
        Times (s), increasing.
    v_mps : array_like (m,)
        Speed (m/s); 0 = standing.
    wavelength_m : float
        Cutoff wavelength (m), > 0.
    level : array_like (m,), optional
        See above (m).
    degree : int
        Degree of the polynomial in distance taken off first (< 0: none).
    order : int
        Butterworth order of the high-pass (each of the two passes).

    Returns
    -------
    ndarray (m,)
        ``z_s`` (m); zeros when there are fewer than 8 samples.
    """
    import numpy as np
    from road_force_estimator.core.scipy_signal import signal as _signal

    a = np.asarray(accel, dtype=float)
    t = np.asarray(t_s, dtype=float)
    v = np.abs(np.asarray(v_mps, dtype=float))
    if a.size < 8:
        return np.zeros_like(a)
    dt = np.diff(t)
    standing = (v[1:] == 0.0) & (v[:-1] == 0.0)
    vel = np.concatenate([[0.0], np.cumsum(0.5 * (a[1:] + a[:-1]) * dt)])
    z = np.concatenate([[0.0], np.cumsum(0.5 * (vel[1:] + vel[:-1]) * dt)])
    if standing.any():
        lev = np.zeros_like(a) if level is None else np.asarray(level, dtype=float)
        c = old_rest_correction(t, z, standing, lev)
        if c is not None:
            vel = vel - c
            z = np.concatenate([[0.0], np.cumsum(0.5 * (vel[1:] + vel[:-1]) * dt)])
    dx = 0.5 * (v[1:] + v[:-1]) * dt
    x = np.concatenate([[0.0], np.cumsum(dx)])
    moving = np.concatenate([[True], dx > 0.0])
    xm, zm = x[moving], z[moving]
    if xm.size < 8 or not xm[-1] > 0.0:
        return z - np.mean(z)
    h = float(np.median(np.diff(xm)))
    grid = np.linspace(0.0, xm[-1], max(8, int(math.ceil(xm[-1] / h)) + 1))
    zg = np.interp(grid, xm, zm)
    trend = np.zeros_like(zg)
    if degree >= 0:
        tt = np.linspace(-1.0, 1.0, grid.size)
        trend = np.polyval(np.polyfit(tt, zg, degree), tt)
    signal = _signal()
    sos = signal.butter(order, 2.0 * (grid[1] - grid[0]) / wavelength_m, btype='high',
                        output='sos')
    rest = zg - trend
    trend = trend + (rest - signal.sosfiltfilt(sos, rest))
    return z - np.interp(x, grid, trend)



def old_offline_profile(accel, level, t_s, v_mps, dt_s: float, speed_mps: float,
                    cutoff_wavelength_m: float, ratio: float, degree: int):
    """The offline profile's body heave (m; 0 under 8 samples) of one run (the smoother's).

    Steady speed (the 5th percentile of ``|v|`` at least half of ``speed_mps``, the run's
    median |v|, floored at :data:`SPEED_FLOOR_MPS` for the cutoffs): :func:`zero_phase` at
    ``ratio x cutoff_wavelength_m`` at that speed, less the run's least-squares polynomial of
    degree ``degree`` (a cutoff longer than the run leaves the filter's edge transients and
    the double integral's wander as a smooth curve over the whole run: metres on a 120 m run
    at 10 km; waves of the run's length, which no band-passed figure sees). A stop
    (:func:`rest_stretches`): :func:`in_distance` at that wavelength with ``level`` (run in
    time with one cutoff, the slow stretches lost their metre waves: C20-stop 55.4 %, now
    0.88 %; kf-model-rts 4.17 %). A speed that changes without a stop to correct the rate
    with: :func:`zero_phase` at ``cutoff_wavelength_m`` (the long one lets the drift of the
    slow stretches into the profile: C20-stop 164 % against 55 %). ``accel`` (m/s^2),
    ``level`` (m), times ``t_s``
    (s), speeds ``v_mps`` (m/s): (m,); ``dt_s`` the run's step (s).
    """
    import numpy as np

    a = np.asarray(accel, dtype=float)
    if a.size < 8:
        return 0.0
    v = np.asarray(v_mps, dtype=float)
    wavelength = ratio * cutoff_wavelength_m
    steady = float(np.percentile(np.abs(v), 5.0)) >= 0.5 * speed_mps
    if not steady and rest_stretches(v):
        return old_in_distance(a, t_s, v, wavelength, level=level, degree=degree)
    speed = max(speed_mps, SPEED_FLOOR_MPS)
    if not steady:
        return old_zero_phase(a, dt_s, 2.0 * math.pi * speed / cutoff_wavelength_m)
    zs = old_zero_phase(a, dt_s, 2.0 * math.pi * speed / wavelength)
    tt = np.linspace(-1.0, 1.0, zs.size)
    return zs - np.polyval(np.polyfit(tt, zs, degree), tt)


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
