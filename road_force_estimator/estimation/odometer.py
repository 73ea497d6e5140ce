"""The travelled distance fused from the speed and GNSS: the odometer scale, estimated.

A wheel-speed odometer's scale drifts 1-3 % with tire wear and pressure, and the profile's
distance (MODEL.md step 7, ``x = integral of v dt``) with it: every 100 m segment moves by
metres per kilometre. The fixes (``/fix``) measure the route; the speed integral ``x`` (m, the
odometer) measures the distance along it up to a scale ``k`` (true metres per odometer metre;
the speed reads high by ``1 / k - 1``).

:func:`fit_odometer` runs an extended Kalman filter over the fixes with the state
``[east, north, theta, kappa, k]`` (m on a plane, built fix to fix from the first,
:func:`~.core.gnss.local_east_north`; heading theta counter-clockwise from east, rad;
curvature kappa, 1/m; scale k). Between two fixes the odometer advances by ``d >= 0`` and the
vehicle by ``s = k d`` along an arc of constant curvature::

    theta_m = theta + kappa s / 2
    east += s cos(theta_m),  north += s sin(theta_m),  theta += kappa s

(exact on a circle), with random walks per metre travelled (:data:`PROCESS_STD`: position,
heading, curvature, and the slow drift of the scale). The fixes, of standard deviation
``sigma`` estimated from themselves (:func:`fix_noise_m`), come in groups of :data:`GROUP_M` of
odometer: a group's fix off the line through the others by more than :data:`GROUP_GATE` sigma
is an outlier; the rest measure ``[east, north]`` at their mean odometer reading with the
variance ``sigma^2 / n`` (as informative as the n fixes but for the heading within 10 m, with
n times fewer steps). A point whose innovation has a squared Mahalanobis distance above
:data:`GATE` (chi-square, 2 degrees of freedom, p = 1e-6) is rejected with its fixes,
counted; when every point over :data:`RESET_AFTER_M` of odometer distance is rejected, the
position restarts at the next one (counted: ``resets``).
A gap in the fixes only makes ``d`` longer; at a standstill (``d = 0``) nothing moves and no
uncertainty grows. The forward pass gives the causal scale at each point (what an onboard
filter would know then: :func:`causal_distance`); the Rauch-Tung-Striebel smoother (Rauch,
Tung, Striebel 1965), backward over each stretch between restarts, the offline one, iterated
(:data:`ITERATIONS`): the second pass linearises the motion about the first's smoothed
trajectory, which removes the bias an extended filter's own noisy heading leaves in the scale
(a heading off by ``e`` sees only ``cos e`` of the progress: -0.24 % at 2.5 m of noise with a
free curvature, measured; 0.02 % iterated).

:func:`scale_at` gives the scale at any stamps; the offline estimate (:func:`.offline.
estimate_recording`) multiplies the speed by it when :func:`distance_speed` says so
(``observer.distance_source``: ``gnss``, or ``auto``, the default, when the fixes give the
scale to 0.2 %), so its distance is ``integral of k v dt`` and every profile point and segment
boundary follows; :class:`DistanceSource` says which distance was used and why.

This module imports numpy only (core, estimation).
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from road_force_estimator.core.gnss import local_east_north
from road_force_estimator.estimation.reconstruction import distance_m

__all__ = ['PROCESS_STD', 'GATE', 'RESET_AFTER_M', 'MIN_NOISE_M', 'MIN_FIXES', 'INIT_BASE_M',
           'OdometerFit', 'fix_noise_m', 'odometer_distance', 'fit_odometer', 'scale_at',
           'causal_distance', 'AUTO_MAX_SCALE_STD', 'DISTANCE_SOURCES', 'DistanceSource',
           'distance_speed']

#: Random-walk standard deviations per square root of metre travelled: position (m), heading
#: (rad), curvature (1/m), scale (1): model errors, a road's changing bends, the scale's drift
#: (1e-6: 1e-4 over 10 km).
PROCESS_STD = (0.003, 3e-4, 1e-4, 1e-6)
_Q_PER_M = np.square(np.array([PROCESS_STD[0], *PROCESS_STD]))
_DIAG = (np.arange(5), np.arange(5))
#: Squared Mahalanobis distance above which a fix is an outlier (chi^2_2, p = 1e-6).
GATE = -2.0 * math.log(1e-6)
#: Odometer distance (m) of consecutive rejected fixes after which the position restarts.
RESET_AFTER_M = 50.0
#: Floor of the fix noise (m): exact (simulated) fixes still get a finite weight.
MIN_NOISE_M = 0.05
#: Consecutive fixes within this odometer distance (m) and :data:`GROUP_S` make one point of
#: the filter: their mean position at their mean odometer reading, with the noise variance
#: over their number (lossless but for the heading within the group, which 10 m of fixes
#: with metres of noise do not tell); a fix more than :data:`GROUP_GATE` sigma off the line
#: fitted through its group is an outlier.
GROUP_M = 10.0
GROUP_S = 2.0
GROUP_GATE = 5.0
GROUP_PASSES = 3
#: Fewest fixes for a fit.
MIN_FIXES = 10
#: Odometer distance (m) of the first fixes whose line starts the filter (heading, scale).
INIT_BASE_M = 50.0
#: Passes of the iterated smoother (1: the extended Kalman smoother).
ITERATIONS = 2
#: A fitted scale further than this from 1 is refused (an odometer is off by a few %).
MAX_SCALE_ERROR = 0.2
#: Prior standard deviations of the scale (1) and the curvature (1/m) at the start.
PRIOR_SCALE_STD = 0.05
PRIOR_CURVATURE_STD = 0.005


@dataclass(frozen=True)
class OdometerFit:
    """The odometer scale of a drive, from its fixes.

    Attributes
    ----------
    stamps_ns, known_ns : ndarray (m,) int64
        The filter's points (groups of fixes, :data:`GROUP_M`): the mean stamp of each group's
        fixes and the stamp of its last fix (from when the causal scale is known).
    scale_causal, scale_smoothed, scale_std : ndarray (m,)
        The scale k (true m per odometer m) at each point: the forward filter's (causal), the
        smoother's, and the smoother's standard deviation.
    fix_stamps_ns : ndarray (f,) int64
        The fixes inside the odometer's span.
    accepted : ndarray (f,) of bool
        Fixes used (False: rejected as outliers).
    scale, scale_sigma : float
        The drive's scale (the odometer-distance-weighted mean of ``scale_smoothed``) and its
        standard deviation (the smoother's, at the middle point).
    noise_m : float
        Fix noise used (m, per axis).
    fixes, rejected, resets : int
        Fixes in the span, rejected outliers, restarts of the position.
    """

    stamps_ns: np.ndarray
    known_ns: np.ndarray
    scale_causal: np.ndarray
    scale_smoothed: np.ndarray
    scale_std: np.ndarray
    fix_stamps_ns: np.ndarray
    accepted: np.ndarray
    scale: float
    scale_sigma: float
    noise_m: float
    fixes: int
    rejected: int
    resets: int

    @property
    def problem(self) -> str:
        """Why the fit is not to be used ('' when it is): most fixes rejected, or a scale
        beyond :data:`MAX_SCALE_ERROR` of 1 (frozen or wrong fixes, not an odometer)."""
        if self.rejected > 0.5 * self.fixes:
            return f'{self.rejected} of {self.fixes} fixes rejected'
        if abs(self.scale - 1.0) > MAX_SCALE_ERROR:
            return f'scale {self.scale:.4g} beyond 1 +- {MAX_SCALE_ERROR:g}'
        return ''

    @property
    def speed_error(self) -> float:
        """The fraction by which the speed reads high: ``1 / k - 1``."""
        return 1.0 / self.scale - 1.0

    def as_dict(self) -> dict:
        """The report's figures (``odometer`` of the summary)."""
        return {'scale': self.scale, 'scale_std': self.scale_sigma,
                'speed_error_pct': 100.0 * self.speed_error,
                'speed_error_std_pct': 100.0 * self.scale_sigma / self.scale ** 2,
                'fix_noise_m': self.noise_m, 'fixes': self.fixes,
                'fixes_rejected': self.rejected, 'resets': self.resets,
                'applied': not self.problem, 'problem': self.problem}


def odometer_distance(stamps_ns, speed_mps) -> tuple[np.ndarray, np.ndarray]:
    """``(stamps (n,) int64, x (n,) m)``: the speed integral (the estimator's trapezoid rule,
    :func:`.reconstruction.distance_m`) over the samples with a finite speed and a stamp
    beyond every earlier one."""
    s = np.asarray(stamps_ns, dtype=np.int64)
    v = np.broadcast_to(np.asarray(speed_mps, dtype=float), s.shape)
    before = np.concatenate([[np.iinfo(np.int64).min], np.maximum.accumulate(s)[:-1]]) \
        if s.size else s
    keep = np.isfinite(v) & (s > before)
    s, v = s[keep], v[keep]
    return s, distance_m(np.diff(s) * 1e-9, v)


def fix_noise_m(east_m: np.ndarray, north_m: np.ndarray, stamps_ns: np.ndarray) -> float:
    """White fix noise (m, per axis) from the second differences of positions at even fix
    steps (variance 6 sigma^2; the motion's share, ``a dt^2``, is centimetres at 10 Hz),
    robustly: ``sigma = 1.4826 MAD / sqrt(6)``; at least :data:`MIN_NOISE_M`."""
    dt = np.diff(np.asarray(stamps_ns, dtype=np.int64)).astype(float)
    if dt.size < 2:
        return MIN_NOISE_M
    even = np.abs(dt[1:] - dt[:-1]) <= 0.01 * dt[1:]
    d2 = np.concatenate([np.diff(np.asarray(a, dtype=float), 2)[even]
                         for a in (east_m, north_m)])
    if d2.size < 4:
        return MIN_NOISE_M
    mad = float(np.median(np.abs(d2 - np.median(d2))))
    return max(MIN_NOISE_M, 1.4826 * mad / math.sqrt(6.0))


def _initial_state(xf: np.ndarray, east: np.ndarray, north: np.ndarray, sigma: float):
    """State and covariance at the first point from a line fitted (least squares, then once
    more without the residuals above 5 sigma) to the points up to the first one
    :data:`INIT_BASE_M` of odometer on; None when the drive is shorter."""
    if xf[-1] - xf[0] < INIT_BASE_M:
        return None
    near = np.arange(int(np.argmax(xf - xf[0] >= INIT_BASE_M)) + 1)   # one beyond, at least
    if near.size < 3:
        return None
    rows = near
    for _ in range(2):
        a = np.column_stack([np.ones(rows.size), xf[rows] - xf[0]])
        (e0, be), *_ = np.linalg.lstsq(a, east[rows], rcond=None)
        (n0, bn), *_ = np.linalg.lstsq(a, north[rows], rcond=None)
        res = np.hypot(east[near] - e0 - be * (xf[near] - xf[0]),
                       north[near] - n0 - bn * (xf[near] - xf[0]))
        rows = near[res <= max(5.0 * sigma, 1e-9)]
        if rows.size < 3:
            return None
    span = float(xf[near[-1]] - xf[0])
    k0 = float(np.clip(math.hypot(be, bn), 1.0 - 3 * PRIOR_SCALE_STD, 1.0 + 3 * PRIOR_SCALE_STD))
    x = np.array([e0, n0, math.atan2(bn, be), 0.0, k0])
    heading_var = (2.0 * sigma / span) ** 2 + (PRIOR_CURVATURE_STD * span / 2.0) ** 2 + 1e-6
    p = np.diag([sigma ** 2, sigma ** 2, heading_var, PRIOR_CURVATURE_STD ** 2,
                 PRIOR_SCALE_STD ** 2])
    return x, p


def _predict(x: np.ndarray, d: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(x', F, q)``: the state after ``d`` odometer metres, its Jacobian and the diagonal of
    the process noise."""
    e, n, th, ka, k = x
    s = k * d
    tm = th + 0.5 * ka * s
    c, sn = math.cos(tm), math.sin(tm)
    xn = np.array([e + s * c, n + s * sn, th + ka * s, ka, k])
    hs = 0.5 * s
    f = np.array([[1.0, 0.0, -s * sn, -hs * s * sn, d * c - hs * sn * ka * d],
                  [0.0, 1.0, s * c, hs * s * c, d * sn + hs * c * ka * d],
                  [0.0, 0.0, 1.0, s, ka * d],
                  [0.0, 0.0, 0.0, 1.0, 0.0],
                  [0.0, 0.0, 0.0, 0.0, 1.0]])
    return xn, f, _Q_PER_M * abs(s)


def _forward(xf, east, north, rs, x, p, lin=None, decided=None):
    """The filter over the points (odometer ``xf``, position, noise variance ``rs``): per
    point the a-priori and a-posteriori states and covariances, the Jacobians, the accepted
    mask and where the position restarted.

    ``lin`` (m, 5): the trajectory to linearise the motion about (an iterated smoother's
    previous pass; default the filter's own estimate, the extended Kalman filter);
    ``decided``: ``(accepted, restart)`` of an earlier pass, kept instead of gating again.
    """
    m = xf.size
    x, p = np.array(x, dtype=float), np.array(p, dtype=float)
    xs_p, ps_p = np.empty((m, 5)), np.empty((m, 5, 5))
    xs_f, ps_f = np.empty((m, 5)), np.empty((m, 5, 5))
    fs = np.empty((m, 5, 5))
    accepted = np.zeros(m, bool) if decided is None else decided[0]
    restart = np.zeros(m, bool) if decided is None else decided[1]
    rejected_since = None
    fs[0] = np.eye(5)
    for j in range(m):
        if j:
            d = max(float(xf[j] - xf[j - 1]), 0.0)
            if lin is None:
                x, f, q = _predict(x, d)
            else:
                xl, f, q = _predict(lin[j - 1], d)
                x = xl + f @ (x - lin[j - 1])
            p = f @ p @ f.T
            p[_DIAG] += q
            fs[j] = f
        xs_p[j], ps_p[j] = x, p
        z0, z1 = east[j] - x[0], north[j] - x[1]
        r = rs[j]
        a, b, c = p[0, 0] + r, p[0, 1], p[1, 1] + r
        det = a * c - b * b
        si = np.array([[c, -b], [-b, a]]) / det
        if decided is None:
            accepted[j] = (c * z0 * z0 - 2.0 * b * z0 * z1 + a * z1 * z1) / det <= GATE
            if accepted[j]:
                rejected_since = None
            elif rejected_since is None:
                rejected_since = xf[j]
            elif xf[j] - rejected_since >= RESET_AFTER_M:
                restart[j] = True
                rejected_since = None
        if accepted[j]:
            g = p[:, :2] @ si
            x = x + g @ np.array([z0, z1])
            p = p - g @ p[:2, :]
            p = 0.5 * (p + p.T)
        elif restart[j]:
            x = x.copy()
            x[:2] = east[j], north[j]
            p = p.copy()
            p[:2, :], p[:, :2] = 0.0, 0.0
            p[0, 0] = p[1, 1] = r
            p[2, 2] = max(p[2, 2], 0.04)
        xs_f[j], ps_f[j] = x, p
    return xs_p, ps_p, xs_f, ps_f, fs, accepted, restart


def _smooth(xs_p, ps_p, xs_f, ps_f, fs, restart) -> tuple[np.ndarray, np.ndarray]:
    """RTS smoother, backward over each stretch between restarts: states and covariances.
    The gains ``C_j = P_j F_(j+1)^T Pp_(j+1)^-1`` at once (stacked solves), then the
    recursion."""
    m = xs_f.shape[0]
    xs, ps = xs_f.copy(), ps_f.copy()
    if m < 2:
        return xs, ps
    gains = np.linalg.solve(ps_p[1:], fs[1:] @ ps_f[:-1]).transpose(0, 2, 1)
    for j in range(m - 2, -1, -1):
        if restart[j + 1]:
            continue
        c = gains[j]
        xs[j] = xs_f[j] + c @ (xs[j + 1] - xs_p[j + 1])
        ps[j] = ps_f[j] + c @ (ps[j + 1] - ps_p[j + 1]) @ c.T
    return xs, ps


def _group_ids(xf: np.ndarray, fsn: np.ndarray) -> np.ndarray:
    """Group of each fix (int, (f,)): consecutive fixes within :data:`GROUP_M` of odometer
    and :data:`GROUP_S` of time from the group's first."""
    ids = np.empty(xf.size, np.int64)
    g, x0, t0 = 0, xf[0], fsn[0]
    limit_ns = GROUP_S * 1e9
    for i, (x, t) in enumerate(zip(xf.tolist(), fsn.tolist())):
        if x - x0 > GROUP_M or t - t0 > limit_ns:
            g, x0, t0 = g + 1, x, t
        ids[i] = g
    return ids


def _line_residuals(ids, keep, d, east, north) -> np.ndarray:
    """Distance (m) of each fix from the least-squares line (position against odometer
    offset ``d``) of its group's kept fixes (the group's mean where it has fewer than 3),
    over ``sqrt(1 - h)`` (``h`` the fix's leverage on that line): of the same spread for
    every fix, and large for an outlier at a group's end, which pulls the line to it."""
    k = ids[-1] + 1
    w = keep.astype(float)

    def total(v):
        return np.bincount(ids, w * v, minlength=k)
    n = np.maximum(total(np.ones_like(d)), 1.0)
    md = total(d) / n
    dd = d - md[ids]
    sdd = total(dd * dd)
    line = (n >= 3) & (sdd > 0)
    inv_sdd = np.where(line, 1.0 / np.where(sdd > 0, sdd, 1.0), 0.0)
    res2 = np.zeros(d.size)
    for v in (east, north):
        mv = total(v) / n
        slope = total(dd * v) * inv_sdd
        res2 += (v - mv[ids] - slope[ids] * dd) ** 2
    leverage = np.where(keep, 1.0 / n[ids] + dd * dd * inv_sdd[ids], 0.0)
    return np.sqrt(res2 / np.maximum(1.0 - leverage, 0.05))


def _points(xf, east, north, fsn, sigma):
    """The filter's points from the fixes (:data:`GROUP_M`): ``(x, east, north, noise
    variance, mean stamp, last stamp, group of each fix, fixes kept)``; the fix farthest off
    its group's line, when more than :data:`GROUP_GATE` sigma off, is not kept, then the line
    is fitted again without it (up to :data:`GROUP_PASSES` times)."""
    ids = _group_ids(xf, fsn)
    keep = np.ones(xf.size, bool)
    d = xf - xf[np.searchsorted(ids, ids)]         # odometer from the group's first fix
    for _ in range(GROUP_PASSES):          # the worst fix of each group, if off, at a time
        res = np.where(keep, _line_residuals(ids, keep, d, east, north), 0.0)
        worst = np.zeros(ids[-1] + 1)
        np.maximum.at(worst, ids, res)
        off = (res > GROUP_GATE * sigma) & (res == worst[ids])
        if not off.any():
            break
        keep &= ~off
    ids_k = ids[keep]
    k = ids[-1] + 1
    n = np.bincount(ids_k, minlength=k).astype(float)
    has = n > 0
    mean = [np.bincount(ids_k, v[keep], minlength=k)[has] / n[has]
            for v in (xf, east, north, (fsn - fsn[0]).astype(float))]
    last = np.full(k, -1, np.int64)
    np.maximum.at(last, ids_k, fsn[keep])
    stamps = fsn[0] + np.round(mean[3]).astype(np.int64)
    return (mean[0], mean[1], mean[2], sigma * sigma / n[has], stamps, last[has],
            np.cumsum(has)[ids] - 1, keep)


def fit_odometer(stamps_ns, odometer_m, fix_stamps_ns, fix_latitude_deg,
                 fix_longitude_deg) -> OdometerFit | None:
    """Estimate the odometer scale from the fixes (see the module notes).

    Parameters
    ----------
    stamps_ns : array (n,) int64
        Stamps of the odometer readings, increasing.
    odometer_m : array (n,)
        The speed integral at them (m, non-decreasing): :func:`odometer_distance`.
    fix_stamps_ns, fix_latitude_deg, fix_longitude_deg : arrays (f,)
        The fixes (increasing stamps; WGS84 degrees).

    Returns
    -------
    OdometerFit or None
        None with fewer than :data:`MIN_FIXES` fixes inside the odometer's span or less than
        :data:`INIT_BASE_M` of odometer distance between them.
    """
    t = np.asarray(stamps_ns, dtype=np.int64)
    x = np.asarray(odometer_m, dtype=float)
    fsn = np.asarray(fix_stamps_ns, dtype=np.int64)
    if t.size < 2 or fsn.size < MIN_FIXES:
        return None
    inside = (fsn >= t[0]) & (fsn <= t[-1])
    fsn = fsn[inside]
    if fsn.size < MIN_FIXES:
        return None
    lat = np.asarray(fix_latitude_deg, dtype=float)[inside]
    lon = np.asarray(fix_longitude_deg, dtype=float)[inside]
    east, north = local_east_north(lat, lon)
    xf = np.interp((fsn - t[0]).astype(float), (t - t[0]).astype(float), x)
    sigma = fix_noise_m(east, north, fsn)
    gx, ge, gn, rs, g_ns, g_known, group, kept = _points(xf, east, north, fsn, sigma)
    start = _initial_state(gx, ge, gn, sigma)
    if start is None or gx.size < 3:
        return None
    xs_p, ps_p, xs_f, ps_f, fs, accepted, restart = _forward(gx, ge, gn, rs, *start)
    causal = xs_f[:, 4].copy()
    xs, ps = _smooth(xs_p, ps_p, xs_f, ps_f, fs, restart)
    for _ in range(ITERATIONS - 1):
        # Iterated smoother (Gauss-Newton on the whole trajectory): the motion linearised
        # about the last smoothed trajectory, not about the filter's own, noisier, estimate.
        out = _forward(gx, ge, gn, rs, *start, lin=xs, decided=(accepted, restart))
        xs, ps = _smooth(*out[:5], restart)
    k_s = xs[:, 4].copy()
    std = np.sqrt(np.maximum(ps[:, 4, 4], 0.0))
    w = np.diff(gx)
    scale = float(np.sum(w * 0.5 * (k_s[1:] + k_s[:-1])) / np.sum(w)) if np.sum(w) > 0 \
        else float(k_s[-1])
    used = kept & (accepted | restart)[group]
    return OdometerFit(g_ns, g_known, causal, k_s, std, fsn, used, scale,
                       float(std[min(np.searchsorted(gx, 0.5 * (gx[0] + gx[-1])), gx.size - 1)]),
                       sigma, int(fsn.size), int(np.count_nonzero(~used)),
                       int(np.count_nonzero(restart)))


def scale_at(stamps_ns, fit: OdometerFit, *, causal: bool = False) -> np.ndarray:
    """The scale k at ``stamps_ns`` (n,): offline the smoothed scale interpolated between the
    filter's points in time (held before the first and after the last); ``causal``, the
    filter's at the latest point known at or before each stamp (its group's last fix; 1
    before the first: the odometer as it reads)."""
    q = np.asarray(stamps_ns, dtype=np.int64)
    if causal:
        j = np.searchsorted(fit.known_ns, q, side='right') - 1
        return np.where(j >= 0, fit.scale_causal[np.maximum(j, 0)], 1.0)
    f = fit.stamps_ns
    return np.interp((q - f[0]).astype(float), (f - f[0]).astype(float), fit.scale_smoothed)


def causal_distance(stamps_ns, odometer_m, fit: OdometerFit) -> np.ndarray:
    """The fused distance an onboard filter would know at each stamp (m, (n,)): the odometer
    times the forward filter's latest scale, ``k_f(t) x(t)`` (not the integral of the scale's
    history, which would keep the early, poorly known, scales forever), never decreasing."""
    x = np.asarray(odometer_m, dtype=float)
    return np.maximum.accumulate(scale_at(stamps_ns, fit, causal=True) * (x - x[0])) + x[0]


# --------------------------------------------------------------------------------------------
# observer.distance_source: which distance a drive's estimate runs on
# --------------------------------------------------------------------------------------------

#: ``observer.distance_source: auto`` takes the fixes' distance when they give the odometer
#: scale to this standard deviation or better (0.2 %: a wheel odometer reads 1-3 % off, so a
#: scale known to 0.2 % corrects it; a shorter or noisier drive's would only add its noise).
AUTO_MAX_SCALE_STD = 0.002
DISTANCE_SOURCES = ('auto', 'speed', 'gnss')


@dataclass(frozen=True)
class DistanceSource:
    """Which distance an estimate ran on, and why (for the report and ``report.json``).

    ``requested`` is ``observer.distance_source``; ``used`` ``'gnss'`` (the speed times the
    scale fitted from the fixes) or ``'speed'``; ``fixes`` the fixes the drive has; ``fit`` the
    fit when one was made (None otherwise).
    """

    requested: str
    used: str
    reason: str
    fixes: int = 0
    fit: OdometerFit | None = None

    def as_dict(self) -> dict:
        return {'requested': self.requested, 'used': self.used, 'reason': self.reason,
                'fixes': self.fixes}


def _fit_words(fit: OdometerFit) -> str:
    error = 100.0 * fit.speed_error
    return (f'{fit.fixes - fit.rejected} of {fit.fixes} fixes used (noise {fit.noise_m:.2g} m '
            f'per axis), odometer scale {fit.scale:.5f} +- {fit.scale_sigma:.5f} (the speed '
            f'reads {abs(error):.2f} % {"high" if error >= 0 else "low"})')


def distance_speed(requested: str, stamps_ns, speed_mps, fixes, *,
                   offline: bool = True) -> tuple[np.ndarray, DistanceSource]:
    """The speed whose integral is the estimate's distance, and the :class:`DistanceSource`.

    ``requested`` (``observer.distance_source``): ``speed``, the speed as given; ``gnss``, the
    speed times :func:`scale_at` of :func:`fit_odometer` when the fixes make a fit without a
    ``problem``; ``auto``, the same when the fit's scale is known to
    :data:`AUTO_MAX_SCALE_STD` or better, else the speed. Online (``offline`` False) the
    distance is the speed's: the scale is fitted over the whole drive. ``fixes`` has
    ``stamps_ns``, ``latitude_deg``, ``longitude_deg`` (or is None).
    """
    if requested not in DISTANCE_SOURCES:
        raise ValueError(f'observer.distance_source = {requested!r}: must be one of '
                         f'{", ".join(DISTANCE_SOURCES)}')
    n = 0 if fixes is None else int(np.size(fixes.stamps_ns))
    if requested == 'speed':
        return speed_mps, DistanceSource(requested, 'speed', 'observer.distance_source = '
                                         'speed', n)
    if not offline:
        return speed_mps, DistanceSource(requested, 'speed', 'online: the odometer scale is '
                                         'fitted over the whole drive (offline mode only)', n)
    if n == 0:
        return speed_mps, DistanceSource(requested, 'speed', 'no /fix in the drive', 0)
    fit = fit_odometer(*odometer_distance(stamps_ns, speed_mps), fixes.stamps_ns,
                       fixes.latitude_deg, fixes.longitude_deg)
    if fit is None:
        return speed_mps, DistanceSource(requested, 'speed', f'{n} fixes: fewer than '
                                         f'{MIN_FIXES} in the drive or less than '
                                         f'{INIT_BASE_M:g} m between them', n)
    if fit.problem:
        return speed_mps, DistanceSource(requested, 'speed', f'the fixes refused: '
                                         f'{fit.problem}', n, fit)
    if requested == 'auto' and not fit.scale_sigma <= AUTO_MAX_SCALE_STD:
        return speed_mps, DistanceSource(requested, 'speed', f'{_fit_words(fit)}: the scale '
                                         f'is known to {100.0 * fit.scale_sigma:.2f} % only '
                                         f'(auto wants {100.0 * AUTO_MAX_SCALE_STD:g} %)',
                                         n, fit)
    v = np.broadcast_to(np.asarray(speed_mps, dtype=float), np.shape(stamps_ns))
    return v * scale_at(stamps_ns, fit), DistanceSource(requested, 'gnss', _fit_words(fit),
                                                        n, fit)
