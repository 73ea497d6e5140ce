"""A regular sample clock under jittered stamps: the step the model observer takes.

A sensor sampled by its own clock and stamped by software later (a driver, a bus) has stamps
that scatter around a regular grid while the samples stay on it (``simulator.stamp_jitter``:
each stamp moved by its own draw). The steps between such stamps are then negatively
correlated (``d_k = e_k - e_(k-1)``: lag-1 correlation -1/2), where steps that really vary
(a sensor sampled at uneven times) are not (independent steps: 0; a slowly drifting period:
positive). :func:`clock_step` tells the two apart on a block of steps; where it finds a
jittered regular clock, :class:`.ModelCore` steps with the block's mean step instead of each
stamp's (the samples are where the clock put them), for steps within
:data:`JITTER_MAX_FRACTION` of it. Exactly regular streams (every step equal) and stamps
rounded to the nanosecond (a scatter below :data:`JITTER_MIN_FRACTION` of the step, which the
model's transitions do not resolve: :data:`.gains.DT_QUANTUM`) are left as they are.

With the clock's steps the zero-latency load error is that of the true sample times and of
the Kalman peer on the regular grid, where the stamps' own steps cost some; the offline
smoother runs such a run on the clock's grid too (``smoother._clock_grid``: not step by step).
Measured on the real-truck family's sensor drive (a 3 ms lag, +-2 % scale errors and +-50 us
of stamp jitter): ``python -m bench.accuracy.real_truck --drives sensors``.
"""
from __future__ import annotations

import numpy as np

__all__ = ['JITTER_MIN_FRACTION', 'JITTER_MAX_FRACTION', 'JITTER_CORRELATION', 'clock_step']

#: Smallest RMS scatter of the steps (relative to their mean) that counts as stamp jitter.
JITTER_MIN_FRACTION = 1e-3
#: Steps further than this fraction from the clock's step keep their own (a lost sample).
JITTER_MAX_FRACTION = 0.25
#: Lag-1 correlation of the steps' deviations below which the stamps jitter about a regular
#: clock (jitter: -1/2; independent steps: 0, with a spread of ~1/sqrt(n): 0.06 at 256 steps).
JITTER_CORRELATION = -0.3


def clock_step(dts) -> float | None:
    """The step (s) of the regular clock under jittered stamps, from a block of consecutive
    steps ``dts`` (s), or None where the steps are regular or really vary (see the module
    notes). Steps beyond :data:`JITTER_MAX_FRACTION` of the median (gaps, lost samples) are
    left out."""
    d = np.asarray(dts, dtype=float)
    if d.size < 16:
        return None
    med = float(np.median(d))
    if not med > 0.0:
        return None
    d = d[np.abs(d - med) <= JITTER_MAX_FRACTION * med]
    if d.size < 16:
        return None
    mean = float(np.mean(d))
    dev = d - mean
    var = float(np.mean(dev * dev))
    if var <= (JITTER_MIN_FRACTION * mean) ** 2:
        return None
    r1 = float(np.mean(dev[1:] * dev[:-1])) / var
    return mean if r1 < JITTER_CORRELATION else None
