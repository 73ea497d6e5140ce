"""The sinks of a drive in many blocks that are not files of their own: the diagnostics per
second (:class:`DiagnosticWindows`), the model fit (:class:`ModelFitSink`), and the recorded
speeds and true loads waiting for their estimates (:class:`SampleQueue`). Each takes the
pieces of estimates as the estimator stage hands them out (``add``) and gives its figures at
the end, as the one-block path computes them from the whole arrays (:mod:`.one_block`)."""
from __future__ import annotations

import math

import numpy as np

from road_force_estimator.pipeline.result import finite_fit

__all__ = ['DiagnosticWindows', 'ModelFitSink', 'SampleQueue']


class DiagnosticWindows:
    """The estimator status per second of data time (:func:`.diagnostics.batch_diagnostics`)
    from consecutive pieces: per window its samples, last converged flag, lift-off samples,
    largest |LTR| and |residual|, contradicted speeds and last stamp."""

    def __init__(self) -> None:
        self.s0: int | None = None
        self.windows: list[list] = []

    def add(self, piece) -> None:
        rows = np.flatnonzero(piece.valid)
        if rows.size == 0:
            return
        stamps = piece.stamp_ns[rows]
        if self.s0 is None:
            self.s0 = int(stamps[0])
        second = (stamps - self.s0) // 1_000_000_000
        starts = np.concatenate([[0], np.flatnonzero(np.diff(second)) + 1])
        ends = np.concatenate([starts[1:], [rows.size]])
        lifted = piece.lift_off[rows].any(axis=1).astype(np.int64)
        contra = piece.speed_contradicted[rows].astype(np.int64)
        ltr = np.maximum.reduceat(np.abs(piece.ltr[rows]), starts)
        res = np.maximum.reduceat(np.abs(piece.residual_nm[rows]), starts)
        lifts = np.add.reduceat(lifted, starts)
        bad = np.add.reduceat(contra, starts)
        conv = piece.converged[rows]
        for j, (a, b) in enumerate(zip(starts.tolist(), ends.tolist())):
            w = [int(second[a]), b - a, bool(conv[b - 1]), int(lifts[j]), float(ltr[j]),
                 float(res[j]), int(bad[j]), int(stamps[b - 1])]
            if self.windows and self.windows[-1][0] == w[0]:
                last = self.windows[-1]
                w = [w[0], last[1] + w[1], w[2], last[3] + w[3], max(last[4], w[4]),
                     max(last[5], w[5]), last[6] + w[6], w[7]]
                self.windows[-1] = w
            else:
                self.windows.append(w)

    def statuses(self, totals: dict, name: str, hardware_id: str, model_fit) -> list:
        from road_force_estimator.estimation.diagnostics import (
            estimator_status, model_fit_values)

        out = []
        for j, (_, samples, conv, lifts, ltr, res, bad, stamp) in enumerate(self.windows):
            values = {'samples': samples, 'converged': conv, 'lift_off_samples': lifts,
                      'max_abs_ltr': ltr, 'max_abs_residual_nm': res}
            if bad:
                values['speed_contradicted_samples'] = bad
            if model_fit is not None:
                values.update(model_fit_values(*model_fit))
            if j == len(self.windows) - 1:
                values.update({f'total.{k}': v for k, v in totals.items()})
            status = estimator_status(name, hardware_id, values, converged=conv,
                                      lift_off_samples=lifts, speed_contradicted=bad,
                                      model_fit=values.get('model_fit', 'ok'))
            out.append((stamp, [status.as_dict()]))
        return out


class ModelFitSink:
    """:func:`.model_fit.assess` from consecutive pieces (its monitor fed as they come)."""

    def __init__(self) -> None:
        from road_force_estimator.estimation.fit_check import ModelFitMonitor

        self.monitor = ModelFitMonitor(2.0)
        self.count = 0

    def add(self, piece) -> None:
        rows = np.flatnonzero(piece.valid)
        t = piece.stamp_ns[rows] * 1e-9
        update = self.monitor.update
        for tk, rk in zip(t.tolist(), piece.residual_nm[rows].tolist()):
            update(tk, rk)
        self.count += rows.size

    def result(self, summary, status, vehicle, observer):
        """``(ratio, verdict)`` or None (as :mod:`.one_block` gives it)."""
        from road_force_estimator.estimation.fit_check import OK, moment_std_nm, verdict

        if status.method != 'model':
            return None
        if self.count < 16:
            ratio, word = math.nan, OK
        else:
            speed, dt = summary.fit_speed_and_step()      # read a piece at a time
            sigma = moment_std_nm(vehicle, observer, status, dt, speed)
            ratio = self.monitor.ratio(sigma)
            word = verdict(ratio)
        return finite_fit(ratio, word)


class SampleQueue:
    """A per-sample column of the samples read and not yet estimated (the recorded speeds,
    the true loads), first in first out: in memory (online: a block or two), or in a
    temporary file in ``spill`` (offline: the whole drive is read before its first
    estimate); ``width``: values per sample (None: one, a 1-D column)."""

    def __init__(self, spill=None, width: int | None = None) -> None:
        self.parts: list[np.ndarray] = []
        self.file = None
        self.done = 0
        if spill is not None:
            from road_force_estimator.core.spill import SpillColumn

            self.file = SpillColumn(float, width, spill)

    def append(self, values: np.ndarray) -> None:
        if self.file is not None:
            self.file.append(values)
        else:
            self.parts.append(values)

    def take(self, m: int) -> np.ndarray:
        """The next m values."""
        if self.file is not None:
            self.done += m
            return self.file.read(self.done - m, self.done)
        v = np.concatenate(self.parts) if len(self.parts) > 1 else self.parts[0]
        self.parts[:] = [v[m:]]
        return v[:m]
