"""``estimate_bag`` on a long drive, block by block: memory that does not grow with the drive
(issue 21).

Used by :func:`.estimate_bag.run` for a drive bag whose metadata lists at least
:data:`STREAM_MIN_SAMPLES` deflection messages (fewer in a Dask worker with a memory limit:
:func:`stream_threshold`) and no ground truth, when no reference profile is given
(:func:`use_stream`); shorter drives go through in one piece (their outputs
unchanged, byte for byte). The blocks: the bag read :data:`~.bagio.drive_blocks.BLOCK_SAMPLES`
samples at a time (:class:`~.bagio.drive_blocks.DriveBlocks`); online the estimate of each
block (:class:`~.estimation.stream_run.OnlineStream`, bit-identical to one piece: the chain is
causal), offline (the model's smoother) the drive gathered and its estimate handed out piece
by piece (:class:`~.estimation.offline_stream.OfflineStream`: runs longer than ~11 min at
1 kHz in windows, ~1e-11 of one piece; the differentiator schemes' offline chain stays one
piece); the pieces' messages written at once (:class:`~.bagio.estimate_stream.EstimateBagStream`),
the diagnostics per second, the model fit and the report's accumulators
(:class:`~.report.streamed.StreamedSummary`) fed with it. The bag's messages, ``segments.csv``
and ``report.json`` are those of the one-piece path (test_estimate_stream); the detail
figures too (:mod:`.stream_figures`), the profile and overview figures show the detail window
only (a note in the report says so). The per-sample columns needed only at the end (or, offline,
piece by piece) wait in unnamed temporary files in the output folder (:mod:`.core.spill`).
"""
from __future__ import annotations

import json
import math
from pathlib import Path
import sys
from types import SimpleNamespace
from typing import Any

import numpy as np

__all__ = ['STREAM_MIN_SAMPLES', 'use_stream', 'run_stream']

#: Drives of at least this many deflection messages (metadata.yaml) are estimated block by
#: block (about 35 min at 1 kHz; below it one piece takes less than ~1 GB).
STREAM_MIN_SAMPLES = 1 << 21
#: The note in the report of a streamed drive with figures.
FIGURES_NOTE = ('figures: the profile and overview show the detail window (a drive '
                'estimated block by block)')


#: What a sample costs the one-piece path at its peak, figures on (bytes; measured 545
#: offline and ~720 online, ``bench/long_drive_memory.py``), rounded up.
ONE_PIECE_BYTES_PER_SAMPLE = 1000


def worker_memory_limit() -> float | None:
    """The memory limit (bytes) of the Dask worker this runs in (``estimate_fleet``), None
    outside one or without a limit."""
    if 'distributed' not in sys.modules:
        return None
    try:
        from distributed import get_worker
        worker = get_worker()
    except (ImportError, ValueError):
        return None
    limit = getattr(getattr(worker, 'memory_manager', None), 'memory_limit', None)
    return float(limit) if limit else None


def stream_threshold() -> int:
    """Deflection messages from which a drive is streamed: :data:`STREAM_MIN_SAMPLES`, less
    in a Dask worker whose memory limit one piece would pass half of
    (:data:`ONE_PIECE_BYTES_PER_SAMPLE` a sample)."""
    limit = worker_memory_limit()
    if limit is None:
        return STREAM_MIN_SAMPLES
    return max(1, min(STREAM_MIN_SAMPLES, int(0.5 * limit / ONE_PIECE_BYTES_PER_SAMPLE)))


def use_stream(input_path: Path, mode: str, reference, observer,
               min_samples: int | None = None) -> bool:
    """Whether :func:`run_stream` estimates this drive (see the module notes);
    ``min_samples``: instead of :func:`stream_threshold`."""
    from road_force_estimator.bagio.drive_blocks import streamable

    limit = stream_threshold() if min_samples is None else min_samples
    if reference is not None or mode not in ('online', 'offline'):
        return False
    if mode == 'offline' and observer.discretization != 'model':
        return False                # the differentiators' zero-phase chain: one piece
    return streamable(input_path) >= limit


class _DiagnosticWindows:
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


class _ModelFit:
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
        """``(ratio, verdict)`` or None (as ``estimate_bag._model_fit``)."""
        from road_force_estimator.estimation.fit_check import OK, moment_std_nm, verdict

        if getattr(status, 'method', '') != 'model':
            return None
        if self.count < 16:
            ratio, word = math.nan, OK
        else:
            v = np.abs(summary.speed.array())
            moving = v[v >= 1.0]
            speed = float(np.median(moving)) if moving.size else 1.0
            dt = float(np.median(np.diff(summary.stamps.array() * 1e-9)))
            sigma = moment_std_nm(vehicle, observer, status, dt, speed)
            ratio = self.monitor.ratio(sigma)
            word = verdict(ratio)
        return None if not math.isfinite(ratio) else (ratio, word)


def run_stream(folder: Path, output: Path, input_path: Path, vehicle, observer,
               options: dict, stages, api, progress: bool = False,
               block_samples: int | None = None):
    """Estimate the drive block by block and write ``folder/bag`` and ``folder/report``.

    ``api``: estimate_bag's ``PROG``, ``InputError`` and ``EstimateResult`` (attributes
    ``prog``, ``error``, ``result``). Returns the ``EstimateResult``; its ``estimates`` are
    never held whole: only the stamps and distances of the accepted samples for
    ``estimate_fleet``'s polylines when the drive has ``/fix``
    (:meth:`.StreamedSummary.track`).

    Raises
    ------
    api.error
        As the one-piece path: no usable sample or speed, no sample estimated.
    """
    for p in (folder / 'bag', folder / 'report'):
        if p.exists():
            raise api.error(f'{p} exists (use --force to replace it)')
    folder.mkdir(parents=True, exist_ok=True)
    run = _StreamRun(folder, input_path, vehicle, observer, options, api, block_samples)
    stages.next(f'estimating ({options["mode"]}) and writing the bag, block by block')
    run.estimate(progress)
    extra, written = run.close_bag()
    stages.next('writing the report' + (' and figures' if options['figures'] else ''))
    doc = _write_report(folder / 'report', run.summary, run.stream, run.drive(),
                        vehicle, observer, extra, input_path.name, options, run.figures)
    warnings = [f'{input_path}: {issue}' for issue in run.reader.issues]
    return api.result(doc, output / 'bag', output / 'report', run.summary.track(), written,
                      warnings, run.drive())


class _StreamRun:
    """The state of :func:`run_stream`: the reader, the estimator, the bag, the
    accumulators."""

    def __init__(self, folder: Path, input_path: Path, vehicle, observer, options: dict, api,
                 block_samples: int | None) -> None:
        from road_force_estimator.bagio.drive_blocks import (
            BLOCK_SAMPLES, DriveBlocks, streamable)
        from road_force_estimator.bagio.estimate_stream import EstimateBagStream
        from road_force_estimator.estimation.offline_stream import OfflineStream
        from road_force_estimator.estimation.stream_run import OnlineStream
        from road_force_estimator.report.figures import DEFAULT_WINDOW_S
        from road_force_estimator.report.streamed import StreamedSummary
        from road_force_estimator.tools.stream_figures import OfflineWindow, Snapshots

        self.folder, self.input_path, self.api = folder, input_path, api
        self.vehicle, self.observer, self.options = vehicle, observer, options
        self.reader = DriveBlocks(input_path, block_samples or BLOCK_SAMPLES)
        self.offline = options['mode'] == 'offline'
        # offline, the columns needed only piece by piece wait in files in the output folder
        self.stream = (OfflineStream(vehicle, observer, capacity=streamable(input_path),
                                     spill=folder, eager=True)
                       if self.offline else OnlineStream(vehicle, observer))
        custom = {'road_force_estimator.mode': options['mode'],
                  'road_force_estimator.input': input_path.name,
                  'road_force_estimator.writer_command': api.prog}
        self.bag = EstimateBagStream(folder / 'bag', track_width_m=vehicle.track_width_m,
                                     custom_data=custom)
        self.summary = StreamedSummary(options['segment_length_m'],
                                       with_stamps=_has_fixes(input_path),
                                       capacity=streamable(input_path), spill=folder)
        self.diag, self.fit = _DiagnosticWindows(), _ModelFit()
        self.speeds = _Queue(folder if self.offline else None)
        self.snapshots = self.window = None
        if options['figures'] and self.offline:
            self.window = OfflineWindow(DEFAULT_WINDOW_S, self.stream)
        elif options['figures']:
            self.snapshots = Snapshots(DEFAULT_WINDOW_S)

    def estimate(self, progress: bool) -> None:
        """Every block through the estimator, the pieces to the bag and the accumulators;
        the bag aborted (and the error raised) when the input is bad."""
        from road_force_estimator.bagio import BagReadError

        progress = progress and sys.stderr.isatty()
        try:
            for i, block in enumerate(self.reader):
                self._check_spacing(block)
                if self.snapshots is not None:
                    self.snapshots.keep(i, block.stamps_ns[0], self.stream, self.summary)
                self.speeds.append(np.where(block.early, np.nan, block.speed_mps))
                for piece in self.stream.feed(block.stamps_ns, block.q_m, block.roll_rad,
                                              block.speed_mps):
                    self._consume(piece)
                if progress:
                    done = (f'{self.stream.fed} samples read' if self.offline
                            else f'{self.summary.inputs} samples')
                    print(f'{self.api.prog}: {done}', end='\r',
                          flush=True, file=sys.stderr)
            rest = (self.stream.finish(self.reader.fixes) if self.offline
                    else self.stream.finish())
            for piece in rest:
                self._consume(piece)
            problem = self._problem()
        except BagReadError as err:
            self.bag.abort()
            raise self.api.error(str(err)) from None
        except BaseException:
            self.bag.abort()
            raise
        if problem:
            self.bag.abort()
            raise self.api.error(problem)

    def _check_spacing(self, block) -> None:
        """The segments no shorter than the block's sample spacing (else api.error)."""
        from road_force_estimator.core.segments import check_segment_length, sample_spacing
        from road_force_estimator.estimation.acceptance import MAX_SPEED_MPS

        try:
            check_segment_length(self.options['segment_length_m'], sample_spacing(
                block.stamps_ns, block.speed_mps, MAX_SPEED_MPS))
        except ValueError as err:
            raise self.api.error(str(err)) from None

    def _consume(self, piece) -> None:
        """One piece of estimates to the bag, the report's accumulators, the diagnostics and
        the model fit (with the recorded speeds of its samples)."""
        m = len(piece.stamp_ns)
        v = self.speeds.take(m)
        self.bag.write(piece)
        self.summary.add(piece, v)
        self.diag.add(piece)
        self.fit.add(piece)
        if self.window is not None:
            self.window.keep(piece, self.summary)

    def _problem(self) -> str | None:
        """Why nothing can be estimated (the one-piece path's reasons), or None."""
        status, n, reader = self.stream.status, self.summary.inputs, self.reader
        if n == 0:
            return (f'{self.input_path}: no usable /suspension/deflections message'
                    + (f' ({reader.issues[0]})' if reader.issues else ''))
        if reader.twists == 0:
            return 'no usable /vehicle/twist message: the speed is unknown'
        if status.accepted == 0:
            return (f'{self.input_path}: no sample could be estimated: all {n} samples '
                    f'rejected ({status.rejected_range} out of range, '
                    f'{status.rejected_nonfinite} non-finite, {status.rejected_time} with a '
                    'bad stamp)')
        return None

    def close_bag(self) -> tuple[dict[str, Any], dict[str, int]]:
        """The notes for the report and the bag's counts, once its diagnostics are written."""
        from road_force_estimator.estimation.fit_check import ADVICE, MISMATCH

        status, reader, prog = self.stream.status, self.reader, self.api.prog
        extra: dict[str, Any] = {}
        if reader.early:
            extra['samples before the first twist (given its speed)'] = reader.early
        counts = {'samples': self.summary.inputs, 'estimated': int(status.accepted),
                  'rejected_by_reader': int(reader.rejected_total),
                  'rejected_by_estimator': int(status.rejected), 'resets': int(status.resets)}
        fit = getattr(self.stream, 'odometer', None)  # a GNSS fit was made (offline)
        if fit is not None and not fit.problem:
            counts.update(odometer_scale=fit.scale, odometer_scale_std=fit.scale_sigma,
                          odometer_fixes_rejected=fit.rejected)
        verdict = self.fit.result(self.summary, status, self.vehicle, self.observer)
        if verdict is not None:
            extra['model fit'] = (f'{verdict[1]} (residual band RMS {verdict[0]:.3g} x '
                                  'sigma_M)' + (f': {ADVICE}' if verdict[1] == MISMATCH else ''))
        written = self.bag.close(self.diag.statuses(
            counts, f'{prog}: estimator ({self.options["mode"]})', prog, verdict))
        if written.get('nonfinite'):
            extra['estimates not written (non-finite)'] = written['nonfinite']
        if self.options['figures']:
            extra[FIGURES_NOTE] = 1
        return extra, written

    def drive(self) -> SimpleNamespace:
        """What the report reads of the drive (as :class:`.bagio.Drive`, without arrays)."""
        r = self.reader
        return SimpleNamespace(messages=r.messages, rejected=r.rejected, issues=tuple(r.issues),
                               fixes=r.fixes, custom_data=r.custom_data, noted=r.noted)

    def figures(self, segments: dict, doc: dict) -> list[str]:
        """The figures (:func:`.stream_figures.draw`) of the report ``doc``."""
        from road_force_estimator.report.folder import static_line
        from road_force_estimator.tools.stream_figures import draw

        keeper = self.window if self.offline else self.snapshots
        if keeper is None:
            return []
        name, mode = self.input_path.name, self.options['mode']
        return draw(self.folder / 'report', self.input_path, self.reader.block_samples,
                    keeper, self.summary, segments,
                    f'{name} ({mode})' if name else mode, self.options['units'],
                    static_line(doc, self.vehicle), self._rerun)

    def _rerun(self):
        """A new stream of this drive's estimates (the offline detail window's fallback:
        :class:`.stream_figures.OfflineWindow`): the blocks read again, its pieces."""
        from road_force_estimator.bagio.drive_blocks import DriveBlocks, streamable
        from road_force_estimator.estimation.offline_stream import OfflineStream

        reader = DriveBlocks(self.input_path, self.reader.block_samples)
        stream = OfflineStream(self.vehicle, self.observer, eager=True,
                               capacity=streamable(self.input_path))
        for block in reader:
            stream.feed(block.stamps_ns, block.q_m, block.roll_rad, block.speed_mps)
        return stream.finish(reader.fixes)


class _Queue:
    """The recorded speeds of the samples read and not yet estimated, first in first out:
    in memory (online: a block or two), or in a temporary file in ``spill`` (offline: the
    whole drive is read before its first estimate)."""

    def __init__(self, spill=None) -> None:
        self.parts: list[np.ndarray] = []
        self.file = None
        self.done = 0
        if spill is not None:
            from road_force_estimator.core.spill import SpillColumn

            self.file = SpillColumn(float, None, spill)

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


def _has_fixes(input_path: Path) -> bool:
    """Whether the bag's metadata lists ``/fix`` messages."""
    from road_force_estimator.bagio.reader import bag_files
    from road_force_estimator.interfaces import FIX

    info = bag_files(input_path)[1]
    return any(((e or {}).get('topic_metadata') or {}).get('name') == FIX
               and (e or {}).get('message_count') for e in
               (info.get('topics_with_message_count') or []))


def _write_report(folder: Path, acc, stream, drive, vehicle, observer, extra: dict,
                  input_name: str, options: dict, figures) -> dict[str, Any]:
    """``report.md``, ``segments.csv``, ``report.json`` and the figures
    (``figures(segments, summary)`` draws them) as :func:`.report.write_report`, from the
    accumulators."""
    from road_force_estimator.report.folder import json_safe, write_segments_csv
    from road_force_estimator.report.markdown import write_markdown

    folder.mkdir(parents=True, exist_ok=True)
    summary, segments = _summary(acc, stream, drive, vehicle, observer, extra, input_name,
                                 options)
    names = figures(segments, summary)
    summary['figures'] = names
    write_segments_csv(folder / 'segments.csv', segments)
    write_markdown(folder / 'report.md', summary, segments, names)
    (folder / 'report.json').write_text(json.dumps(json_safe(summary), indent=2) + '\n')
    return summary


def _summary(acc, stream, drive, vehicle, observer, extra: dict, input_name: str,
             options: dict) -> tuple[dict[str, Any], dict]:
    """:func:`.summary.summarize`'s ``(summary, segments)`` of a streamed drive (``stream``:
    its :class:`.OnlineStream` or :class:`.OfflineStream`)."""
    from road_force_estimator import __version__
    from road_force_estimator.report.summary import (
        convergence_summary, notes, rejections, segment_counts, sensor_summary)

    st = stream.status
    rejected = rejections(drive, st)
    t_s = (0.0 if acc.t0_ns is None else (acc.last_ns - acc.t0_ns) * 1e-9)
    judged = 'converged' if acc.converged or acc.t0_ns is None else 'settling time'
    run_info = options.get('run_info') or {}
    summary: dict[str, Any] = {
        'input': input_name, 'mode': options['mode'],
        'messages': dict(sorted(drive.messages.items())),
        'samples': {'input': acc.inputs, 'estimated': int(st.accepted),
                    'converged': acc.converged},
        'judged_from': judged,
        'rejected': rejected,
        'rejected_total': int(sum(sum(r.values()) for r in rejected.values())),
        'issues': list(drive.issues), 'resets': int(st.resets), 'gaps': int(st.gaps),
        'duration_s': float(t_s),
        'distance_m': float(acc.x_last - acc.x_first) if acc.x_first is not None else 0.0,
        'settling_time_s': float(st.settling_time_s),
        'first_converged_s': (float((acc.first_converged_ns - acc.t0_ns) * 1e-9)
                              if acc.first_converged_ns is not None else math.inf),
        'lift_off_samples': acc.lift_off_samples,
        'negative_load_samples': acc.negative_load_samples,
        'max_abs_ltr': acc.max_abs_ltr, 'static_load_final_n': acc.static_final,
        'fixes': int(len(drive.fixes.stamps_ns)) if drive.fixes is not None else 0,
        'has_ground_truth': False, 'reference_profile': None, 'reference_offset_m': None,
        'segment_length_m': float(options['segment_length_m']), 'units': options['units'],
        'run': {'command': run_info.get('command'), 'params_file': run_info.get('params_file'),
                'overrides': list(run_info.get('overrides') or ()),
                'package_version': __version__, 'mode': options['mode'],
                'latency_s': float(observer.latency_s),
                'road_source': (drive.custom_data or {}).get('road_force_estimator.road_name'),
                'speed_mps': acc.speed_stats(),
                'static_load_n': [float(v) for v in vehicle.static_load_n]},
        'parameters': {**vehicle.to_parameters(), **observer.to_parameters()},
    }
    summary.update(notes(SimpleNamespace(), extra))
    summary['sensors'] = sensor_summary(st, acc.first_stamp or 0)
    if getattr(stream, 'fused', False):           # a GNSS fit was made (offline)
        summary['odometer'] = stream.odometer.as_dict() if stream.odometer is not None else None
    source = getattr(stream, 'distance_source', None)
    if source is None:                            # online: the distance is the speed's
        from road_force_estimator.estimation.odometer import distance_speed
        source = distance_speed(observer.distance_source, (), (), drive.fixes,
                                offline=False)[1]
    summary['distance'] = source.as_dict()
    summary.update(acc.speed_findings())
    summary['accuracy'] = None
    segments = acc.segment_table(drive.fixes)
    summary.update(segment_counts(segments))
    summary['iri_m_per_km'] = {'estimated': acc.whole_iri(segments), 'true': None,
                               'raw': None, 'reference': None}
    summary['convergence'] = convergence_summary(summary)
    return summary, segments
