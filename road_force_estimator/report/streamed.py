"""The report of a drive estimated piece by piece (issue 21): the numbers of
:func:`.summary.summarize` and the segment table of :func:`.summary.drive_segments`, from
accumulators fed with consecutive pieces of estimates (:class:`StreamedSummary`).

What each number needs of the whole drive is kept, and only that:

- per segment of :func:`~road_force_estimator.core.segments.segment_table`, its sums (in
  sample order, as ``np.bincount`` adds them in one piece: each piece's sums start from the
  previous ones), peaks, maxima and lift-off events, on the grid ``arange(x0, ., L)``; the
  last full segment also as continued by the remainder, for when the remainder is merged
  into it;
- the travelled distance and the road of the samples that advance (8 + 16 bytes a sample),
  for the IRI per segment and the coverage (the quarter-car runs over the whole profile at
  its mean spacing, which only the whole drive gives), read back a piece at a time
  (:data:`.core.pieces.PIECE_ROWS`: :func:`.core.iri_chunks.profile_segment_iri`,
  :func:`.core.segments.coverage_pieces`), with their stamps when the drive has fixes, for
  the segments' coordinates (:func:`.core.segments.coordinate_columns_pieces`);
- the stamps and speeds of the accepted samples (16 bytes a sample), for the speed's
  statistics of :func:`~.drive_info.run_description` and the medians of the model fit
  (read a piece at a time) and the fleet's map of distance to stamp
  (:meth:`StreamedSummary.track`, whole).

With a ground truth of the loads, :class:`LoadAccuracy` gives the load and LTR figures of
:func:`.summary.accuracy` from sums over the converged samples (equal to one piece's to the
last bits of the sums' order); the profile's band-passed errors, its cross correlation, the
measured convergence time and the truth's IRI need the whole drive and are left out
(:data:`TRUTH_NOTE`). A reference profile is not handled here (such drives go in one piece).
The other numbers equal the one-piece report's (test/pipeline/test_blocks.py).
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any

import numpy as np

from road_force_estimator.core.iri_chunks import profile_iri, profile_segment_iri
from road_force_estimator.core.pieces import PIECE_ROWS, median, pairwise_mean, steps
from road_force_estimator.core.segments import (
    MIN_COVERAGE, SEGMENT_COLUMNS, blank_empty, coordinate_columns_pieces, coverage_pieces,
    segment_bounds)

__all__ = ['GrowingArray', 'SegmentAccumulator', 'StreamedSummary', 'Track', 'LoadAccuracy',
           'TRUTH_NOTE']

#: The note in the report of a drive with ground truth estimated block by block.
TRUTH_NOTE = ('accuracy: loads and LTR (a drive estimated block by block; the profile errors, '
              'cross correlation, measured convergence time and true IRI need it in one block)')


class GrowingArray:
    """A column that grows by appends (capacity doubling); :meth:`array` is a view."""

    def __init__(self, dtype=float, width: int | None = None, capacity: int = 1024) -> None:
        """``capacity``: rows reserved (pages untouched until written cost no memory)."""
        self.shape = () if width is None else (width,)
        self.data = np.empty((max(int(capacity), 1024),) + self.shape, dtype)
        self.size = 0

    def append(self, values: np.ndarray) -> None:
        k = len(values)
        if self.size + k > self.data.shape[0]:
            grown = np.empty((max(2 * self.data.shape[0], self.size + k),) + self.shape,
                             self.data.dtype)
            grown[:self.size] = self.data[:self.size]
            self.data = grown
        self.data[self.size:self.size + k] = values
        self.size += k

    def array(self) -> np.ndarray:
        return self.data[:self.size]

    def read(self, start: int, stop: int) -> np.ndarray:
        """Rows ``start:stop`` (a view; as :meth:`.core.spill.SpillColumn.read`)."""
        return self.data[max(0, int(start)):min(self.size, int(stop))]


def _seq_bins(acc: np.ndarray, idx: np.ndarray, w: np.ndarray, lo: int) -> None:
    """``acc[j] += w[idx == j]`` in sample order from ``acc``'s values (bins from ``lo``)."""
    hi = int(idx[-1]) + 1
    sums = np.bincount(np.concatenate([np.arange(lo, hi), idx]) - lo,
                       np.concatenate([acc[lo:hi], w]), minlength=hi - lo)
    acc[lo:hi] = sums


class SegmentAccumulator:
    """The per-segment load columns of :func:`.segment_table`, piece by piece."""

    SUMS = ('total0', 'square0', 'total1', 'square1', 'static0', 'static1')
    MAXES = ('peak0', 'peak1', 'ltr', 'quasi')

    def __init__(self, segment_length_m: float) -> None:
        self.length = float(segment_length_m)
        self.x0: float | None = None
        self.grid = np.zeros(0)
        self.n = 0                                   # bins allocated
        self.acc: dict[str, np.ndarray] = {}
        self.cont: dict[str, float] = {}             # the last bin continued from the one before
        self.cont_count = 0
        self.cont_bin = -1
        self.last_lifted = np.zeros(2, bool)

    def _bins(self, x: np.ndarray) -> np.ndarray:
        if self.x0 is None:
            self.x0 = float(x[0])
        top = float(x[-1])
        if self.grid.size == 0 or self.grid[-1] <= top:
            span = max(top - self.x0, 0.0)
            self.grid = np.arange(self.x0, self.x0 + 2.0 * span + 4.0 * self.length,
                                  self.length, dtype=float)
        idx = np.searchsorted(self.grid, x, side='right') - 1
        need = int(idx[-1]) + 2
        if need > self.n:
            m = max(need, 2 * self.n, 64)
            for name in self.SUMS + ('count', 'lifts'):
                old = self.acc.get(name, np.zeros(0))
                self.acc[name] = np.concatenate([old, np.zeros(m - old.size)])
            for name in self.MAXES:
                old = self.acc.get(name, np.zeros(0))
                self.acc[name] = np.concatenate([old, np.full(m - old.size, np.nan)])
            self.n = m
        return idx

    def add(self, x, load, ltr, lift_off, quasi, static) -> None:
        """Samples that advance, in order: distance (m), loads (k, 2), LTR, lift-off (k, 2),
        quasi-static LTR, static loads (k, 2)."""
        if len(x) == 0:
            return
        idx = self._bins(np.asarray(x, dtype=float))
        lo = int(idx[0])
        weights = {'total0': load[:, 0], 'square0': load[:, 0] * load[:, 0],
                   'total1': load[:, 1], 'square1': load[:, 1] * load[:, 1],
                   'static0': static[:, 0], 'static1': static[:, 1]}
        last = int(idx[-1])
        tail = idx == last
        for name, w in weights.items():
            w = np.asarray(w, dtype=float)
            _seq_bins(self.acc[name], idx, w, lo)
            start = (self.cont[name] if last == self.cont_bin
                     else (self.acc[name][last - 1] if last > 0 else 0.0))
            self.cont[name] = float(np.cumsum(np.concatenate([[start], w[tail]]))[-1])
        self.acc['count'][lo:last + 1] += np.bincount(idx - lo, minlength=last + 1 - lo)
        for name, w in (('peak0', load[:, 0]), ('peak1', load[:, 1]), ('ltr', np.abs(ltr)),
                        ('quasi', np.abs(quasi))):
            np.fmax.at(self.acc[name], idx, w)
        lifted = np.asarray(lift_off, dtype=bool)
        before = np.vstack([self.last_lifted[None, :], lifted[:-1]])
        starts = (lifted & ~before).sum(axis=1)
        self.acc['lifts'][lo:last + 1] += np.bincount(idx - lo, starts, minlength=last + 1 - lo)
        self.last_lifted = lifted[-1].copy()
        self.cont_bin = last

    def table(self, x_end: float) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """``(edges, load columns)`` of the drive ending at ``x_end`` (as
        :func:`.segment_table`: the remainder merged when shorter than half a segment)."""
        edges = segment_bounds(self.x0, x_end, self.length)
        k = edges.size - 1
        a = {name: v[:k].copy() for name, v in self.acc.items()}
        m = np.arange(self.x0, x_end, self.length).size   # bins of the unmerged edges
        if m > k:                                         # the remainder merged into k - 1
            for name in self.SUMS:
                a[name][k - 1] = (self.cont[name] if self.cont_bin == m - 1
                                  else self.acc[name][k - 1])
            for name in ('count', 'lifts'):
                a[name][k - 1] += self.acc[name][m - 1]
            for name in self.MAXES:
                a[name][k - 1] = np.fmax(a[name][k - 1], self.acc[name][m - 1])
        return edges, self._columns(a, k)

    @staticmethod
    def _columns(a: dict, k: int) -> dict[str, np.ndarray]:
        counts = a['count']
        out: dict[str, np.ndarray] = {}
        for side, name in ((0, 'left'), (1, 'right')):
            with np.errstate(invalid='ignore', divide='ignore'):
                mean = a[f'total{side}'] / counts
                std = np.sqrt(np.maximum(a[f'square{side}'] / counts - mean * mean, 0.0))
                out[f'dlc_{name}'] = np.where(counts > 1, std / mean, np.nan)
                out[f'static_load_{name}_n'] = a[f'static{side}'] / counts
            out[f'peak_load_{name}_n'] = a[f'peak{side}']
        out['max_abs_ltr'] = a['ltr']
        out['lift_offs'] = a['lifts'].astype(np.int64)
        out['max_abs_ltr_quasi_static'] = a['quasi']
        out['count'] = counts.astype(np.int64)
        return out


@dataclass(frozen=True)
class Track:
    """The accepted samples' stamps (ns) and distances (m) of a drive estimated piece by
    piece (what ``estimate_fleet`` maps a distance to a stamp with); ``valid`` all True."""

    valid: np.ndarray
    stamp_ns: np.ndarray
    distance_m: np.ndarray


class LoadAccuracy:
    """:func:`.summary.accuracy`'s load and LTR figures from consecutive pieces and the true
    loads of their samples (N, (m, 2), NaN where the truth has none): sums over the accepted,
    converged samples with a finite truth."""

    def __init__(self) -> None:
        self.samples = 0
        self.seen = False               #: a finite true load at an accepted sample
        self.err2 = np.zeros(2)
        self.ref2 = np.zeros(2)
        self.peak = np.zeros(2)
        self.ltr_err2 = 0.0
        self.ltr_peak = 0.0
        self.ltr_max = 0.0
        self.ltr_true_max = 0.0

    def add(self, piece, true_load_n: np.ndarray, static_n: np.ndarray) -> None:
        """One piece, the true loads of its samples and the static loads F_c (N, (2,))."""
        rows = np.flatnonzero(piece.valid)
        true = np.asarray(true_load_n, dtype=float)[rows]
        finite = np.isfinite(true).all(axis=1)
        self.seen = self.seen or bool(np.isfinite(true).any())
        judged = rows[piece.converged[rows] & finite]
        if judged.size == 0:
            return
        true = true[piece.converged[rows] & finite]
        err = piece.wheel_load_n[judged] - true
        self.samples += judged.size
        self.err2 += np.sum(err ** 2, axis=0)
        self.ref2 += np.sum((true - static_n) ** 2, axis=0)
        self.peak = np.maximum(self.peak, np.max(np.abs(err), axis=0))
        ltr_true = (true[:, 1] - true[:, 0]) / (true[:, 0] + true[:, 1])
        ltr = piece.ltr[judged]
        self.ltr_err2 += float(np.sum((ltr - ltr_true) ** 2))
        self.ltr_peak = max(self.ltr_peak, float(np.max(np.abs(ltr - ltr_true))))
        self.ltr_max = max(self.ltr_max, float(np.max(np.abs(ltr))))
        self.ltr_true_max = max(self.ltr_true_max, float(np.max(np.abs(ltr_true))))

    def result(self, static_n: np.ndarray) -> dict[str, Any] | None:
        """The figures (keys of :func:`.summary.accuracy`), None under two judged samples."""
        if self.samples < 2:
            return None
        n = self.samples
        rms, ref = np.sqrt(self.err2 / n), np.sqrt(self.ref2 / n)
        with np.errstate(divide='ignore', invalid='ignore'):
            pooled = float(100.0 * math.sqrt(np.mean(np.square(rms)))
                           / math.sqrt(np.mean(np.square(ref))))
            return {
                'samples_judged': n, 'load_rms_n': _floats(rms), 'load_peak_n': _floats(self.peak),
                'load_rms_pct_dynamic': _floats(100.0 * rms / ref),
                'load_rms_pct_static': _floats(100.0 * rms / static_n),
                'load_rms_pct_dynamic_both': pooled, 'true_dynamic_rms_n': _floats(ref),
                'ltr_rms_error': math.sqrt(self.ltr_err2 / n), 'ltr_peak_error': self.ltr_peak,
                'max_abs_ltr': self.ltr_max, 'max_abs_ltr_true': self.ltr_true_max}


def _floats(a) -> list[float]:
    return [float(v) for v in np.ravel(a)]


class StreamedSummary:
    """What :func:`.summary.summarize` reports of a drive, from consecutive pieces."""

    def __init__(self, segment_length_m: float, with_stamps: bool = False,
                 capacity: int = 0, spill=None) -> None:
        """``with_stamps``: keep the stamps of the samples that advance too (8 bytes a
        sample), for the segments' coordinates (a drive with ``/fix``); ``capacity``: the
        samples expected (the columns reserved at once, never copied as they grow);
        ``spill``: a folder where the per-sample columns (distance, profile, stamps, speed:
        32-48 bytes a sample) wait in temporary files until the end of the drive
        (:class:`.core.spill.SpillColumn`) instead of memory."""
        self.segments = SegmentAccumulator(segment_length_m)
        self.inputs = 0
        self.converged = 0
        self.first_converged_ns: int | None = None
        self.last_converged_ns: int | None = None
        self.t0_ns: int | None = None
        self.last_ns: int | None = None
        self.first_stamp: int | None = None
        self.x_first: float | None = None
        self.x_last = 0.0
        self.x_max = -math.inf
        self.lift_off_samples = 0
        self.negative_load_samples = 0
        self.max_abs_ltr = 0.0
        self.static_final = None
        self.contra_samples = 0
        self.spans: list[list[int]] = []
        self._contra_open = False
        if spill is None:
            def column(dtype=float, width=None):
                return GrowingArray(dtype, width, capacity=capacity)
        else:
            from road_force_estimator.core.spill import SpillColumn

            def column(dtype=float, width=None):
                return SpillColumn(dtype, width, spill)
        self.x_up = column()
        self.road_up = column(width=2)
        self.stamps = column(np.int64)
        self.stamps_up = column(np.int64) if with_stamps else None
        #: the distance of every accepted sample (with_stamps: for the fleet's polylines)
        self.x_valid = column() if with_stamps else None
        self.speed = column()
        #: the samples read at a time for the whole drive's IRI and coverage
        self.piece_rows = PIECE_ROWS

    def add(self, piece, speed_mps: np.ndarray) -> None:
        """One piece of estimates and the recorded speed of its samples (m/s)."""
        n = len(piece.stamp_ns)
        if n == 0:
            return
        if self.first_stamp is None:
            self.first_stamp = int(piece.stamp_ns[0])
        self.inputs += n
        self._contradicted(piece)
        rows = np.flatnonzero(piece.valid)
        if rows.size == 0:
            return
        stamps = piece.stamp_ns[rows]
        if self.t0_ns is None:
            self.t0_ns = int(stamps[0])
        self.last_ns = int(stamps[-1])
        conv = piece.converged[rows]
        self.converged += int(np.count_nonzero(conv))
        if conv.any():
            if self.first_converged_ns is None:
                self.first_converged_ns = int(stamps[np.argmax(conv)])
            self.last_converged_ns = int(stamps[conv.size - 1 - np.argmax(conv[::-1])])
        x = piece.distance_m[rows]
        if self.x_first is None:
            self.x_first = float(x[0])
        self.x_last = float(x[-1])
        self.lift_off_samples += int(np.count_nonzero(piece.lift_off[rows].any(axis=1)))
        self.negative_load_samples += int(np.count_nonzero(
            piece.load_clipped[rows].any(axis=1)))
        self.max_abs_ltr = max(self.max_abs_ltr, float(np.max(np.abs(piece.ltr[rows]))))
        self.static_final = [float(v) for v in piece.static_load_n[rows[-1]]]
        self.stamps.append(stamps)
        if self.x_valid is not None:
            self.x_valid.append(x)
        self.speed.append(np.asarray(speed_mps, dtype=float)[rows])
        before = np.concatenate([[self.x_max], np.maximum.accumulate(x)[:-1]])
        before = np.maximum(before, self.x_max)
        up = x > before
        self.x_max = max(self.x_max, float(np.max(x)))
        r = rows[up]
        self.x_up.append(x[up])
        if self.stamps_up is not None:
            self.stamps_up.append(stamps[up])
        self.road_up.append(piece.road_m[r])
        self.segments.add(x[up], piece.wheel_load_n[r], piece.ltr[r], piece.lift_off[r],
                          piece.ltr_quasi_static[r], piece.static_load_n[r])

    def _contradicted(self, piece) -> None:
        flags = np.asarray(piece.speed_contradicted, bool)
        self.contra_samples += int(np.count_nonzero(flags))
        if not flags.any() and not self._contra_open:
            return
        f = np.concatenate([[self._contra_open], flags]).astype(np.int8)
        d = np.diff(f)
        s = piece.stamp_ns
        for i in np.flatnonzero(d != 0).tolist():
            if d[i] == 1:
                self.spans.append([int(s[i]), int(s[i])])
            else:
                self.spans[-1][1] = int(s[i - 1]) if i else self.spans[-1][1]
        if flags[-1]:
            self.spans[-1][1] = int(s[-1])
        self._contra_open = bool(flags[-1])

    # -- the whole drive's numbers ----------------------------------------------------------
    def speed_findings(self) -> dict[str, Any]:
        if not self.contra_samples:
            return {}
        t0 = self.first_stamp
        return {'speed_contradicted': {
            'samples': self.contra_samples,
            'spans_s': [[round((a - t0) * 1e-9, 3), round((b - t0) * 1e-9, 3)]
                        for a, b in self.spans]}}

    def segment_table(self, fixes=None) -> dict[str, np.ndarray]:
        """:func:`.summary.drive_segments` of the drive (no truth); coordinates from
        ``fixes`` (:class:`.bagio.Fixes`) when the stamps were kept. The IRI, the coverage
        and the coordinates read the distances, the road and the stamps a piece at a time
        (:meth:`_iri`, :func:`.core.segments.coverage_pieces`,
        :func:`.core.segments.coordinate_columns_pieces`)."""
        n = self.x_up.size
        empty = {name: np.zeros(0) for name in SEGMENT_COLUMNS}
        if n < 2:
            return empty
        try:
            edges, cols = self.segments.table(float(self.x_up.read(n - 1, n)[0]))
        except ValueError:
            return empty
        table: dict[str, np.ndarray] = {'start_m': edges[:-1].copy(),
                                        'end_m': edges[1:].copy()}
        counts = cols.pop('count')
        table.update(cols)
        table.update(self._iri(edges))
        blank_empty(table, coverage_pieces(n, self.x_up.read, edges, self.piece_rows)
                    < MIN_COVERAGE, counts)
        have = fixes is not None and self.stamps_up is not None
        table.update(coordinate_columns_pieces(
            n, lambda lo, hi: (self.x_up.read(lo, hi), self.stamps_up.read(lo, hi)), edges,
            fixes.stamps_ns if have else None, fixes.latitude_deg if have else None,
            fixes.longitude_deg if have else None, self.piece_rows))
        return {name: table[name] for name in SEGMENT_COLUMNS}

    def _profile(self, side: int | None = None):
        """``read(lo, hi) -> (x, z)`` of the profile of the samples that advance: both tracks
        ((k, 2)), or track ``side`` ((k, 1))."""
        cols = slice(None) if side is None else slice(side, side + 1)
        return lambda lo, hi: (self.x_up.read(lo, hi), self.road_up.read(lo, hi)[:, cols])

    def _iri(self, edges: np.ndarray) -> dict[str, np.ndarray]:
        """The IRI columns (:func:`.core.iri_chunks.profile_segment_iri` per track, read a
        piece at a time: :func:`.core.iri.iri_segments`' bits; NaN where it raises, as
        :func:`.summary._iri_hook`); the intervals per segment kept for :meth:`whole_iri`."""
        k = edges.size - 1
        out = {f'true_iri_{name}_m_per_km': np.full(k, np.nan) for name in ('left', 'right')}
        self._counts = None
        for side, name in ((0, 'left'), (1, 'right')):
            try:
                values, self._counts = profile_segment_iri(
                    self.x_up.size, self._profile(side), edges, self.piece_rows)
                values = values[:, 0]
            except ValueError:
                values = np.full(k, np.nan)
            out[f'iri_{name}_m_per_km'] = np.asarray(values, dtype=float)
        return out

    def _whole(self) -> list[float] | None:
        """:func:`.summary.whole_iri` of the estimated profile read a piece at a time
        (:func:`.core.iri_chunks.profile_iri`, the same bits): None where it is not finite
        or ``iri`` raises."""
        if not self._road_finite():
            return None
        try:
            return _floats(profile_iri(self.x_up.size, self._profile(), self.piece_rows))
        except ValueError:
            return None

    def _road_finite(self) -> bool:
        """Whether the road of every sample that advances is finite (read a piece at a time)."""
        road, n, rows = self.road_up, self.road_up.size, self.piece_rows
        return all(np.isfinite(road.read(lo, lo + rows)).all() for lo in range(0, n, rows))

    def whole_iri(self, segments: dict) -> list[float] | None:
        """:func:`.summary.whole_from_segments` of the estimated profile (the intervals per
        segment from :meth:`segment_table`), the profile read a piece at a time (where the
        segments do not give it: :meth:`_whole`)."""
        if self.x_up.size < 2:
            return None
        start = segments.get('start_m')
        counts = getattr(self, '_counts', None)
        # (no intervals: each track's segment IRI raised; where the profile is finite its
        # IRI raises too: None, as summary.whole_from_segments gives)
        if (counts is None or start is None or len(start) == 0
                or not self._road_finite()):
            return self._whole()
        values = np.column_stack([segments['iri_left_m_per_km'],
                                  segments['iri_right_m_per_km']])
        used = (counts > 0) & np.isfinite(values).all(axis=1)
        if not used.any():
            return self._whole() if np.isfinite(values).all() else None
        return [float(v) for v in values[used].T @ counts[used] / counts[used].sum()]

    def track(self) -> Track:
        """What ``estimate_fleet`` maps distance to stamp with (:class:`Track`; empty without
        ``with_stamps``)."""
        if self.x_valid is None:
            return Track(np.zeros(0, bool), np.zeros(0, np.int64), np.zeros(0))
        x = self.x_valid.array()
        return Track(np.ones(x.size, bool), self.stamps.array(), x)

    def fit_speed_and_step(self) -> tuple[float, float]:
        """What :func:`.estimation.fit_check.assess` sets sigma_M with, of the accepted
        samples: the median moving speed (m/s; ``|v| >= 1``, 1.0 without one) and the median
        stamp step (s), read a piece at a time (:func:`.core.pieces.median`, exact; the steps
        by :func:`.core.pieces.steps`)."""
        speed, stamps, rows = self.speed, self.stamps, self.piece_rows

        def moving():
            for lo in range(0, speed.size, rows):
                v = np.abs(speed.read(lo, lo + rows))
                yield v[v >= 1.0]

        moving_median = median(moving)           # NaN: none moving (|v| >= 1 has no NaN)
        step = median(lambda: steps(stamps.size, lambda lo, hi: stamps.read(lo, hi) * 1e-9,
                                    rows))
        return (1.0 if math.isnan(moving_median) else moving_median), step

    def speed_stats(self) -> dict[str, float] | None:
        """Mean, min and max (m/s) of the finite recorded speeds of the accepted samples
        (None without one), read a piece at a time: ``np.mean``'s bits by
        :func:`.core.pieces.pairwise_mean`, the extremes of the pieces' extremes."""
        speed, n, rows = self.speed, self.speed.size, self.piece_rows

        def finite():
            for lo in range(0, n, rows):
                v = speed.read(lo, lo + rows)
                yield v[np.isfinite(v)]

        count, low, high = 0, math.inf, -math.inf
        for v in finite():
            if v.size:
                count += v.size
                low, high = min(low, float(np.min(v))), max(high, float(np.max(v)))
        if not count:
            return None
        return {'mean': pairwise_mean(count, finite()), 'min': low, 'max': high}
