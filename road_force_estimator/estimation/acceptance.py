"""Which samples the estimators use: the rejection and gap rules, per sample and over arrays.

A sample is rejected when a value or the stamp (integer nanoseconds) is non-finite or malformed
(``rejected_nonfinite``), when a value is impossible (``|q| > 1 m``, ``|phi| > pi/2``:
``rejected_range``), when the speed is negative or above 100 m/s (``rejected_speed``), when the
deflections and roll repeat exactly, for the :data:`FROZEN_REPEATS` th time in a row or more,
those of a sample that was moving while the speed now reads standing (below
:data:`~.speed_check.STANDING_MPS`): a CAN drop-out holding the last values
(``rejected_stale``; a truck that stands still from the start keeps its estimate), or when its
stamp is not later than the last accepted one (``rejected_time``). A step of more than
:data:`GAP_PERIODS` typical steps (with no typical step yet, at a run's second sample, one over
:data:`MAX_STAMP_JUMP_S`) is a jump no regular stream takes: the sample is held back (counted
in ``rejected_time``) and the next decides. Earlier than the held stamp (a lone corrupt header,
a minute or a year ahead), it is judged against the stream as if the outlier had never come;
later and continuing from it (the stream really jumped: a gap, a pause, lost samples, a rate
that dropped), it is taken, and the held sample stays lost. So any number of lone outlier
stamps ahead of the stream cost those samples only, and so do those behind it (rejected as
backwards); one less than :data:`GAP_PERIODS` steps ahead costs the samples it overtakes.
:data:`BEHIND_SAMPLES` samples in a row behind the last accepted one that continue each other
mean the stream is there (the accepted ones were ahead of it, e.g. a first sample stamped in
the future, or the clock was set back): a new run starts at the last of them (a gap). A step
longer than ``max(gap_threshold_s,`` :data:`GAP_PERIODS` ``typical steps)`` is a gap (the
estimate restarts there; ``gaps``, ``resets``); the typical step is the running average
``dt_typ += 0.05 (dt - dt_typ)`` of the accepted steps, restarted (the next step taken as it
is) at every restart.

:class:`SampleGate` applies the rules one sample at a time (the per-sample path and
:func:`.estimate_batch`); :func:`accept_arrays` over whole arrays (the offline smoothers), with
the same result. The gap rule alone, for a model whose samples are not the front axle's
three readings (the whole vehicle's, :mod:`.articulated`): :class:`StepGaps` one step at a
time, :func:`gap_samples` over a drive's steps.
"""
from __future__ import annotations

import math

import numpy as np

from road_force_estimator.estimation.speed_check import STANDING_MPS

__all__ = [
    'GAP_THRESHOLD_S', 'GAP_PERIODS', 'MAX_DEFLECTION_M', 'MAX_ROLL_RAD', 'MAX_SPEED_MPS',
    'MAX_STAMP_JUMP_S', 'BEHIND_SAMPLES', 'FROZEN_REPEATS', 'TYPICAL_STEP_WEIGHT',
    'check_gap_threshold',
    'batch_inputs', 'SampleGate', 'StepGaps',
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
#: A forward stamp step longer than this (s) is held until the next sample confirms it (as
#: every jump of more than GAP_PERIODS typical steps now is).
MAX_STAMP_JUMP_S = 60.0
_MAX_JUMP_NS = int(MAX_STAMP_JUMP_S * 1e9)
#: Samples in a row behind the last accepted stamp, continuing each other, from which the
#: stream is taken to be there (a new run starts): more than an outlier less than
#: GAP_PERIODS steps ahead can put behind it.
BEHIND_SAMPLES = int(GAP_PERIODS) + 2
#: Exact repeats of (q_1, q_2, phi) in a row from which samples are stale (a real sensor
#: has noise).
FROZEN_REPEATS = 10


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
        self.clock = 0          # the stream's latest stamp (ns): accepted, or continuing it
        self.held = None        # stamp (ns) of a jump not confirmed yet
        self._behind = None     # (last stamp, count) of the samples in a row behind the stream
        self._values = None     # (q1, q2, phi) of the last sample with good values
        self._moving = False    # whether the sample that first had them was moving
        self._repeats = 0

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
                and -MAX_ROLL_RAD <= phi <= MAX_ROLL_RAD and 0.0 <= v <= MAX_SPEED_MPS):
            self._count_bad(q1, q2, phi, v)
            self._tick(stamp)
            return None
        values = (q1, q2, phi)
        if values == self._values:
            self._repeats += 1
            if self._repeats >= FROZEN_REPEATS and self._moving and v < STANDING_MPS:
                st.rejected_stale += 1
                self._tick(stamp)
                return None
        else:
            self._values = values
            self._moving = v >= STANDING_MPS
            self._repeats = 0
        if not self.started:
            return stamp, q1, q2, phi, v, 0.0, True, 0.0
        dt_ns = stamp - self.stamp
        if dt_ns <= 0:
            if self._behind_run(stamp):       # the stream is back there: a new run
                st.gaps += 1
                st.resets += 1
                return stamp, q1, q2, phi, v, 0.0, True, 0.0
            st.rejected_time += 1
            return None
        self._behind = None
        dt = dt_ns * 1e-9
        typ = self.dt_typ
        if self._jump((stamp - self.clock) * 1e-9):
            if not self._jump_confirmed(stamp):
                st.rejected_time += 1
                return None
        else:
            self.held = None              # back in the stream: a held stamp was an outlier
        if dt > self.gap_threshold_s and dt > GAP_PERIODS * typ:
            st.gaps += 1
            st.resets += 1
            return stamp, q1, q2, phi, v, dt, True, 0.0
        return (stamp, q1, q2, phi, v, dt, False,
                dt if typ == 0.0 else typ + TYPICAL_STEP_WEIGHT * (dt - typ))

    def _tick(self, stamp: int) -> None:
        """A sample rejected for its values still tells where the stream is: its stamp
        moves the clock on when it continues it (so that a run of such samples makes no
        jump of the next good one)."""
        if self.started and 0 < stamp - self.clock and not self._jump(
                (stamp - self.clock) * 1e-9):
            self.clock = stamp

    def _jump(self, dt: float) -> bool:
        """Whether a step of dt (s) is one no regular stream takes: more than GAP_PERIODS
        typical steps, or with no typical step yet (a run's second sample) more than
        :data:`MAX_STAMP_JUMP_S`."""
        typ = self.dt_typ
        return dt > GAP_PERIODS * typ if typ > 0.0 else dt > MAX_STAMP_JUMP_S

    def _jump_confirmed(self, stamp: int) -> bool:
        """Whether the jump to ``stamp`` (ns) is real: it continues from the held stamp (a
        step after it that is no jump itself, or no longer than the jump to the held one: a
        stream whose rate dropped); else ``stamp`` is held instead."""
        held, self.held = self.held, None
        if held is not None and 0 < stamp - held and (
                not self._jump((stamp - held) * 1e-9) or stamp - held <= held - self.clock):
            return True
        self.held = stamp
        return False

    def _behind_run(self, stamp: int) -> bool:
        """Count ``stamp`` (not after the last accepted one) into the run of such samples
        that continue each other; True when it is :data:`BEHIND_SAMPLES` long (forgotten)."""
        run = self._behind
        if run is not None and stamp > run[0] and not self._jump((stamp - run[0]) * 1e-9):
            run = (stamp, run[1] + 1)
        else:
            run = (stamp, 1)
        if run[1] >= BEHIND_SAMPLES:
            self._behind = self.held = None
            return True
        self._behind = run
        return False

    def _count_bad(self, q1: float, q2: float, phi: float, v: float) -> None:
        """Count a sample with a value out of its range: speed, range or non-finite."""
        st = self.status
        if not (math.isfinite(q1) and math.isfinite(q2) and math.isfinite(phi)
                and math.isfinite(v)):
            st.rejected_nonfinite += 1
        elif (abs(q1) <= MAX_DEFLECTION_M and abs(q2) <= MAX_DEFLECTION_M
              and abs(phi) <= MAX_ROLL_RAD):
            st.rejected_speed += 1
        else:
            st.rejected_range += 1

    def commit(self, stamp: int, dt_typ: float) -> None:
        """Record an accepted sample and the typical step after it."""
        self.started = True
        self.stamp = stamp
        if stamp > self.clock or dt_typ == 0.0:     # (a run starting behind: the clock too)
            self.clock = stamp
        self.dt_typ = dt_typ


class StepGaps:
    """The gap rule of :class:`SampleGate` alone, one step at a time (what
    :func:`gap_samples` finds over a drive's steps): a step longer than ``max(gap_threshold_s,``
    :data:`GAP_PERIODS` ``typical steps)`` is a gap, the typical step the running average of
    the steps since the last restart (the first taken as it is)."""

    def __init__(self, gap_threshold_s: float = GAP_THRESHOLD_S) -> None:
        self.gap_threshold_s = check_gap_threshold(gap_threshold_s)
        #: the typical step (s; 0: none since the last restart)
        self.dt_typ = 0.0

    def is_gap(self, dt: float) -> bool:
        """Whether a step of dt (s) after the last one taken is a gap (nothing changed)."""
        return dt > self.gap_threshold_s and dt > GAP_PERIODS * self.dt_typ

    def take(self, dt: float) -> bool:
        """Take a step of dt (s): True when it is a gap (the typical step restarts)."""
        if self.is_gap(dt):
            self.dt_typ = 0.0
            return True
        typ = self.dt_typ
        self.dt_typ = dt if typ == 0.0 else typ + TYPICAL_STEP_WEIGHT * (dt - typ)
        return False


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
        ``rejected_nonfinite``, ``rejected_range``, ``rejected_speed``, ``rejected_stale``,
        ``rejected_time``, ``gaps``, ``resets``.
    """
    st = np.asarray(stamps)
    n = st.shape[0]
    cnt = dict(rejected_nonfinite=0, rejected_range=0, rejected_speed=0, rejected_stale=0,
               rejected_time=0, gaps=0, resets=0)
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
    values_ok = ((np.abs(a) <= MAX_DEFLECTION_M) & (np.abs(b) <= MAX_DEFLECTION_M)
                 & (np.abs(phi) <= MAX_ROLL_RAD))
    speed_ok = (v >= 0.0) & (v <= MAX_SPEED_MPS)
    in_range = values_ok & speed_ok
    out = stamp_ok & ~in_range
    finite = np.isfinite(a) & np.isfinite(b) & np.isfinite(phi) & np.isfinite(v)
    cnt['rejected_speed'] += int(np.count_nonzero(out & finite & values_ok))
    cnt['rejected_range'] += int(np.count_nonzero(out & finite & ~values_ok))
    cnt['rejected_nonfinite'] += int(np.count_nonzero(out & ~finite))
    cand = stamp_ok & in_range
    stale = _stale(q, phi, v, cand)
    cnt['rejected_stale'] = int(np.count_nonzero(stale))
    cand &= ~stale
    # accepted: later than every earlier candidate (the time-rejected ones are never later
    # than the last accepted stamp, so they do not change the running maximum)
    low = np.iinfo(np.int64).min
    run_max = np.maximum.accumulate(np.where(cand, stamp_int, low))
    before = np.empty(n, np.int64)
    if n:
        before[0] = low
        before[1:] = run_max[:-1]
    valid = cand & (stamp_int > before)
    acc = np.flatnonzero(valid)
    steps = np.diff(stamp_int[acc])
    if steps.size and (int(steps.max()) > GAP_PERIODS * int(steps.min())
                       or steps[0] > _MAX_JUMP_NS) \
            or np.count_nonzero(cand & ~valid) >= BEHIND_SAMPLES:
        # a step that may be a jump (held until the next sample decides) or a run behind
        # the stream: one sample at a time
        valid, restart, gate = _gate_over(stamp_int, q, phi, v, cand, gap_threshold_s)
        cnt.update(rejected_time=gate.rejected_time, gaps=gate.gaps, resets=gate.resets)
        return valid, restart, np.where(valid, stamp_int, 0), cnt
    cnt['rejected_time'] = int(np.count_nonzero(cand & ~valid))
    stamp_int = np.where(valid, stamp_int, 0)
    restart = np.zeros(n, bool)
    if acc.size:
        restart[acc[0]] = True
        dts = np.diff(stamp_int[acc]) * 1e-9                   # dts[i]: acc[i] -> acc[i + 1]
        gaps = gap_samples(dts, gap_threshold_s)
        restart[acc[gaps + 1]] = True
        cnt['gaps'] = cnt['resets'] = int(gaps.size)
    return valid, restart, stamp_int, cnt


def _stale(q, phi, v, cand) -> np.ndarray:
    """(n,) bool: the candidates that repeat the values of a moving candidate for the
    :data:`FROZEN_REPEATS` th time in a row or more while the speed reads standing."""
    n = cand.size
    out = np.zeros(n, bool)
    idx = np.flatnonzero(cand)
    if idx.size <= FROZEN_REPEATS:
        return out
    vals = np.column_stack([q[idx], phi[idx]])
    same = np.zeros(idx.size, bool)
    same[1:] = (vals[1:] == vals[:-1]).all(axis=1)
    if not same.any():
        return out
    k = np.arange(idx.size)
    last_new = np.maximum.accumulate(np.where(same, 0, k))
    vi = v[idx]
    out[idx[((k - last_new) >= FROZEN_REPEATS) & (vi[last_new] >= STANDING_MPS)
            & (vi < STANDING_MPS)]] = True
    return out


class _Counts:
    """The time counters of a :class:`SampleGate` run by :func:`_gate_over`."""

    rejected_time = gaps = resets = 0
    rejected_nonfinite = rejected_range = rejected_speed = rejected_stale = 0


def _gate_over(stamp_int, q, phi, v, cand, gap_threshold_s: float):
    """The time rules of :class:`SampleGate` over the candidates ``cand`` (values good),
    sample by sample: ``(valid, restart, counts)``."""
    n = stamp_int.shape[0]
    counts = _Counts()
    gate = SampleGate(gap_threshold_s, counts)
    valid = np.zeros(n, bool)
    restart = np.zeros(n, bool)
    for i in np.flatnonzero(cand).tolist():
        sample = gate.check(int(stamp_int[i]), q[i, 0], q[i, 1], phi[i], v[i])
        if sample is not None:
            valid[i] = True
            restart[i] = sample[6]
            gate.commit(sample[0], sample[7])
    return valid, restart, counts


def gap_samples(dts: np.ndarray, threshold_s: float, periods: float = GAP_PERIODS) -> np.ndarray:
    """Indices i of the steps ``dts[i]`` (s) between accepted samples that are gaps.

    The typical step is the running mean of :class:`SampleGate` (the first step after a
    restart taken as it is); only steps longer than ``threshold_s`` can be gaps, so the mean
    is only evaluated there, one stretch of steps at a time.
    """
    from road_force_estimator.core.scipy_signal import signal as _signal
    signal = _signal()

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
