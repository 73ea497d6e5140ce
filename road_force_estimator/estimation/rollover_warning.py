"""The rollover warning's predictor (issue 32): the quasi-static LTR a short lead ahead.

The quasi-static LTR (:mod:`road_force_estimator.core.unit_loads`: the loads through two 2 Hz
first-order lags) is an estimate of the truth's same low-pass; online, the estimate's own lag
and its small deficit in a curve (0.0015 under the truth's when the truth reaches 0.6 on the
family's curve at zero latency) make a threshold on it trip a few samples after the truth's
would (``python -m bench.studies.roll_sensors --parts warning``). The predictor::

    LTR_pred(t) = LTR_qs(t) + T_lead (LTR_qs(t) - LTR_qs(t - T_rate)) / T_rate

extrapolates the quasi-static LTR by :data:`LEAD_S` along its rate over the last
:data:`RATE_WINDOW_S` (causal: the samples so far). It is a predictor for a warning, not an
estimate: the quasi-static LTR itself is unchanged. Dimensionless, > 0 = load to the right.
"""
from __future__ import annotations

from collections import deque
from typing import Sequence

import numpy as np

__all__ = ['LEAD_S', 'RATE_WINDOW_S', 'WARNING_THRESHOLD', 'predicted_ltr', 'first_reached',
           'LtrPredictor']

#: The predictor's lead (s): the largest lateness measured on the family's curves (3 ms at
#: zero latency, ``bench.studies.roll_sensors --parts warning``) with a margin for the
#: estimate's deficit there (0.0015 at a rate of ~0.3 /s: 5 ms).
LEAD_S = 0.005
#: The window (s) of the quasi-static LTR's rate: a few times its noise's correlation time and
#: well below its 2 Hz low-pass's.
RATE_WINDOW_S = 0.05
#: Issue 32's example threshold.
WARNING_THRESHOLD = 0.6


def predicted_ltr(stamps_ns, ltr_quasi_static, lead_s: float = LEAD_S,
                  rate_window_s: float = RATE_WINDOW_S, t0_ns: int | None = None) -> np.ndarray:
    """The predictor (module notes) over a drive: ``stamps_ns`` (m,) increasing,
    ``ltr_quasi_static`` (..., m) one row per unit; the same shape. The first
    ``rate_window_s`` of samples take the rate since the first sample (0 at it).
    ``t0_ns``: the drive's first stamp when these samples are a later part of it (None:
    ``stamps_ns[0]``); the same bits as the whole drive's at the samples whose window the
    part holds."""
    t = np.asarray(stamps_ns, np.int64)
    qs = np.asarray(ltr_quasi_static, float)
    if lead_s < 0.0 or rate_window_s <= 0.0:
        raise ValueError(f'lead {lead_s!r} s, rate window {rate_window_s!r} s: must be >= 0 '
                         'and > 0')
    if t.size == 0:
        return qs.copy()
    ts = (t - (t[0] if t0_ns is None else np.int64(t0_ns))) * 1e-9
    back = np.searchsorted(ts, ts - rate_window_s, side='left')
    span = ts - ts[back]
    rise = qs - qs[..., back]
    rate = np.divide(rise, span, out=np.zeros_like(qs), where=span > 0.0)
    return qs + lead_s * rate


def first_reached(values, threshold: float = WARNING_THRESHOLD) -> int | None:
    """The first sample at which ``values`` (m,) reach ``threshold``, or None."""
    hit = np.nonzero(np.asarray(values, float) >= threshold)[0]
    return int(hit[0]) if hit.size else None


class LtrPredictor:
    """:func:`predicted_ltr` one sample at a time (the node's; the same numbers): ``update``
    with a sample's stamp (ns, increasing) and each unit's quasi-static LTR returns each
    unit's predicted LTR. Holds the samples of the last ``rate_window_s``."""

    def __init__(self, lead_s: float = LEAD_S, rate_window_s: float = RATE_WINDOW_S) -> None:
        if lead_s < 0.0 or rate_window_s <= 0.0:
            raise ValueError(f'lead {lead_s!r} s, rate window {rate_window_s!r} s: must be '
                             '>= 0 and > 0')
        self.lead_s, self.rate_window_s = float(lead_s), float(rate_window_s)
        self._first: int | None = None
        self._held: deque = deque()          # (seconds since the first, the LTRs)

    def update(self, stamp_ns: int, ltr_quasi_static: Sequence[float]) -> tuple:
        if self._first is None:
            self._first = int(stamp_ns)
        ts = (int(stamp_ns) - self._first) * 1e-9     # (as the array form's float64)
        qs = tuple(map(float, ltr_quasi_static))
        held = self._held
        held.append((ts, qs))
        early = ts - self.rate_window_s
        while held[0][0] < early:
            held.popleft()
        t0, q0 = held[0]
        span = ts - t0
        if not span > 0.0:
            return qs
        lead = self.lead_s
        return tuple([q + lead * ((q - b) / span) for q, b in zip(qs, q0)])
