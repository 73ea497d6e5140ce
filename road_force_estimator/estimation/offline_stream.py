"""The offline estimate of a long drive handed out piece by piece, as :func:`.offline.
estimate_recording` gives it in one piece (issue 21: memory that does not grow with the drive
but by a few whole-run arrays).

The model observer's smoother (:mod:`.smoother`) needs the whole run before its first row
(its noise and roughness statistics, the profile pass over the whole run), so
:meth:`OfflineStream.feed` only gathers the inputs (40 bytes a sample) and
:meth:`OfflineStream.finish` yields the estimates: :func:`.smoother.prepare` and
:func:`.smoother.smoothed_rows`, the same functions :func:`.smoother.smooth` runs, with a
long run's rows coming window by window (:meth:`.smoother.Smoother.pieces`) and never held
whole. Pieces of at most :data:`PIECE_ROWS` consecutive input rows; a rejected sample holds
the previous row (zeros before the first accepted one). Concatenated, the pieces are
:func:`.smoother.smooth`'s arrays bit for bit with the same windows (test_offline_stream);
with ``eager`` (``estimate_bag``'s stream) a run goes in windows once it is longer than one
window and its overlap (~11 min at 1 kHz; :func:`.smoother.smooth` by default from ~55 min),
and the windows' own difference from a smoother over the whole run in one go is ~1e-11 of
each field's RMS (:data:`.smoother.WINDOW_OVERLAP_TAUS`, ``python -m
bench.studies.offline_windows``).

With ``spill`` (``estimate_bag`` in pieces) what the smoother needs only piece by piece waits
in temporary files (:mod:`.core.spill`): the distance and output stamps, the readings
(:func:`.offline.spill_readings`: the smoother reads them as rows in a file, the fault
detector a piece's range), and a windowed run's profile pass (its columns, the road built
over them in pieces, :meth:`.front_axle_rows.OfflineRows.road_pieces`): the same bits.

Only the model's smoother (``observer.discretization: model``, the default) streams; the
differentiator schemes' zero-phase chain (:func:`.offline.estimate_offline`) is one piece.
"""
from __future__ import annotations

from typing import Iterator

import numpy as np

from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
from road_force_estimator.estimation.acceptance import GAP_THRESHOLD_S
from road_force_estimator.estimation.models.front_axle import FrontAxleModel
from road_force_estimator.estimation.outputs import (
    N_COLUMNS, Column, EstimateArrays, EstimatorStatus, arrays_from_table)
from road_force_estimator.estimation.offline import (
    LAST_ROW_FIELDS, FaultRows, fill_status, prepare, rows_of, smoothed_rows, spill_readings)
from road_force_estimator.estimation.smoothing.smoother import Smoother

__all__ = ['PIECE_ROWS', 'OfflineStream']

#: Most input rows of a piece handed out.
PIECE_ROWS = 1 << 16


class OfflineStream:
    """:func:`.offline.estimate_recording` (model smoother) over blocks of samples.

    :meth:`feed` gathers a block (returns no piece: the smoother needs the whole drive),
    :meth:`finish` yields the pieces; :attr:`status` is the estimate's (complete once
    :meth:`finish` is exhausted, with ``negative_load_samples`` over every piece), and
    :attr:`odometer` the GNSS fit when one was made from the ``fixes`` given to :meth:`finish`
    and :attr:`distance_source` which distance was used and why
    (:func:`.odometer.distance_speed`).
    """

    def __init__(self, vehicle: VehicleParameters | None = None,
                 observer: ObserverParameters | None = None, *,
                 gap_threshold_s: float = GAP_THRESHOLD_S, capacity: int = 0,
                 window: tuple[int, int] | None = None, spill=None,
                 eager: bool = False) -> None:
        self.vehicle = VehicleParameters() if vehicle is None else vehicle
        self.observer = ObserverParameters() if observer is None else observer
        if self.observer.discretization != 'model':
            raise ValueError('OfflineStream: only the model smoother streams '
                             f'(observer.discretization = {self.observer.discretization!r})')
        self.gap_threshold_s = gap_threshold_s
        self.window = window
        #: windows for every run longer than one (:class:`.smoother.Smoother`'s ``eager``)
        self.eager = eager
        #: a folder for the per-sample columns needed only piece by piece
        #: (:class:`.core.spill.SpillColumn`); None: in memory
        self.spill = spill
        self._buf = _Inputs(max(int(capacity), 1))
        self.status = EstimatorStatus()
        self.odometer = None
        self.fused = False
        self.distance_source = None
        #: the tanh friction's ``v_f`` taken and the file's (:class:`.friction_fit.
        #: FrictionVelocity`, once :meth:`finish` has begun; None: no tanh friction stated)
        self.friction_velocity = None
        #: the last accepted stamp (ns; None before :meth:`finish` or without one)
        self.last_stamp_ns: int | None = None

    @property
    def fed(self) -> int:
        """Samples fed so far."""
        return self._buf.n if self._buf is not None else 0

    def feed(self, stamps_ns, q_m, roll_rad, speed_mps) -> list[EstimateArrays]:
        """One block of samples (stamps ns, q (k, 2) m, roll rad, speed m/s); no piece."""
        self._buf.append(stamps_ns, q_m, roll_rad, speed_mps)
        return []

    def finish(self, fixes=None) -> Iterator[EstimateArrays]:
        """The estimates, piece after piece, in input order (see the module notes)."""
        stamps, q, phi, v = self._buf.arrays()
        self._buf = None
        from road_force_estimator.estimation.offline import attach_distance_source, fused_speed

        v, source = fused_speed(stamps, v, fixes, self.observer.distance_source)
        attach_distance_source(self, source)
        prep = prepare(stamps, q, phi, v, self.vehicle, self.observer,
                       gap_threshold_s=self.gap_threshold_s)
        del stamps, q, phi, v
        self.last_stamp_ns = prep.last_stamp_ns
        self.friction_velocity = prep.friction_velocity
        if self.spill:            # needed only piece by piece: out of memory until then
            prep.dist, prep.stamps_out = _spilled(prep.dist, self.spill), _spilled(
                prep.stamps_out, self.spill)
            spill_readings(prep, self.spill)    # the smoother's rows in a file too
        smoother = Smoother(FrontAxleModel(prep.vehicle), prep.observer, self.window,
                            eager=self.eager)
        smoother.spill = self.spill     # a windowed run's profile pass and road in files
        self.status = EstimatorStatus(**prep.counts)
        out = _Pieces(prep, self.status)
        for rows, part in smoothed_rows(prep, smoother):
            k = part[0].shape[0]
            for a in range(0, k, PIECE_ROWS):        # a run in one piece: its rows in pieces
                b = min(k, a + PIECE_ROWS)
                end = rows.start + b if isinstance(rows, slice) else int(rows[b - 1]) + 1
                yield from out.emit(end, np.column_stack([col[a:b] for col in part]))
            del part
        yield from out.emit(prep.n, np.zeros((0, N_COLUMNS)))
        acc = prep.acc
        fill_status(self.status, acc.size, prep.contradicted, prep.last_stamp_ns,
                    out.last_accepted, smoother)
        out.faults.fill_status(self.status)
        self.status.negative_load_samples = out.negative_load_samples


def _spilled(column: np.ndarray, spill):
    """``column`` moved into a :class:`.core.spill.SpillColumn` in the folder ``spill``."""
    from road_force_estimator.core.spill import SpillColumn

    out = SpillColumn(column.dtype, None if column.ndim == 1 else column.shape[1], spill)
    for a in range(0, column.shape[0], 1 << 20):
        out.append(column[a:a + (1 << 20)])
    return out


class _Inputs:
    """Growable input columns (doubling, trimmed by :meth:`arrays`): the stamps, the
    measurements ``[q_1, q_2, phi]`` as one (n, 3) array (the smoother's, not copied
    again), the speeds."""

    def __init__(self, capacity: int) -> None:
        self.n = 0
        self.cols = [np.empty(capacity, np.int64), np.empty((capacity, 3)), np.empty(capacity)]

    def append(self, stamps_ns, q_m, roll_rad, speed_mps) -> None:
        stamps = np.asarray(stamps_ns, dtype=np.int64)
        k = stamps.shape[0]
        if self.n + k > self.cols[0].shape[0]:
            size = max(2 * self.cols[0].shape[0], self.n + k)
            self.cols = [np.concatenate([c[:self.n], np.empty((size - self.n,) + c.shape[1:],
                                                              c.dtype)]) for c in self.cols]
        rows = slice(self.n, self.n + k)
        self.cols[0][rows] = stamps
        self.cols[1][rows, :2] = np.asarray(q_m, dtype=float)
        self.cols[1][rows, 2] = np.asarray(roll_rad, dtype=float)
        self.cols[2][rows] = np.broadcast_to(np.asarray(speed_mps, dtype=float), (k,))
        self.n += k

    def arrays(self) -> list[np.ndarray]:
        """stamps (n,), q (n, 2), phi (n,), speed (n,): q and phi views of one array."""
        cols = self.cols
        self.cols = []
        stamps, y, v = (c[:self.n] for c in cols)    # views (no copy of a long drive)
        return [stamps, y[:, :2], y[:, 2], v]


class _Pieces:
    """The rows of :func:`.smoother.smoothed_rows` as pieces of input rows: accepted rows in
    order, rejected ones holding the previous row (zeros before the first)."""

    def __init__(self, prep, status: EstimatorStatus) -> None:
        self.prep, self.status = prep, status
        self.faults = FaultRows(prep)      # the sensors' flags (estimation.sensor_health)
        self.row = 0                      # the next input row
        self.done = 0                     # accepted rows handed out
        self.held = np.zeros(N_COLUMNS)   # the row a rejected sample holds
        self.last_accepted: dict | None = None
        self.negative_load_samples = 0

    def emit(self, end: int, accepted: np.ndarray) -> Iterator[EstimateArrays]:
        """Input rows ``self.row:end``, whose accepted ones are the rows ``accepted``
        (k, :data:`.N_COLUMNS`), as pieces."""
        p0, prep = self.row, self.prep
        if end <= p0:
            return
        first = p0 + int(np.argmax(prep.valid[p0:end])) if accepted.shape[0] else end
        if first - p0 > PIECE_ROWS:       # a long stretch of rejected rows: pieces of its own
            for a in range(p0, first, PIECE_ROWS):
                yield from self.emit(min(first, a + PIECE_ROWS), accepted[:0])
            p0 = self.row
        ok = prep.valid[p0:end]
        k = accepted.shape[0]
        table = np.empty((end - p0, N_COLUMNS))
        table[ok] = accepted
        if k < end - p0:                  # rejected rows: the last accepted row before them
            src = np.where(ok, np.arange(end - p0), -1)
            np.maximum.accumulate(src, out=src)
            rej = ~ok
            table[rej & (src >= 0)] = table[src[rej & (src >= 0)]]
            table[rej & (src < 0)] = self.held
        self.held = table[-1].copy()
        flags = np.zeros(end - p0, bool)
        flags[ok] = prep.contradicted[self.done:self.done + k]
        faults = self.faults.flags(p0, end, ok, accepted[:, [Column.DZS, Column.DPHI]])
        self.row, self.done = end, self.done + k
        for a in range(0, end - p0, PIECE_ROWS):
            b = min(end - p0, a + PIECE_ROWS)
            piece = arrays_from_table(table[a:b], rows_of(prep.stamps_out, p0 + a, p0 + b),
                                      ok[a:b], self.status, flags[a:b])
            piece.fault_flags = faults[a:b]
            self.negative_load_samples += piece.negative_load_samples()
            rows = np.flatnonzero(piece.valid)
            if rows.size:
                self.last_accepted = {name: getattr(piece, name)[rows[-1]]
                                      for name in LAST_ROW_FIELDS}
            yield piece
