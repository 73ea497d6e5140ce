"""Band-limited double integration of the body heave acceleration (MODEL.md step 4).

``z_s = H(s) dd z_s / s^2`` with the high-pass ``H = 1 - G``, ``G = (n w^(n-1) s + w^n) / (s +
w)^n``, n = :data:`ORDER` = 8: eight Tustin lags ``1/(s + w)`` in cascade on ``dd z_s`` (states
``y_1..y_8``), and ``z_s = sum_{k=2..8} (k-1) w^(k-2) y_k``, ``dz_s = sum_{k<8} w^(k-1) y_k - 7
w^7 y_8``. The cutoff ``w = 2 pi max(|v|, SPEED_FLOOR_MPS) / lambda_c`` follows the speed;
standing (``|v| <`` :data:`STANDING_MPS`, the speed check's threshold) the state holds, as a
filter in distance does. In the band the error is ``|G(j Omega)|`` (first-order estimate ``n (w
/ Omega)^(n-1)``): 0.12 % at 30 m for the 100 m default (the estimate: 0.18 %), and the
Tustin steps' frequency warping at the short waves (about 1 % at 0.5 m at 20 m/s and 1 kHz;
both measured on :func:`step` by ``python -m bench.studies.body_heave_band``). Why eight: a
second-order high-pass's phase lead would cost tens of % of the band-passed profile; five
lags, ``5 (w / Omega)^4``, cost several times what eight cost on the noise-free benchmark
scenario when the order was chosen (``python -m bench.accuracy.run_benchmark --scenarios
C20-1k-0um``; the noisy ones improved too). A
constant acceleration bias ``b`` settles at ``C(n, 2) b / w^2 = 28 b / w^2``. The price,
outside the band: ``|H|`` peaks at 2.5 near ``0.52 w`` (waves of ~1.9 lambda_c; five poles:
1.9) and is -3 dB near ``w / 5.9``, and a start takes longer to settle (``~t^7 exp(-w t)``:
~30 s at 20 m/s for the 100 m default).

The filter runs in distance: when the cutoff rises with the speed, the states
``w^(k-2) y_k`` are kept (so ``z_s`` is continuous and ``dz_s`` scales with the speed; when
it falls the ``y_k`` are, so ``z_s`` shrinks: neither amplifies), and standing it holds.
At a constant speed nothing of this runs. (What it does on a stop: ``python -m
bench.accuracy.run_benchmark --scenarios C20-stop``.)

The state is a plain tuple ``(dd z_s of the last step, its cutoff w (0 = none yet), y_1..y_8,
z_s, dz_s)`` (``z_s`` and ``dz_s`` last) so that the per-sample estimators pay one function
call. The per-sample path
uses nothing but ``math``; :func:`step_matrix` is the same step as one matrix (numpy), for
many filters of one cutoff at once (the whole vehicle's wheels).

Offline (non-causal) the same band-limiting is done without phase error by
:func:`zero_phase`: the double integral times ``|H_B|^2``, ``H_B`` the Butterworth high-pass
of order :data:`ZERO_PHASE_ORDER` at ``w``.
"""
from __future__ import annotations

import functools
import math

from road_force_estimator.estimation.speed_check import STANDING_MPS

__all__ = ['STANDING_MPS', 'SPEED_FLOOR_MPS', 'ORDER', 'ZERO_PHASE_ORDER', 'cutoff_per_speed',
           'start', 'step', 'step_matrix', 'zero_phase', 'in_distance', 'rest_stretches',
           'offline_profile', 'MIN_REST_SAMPLES', 'CHUNK', 'polynomial_fit',
           'polynomial_values', 'subtract_polynomial', 'zero_phase_sections',
           'zero_phase_pieces', 'polynomial_fit_pieces', 'offline_profile_way']

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


def step_matrix(dt: float, wc: float):
    """:func:`step`'s eight Tustin lags and its ``z_s`` over a step dt (s) at the cutoff wc
    (rad/s) as one (9, 9) matrix M (numpy): ``[n_1..n_8, z_s] = M [y_1..y_8, a_old + accel]``
    (a column per filter: many filters of one cutoff step in one product). The recursion
    ``n_k = g y_k + hh (y_(k-1) + n_(k-1))`` (``y_0 + n_0 = a_old + accel``) multiplied out:
    ``n = g y + (1 + g) sum_(m>=1) hh^m S^m y + (hh, hh^2, .., hh^8) (a_old + accel)``, S
    the shift, g and hh as :func:`step` makes them; ``z_s`` the row ``(0, 1, 2 wc, ..,
    7 wc^6) @ M``. The same filter, rounded otherwise than :func:`step` (within rounding:
    test_body_heave.py); the speed's rescaling and standing are the caller's, as in
    :func:`step`."""
    import numpy as np

    hh = 0.5 * dt
    inv = 1.0 / (1.0 + wc * hh)
    g = (1.0 - wc * hh) * inv
    hh *= inv
    one_g = 1.0 + g
    h2 = hh * hh
    h4 = h2 * h2
    w2 = wc * wc
    w4 = w2 * w2
    pw = (hh, h2, h2 * hh, h4, h4 * hh, h4 * h2, h4 * h2 * hh, h4 * h4)   # hh^1 .. hh^8
    # [0, g, (1 + g) hh^1..7, hh^1..8, then (k - 1) wc^(k - 2) of k = 1..8]
    gen = np.array((0.0, g, one_g * hh, one_g * pw[1], one_g * pw[2], one_g * pw[3],
                    one_g * pw[4], one_g * pw[5], one_g * pw[6], *pw,
                    0.0, 1.0, 2.0 * wc, 3.0 * w2, 4.0 * w2 * wc, 5.0 * w4, 6.0 * w4 * wc,
                    7.0 * w4 * w2))
    m = np.empty((ORDER + 1, ORDER + 1))
    m[:ORDER] = gen[_matrix_index()]               # Toeplitz, lower triangular; the input
    np.dot(gen[2 * ORDER + 1:], m[:ORDER], out=m[ORDER])
    return m


@functools.lru_cache(maxsize=1)
def _matrix_index():
    """Where :func:`step_matrix`'s rows of the lags take their numbers from ``[0, g, (1 + g)
    hh^1..7, hh^1..8]``: (8, 9) indices."""
    import numpy as np

    k = np.arange(ORDER)
    lag = k[:, None] - k[None, :]
    index = np.where(lag >= 0, 1 + lag, 0)
    return np.hstack([index, (1 + ORDER + k)[:, None]])


#: Samples per chunk of the whole-run steps done piecewise (a float64 chunk: 512 kB), so that
#: a run of hours (14.4 M samples at 1 kHz in 4 h: 115 MB per float64 array) needs no
#: whole-run temporaries there.
CHUNK = 1 << 16


def _chunks(m: int, backward: bool = False):
    """``(i, j)`` of the :data:`CHUNK`-long pieces of ``range(m)``, in order (or backward)."""
    starts = range(0, m, CHUNK)
    for i in (reversed(starts) if backward else starts):
        yield i, min(m, i + CHUNK)


def _sosfilt_chunks(sos, src, dst, zi, backward: bool = False) -> None:
    """``scipy.signal.sosfilt(sos, src, zi=zi)`` (over ``src[::-1]``, the result reversed,
    when ``backward``) into ``dst`` (may be ``src``), chunk after chunk with the state carried:
    the same bits, no whole-run copy."""
    from road_force_estimator.core.scipy_signal import signal as _signal
    sosfilt = _signal().sosfilt

    for i, j in _chunks(src.size, backward):
        if backward:
            dst[i:j][::-1], zi = sosfilt(sos, src[i:j][::-1], zi=zi)
        else:
            dst[i:j], zi = sosfilt(sos, src[i:j], zi=zi)


def _sosfiltfilt(sos, x):
    """``scipy.signal.sosfiltfilt(sos, x)`` (1-D, its default odd padding), the same bits and
    errors, with one whole-run array (the padded one; the result is a view of it)."""
    import numpy as np
    from road_force_estimator.core.scipy_signal import signal as _signal

    ntaps = 2 * sos.shape[0] + 1 - min(int((sos[:, 2] == 0).sum()), int((sos[:, 5] == 0).sum()))
    edge = 3 * ntaps
    if x.size <= edge:
        raise ValueError('The length of the input vector x must be greater than padlen, '
                         f'which is {edge}.')
    ext = np.empty(x.size + 2 * edge)
    np.subtract(2 * x[:1], x[edge:0:-1], out=ext[:edge])
    ext[edge:-edge] = x
    np.subtract(2 * x[-1:], x[-2:-(edge + 2):-1], out=ext[-edge:])
    zi = _signal().sosfilt_zi(sos)
    _sosfilt_chunks(sos, ext, ext, zi * ext[:1])
    _sosfilt_chunks(sos, ext, ext, zi * ext[-1:], backward=True)
    return ext[edge:-edge]


def zero_phase(accel, dt_s: float, w: float, order: int = ZERO_PHASE_ORDER):
    """Band-limited double integral of an evenly sampled acceleration, without phase error.

    ``z = -|H_B(j Omega)|^2 a / Omega^2``: ``s^(n-2) / D(s)`` run forward and ``s^n / D(s)``
    backward (D the Butterworth denominator of even order n at ``w`` rad/s; bilinear at the
    sample rate, in second-order sections, each pass started in its steady state for the first
    / last value). A constant acceleration gives zero. Both passes run in chunks in the result
    (one whole-run array).

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
    out = np.empty(a.shape)
    for sos, backward in zip(zero_phase_sections(dt_s, w, order), (False, True)):
        src = out if backward else a
        zi = signal.sosfilt_zi(sos) * src[-1 if backward else 0]
        _sosfilt_chunks(sos, src, out, zi, backward)
    return out


def zero_phase_pieces(m: int, read, width: int, dt_s: float, w: float, folder=None,
                      piece: int = CHUNK, order: int = ZERO_PHASE_ORDER):
    """:func:`zero_phase` of ``width`` series of ``m`` samples (m >= 8) read ``piece`` rows at a
    time, ``read(i, j) -> (j - i, width)`` accelerations (m/s^2): the forward pass over the
    pieces in order, its state carried, its output in a file in ``folder``, the backward pass
    over the pieces in reverse, written over it. Returns that file (a
    :class:`~.core.spill.SpillColumn` (m, width) of displacements, m; the caller closes it):
    each column :func:`zero_phase`'s bits, none held whole."""
    import numpy as np
    from road_force_estimator.core.scipy_signal import signal as _signal
    from road_force_estimator.core.spill import SpillColumn

    sosfilt, sosfilt_zi = _signal().sosfilt, _signal().sosfilt_zi
    piece = max(int(piece), 1)
    bounds = [(i, min(m, i + piece)) for i in range(0, m, piece)]
    fwd_sos, back_sos = zero_phase_sections(dt_s, w, order)
    out = SpillColumn(float, width, folder)
    try:
        zi = None
        for i, j in bounds:
            a = np.asarray(read(i, j), dtype=float)
            if zi is None:
                zi = [sosfilt_zi(fwd_sos) * a[0, k] for k in range(width)]
            f = np.empty_like(a)
            for k in range(width):
                f[:, k], zi[k] = sosfilt(fwd_sos, a[:, k], zi=zi[k])
            out.append(f)
        last = out.read(m - 1, m)[0]
        zi = [sosfilt_zi(back_sos) * last[k] for k in range(width)]
        for i, j in reversed(bounds):
            f = out.read(i, j)
            z = np.empty_like(f)
            for k in range(width):
                z[::-1, k], zi[k] = sosfilt(back_sos, f[::-1, k], zi=zi[k])
            out.write(i, z)
    except BaseException:
        out.close()
        raise
    return out


def zero_phase_sections(dt_s: float, w: float, order: int = ZERO_PHASE_ORDER) -> tuple:
    """The second-order sections of :func:`zero_phase`'s forward pass (``s^(n-2) / D(s)``)
    and backward pass (``s^n / D(s)``), bilinear at the step ``dt_s`` (s), cutoff ``w``
    (rad/s), even order ``n``: for a caller that runs them over pieces (the same bits)."""
    import numpy as np
    from road_force_estimator.core.scipy_signal import signal as _signal
    signal = _signal()

    if order < 2 or order % 2:
        raise ValueError(f'order = {order!r}: must be an even integer >= 2')
    _, poles, _ = signal.butter(order, w, btype='high', analog=True, output='zpk')
    out = []
    for n_zeros in (order - 2, order):
        z, p, k = signal.bilinear_zpk(np.zeros(n_zeros), poles, 1.0, 1.0 / dt_s)
        out.append(signal.zpk2sos(z, p, k))
    return tuple(out)


def _linspace_part(start: float, stop: float, num: int, i: int, j: int):
    """``np.linspace(start, stop, num)[i:j]`` bit for bit without the whole array (numpy's
    ``k * step + start``, the last point ``stop``)."""
    import numpy as np

    if num < 2:
        return np.linspace(start, stop, num)[i:j]
    div = num - 1
    delta = stop - start
    step = delta / div
    y = np.arange(i, j, dtype=float)
    if step == 0:                                    # numpy's way for denormal steps
        y /= div
        y *= delta
    else:
        y *= step
    y += start
    if j == num and j > i:
        y[-1] = stop
    return y


def _legendre(tt, degree: int):
    """The Legendre polynomials ``P_0 .. P_degree`` at ``tt``: (degree + 1, tt.size)."""
    import numpy as np

    p = np.empty((degree + 1, tt.size))
    p[0] = 1.0
    if degree >= 1:
        p[1] = tt
    for k in range(1, degree):
        p[k + 1] = ((2 * k + 1) * tt * p[k] - k * p[k - 1]) / (k + 1)
    return p


def polynomial_fit(z, degree: int):
    """Legendre coefficients (degree + 1,) of the least-squares polynomial of degree ``degree``
    of ``z`` (m,) on ``tt = linspace(-1, 1, m)`` (``np.polyfit(tt, z, degree)``'s), from sums
    over chunks (the basis' Gram matrix and its dot products with z, solved as a small system)
    instead of an (m, degree + 1) Vandermonde matrix and its copies (~80 bytes a sample).

    Its values (:func:`polynomial_values`) differ from ``np.polyval(np.polyfit(tt, z, degree),
    tt)`` by at most 1.3e-14 of z's RMS (random data, m = 5 .. 3.6 M, degree 0 .. 5; 2.2e-15 on
    :func:`zero_phase`'s output over 3.6 M samples: docs/notes/body_heave_bits.md).
    """
    import numpy as np

    z = np.asarray(z, dtype=float)
    return polynomial_fit_pieces(z.size, lambda i, j: z[i:j], degree)


def polynomial_fit_pieces(m: int, read, degree: int):
    """:func:`polynomial_fit` of a series of ``m`` values read a :data:`CHUNK` at a time,
    ``read(i, j) -> z[i:j]`` (m,), in order (from a file: the same chunks, the same bits)."""
    import numpy as np

    if degree < 0:
        raise ValueError('expected deg >= 0')
    gram = np.zeros((degree + 1, degree + 1))
    dot = np.zeros(degree + 1)
    for i, j in _chunks(m):
        p = _legendre(_linspace_part(-1.0, 1.0, m, i, j), degree)
        gram += p @ p.T
        dot += p @ np.asarray(read(i, j), dtype=float)
    if m > degree:
        return np.linalg.solve(gram, dot)
    return np.linalg.lstsq(gram, dot, rcond=None)[0]       # interpolates: any solution


def polynomial_values(coef, m: int, i: int = 0, j: int | None = None):
    """The polynomial of Legendre coefficients ``coef`` (:func:`polynomial_fit`) on
    ``linspace(-1, 1, m)[i:j]``; each value the same bits whatever the piece."""
    j = m if j is None else j
    p = _legendre(_linspace_part(-1.0, 1.0, m, i, j), coef.size - 1)
    out = coef[0] * p[0]
    for k in range(1, coef.size):              # elementwise (a matrix product's rounding
        out += coef[k] * p[k]                  # would depend on the piece)
    return out


def subtract_polynomial(z, degree: int):
    """``z`` (m,) less its least-squares polynomial (:func:`polynomial_fit`), in place and in
    chunks; returns ``z``."""
    coef = polynomial_fit(z, degree)
    for i, j in _chunks(z.size):
        z[i:j] -= polynomial_values(coef, z.size, i, j)
    return z

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
    """The knots ``(kt, kc, bias)`` of the rate error (m/s) of a double integral ``z`` (m) at
    the times t (s) from the standing steps (:func:`_rest_rate` makes the error of them): over
    each stretch of them (at least :data:`MIN_REST_SAMPLES` samples) ``z + level`` (``level``
    None: 0) is constant but for the integral's error, fitted there by a quadratic in time; its
    derivative is the error there (``kc`` at the stretch's times ``kt``), linear in time between
    stretches (a constant acceleration bias), before the first and after the last going on with
    the acceleration bias fitted on it (``bias``, m/s^2; held constant there, a bias the whole
    drive long, as the profile pass's under ``zero_load`` while its offset settles, made a kink
    of the rate at the stop: the real-truck family's drive with every effect at once, ``python
    -m bench.accuracy.real_truck --drives all``). None without such a stretch."""
    import numpy as np

    knots_t, knots_c, bias = [], [], []
    for s0, s1 in _rest_edges(standing):
        rows = slice(s0, s1 + 1)                     # the samples at both ends of its steps
        tt = t[rows] - t[s0]
        scale = max(float(tt[-1]), 1e-9)
        p = np.polyfit(tt / scale, z[rows] + (0.0 if level is None else level[rows]), 2)
        knots_t.append(t[rows])
        knots_c.append((p[1] + 2.0 * p[0] * tt / scale) / scale)
        bias.append(2.0 * p[0] / (scale * scale))    # the acceleration bias there (m/s^2)
    if not knots_t:
        return None
    return np.concatenate(knots_t), np.concatenate(knots_c), bias


def _rest_rate(t, knots):
    """The rate error (m/s) at the times ``t`` (s; any piece of the run's) of the knots of
    :func:`_rest_correction`."""
    import numpy as np

    kt, kc, bias = knots
    c = np.interp(t, kt, kc)
    # before the first stretch and after the last the bias goes on as fitted there (between
    # two the rate's linear interpolation is a constant bias too); in place in c
    for side, k in ((t < kt[0], 0), (t > kt[-1], -1)):
        np.subtract(t, kt[k], out=c, where=side)
        np.multiply(c, bias[k], out=c, where=side)
        np.add(c, kc[k], out=c, where=side)
    return c


def _compact(z, keep):
    """Move ``z[keep]`` (keep: bool) to the front of ``z`` in place, chunk by chunk; returns
    how many and a copy of the others (for :func:`_expand`)."""
    others = z[~keep]
    n = 0
    for i, j in _chunks(z.size):
        part = z[i:j][keep[i:j]]
        z[n:n + part.size] = part
        n += part.size
    return n, others


def _expand(z, keep, n: int, others) -> None:
    """Undo :func:`_compact` (``n, others`` its result) in place, chunk by chunk from the end."""
    import numpy as np

    n_others = others.size
    for i, j in _chunks(z.size, backward=True):
        k = keep[i:j]
        c = int(np.count_nonzero(k))
        kept = z[n - c:n].copy()
        seg = z[i:j]
        seg[k] = kept
        seg[~k] = others[n_others - (k.size - c):n_others]
        n -= c
        n_others -= k.size - c


def _cumtrapz_parts(y, t, absolute: bool = False):
    """``(i, j, c, up)`` chunk after chunk: ``c`` is ``[0, cumsum(0.5 (y[1:] + y[:-1])
    diff(t))][i:j]`` (of ``|y|`` when ``absolute``) bit for bit (the sum carried from chunk to
    chunk), ``up`` whether the step ending at each sample is > 0 (True at sample 0)."""
    import numpy as np

    carry = 0.0
    for i, j in _chunks(y.size):
        k = max(i, 1)                                # the steps ending at k .. j - 1
        y0, y1 = y[k - 1:j - 1], y[k:j]
        d = np.abs(y1) + np.abs(y0) if absolute else y1 + y0
        d *= 0.5
        d *= t[k:j] - t[k - 1:j - 1]
        c = np.empty(j - i)
        up = np.empty(j - i, dtype=bool)
        np.greater(d, 0.0, out=up[k - i:])
        if i == 0:
            c[0], up[0] = 0.0, True
        elif d.size:
            d[0] += carry
        np.cumsum(d, out=c[k - i:])
        carry = c[-1]
        yield i, j, c, up


def _cumtrapz(y, t, out=None):
    """``[0, cumsum(0.5 (y[1:] + y[:-1]) diff(t))]`` bit for bit, into ``out`` if given."""
    import numpy as np

    out = np.empty(y.size) if out is None else out
    for i, j, c, _ in _cumtrapz_parts(y, t):
        out[i:j] = c
    return out


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
    in x (:func:`polynomial_fit`) and the zero-phase Butterworth high-pass ``|H_B|^2`` (order
    ``order`` per pass) at ``wavelength_m``; the trend so removed is interpolated back onto the
    samples (the short waves stay those of the samples). A filter run in time with one cutoff
    removes, through the slow stretches, waves of a few metres (``v / f_c``): this one's cutoff
    is a wavelength everywhere. Extra memory: three whole-run float64 arrays (the result
    included) and small ones.

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

    a = np.asarray(accel, dtype=float)
    t = np.asarray(t_s, dtype=float)
    v = np.asarray(v_mps, dtype=float)
    if a.size < 8:
        return np.zeros_like(a)
    standing = v[1:] == 0.0
    standing &= v[:-1] == 0.0
    vel = _cumtrapz(a, t)
    z = _cumtrapz(vel, t)
    if standing.any():
        lev = None if level is None else np.asarray(level, dtype=float)
        knots = _rest_correction(t, z, standing, lev)
        if knots is not None:
            for i, j in _chunks(a.size):
                vel[i:j] -= _rest_rate(t[i:j], knots)
            _cumtrapz(vel, t, out=z)
    del vel, standing
    return _detrend_in_distance(z, t, v, wavelength_m, degree, order)


def _detrend_in_distance(z, t, v, wavelength_m: float, degree: int, order: int):
    """``z`` (m) less its long waves in distance (:func:`in_distance`), in place; ``t`` (s),
    ``v`` (m/s). The distance is made chunk by chunk where needed (three times)."""
    import numpy as np
    from road_force_estimator.core.scipy_signal import signal as _signal

    moving = np.empty(z.size, dtype=bool)
    x_end = 0.0                                      # the distance at the last moving sample
    for i, j, x, up in _cumtrapz_parts(v, t, absolute=True):
        moving[i:j] = up
        if up.any():
            x_end = x[np.flatnonzero(up)[-1]]
    n_moving = int(np.count_nonzero(moving))
    if n_moving < 8 or not x_end > 0.0:
        z -= np.mean(z)
        return z
    xm, n = np.empty(n_moving), 0
    for i, j, x, up in _cumtrapz_parts(v, t, absolute=True):
        part = x[up]
        xm[n:n + part.size] = part
        n += part.size
    n, others = _compact(z, moving)                 # z[moving] in front, in place
    zm = z[:n]
    h = float(np.median(np.diff(xm), overwrite_input=True))
    num = max(8, int(math.ceil(x_end / h)) + 1)
    zg = np.empty(num)                               # z on the grid linspace(0, x_end, num)
    for i, j in _chunks(num):
        zg[i:j] = np.interp(_linspace_part(0.0, x_end, num, i, j), xm, zm)
    del xm, zm
    _expand(z, moving, n, others)
    del moving, others
    coef = None
    if degree >= 0:
        coef = polynomial_fit(zg, degree)
        for i, j in _chunks(num):
            zg[i:j] -= polynomial_values(coef, num, i, j)
    g01 = _linspace_part(0.0, x_end, num, 0, 2)
    sos = _signal().butter(order, 2.0 * (g01[1] - g01[0]) / wavelength_m, btype='high',
                           output='sos')
    low = _sosfiltfilt(sos, zg)                      # zg is the rest; the trend into zg
    for i, j in _chunks(num):
        p = 0.0 if coef is None else polynomial_values(coef, num, i, j)
        zg[i:j] = p + (zg[i:j] - low[i:j])
    del low
    grid = np.linspace(0.0, x_end, num)
    for i, j, x, _ in _cumtrapz_parts(v, t, absolute=True):
        z[i:j] -= np.interp(x, grid, zg)
    return z


def offline_profile(accel, level, t_s, v_mps, dt_s: float, speed_mps: float,
                    cutoff_wavelength_m: float, ratio: float, degree: int):
    """The offline profile's body heave (m; 0 under 8 samples) of one run (the smoother's).

    Steady speed (the 5th percentile of ``|v|`` at least half of ``speed_mps``, the run's
    median |v|, floored at :data:`SPEED_FLOOR_MPS` for the cutoffs): :func:`zero_phase` at
    ``ratio x cutoff_wavelength_m`` at that speed, less the run's least-squares polynomial of
    degree ``degree`` (:func:`subtract_polynomial`; a cutoff longer than the run leaves the
    filter's edge transients and the double integral's wander as a smooth curve over the whole
    run: metres on a 120 m run at 10 km; waves of the run's length, which no band-passed figure
    sees). A stop (:func:`rest_stretches`): :func:`in_distance` at that wavelength with
    ``level`` (run in time with one cutoff, the slow stretches lost their metre waves). A speed
    that changes without a stop to correct the rate with: :func:`zero_phase` at
    ``cutoff_wavelength_m`` (the long one lets the drift of the slow stretches into the
    profile). Both measured on the stop scenario beside the RTS peer: ``python -m
    bench.accuracy.run_benchmark --scenarios C20-stop``. ``accel`` (m/s^2),
    ``level`` (m), times ``t_s`` (s), speeds ``v_mps`` (m/s): (m,); ``dt_s`` the run's step
    (s). Extra memory: one whole-run float64 array steady (the result), three with a stop.
    """
    import numpy as np

    a = np.asarray(accel, dtype=float)
    if a.size < 8:
        return 0.0
    v = np.asarray(v_mps, dtype=float)
    way = offline_profile_way(v, speed_mps, cutoff_wavelength_m, ratio)
    if way is None:
        return in_distance(a, t_s, v, ratio * cutoff_wavelength_m, level=level, degree=degree)
    w, detrend = way
    z = zero_phase(a, dt_s, w)
    return subtract_polynomial(z, degree) if detrend else z


def offline_profile_way(v_mps, speed_mps: float, cutoff_wavelength_m: float, ratio: float):
    """How :func:`offline_profile` integrates a run of model speeds ``v_mps`` (m/s, median
    |v| ``speed_mps``): None in distance (a stop), else ``(w, detrend)``, :func:`zero_phase`'s
    cutoff (rad/s) and whether the run's polynomial is subtracted (steady speed)."""
    import numpy as np

    v = np.asarray(v_mps, dtype=float)
    steady = float(np.percentile(np.abs(v), 5.0, overwrite_input=True)) >= 0.5 * speed_mps
    if not steady and rest_stretches(v):
        return None
    speed = max(speed_mps, SPEED_FLOOR_MPS)
    wavelength = ratio * cutoff_wavelength_m if steady else cutoff_wavelength_m
    return 2.0 * math.pi * speed / wavelength, steady
