"""The pipeline's stages on a drive in many blocks: memory that does not grow with the drive
(issue 21).

:func:`.run.run_drive` sends a drive here when :func:`.plan.plan_drive` says so. The source:
the bag read :data:`~.bagio.drive_blocks.BLOCK_SAMPLES` samples at a time
(:class:`~.bagio.drive_blocks.DriveBlocks`). The estimator stage: online the estimate of each
block (:class:`~.estimation.stream_run.OnlineStream`, bit-identical to one block: the chain is
causal), offline (the model's smoother) the drive gathered and its estimate handed out piece
by piece (:class:`~.estimation.offline_stream.OfflineStream`: runs longer than ~11 min at
1 kHz in windows, ~1e-11 of one block). The sinks, fed each piece as it comes: the estimate
bag (:class:`~.bagio.estimate_stream.EstimateBagStream`), the diagnostics per second and the
model fit (:mod:`.sinks`), the report's accumulators
(:class:`~.report.streamed.StreamedSummary`) and the detail figures' window
(:mod:`.window_figures`); :meth:`BlockRun.finish` closes them. The bag's messages,
``segments.csv`` and ``report.json`` are those of one block (test_blocks); the detail
figures too, the profile and overview figures show the detail window only (a note in the
report says so). The per-sample columns needed only at the end (or, offline, piece by piece)
wait in unnamed temporary files in the output folder (:mod:`.core.spill`).
"""
from __future__ import annotations

from dataclasses import replace
import json
import math
from pathlib import Path
import sys
from typing import Any

import numpy as np

from road_force_estimator.pipeline.result import (
    PROG, EstimateResult, InputError, check_spacing, estimate_counts, fit_note,
    nothing_estimated)
from road_force_estimator.report.streamed import TRUTH_NOTE

__all__ = ['FIGURES_NOTE', 'run_blocks', 'BlockRun']

#: The note in the report of a drive in many blocks with figures.
FIGURES_NOTE = ('figures: the profile and overview show the detail window (a drive '
                'estimated block by block)')


def run_blocks(folder: Path, output: Path, input_path: Path, vehicle, observer,
               options: dict, stages, progress: bool = False,
               block_samples: int | None = None, samples: int = 0,
               whole=None) -> EstimateResult:
    """Estimate the drive block by block and write ``folder/bag`` and ``folder/report``.

    ``samples``: the deflection messages metadata.yaml lists (the columns reserved at once);
    ``whole``: an articulated drive's whole-vehicle estimate joined to every piece and sink
    (:class:`.whole_vehicle.BlockJoin`, online), or None.
    The result's ``estimates`` are never held whole: only the stamps and distances of the
    accepted samples for ``estimate_fleet``'s polylines when the drive has ``/fix``
    (:meth:`.StreamedSummary.track`).

    Raises
    ------
    InputError
        As one block: no usable sample or speed, no sample estimated.
    """
    for p in (folder / 'bag', folder / 'report'):
        if p.exists():
            raise InputError(f'{p} exists (use --force to replace it)')
    folder.mkdir(parents=True, exist_ok=True)
    run = BlockRun(folder, input_path, vehicle, observer, options, block_samples, samples,
                   whole)
    stages.next(f'estimating ({options["mode"]}) and writing the bag, block by block')
    run.estimate(progress)
    drive = run.reader.record()
    if whole is not None:                     # the whole vehicle's reader's rejections
        drive = whole.drive(drive)
    extra, written = run.close_bag(drive.rejected_total)
    stages.next('writing the report' + (' and figures' if options['figures'] else ''))
    doc = _write_report(folder / 'report', run, drive, extra, input_path.name, options)
    warnings = [f'{input_path}: {issue}' for issue in drive.issues]
    return EstimateResult(doc, output / 'bag', output / 'report', run.summary.track(),
                          written, warnings, drive)


class BlockRun:
    """The stages of :func:`run_blocks`: the source (the reader), the estimator stage, the
    sinks (the bag, the accumulators, the diagnostics, the model fit, the figures' window)."""

    def __init__(self, folder: Path, input_path: Path, vehicle, observer, options: dict,
                 block_samples: int | None, samples: int, whole=None) -> None:
        from road_force_estimator.bagio.drive_blocks import BLOCK_SAMPLES, DriveBlocks
        from road_force_estimator.bagio.estimate_stream import EstimateBagStream
        from road_force_estimator.bagio.drive_blocks import listed_messages
        from road_force_estimator.interfaces import TRUE_LOAD
        from road_force_estimator.pipeline.sinks import (
            DiagnosticWindows, ModelFitSink, SampleQueue)
        from road_force_estimator.report.streamed import LoadAccuracy, StreamedSummary

        self.folder, self.input_path, self.samples = folder, input_path, samples
        self.vehicle, self.observer, self.options = vehicle, observer, options
        self.whole = whole
        self.reader = DriveBlocks(input_path, block_samples or BLOCK_SAMPLES)
        self.offline = options['mode'] == 'offline'
        self.stream = self._estimator_stage(folder)
        custom = {'road_force_estimator.mode': options['mode'],
                  'road_force_estimator.input': input_path.name,
                  'road_force_estimator.writer_command': PROG}
        track = vehicle.track_width_m if whole is None else 2.0 * whole.half_track_m
        self.bag = EstimateBagStream(folder / 'bag', track_width_m=track, custom_data=custom)
        self.summary = StreamedSummary(options['segment_length_m'],
                                       with_stamps=_has_fixes(input_path),
                                       capacity=samples, spill=folder)
        self.diag, self.fit = DiagnosticWindows(), ModelFitSink()
        spill = folder if self.offline else None
        self.speeds = SampleQueue(spill)
        #: the true loads wait for their estimates as the speeds do (a drive with truth)
        listed = listed_messages(input_path)
        self.truths = (SampleQueue(spill, 2) if any(listed.get(t) for t in TRUE_LOAD)
                       else None)
        self.accuracy = LoadAccuracy()
        self.static_n = np.asarray(vehicle.static_load_n, dtype=float)
        self.snapshots = self.window = None
        if options['figures']:
            self._figure_window()

    def _estimator_stage(self, spill: Path | None, eager: bool = True):
        """The estimator stage: :class:`.OfflineStream` (the columns it needs only piece by
        piece waiting in files in ``spill``) or :class:`.OnlineStream`."""
        from road_force_estimator.estimation.offline_stream import OfflineStream
        from road_force_estimator.estimation.stream_run import OnlineStream

        if not self.offline:
            return OnlineStream(self.vehicle, self.observer)
        return OfflineStream(self.vehicle, self.observer, capacity=self.samples, spill=spill,
                             eager=eager)

    def _figure_window(self) -> None:
        """The sink of the detail figures' window (:mod:`.window_figures`)."""
        from road_force_estimator.pipeline.window_figures import OfflineWindow, Snapshots
        from road_force_estimator.report.figures import DEFAULT_WINDOW_S

        if self.offline:
            self.window = OfflineWindow(DEFAULT_WINDOW_S, self.stream)
        else:
            self.snapshots = Snapshots(DEFAULT_WINDOW_S)

    def estimate(self, progress: bool) -> None:
        """Every block through the estimator, the pieces to the sinks; the bag aborted (and
        the error raised) when the input is bad."""
        from road_force_estimator.bagio import BagReadError

        progress = progress and sys.stderr.isatty()
        try:
            for i, block in enumerate(self.reader):
                check_spacing(self.options['segment_length_m'], block.stamps_ns,
                              block.speed_mps)
                if self.snapshots is not None:
                    self.snapshots.keep(i, block.stamps_ns[0], self.stream, self.summary)
                self.speeds.append(np.where(block.early, np.nan, block.speed_mps))
                if self.truths is not None:
                    self.truths.append(np.full((block.stamps_ns.size, 2), np.nan)
                                       if block.truth is None else block.truth.wheel_load_n)
                for piece in self.stream.feed(block.stamps_ns, block.q_m, block.roll_rad,
                                              block.speed_mps):
                    self._consume(piece)
                if progress:
                    done = (f'{self.stream.fed} samples read' if self.offline
                            else f'{self.summary.inputs} samples')
                    print(f'{PROG}: {done}', end='\r', flush=True, file=sys.stderr)
            rest = (self.stream.finish(self.reader.fixes) if self.offline
                    else self.stream.finish())
            for piece in rest:
                self._consume(piece)
                del piece       # not held while the next window is smoothed
            problem = self._problem()
        except BagReadError as err:
            self.bag.abort()
            raise InputError(str(err)) from None
        except BaseException:
            self.bag.abort()
            raise
        if problem:
            self.bag.abort()
            raise InputError(problem)

    def _consume(self, piece) -> None:
        """One piece of estimates to the sinks: the bag, the report's accumulators, the
        diagnostics, the model fit (with the recorded speeds of its samples), the window."""
        if self.whole is not None:            # the whole vehicle's front wheels
            piece = self.whole.piece(piece)
        m = len(piece.stamp_ns)
        v = self.speeds.take(m)
        self.bag.write(piece)
        self.summary.add(piece, v)
        self.diag.add(piece)
        self.fit.add(piece)
        if self.truths is not None:
            self.accuracy.add(piece, self.truths.take(m), self.static_n)
        if self.window is not None:
            self.window.keep(piece, self.summary)

    def _problem(self) -> str | None:
        """Why nothing can be estimated (one block's reasons), or None."""
        status, n, reader = self.stream.status, self.summary.inputs, self.reader
        if n == 0:
            return (f'{self.input_path}: no usable /suspension/deflections message'
                    + (f' ({reader.issues[0]})' if reader.issues else ''))
        if reader.twists == 0:
            return 'no usable /vehicle/twist message: the speed is unknown'
        if status.accepted == 0:
            return nothing_estimated(self.input_path, n, status)
        return None

    @property
    def status(self):
        """The estimator's status (with the whole vehicle's sensor fields when joined)."""
        st = self.stream.status
        return st if self.whole is None else self.whole.status(st)

    def close_bag(self, rejected_total: int | None = None
                  ) -> tuple[dict[str, Any], dict[str, int]]:
        """The notes for the report and the bag's counts, once its diagnostics are written;
        ``rejected_total``: the drive's rejections (None: the reader's)."""
        status, reader = self.status, self.reader
        extra: dict[str, Any] = {}
        if reader.early:
            extra['samples before the first twist (given its speed)'] = reader.early
        odometer = self.stream.odometer if self.offline else None
        counts = estimate_counts(self.summary.inputs, status, reader.rejected_total
                                 if rejected_total is None else rejected_total, odometer)
        verdict = self.fit.result(self.summary, status, self.vehicle, self.observer)
        if verdict is not None:
            extra['model fit'] = fit_note(verdict)
        diagnostics = self.diag.statuses(
            counts, f'{PROG}: estimator ({self.options["mode"]})', PROG, verdict)
        if self.whole is not None:            # its topics, its status beside the estimator's
            self.whole.write_streams(self.bag)
            diagnostics = self.whole.diagnostics(diagnostics)
        written = self.bag.close(diagnostics)
        if written.get('nonfinite'):
            extra['estimates not written (non-finite)'] = written['nonfinite']
        if self.options['figures']:
            extra[FIGURES_NOTE] = 1
        if self.accuracy.seen:
            extra[TRUTH_NOTE] = 1
        return extra, written

    def figures(self, segments: dict, doc: dict) -> list[str]:
        """The figures (:func:`.window_figures.draw`) of the report ``doc``."""
        from road_force_estimator.pipeline.window_figures import draw
        from road_force_estimator.report.folder import static_line

        keeper = self.window if self.offline else self.snapshots
        if keeper is None:
            return []
        name, mode = self.input_path.name, self.options['mode']
        return draw(self.folder / 'report', self.input_path, self.reader.block_samples,
                    keeper, self.summary, segments,
                    f'{name} ({mode})' if name else mode, self.options['units'],
                    static_line(doc, self.vehicle), self._rerun,
                    join=None if self.whole is None else replace(self.whole).piece)

    def _rerun(self):
        """A new estimator stage over this drive's blocks (the offline detail window's
        fallback: :class:`.window_figures.OfflineWindow`): its pieces."""
        from road_force_estimator.bagio.drive_blocks import DriveBlocks

        reader = DriveBlocks(self.input_path, self.reader.block_samples)
        stream = self._estimator_stage(None)
        for block in reader:
            stream.feed(block.stamps_ns, block.q_m, block.roll_rad, block.speed_mps)
        return stream.finish(reader.fixes)


def _has_fixes(input_path: Path) -> bool:
    """Whether the bag's metadata lists ``/fix`` messages."""
    from road_force_estimator.bagio.drive_blocks import listed_messages
    from road_force_estimator.interfaces import FIX

    return bool(listed_messages(input_path).get(FIX))


def _write_report(folder: Path, run: BlockRun, drive, extra: dict, input_name: str,
                  options: dict) -> dict[str, Any]:
    """``report.md``, ``segments.csv``, ``report.json`` and the figures
    (:meth:`BlockRun.figures`) as :func:`.report.write_report`, from the run's sinks."""
    from road_force_estimator.report.folder import json_safe, write_segments_csv
    from road_force_estimator.report.markdown import write_markdown

    folder.mkdir(parents=True, exist_ok=True)
    summary, segments = _summary(run.summary, run.stream, drive, run.vehicle, run.observer,
                                 extra, input_name, options, run.status)
    if run.accuracy.seen:
        summary['has_ground_truth'] = True
        summary['accuracy'] = run.accuracy.result(run.static_n)
    names = run.figures(segments, summary)
    summary['figures'] = names
    write_segments_csv(folder / 'segments.csv', segments)
    write_markdown(folder / 'report.md', summary, segments, names)
    (folder / 'report.json').write_text(json.dumps(json_safe(summary), indent=2) + '\n')
    return summary


def _summary(acc, stream, drive, vehicle, observer, extra: dict, input_name: str,
             options: dict, status=None) -> tuple[dict[str, Any], dict]:
    """:func:`.summary.summarize`'s ``(summary, segments)`` of a streamed drive (``stream``:
    its :class:`.OnlineStream` or :class:`.OfflineStream`; ``status``: its status as
    reported, None: ``stream.status``)."""
    from road_force_estimator import __version__
    from road_force_estimator.report.summary import (
        convergence_summary, friction_summary, notes, rejections, segment_counts,
        sensor_summary)

    st = stream.status if status is None else status
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
    summary.update(notes(None, extra))
    summary['sensors'] = sensor_summary(st, acc.first_stamp or 0)
    offline = options['mode'] == 'offline'
    if offline and stream.fused:                  # a GNSS fit was made
        summary['odometer'] = stream.odometer.as_dict() if stream.odometer is not None else None
    source = stream.distance_source if offline else None
    if source is None:                            # online: the distance is the speed's
        from road_force_estimator.estimation.odometer import distance_speed
        source = distance_speed(observer.distance_source, (), (), drive.fixes,
                                offline=False)[1]
    summary['distance'] = source.as_dict()
    if offline:                                   # the friction's v_f the smoother took
        summary.update(friction_summary(stream))
    summary.update(acc.speed_findings())
    summary['accuracy'] = None
    segments = acc.segment_table(drive.fixes)
    summary.update(segment_counts(segments))
    summary['iri_m_per_km'] = {'estimated': acc.whole_iri(segments), 'true': None,
                               'raw': None, 'reference': None}
    summary['convergence'] = convergence_summary(summary)
    return summary, segments
