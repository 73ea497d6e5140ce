"""The online estimate of a drive block by block, as :func:`.estimate_batch` gives it in one
piece (issue 21: memory that does not grow with the drive).

:class:`OnlineStream` feeds the blocks of samples to one :class:`.BatchRun` and hands out
:class:`~.outputs.EstimateArrays` of consecutive samples as soon as every row in them is known
(with a latency the estimates of a block's last samples come with the next block): row k is
the estimate for sample k, a rejected sample holds the previous row (zeros before the first
accepted one), as :func:`.estimate_batch`. Concatenated, the pieces are its arrays bit for
bit (the same step function in the same order; test_stream_run).
"""
from __future__ import annotations

import numpy as np

from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
from road_force_estimator.estimation.acceptance import (
    GAP_THRESHOLD_S, batch_inputs, output_stamps)
from road_force_estimator.estimation.estimator import PROGRESS_BLOCK, BatchRun
from road_force_estimator.estimation.outputs import N_COLUMNS, EstimateArrays, arrays_from_table

__all__ = ['OnlineStream']


class OnlineStream:
    """:func:`.estimate_batch` over blocks (see the module notes).

    :meth:`feed` takes a block and returns the pieces that became complete (possibly
    none), :meth:`finish` the rest; :attr:`status` is the estimator's at the end (with
    ``negative_load_samples`` over every piece handed out).
    """

    def __init__(self, vehicle: VehicleParameters | None = None,
                 observer: ObserverParameters | None = None, *,
                 gap_threshold_s: float = GAP_THRESHOLD_S) -> None:
        self.run = BatchRun(vehicle, observer, gap_threshold_s=gap_threshold_s)
        self._stamps: list[np.ndarray] = []
        self._valid: list[np.ndarray] = []
        self._contra: list[np.ndarray] = []
        self._rows: list[np.ndarray] = []
        self._last = np.zeros(N_COLUMNS)           # the row a rejected sample holds
        self.negative_load_samples = 0

    @property
    def status(self):
        st = self.run.estimator.status
        st.negative_load_samples = self.negative_load_samples
        return st

    def feed(self, stamps_ns, q_m, roll_rad, speed_mps) -> list[EstimateArrays]:
        """One block of samples (as :meth:`.BatchRun.feed`); the complete pieces. The run is
        fed :data:`.PROGRESS_BLOCK` samples at a time (its row list stays small)."""
        stamps, q, phi, speed = batch_inputs(stamps_ns, q_m, roll_rad, speed_mps)
        for a in range(0, stamps.shape[0], PROGRESS_BLOCK):
            b = a + PROGRESS_BLOCK
            ok, contra, rows = self.run.feed(stamps[a:b], q[a:b], phi[a:b], speed[a:b])
            self._valid.append(ok)
            self._contra.append(contra)
            if rows.shape[0]:
                self._rows.append(rows)
        self._stamps.append(output_stamps(stamps))
        return self._emit(final=False)

    def finish(self) -> list[EstimateArrays]:
        """The pieces still held back (the latency's rows, from :meth:`.BatchRun.finish`)."""
        rows = self.run.finish()
        if rows.shape[0]:
            self._rows.append(rows)
        return self._emit(final=True)

    def _emit(self, final: bool) -> list[EstimateArrays]:
        if not self._valid:
            return []
        valid = np.concatenate(self._valid)
        rows = (np.concatenate(self._rows) if len(self._rows) != 1 else self._rows[0]) \
            if self._rows else np.zeros((0, N_COLUMNS))
        # the samples up to (not including) the first accepted one without its row yet
        acc = np.flatnonzero(valid)
        m = valid.size if final or acc.size <= rows.shape[0] else int(acc[rows.shape[0]])
        if m == 0:
            return []
        stamps = np.concatenate(self._stamps)
        contra = np.concatenate(self._contra)
        used = int(np.count_nonzero(valid[:m]))
        table = np.empty((m, N_COLUMNS))
        src = np.where(valid[:m], np.cumsum(valid[:m]) - 1, -1)
        held = np.maximum.accumulate(np.where(valid[:m], np.arange(m), -1))
        src = np.where(held >= 0, src[np.maximum(held, 0)], -1)
        table[src >= 0] = rows[:used][src[src >= 0]]
        table[src < 0] = self._last
        if m:
            self._last = table[-1].copy()
        self._stamps, self._valid, self._contra = [stamps[m:]], [valid[m:]], [contra[m:]]
        self._rows = [rows[used:]] if rows.shape[0] > used else []
        piece = arrays_from_table(table, stamps[:m], valid[:m], self.run.estimator.status,
                                  contra[:m])
        self.negative_load_samples += piece.negative_load_samples()
        return [piece]
