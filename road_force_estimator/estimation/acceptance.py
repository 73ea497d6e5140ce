"""Which samples the estimators use: the rejection and gap rules, per sample and over arrays.

A sample is rejected when a value or the stamp (integer nanoseconds) is non-finite or
malformed (``rejected_nonfinite``), when a value is impossible (``|q| > 1 m``,
``|phi| > pi/2``, ``|v| > 100 m/s``: ``rejected_range``) or when its stamp is not later than
the last accepted one (``rejected_time``). A step longer than ``max(gap_threshold_s,``
:data:`GAP_PERIODS` ``typical steps)`` is a gap (the estimate restarts there; ``gaps``,
``resets``); the typical step is the running average ``dt_typ += 0.05 (dt - dt_typ)`` of the
accepted steps, restarted (the next step taken as it is) at every restart.

:class:`SampleGate` applies the rules one sample at a time (the per-sample path and
:func:`.estimate_batch`); :func:`accept_arrays` over whole arrays (the offline smoothers),
with the same result.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = [
    'GAP_THRESHOLD_S', 'GAP_PERIODS', 'MAX_DEFLECTION_M', 'MAX_ROLL_RAD', 'MAX_SPEED_MPS',
    'TYPICAL_STEP_WEIGHT', 'check_gap_threshold', 'batch_inputs', 'SampleGate',
    'accept_arrays', 'gap_samples', 'output_stamps',
]

#: Shortest step that counts as a gap (s); the threshold is max(this, 10 typical periods).
GAP_THRESHOLD_S = 0.1
#: Gap threshold in typical sample periods.
GAP_PERIODS = 10.0
#: Weight of a new step in the running average of the typical step.
TYPICAL_STEP_WEIGHT = 0.05
#: Physical limits beyond which a sample is refused (m, rad, m/s).
MAX_DEFLECTION_M = 1.0
MAX_ROLL_RAD = 0.5 * math.pi
MAX_SPEED_MPS = 100.0


def check_gap_threshold(gap_threshold_s) -> float:
    """``gap_threshold_s`` as a float (s); ValueError unless finite and > 0."""
    if not (isinstance(gap_threshold_s, (int, float)) and gap_threshold_s > 0.0
            and math.isfinite(gap_threshold_s)):
        raise ValueError(f'gap_threshold_s = {gap_threshold_s!r}: must be finite and > 0 s')
    return float(gap_threshold_s)


def batch_inputs(stamps_ns, q_m, roll_rad, speed_mps):
    """The inputs of a batch path as arrays: stamps (n,), q (n, 2), phi (n,), speed (n,).

    Raises
    ------
    ValueError
        Shapes that do not fit; the message gives them.
    """
    stamps = np.asarray(stamps_ns)
    q = np.asarray(q_m, dtype=float)
    phi = np.asarray(roll_rad, dtype=float)
    n = stamps.shape[0] if stamps.ndim == 1 else -1
    if stamps.ndim != 1 or q.shape != (n, 2) or phi.shape != (n,):
        raise ValueError(f'stamps_ns {stamps.shape}, q_m {q.shape}, roll_rad {phi.shape}: '
                         'expected (n,), (n, 2), (n,)')
    return stamps, q, phi, np.broadcast_to(np.asarray(speed_mps, dtype=float), (n,))


class SampleGate:
    """The rules one sample at a time; counts the rejections and gaps in ``status``.

    :meth:`check` tells what to do with a sample; after the estimator has used it,
    :meth:`commit` records it (stamp, typical step).
    """

    def __init__(self, gap_threshold_s: float, status) -> None:
        self.gap_threshold_s = gap_threshold_s
        self.status = status
        self.started = False
        self.stamp = 0
        self.dt_typ = 0.0

    def check_pair(self, q_m):
        """``(q1, q2)`` of a deflection pair, or None (counted as malformed) if it is none."""
        try:
            q1, q2 = q_m
        except (TypeError, ValueError):
            self.status.rejected_nonfinite += 1
            return None
        return q1, q2

    def check(self, stamp_ns, q1, q2, phi, v):
        """``(stamp, q1, q2, phi, v, dt, restart, dt_typ)`` of a good sample, or None for a
        rejected one (counted). ``dt`` is 0 s for the first; ``restart``: it starts a new run
        (the first, or after a gap); ``dt_typ`` the typical step (s) once it is used (0 at
        a restart)."""
        st = self.status
        try:
            stamp = int(stamp_ns)
            q1 = float(q1)
            q2 = float(q2)
            phi = float(phi)
            v = float(v)
        except (TypeError, ValueError, OverflowError):
            st.rejected_nonfinite += 1
            return None
        # One chain of comparisons passes every good sample (NaN compares false).
        if not (-MAX_DEFLECTION_M <= q1 <= MAX_DEFLECTION_M
                and -MAX_DEFLECTION_M <= q2 <= MAX_DEFLECTION_M
                and -MAX_ROLL_RAD <= phi <= MAX_ROLL_RAD and -MAX_SPEED_MPS <= v <= MAX_SPEED_MPS):
            if (math.isfinite(q1) and math.isfinite(q2) and math.isfinite(phi)
                    and math.isfinite(v)):
                st.rejected_range += 1
            else:
                st.rejected_nonfinite += 1
            return None
        if not self.started:
            return stamp, q1, q2, phi, v, 0.0, True, 0.0
        dt_ns = stamp - self.stamp
        if dt_ns <= 0:
            st.rejected_time += 1
            return None
        dt = dt_ns * 1e-9
        if dt > self.gap_threshold_s and dt > GAP_PERIODS * self.dt_typ:
            st.gaps += 1
            st.resets += 1
            return stamp, q1, q2, phi, v, dt, True, 0.0
        typ = self.dt_typ
        return (stamp, q1, q2, phi, v, dt, False,
                dt if typ == 0.0 else typ + TYPICAL_STEP_WEIGHT * (dt - typ))

    def commit(self, stamp: int, dt_typ: float) -> None:
        """Record an accepted sample and the typical step after it."""
        self.started = True
        self.stamp = stamp
        self.dt_typ = dt_typ


def accept_arrays(stamps, q, phi, v, gap_threshold_s: float):
    """The rules of :class:`SampleGate` over arrays, vectorised.

    Parameters
    ----------
    stamps : ndarray (n,)
        Stamps (ns), integer or float.
    q, phi, v : ndarray (n, 2), (n,), (n,)
        Deflections (m), roll (rad), speed (m/s).
    gap_threshold_s : float

    Returns
    -------
    valid : ndarray of bool (n,)
    restart : ndarray of bool (n,)
        The accepted samples that start a run (the first, and each after a gap).
    stamp_int : ndarray of int64 (n,)
        The accepted stamps (0 where rejected).
    counts : dict
        ``rejected_nonfinite``, ``rejected_range``, ``rejected_time``, ``gaps``, ``resets``.
    """
    st = np.asarray(stamps)
    n = st.shape[0]
    cnt = dict(rejected_nonfinite=0, rejected_range=0, rejected_time=0, gaps=0, resets=0)
    if np.issubdtype(st.dtype, np.integer):
        stamp_ok = np.ones(n, bool)
        stamp_int = st.astype(np.int64)
    else:
        st = st.astype(float)
        stamp_ok = np.isfinite(st) & (np.abs(st) < 2.0 ** 63)
        stamp_int = np.where(stamp_ok, np.trunc(np.where(stamp_ok, st, 0.0)), 0.0).astype(
            np.int64)
    cnt['rejected_nonfinite'] += int(np.count_nonzero(~stamp_ok))
    a, b = q[:, 0], q[:, 1]
    in_range = ((np.abs(a) <= MAX_DEFLECTION_M) & (np.abs(b) <= MAX_DEFLECTION_M)
                & (np.abs(phi) <= MAX_ROLL_RAD) & (np.abs(v) <= MAX_SPEED_MPS))
    out = stamp_ok & ~in_range
    finite = np.isfinite(a) & np.isfinite(b) & np.isfinite(phi) & np.isfinite(v)
    cnt['rejected_range'] += int(np.count_nonzero(out & finite))
    cnt['rejected_nonfinite'] += int(np.count_nonzero(out & ~finite))
    cand = stamp_ok & in_range
    # accepted: later than every earlier candidate (the time-rejected ones are never later
    # than the last accepted stamp, so they do not change the running maximum)
    low = np.iinfo(np.int64).min
    run_max = np.maximum.accumulate(np.where(cand, stamp_int, low))
    before = np.empty(n, np.int64)
    if n:
        before[0] = low
        before[1:] = run_max[:-1]
    valid = cand & (stamp_int > before)
    cnt['rejected_time'] = int(np.count_nonzero(cand & ~valid))
    stamp_int = np.where(valid, stamp_int, 0)
    restart = np.zeros(n, bool)
    acc = np.flatnonzero(valid)
    if acc.size:
        restart[acc[0]] = True
        dts = np.diff(stamp_int[acc]) * 1e-9                   # dts[i]: acc[i] -> acc[i + 1]
        gaps = gap_samples(dts, gap_threshold_s)
        restart[acc[gaps + 1]] = True
        cnt['gaps'] = cnt['resets'] = int(gaps.size)
    return valid, restart, stamp_int, cnt


def gap_samples(dts: np.ndarray, threshold_s: float, periods: float = GAP_PERIODS) -> np.ndarray:
    """Indices i of the steps ``dts[i]`` (s) between accepted samples that are gaps.

    The typical step is the running mean of :class:`SampleGate` (the first step after a
    restart taken as it is); only steps longer than ``threshold_s`` can be gaps, so the mean
    is only evaluated there, one stretch of steps at a time.
    """
    from scipy import signal

    w = TYPICAL_STEP_WEIGHT
    out = []
    typ, done = 0.0, 0                   # dt_typ after dts[:done]
    for i in np.flatnonzero(dts > threshold_s).tolist():
        if i > done:
            x = dts[done:i]
            if typ == 0.0:
                typ, x = float(x[0]), x[1:]
            if x.size:
                typ = float(signal.lfilter([w], [1.0, w - 1.0], x, zi=[(1.0 - w) * typ])[0][-1])
        done = i + 1
        if dts[i] > periods * typ:
            out.append(i)
            typ = 0.0
        else:
            typ = float(dts[i]) if typ == 0.0 else typ + w * (float(dts[i]) - typ)
    return np.asarray(out, dtype=np.int64)


def output_stamps(stamps) -> np.ndarray:
    """The ``stamp_ns`` of a batch's rows (int64): each input stamp as an integer (floats
    truncated), 0 where it is none (non-finite, out of the int64 range, malformed)."""
    st = np.asarray(stamps)
    if np.issubdtype(st.dtype, np.integer):
        return st.astype(np.int64)
    if np.issubdtype(st.dtype, np.floating):
        ok = np.isfinite(st) & (np.abs(st) < 2.0 ** 63)
        return np.where(ok, np.trunc(np.where(ok, st, 0.0)), 0.0).astype(np.int64)
    return np.array([_as_int(t) for t in st.tolist()], dtype=np.int64)


def _as_int(t) -> int:
    try:
        value = int(t)
    except (TypeError, ValueError, OverflowError):
        return 0
    return value if -2 ** 63 <= value < 2 ** 63 else 0
