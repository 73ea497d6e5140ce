"""Band-limited double integration of the body heave acceleration (MODEL.md step 4).

``z_s = H(s) dd z_s / s^2`` with the high-pass ``H = 1 - G``, ``G = (n w^(n-1) s + w^n) / (s +
w)^n``, n = :data:`ORDER` = 8: eight Tustin lags ``1/(s + w)`` in cascade on ``dd z_s`` (states
``y_1..y_8``), and ``z_s = sum_{k=2..8} (k-1) w^(k-2) y_k``, ``dz_s = sum_{k<8} w^(k-1) y_k - 7
w^7 y_8``. The cutoff ``w = 2 pi max(|v|, SPEED_FLOOR_MPS) / lambda_c`` follows the speed;
standing (``|v| <`` :data:`STANDING_MPS`, the speed check's threshold) the state holds, as a
filter in distance does. In the band the error is ``|G| ~ n (w / Omega)^(n-1)``: 0.02 % at 30 m
for the 100 m default (a second-order high-pass's phase lead would cost tens of % of the
band-passed profile; five lags, ``5 (w / Omega)^4``, cost 3.1 % of it on a noise-free ISO C
drive, eight 0.85 %: ``bench`` scenarios C20-1k-0um and the noisy ones improve too); a constant
acceleration bias ``b`` settles at ``C(n, 2) b / w^2 = 28 b / w^2``. The price, outside the
band: ``|H|`` peaks at 2.5 near ``0.52 w`` (waves of ~1.9 lambda_c; five poles: 1.9) and is -3
dB near ``w / 5.9``, and a start takes longer to settle (``~t^7 exp(-w t)``: ~30 s at 20 m/s for
the 100 m default).

The filter runs in distance: when the cutoff rises with the speed, the states
``w^(k-2) y_k`` are kept (so ``z_s`` is continuous and ``dz_s`` scales with the speed; when
it falls the ``y_k`` are, so ``z_s`` shrinks: neither amplifies), and standing it holds.
At a constant speed nothing of this runs. (C20-stop: profile error 161920 % -> 34 %.)

The state is a plain tuple ``(dd z_s of the last step, its cutoff w (0 = none yet), y_1..y_8,
z_s, dz_s)`` (``z_s`` and ``dz_s`` last) so that the per-sample estimators pay one function
call. The per-sample path
uses nothing but ``math``.

Offline (non-causal) the same band-limiting is done without phase error by
:func:`zero_phase`: the double integral times ``|H_B|^2``, ``H_B`` the Butterworth high-pass
of order :data:`ZERO_PHASE_ORDER` at ``w``.
"""
from __future__ import annotations

import math

from road_force_estimator.estimation.speed_check import STANDING_MPS

__all__ = ['STANDING_MPS', 'SPEED_FLOOR_MPS', 'ORDER', 'ZERO_PHASE_ORDER', 'cutoff_per_speed',
           'start', 'step', 'zero_phase', 'in_distance', 'rest_stretches',
           'offline_profile', 'MIN_REST_SAMPLES']

#: Speed floor of the cutoff (m/s): w >= 2 pi v_floor / lambda_c.
SPEED_FLOOR_MPS = 1.0
#: Order n of the filter (n real poles at w); :func:`step` is written out for n = 8.
ORDER = 8
#: Butterworth order of the offline high-pass (even): ``1 - |H_B|^2 = 1 / (1 + (Omega / w)^8)``,
#: 6e-5 at 30 m for the 100 m default, 1.6 % at 60 m (order 2: 1.2 % and 11.5 %).
ZERO_PHASE_ORDER = 4


def cutoff_per_speed(cutoff_wavelength_m: float) -> float:
    """``w / v = 2 pi / lambda_c`` (rad/m)."""
    return 2.0 * math.pi / cutoff_wavelength_m


def start(accel: float) -> tuple:
    """State of a (re)start: at rest, ``z_s = dz_s = 0``, remembering ``dd z_s``."""
    return (accel, 0.0) + (0.0,) * (ORDER + 2)


def step(state: tuple, accel: float, dt: float, v: float, wc_per_speed: float) -> tuple:
    """Advance by ``dt`` (s) with the new acceleration ``accel`` (m/s^2) at speed ``v`` (m/s).

    Returns the new state; ``state[-2]`` is ``z_s`` (m) and ``state[-1]`` is ``dz_s`` (m/s).
    Below :data:`STANDING_MPS` (the truck stands) the state holds: ``z_s`` as it was,
    ``dz_s = 0``.
    """
    a_old, w_old, y1, y2, y3, y4, y5, y6, y7, y8, zs, _ = state
    av = v if v > 0.0 else -v
    if av < STANDING_MPS:
        # standing: the filter runs in distance (its cutoff is a wavelength) and no distance
        # passes, so it holds (run in time, it would forget the body's level: 8.7 mm in
        # 2.5 s at its 1 m/s floor); z_s held, dz_s = 0, the newest dd z_s remembered
        return (accel, w_old, y1, y2, y3, y4, y5, y6, y7, y8, zs, 0.0)
    wc = wc_per_speed * (av if av > SPEED_FLOOR_MPS else SPEED_FLOOR_MPS)
    if wc > w_old > 0.0:
        # the cutoff rose with the speed: the states in distance, w^(k-2) y_k, are kept
        # (z_s continuous, dz_s scaled with the speed); with the y_k kept, those built at a
        # low cutoff would come out times (w / w_old)^6 (1.9 m after pulling away to 20 m/s).
        # (Slowing down, the y_k are kept: z_s then shrinks, it never grows; kept in
        # distance it would, by a bias's 1 / w^2)
        r = w_old / wc
        y1 /= r
        y3 *= r
        r2 = r * r
        y4 *= r2
        y5 *= r2 * r
        r4 = r2 * r2
        y6 *= r4
        y7 *= r4 * r
        y8 *= r4 * r2
    hh = 0.5 * dt
    inv = 1.0 / (1.0 + wc * hh)
    g = (1.0 - wc * hh) * inv
    hh *= inv
    n1 = g * y1 + hh * (a_old + accel)
    n2 = g * y2 + hh * (y1 + n1)
    n3 = g * y3 + hh * (y2 + n2)
    n4 = g * y4 + hh * (y3 + n3)
    n5 = g * y5 + hh * (y4 + n4)
    n6 = g * y6 + hh * (y5 + n5)
    n7 = g * y7 + hh * (y6 + n6)
    n8 = g * y8 + hh * (y7 + n7)
    return (accel, wc, n1, n2, n3, n4, n5, n6, n7, n8,
            n2 + wc * (2.0 * n3 + wc * (3.0 * n4 + wc * (4.0 * n5 + wc * (
                5.0 * n6 + wc * (6.0 * n7 + wc * 7.0 * n8))))),
            n1 + wc * (n2 + wc * (n3 + wc * (n4 + wc * (n5 + wc * (
                n6 + wc * (n7 - 7.0 * wc * n8)))))))


def zero_phase(accel, dt_s: float, w: float, order: int = ZERO_PHASE_ORDER):
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


#: Fewest samples of a standing stretch whose body motion corrects the integrated rate
#: (:func:`in_distance`).
MIN_REST_SAMPLES = 16


def _rest_edges(standing):
    """``(first step, end step)`` pairs of the stretches of standing steps (bool (m - 1,))
    with at least :data:`MIN_REST_SAMPLES` samples."""
    import numpy as np

    flag = np.concatenate([[False], standing, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(flag))          # stretch j: steps s0 .. s1 - 1
    return [(int(s0), int(s1)) for s0, s1 in zip(edges[0::2], edges[1::2])
            if s1 + 1 - s0 >= MIN_REST_SAMPLES]


def rest_stretches(v_mps) -> int:
    """How many standing stretches (``v = 0`` at both ends of each step, at least
    :data:`MIN_REST_SAMPLES` samples) the speeds (m/s) have: those :func:`in_distance`
    corrects the integrated rate with."""
    import numpy as np

    v = np.asarray(v_mps, dtype=float)
    return len(_rest_edges((v[1:] == 0.0) & (v[:-1] == 0.0))) if v.size > 1 else 0


def _rest_correction(t, z, standing, level):
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


def in_distance(accel, t_s, v_mps, wavelength_m: float, *, level=None, degree: int = 3,
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
        c = _rest_correction(t, z, standing, lev)
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


def offline_profile(accel, level, t_s, v_mps, dt_s: float, speed_mps: float,
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
        return in_distance(a, t_s, v, wavelength, level=level, degree=degree)
    speed = max(speed_mps, SPEED_FLOOR_MPS)
    if not steady:
        return zero_phase(a, dt_s, 2.0 * math.pi * speed / cutoff_wavelength_m)
    zs = zero_phase(a, dt_s, 2.0 * math.pi * speed / wavelength)
    tt = np.linspace(-1.0, 1.0, zs.size)
    return zs - np.polyval(np.polyfit(tt, zs, degree), tt)
