"""Metrics of MODEL.md: profile band-pass, errors, convergence time, DLC, LTR statistics.

Errors are judged after convergence (a mask or a start time chosen by the caller), on
(estimate - truth):

- wheel loads: RMS and peak, absolute (N), as a % of the true dynamic-load RMS
  (``RMS(F_n - F_c)``) and as a % of the static load ``F_c``;
- profile: both estimate and truth through the same zero-phase Butterworth band-pass
  (0.5-30 m wavelengths, in the distance domain; :func:`profile_bandpass`), then RMS and peak
  (m and % of the band-passed true profile's RMS);
- LTR: RMS and peak of the error, max |LTR|;
- convergence time t_0: the first time after which an error stays inside a tolerance;
- dynamic load coefficient ``DLC = std(F_n) / mean(F_n)``.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
import math

import numpy as np
from road_force_estimator.core.scipy_signal import signal as _signal

__all__ = [
    'BAND_SHORT_M', 'BAND_LONG_M', 'BAND_ORDER', 'profile_bandpass', 'ErrorStats',
    'error_stats', 'load_errors', 'profile_errors', 'ltr_stats', 'convergence_time', 'dlc',
]

#: Wavelength band in which profiles are judged (m).
BAND_SHORT_M = 0.5
BAND_LONG_M = 30.0
#: Butterworth order of the band-pass (per edge); applied forward and backward (zero phase),
#: so each edge is at -6 dB.
BAND_ORDER = 2


def profile_bandpass(distance_m, elevation_m, *, short_m: float = BAND_SHORT_M,
                     long_m: float = BAND_LONG_M, order: int = BAND_ORDER) -> np.ndarray:
    """Zero-phase Butterworth band-pass of a profile in the distance domain.

    Parameters
    ----------
    distance_m : array_like, shape (n,)
        Distance (m), non-decreasing. Uneven spacing is resampled to the median spacing,
        filtered and interpolated back; at a repeated distance (the truck standing) the
        moving samples are filtered and the standing ones read at their distance.
    elevation_m : array_like, shape (n,) or (n, k)
        Elevation(s) (m).
    short_m, long_m : float
        Pass band in wavelength (m), ``0 < short_m < long_m``; ``short_m`` must be longer than
        four grid spacings.
    order : int
        Butterworth order of the band-pass design (``scipy.signal.butter(order, ...,
        'bandpass')``), run forward and backward (:func:`scipy.signal.sosfiltfilt`).

    Returns
    -------
    numpy.ndarray
        The band-passed elevation, shape of ``elevation_m``. The first and last ~``long_m``
        metres carry the filter's edge transients: judge errors away from them.
    """
    x = np.asarray(distance_m, dtype=float)
    z = np.asarray(elevation_m, dtype=float)
    if x.ndim != 1 or z.shape[0] != x.size or z.ndim not in (1, 2):
        raise ValueError(f'distance_m {x.shape} and elevation_m {z.shape}: expected (n,) and '
                         '(n,) or (n, k)')
    if not 0.0 < short_m < long_m:
        raise ValueError(f'short_m = {short_m!r}, long_m = {long_m!r}: need 0 < short < long')
    if x.size < 3:
        raise ValueError(f'{x.size} profile points: need at least 3')
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(z))):
        raise ValueError('distance_m and elevation_m must be finite')
    dx_all = np.diff(x)
    if np.any(dx_all < 0.0):
        raise ValueError('distance_m must be non-decreasing')
    if np.any(dx_all == 0.0):  # a standstill repeats a distance: filter where the truck moves
        keep = np.concatenate([[True], dx_all > 0.0])
        moving = profile_bandpass(x[keep], z[keep], short_m=short_m, long_m=long_m,
                                  order=order)
        if z.ndim == 1:
            return np.interp(x, x[keep], moving)
        return np.column_stack([np.interp(x, x[keep], moving[:, i])
                                for i in range(moving.shape[1])])
    dx = float(np.median(dx_all))
    if short_m < 4.0 * dx:
        raise ValueError(f'short_m = {short_m:g} m is under 4 grid spacings ({dx:g} m)')
    uniform = np.allclose(dx_all, dx, rtol=1e-6, atol=0.0)
    if uniform:
        xu, zu = x, z
    else:
        xu = x[0] + dx * np.arange(int(math.floor((x[-1] - x[0]) / dx)) + 1)
        zu = (np.interp(xu, x, z) if z.ndim == 1 else
              np.column_stack([np.interp(xu, x, z[:, i]) for i in range(z.shape[1])]))
    fs = 1.0 / dx   # samples per metre
    signal = _signal()
    sos = signal.butter(order, [1.0 / long_m, 1.0 / short_m], btype='bandpass', fs=fs,
                        output='sos')
    padlen = min(zu.shape[0] - 1, int(3 * long_m / dx))
    out = signal.sosfiltfilt(sos, zu, axis=0, padtype='odd', padlen=padlen)
    if uniform:
        return out
    if z.ndim == 1:
        return np.interp(x, xu, out)
    return np.column_stack([np.interp(x, xu, out[:, i]) for i in range(out.shape[1])])


@dataclass(frozen=True)
class ErrorStats:
    """RMS and peak of an error, absolute and relative (per column for (n, k) inputs)."""

    rms: np.ndarray                 #: RMS of (estimate - truth)
    peak: np.ndarray                #: max |estimate - truth|
    rms_pct: np.ndarray             #: 100 rms / reference RMS
    peak_pct: np.ndarray            #: 100 peak / reference RMS
    reference_rms: np.ndarray       #: the reference RMS used for the percentages
    rms_pct_static: np.ndarray | None = None   #: 100 rms / static load (loads only)
    peak_pct_static: np.ndarray | None = None  #: 100 peak / static load (loads only)
    samples: int = 0

    def as_dict(self) -> dict:
        return {k: (v.tolist() if isinstance(v, np.ndarray) else v)
                for k, v in asdict(self).items()}


def _masked(a: np.ndarray, mask) -> np.ndarray:
    return a if mask is None else a[np.asarray(mask, dtype=bool)]


def error_stats(estimate, truth, *, reference=None, mask=None, static=None) -> ErrorStats:
    """RMS and peak of ``estimate - truth``; percentages of ``RMS(reference)``.

    Parameters
    ----------
    estimate, truth : array_like, shape (n,) or (n, k)
    reference : array_like, optional
        Signal whose RMS the percentages use (default: ``truth``).
    mask : array_like of bool, shape (n,), optional
        Samples to judge (e.g. after convergence).
    static : array_like, shape (k,) or scalar, optional
        Static level for the ``*_pct_static`` figures (the static wheel load).
    """
    est = np.asarray(estimate, dtype=float)
    tru = np.asarray(truth, dtype=float)
    if est.shape != tru.shape:
        raise ValueError(f'estimate {est.shape} and truth {tru.shape} differ in shape')
    ref = tru if reference is None else np.asarray(reference, dtype=float)
    err = _masked(est - tru, mask)
    ref = _masked(ref, mask)
    if err.shape[0] == 0:
        raise ValueError('no sample to judge (empty mask)')
    rms = np.sqrt(np.mean(err ** 2, axis=0))
    peak = np.max(np.abs(err), axis=0)
    ref_rms = np.sqrt(np.mean(ref ** 2, axis=0))
    with np.errstate(divide='ignore', invalid='ignore'):
        rms_pct = 100.0 * rms / ref_rms
        peak_pct = 100.0 * peak / ref_rms
        if static is not None:
            st = np.asarray(static, dtype=float)
            rms_s, peak_s = 100.0 * rms / st, 100.0 * peak / st
        else:
            rms_s = peak_s = None
    return ErrorStats(rms, peak, rms_pct, peak_pct, ref_rms, rms_s, peak_s, int(err.shape[0]))


def load_errors(estimate_n, truth_n, static_n, *, mask=None) -> ErrorStats:
    """Wheel-load errors (N), % of the true dynamic-load RMS ``RMS(F_n - F_c)`` and of F_c.

    ``estimate_n``, ``truth_n``: (n, 2) loads F_n [left, right]; ``static_n``: (2,) F_c.
    """
    tru = np.asarray(truth_n, dtype=float)
    st = np.asarray(static_n, dtype=float)
    return error_stats(estimate_n, tru, reference=tru - st, mask=mask, static=st)


def profile_errors(distance_m, estimate_m, truth_m, *, mask=None, short_m: float = BAND_SHORT_M,
                   long_m: float = BAND_LONG_M, order: int = BAND_ORDER,
                   truth_distance_m=None) -> ErrorStats:
    """Profile errors in the band: both through :func:`profile_bandpass`, then compared.

    ``distance_m`` is the estimate's distance (n,); the truth is on ``truth_distance_m`` (the
    same when None) and is interpolated onto ``distance_m`` before filtering. ``mask`` (n,)
    selects the samples judged (keep away from the first/last ~``long_m`` metres and from the
    estimate's start-up). Percentages are of the band-passed truth's RMS.
    """
    x = np.asarray(distance_m, dtype=float)
    tru = np.asarray(truth_m, dtype=float)
    if truth_distance_m is not None:
        xt = np.asarray(truth_distance_m, dtype=float)
        tru = (np.interp(x, xt, tru) if tru.ndim == 1 else
               np.column_stack([np.interp(x, xt, tru[:, i]) for i in range(tru.shape[1])]))
    kw = dict(short_m=short_m, long_m=long_m, order=order)
    return error_stats(profile_bandpass(x, estimate_m, **kw), profile_bandpass(x, tru, **kw),
                       mask=mask)


def ltr_stats(estimate, truth=None, *, mask=None) -> dict:
    """LTR figures: ``max_abs`` of the estimate, and with ``truth`` the error RMS and peak."""
    est = _masked(np.asarray(estimate, dtype=float), mask)
    out = {'max_abs': float(np.max(np.abs(est))) if est.size else 0.0}
    if truth is not None:
        tru = _masked(np.asarray(truth, dtype=float), mask)
        err = est - tru
        out.update(rms_error=float(np.sqrt(np.mean(err ** 2))),
                   peak_error=float(np.max(np.abs(err))),
                   max_abs_truth=float(np.max(np.abs(tru))))
    return out


def convergence_time(t_s, error, tolerance, window_s: float | None = None) -> float:
    """Convergence time t_0 (MODEL.md "Metrics"): the first time after which ``|error| <=
    tolerance`` holds for ``window_s`` (s), or, when ``window_s`` is None, for every later
    sample.

    Parameters
    ----------
    t_s : array_like, shape (n,)
    error : array_like, shape (n,) or (n, k)
        All columns must be inside for a sample to count as inside.
    tolerance : float or array_like (k,)
    window_s : float, optional
        How long the error must stay inside (s); the window must end inside the record.

    Returns
    -------
    float
        ``t_s[j]`` of the first sample j from which the error stays inside (over the window,
        or to the end); ``t_s[0]`` if it is inside from the start; ``math.inf`` if no sample
        qualifies (without a window: the last sample is outside).
    """
    t = np.asarray(t_s, dtype=float)
    err = np.abs(np.asarray(error, dtype=float))
    inside = err <= np.asarray(tolerance, dtype=float)
    if inside.ndim == 2:
        inside = inside.all(axis=1)
    if inside.shape != t.shape:
        raise ValueError(f't_s {t.shape} and error {err.shape} do not match')
    if t.size == 0:
        return math.inf
    if window_s is None:
        if not inside[-1]:
            return math.inf
        outside = np.nonzero(~inside)[0]
        return float(t[0] if outside.size == 0 else t[outside[-1] + 1])
    # next_out[j]: the first sample at or after j that is outside (n if none).
    n = t.size
    idx = np.where(~inside, np.arange(n), n)
    next_out = np.minimum.accumulate(idx[::-1])[::-1]
    end_t = np.append(t, np.inf)[next_out]           # when the error first leaves again
    ok = inside & (end_t > t + window_s) & (t + window_s <= t[-1])
    hit = np.flatnonzero(ok)
    return float(t[hit[0]]) if hit.size else math.inf


def dlc(load_n, *, mask=None) -> np.ndarray:
    """Dynamic load coefficient ``std(F_n) / mean(F_n)`` per column."""
    f = _masked(np.asarray(load_n, dtype=float), mask)
    return np.std(f, axis=0) / np.mean(f, axis=0)
