"""The estimate bag written piece by piece (issue 21): the messages of
:func:`.estimates.write_estimate_bag`, in bounded memory.

:class:`EstimateBagStream` takes consecutive pieces of estimates (:class:`EstimateArrays` of
consecutive samples) and writes each piece's messages as they come (the same topics, types,
QoS, fields and rows as :func:`.write_estimate_bag` of the whole batch; the static loads'
first row of each period carried across pieces), then ``/diagnostics`` when it is closed
(they carry the drive's totals: in the file they follow the estimates; their log times are
those of one piece). The chunks differ from one piece's, the messages do not
(test_estimate_stream).
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from road_force_estimator.serde.cdr import ColumnRows, LazyColumns
from road_force_estimator.bagio.estimates import (
    diagnostic_streams, estimate_streams, EstimateColumns)
from road_force_estimator.serde.messages import (
    DEFAULT_TRACK_WIDTH_M, message_template, stamp_columns)
from road_force_estimator.bagio.writer import BagWriter
from road_force_estimator.interfaces import (
    DIAGNOSTICS, LOAD, LOAD_TRANSFER, LTR, ROAD, STATES, STATIC_LOAD, STATIC_LOAD_PERIOD_NS,
    TOPIC_TYPES, WHEEL_FRAMES, WRENCH, qos_kind)

__all__ = ['EstimateBagStream']

#: Topics in the order :func:`.write_estimate_bag` declares them.
_TOPICS = (*LOAD, *ROAD, LTR, LOAD_TRANSFER, STATES, *STATIC_LOAD)


class EstimateBagStream:
    """An estimate bag written piece by piece (see the module notes); use as a context
    manager or call :meth:`close`."""

    def __init__(self, path: str | Path, *, track_width_m: float = DEFAULT_TRACK_WIDTH_M,
                 custom_data: Mapping[str, str] | None = None) -> None:
        custom = {'road_force_estimator.kind': 'estimates',
                  'road_force_estimator.track_width_m': repr(float(track_width_m))}
        custom.update(custom_data or {})
        self.half = 0.5 * float(track_width_m)
        self.bag = BagWriter(path, custom_data=custom)
        self.bag.open()
        self.counts = {'written': 0, 'invalid': 0, 'nonfinite': 0}
        self._last_stamp: int | None = None
        self._period: int | None = None
        self._declared = False

    def write(self, piece) -> None:
        """Write one piece's messages (rows not valid or not finite are left out, counted)."""
        est = EstimateColumns.of(piece)
        rows = est.valid & est.finite
        index = None if rows.all() else np.flatnonzero(rows)
        s = est.stamp_ns if index is None else est.stamp_ns[index]
        if s.size and (np.any(np.diff(s) <= 0) or (self._last_stamp is not None
                                                    and s[0] <= self._last_stamp)):
            raise ValueError('estimate stamps must be strictly increasing')
        self.counts['written'] += int(s.size)
        self.counts['invalid'] += int(np.count_nonzero(~est.valid))
        self.counts['nonfinite'] += int(np.count_nonzero(est.valid & ~est.finite))
        streams = estimate_streams(replace(est, static_load=None), s, stamp_columns(s), index,
                                    self.half)
        if est.static_load is not None:
            streams += self._static(est, s, index)
        if not self._declared:
            for topic, _, _ in streams:
                self.bag.add_topic(topic, TOPIC_TYPES[topic], qos_kind(topic))
            self._declared = True
        if s.size:
            self._last_stamp = int(s[-1])
            self.bag.write_rows(streams)

    def _static(self, est, s: np.ndarray, index: np.ndarray | None) -> list:
        """The /wheel_load/static/* streams of a piece: the rows that open a period of
        STATIC_LOAD_PERIOD_NS, a period begun in an earlier piece not opened again (as
        :func:`.estimates._static_streams` of the whole batch)."""
        period = s // STATIC_LOAD_PERIOD_NS
        opens = np.ones(s.size, bool)
        opens[1:] = period[1:] != period[:-1]
        if s.size and self._period is not None:
            opens[0] = period[0] != self._period
        if s.size:
            self._period = int(period[-1])
        first = np.flatnonzero(opens)
        rows = first if index is None else index[first]
        stamps = s[first]
        cols_stamp = stamp_columns(stamps)
        streams = []
        for side in (0, 1):
            cols = dict(cols_stamp, **{'wrench.force.z': LazyColumns(
                [est.static_load[:, side]], rows)})
            streams.append((STATIC_LOAD[side], stamps, ColumnRows(
                WRENCH, message_template(WRENCH, WHEEL_FRAMES[side]), stamps.size, cols)))
        return streams

    def write_streams(self, streams: Sequence[tuple[str, np.ndarray, Any]]) -> None:
        """Write more topics of :data:`~road_force_estimator.interfaces.TOPIC_TYPES`
        (``(topic, stamps, rows)`` streams, as :func:`.write_estimate_bag`'s
        ``extra_streams``: the whole vehicle's) beside the estimates."""
        if not self._declared:
            for topic in _TOPICS:
                self.bag.add_topic(topic, TOPIC_TYPES[topic], qos_kind(topic))
            self._declared = True
        for topic, _, _ in streams:
            if topic not in self.bag.topics:
                self.bag.add_topic(topic, TOPIC_TYPES[topic], qos_kind(topic))
        if streams:
            self.bag.write_rows(streams)

    def close(self, diagnostics: Iterable[tuple[int, Any]] = ()) -> dict[str, int]:
        """Write the ``/diagnostics`` messages and close the bag; the counts of
        :func:`.write_estimate_bag` (``written``, ``invalid``, ``nonfinite``)."""
        streams = diagnostic_streams(diagnostics)
        if not self._declared:
            for topic in _TOPICS:
                self.bag.add_topic(topic, TOPIC_TYPES[topic], qos_kind(topic))
            self._declared = True
        if streams:
            self.bag.add_topic(DIAGNOSTICS, TOPIC_TYPES[DIAGNOSTICS], qos_kind(DIAGNOSTICS))
            self.bag.write_rows(streams)
        self.bag.close()
        return dict(self.counts)

    def abort(self) -> None:
        """Close after a failure (the caller removes the folder)."""
        try:
            self.bag.__exit__(RuntimeError, RuntimeError('aborted'), None)
        except Exception:                            # noqa: BLE001 - best effort
            pass
