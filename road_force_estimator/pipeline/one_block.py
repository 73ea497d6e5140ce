"""The pipeline's stages on a drive in one block: the bag read whole
(:func:`.bagio.read_drive_bag`, ground truth and fixes with it), the estimator stage's
one-block call (online :func:`~.estimation.estimate_batch`, offline
:func:`~.estimation.offline.estimate_recording`), the sinks in one call each (the estimate bag
:func:`~.bagio.write_estimate_bag` with one ``/diagnostics`` message per second, the report
:func:`~.report.write_report` with its accuracy, segments, IRI and figures).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from road_force_estimator.pipeline.result import (
    PROG, EstimateResult, InputError, check_spacing, estimate_counts, finite_fit, fit_note,
    nothing_estimated)

__all__ = ['drive_speed', 'estimate_online', 'read', 'estimate', 'write']


def drive_speed(drive) -> tuple[np.ndarray, int]:
    """Speed per sample (m/s) and how many samples took the first twist's speed.

    Samples before the first accepted ``/vehicle/twist`` get its speed (the observer node
    holds them until a speed arrives and estimates them with it).

    Raises
    ------
    InputError
        No usable twist at all.
    """
    speed = np.array(drive.speed_mps, dtype=float)
    if len(drive.twist_speed_mps) == 0:
        raise InputError('no usable /vehicle/twist message: the speed is unknown')
    early = ~np.isfinite(speed)
    speed[early] = float(drive.twist_speed_mps[0])
    return speed, int(np.count_nonzero(early))


def estimate_online(stamps_ns, q_m, roll_rad, speed_mps, vehicle, observer, *,
                    progress=None):
    """The observer node's numbers: :func:`~.estimator.estimate_batch`, which runs
    :meth:`Estimator.update`'s steps per sample, in order, then ``flush`` (bit-identical to
    them: test_estimator); row k holds the estimate of sample k (with a latency it came with a
    later input or from ``flush``), rejected rows hold the previous one with ``valid`` False;
    ``progress(samples)``: called as the samples go (None: not).

    Returns
    -------
    EstimateArrays
    """
    from road_force_estimator.estimation import estimate_batch

    return estimate_batch(stamps_ns, q_m, roll_rad, speed_mps, vehicle, observer,
                          progress=progress)


def read(input_path: Path, segment_length_m: float):
    """The source: ``(drive, speed per sample, samples before the first twist)``.

    Raises
    ------
    InputError
        Not a drive bag, no usable sample or speed, segments shorter than the spacing.
    """
    from road_force_estimator import bagio

    try:
        drive = bagio.read_drive_bag(input_path)
    except bagio.BagReadError as err:
        raise InputError(str(err)) from None
    if len(drive.stamps_ns) == 0:
        raise InputError(f'{input_path}: no usable /suspension/deflections message'
                         + (f' ({drive.issues[0]})' if drive.issues else ''))
    speed, early = drive_speed(drive)
    check_spacing(segment_length_m, drive.stamps_ns, speed)
    return drive, speed, early


def estimate(input_path: Path, drive, speed: np.ndarray, vehicle, observer, mode: str,
             stages):
    """The estimator stage in one call: the drive's :class:`EstimateArrays`.

    Raises
    ------
    InputError
        No sample estimated.
    """
    from road_force_estimator.estimation import estimate_recording

    args = (drive.stamps_ns, drive.q_m, drive.roll_rad, speed, vehicle, observer)
    if mode == 'online':
        with stages.samples(len(drive.stamps_ns), f'{PROG}: online') as bar:
            est = estimate_online(*args, progress=bar.update)
    else:
        est = estimate_recording(*args, fixes=drive.fixes)
    if est.status.accepted == 0:
        raise InputError(f'{input_path}: no sample could be estimated: '
                         f'{_why_none_estimated(input_path, drive, speed, est.status)}')
    if mode == 'online':          # the distance is the speed's online: the report says why
        from road_force_estimator.estimation.odometer import distance_speed
        est.distance_source = distance_speed(observer.distance_source, drive.stamps_ns,
                                             speed, drive.fixes, offline=False)[1]
    return est


def _why_none_estimated(input_path: Path, drive, speed: np.ndarray, status) -> str:
    """Why every one of the drive's samples was rejected (one phrase)."""
    from road_force_estimator.estimation.acceptance import (
        MAX_DEFLECTION_M, MAX_ROLL_RAD, MAX_SPEED_MPS)

    finite = np.isfinite(speed)
    if not np.any(finite & (np.abs(speed) <= MAX_SPEED_MPS)):
        worst = speed[finite][np.argmax(np.abs(speed[finite]))] if finite.any() else math.nan
        return (f'every speed out of range ({worst:g} m/s; the limit is |v| <= '
                f'{MAX_SPEED_MPS:g} m/s)')
    if np.all(speed < 0.0):
        return f'every speed negative (e.g. {speed[0]:g} m/s)'
    q = np.asarray(drive.q_m, dtype=float)
    roll = np.asarray(drive.roll_rad, dtype=float)
    if not np.any(np.all(np.abs(q) <= MAX_DEFLECTION_M, axis=1)):
        return f'every deflection out of range (|q| <= {MAX_DEFLECTION_M:g} m)'
    if not np.any(np.abs(roll) <= MAX_ROLL_RAD):
        return f'every roll angle out of range (|phi| <= {MAX_ROLL_RAD:g} rad)'
    return nothing_estimated(input_path, len(speed), status).split(': ', 2)[-1]


def _diagnostics(est, summary_counts: dict[str, int], mode: str, model_fit=None):
    """One estimator status per second of the drive (data time), the last with the totals;
    ``model_fit``: the drive's (ratio, verdict) or None."""
    from road_force_estimator.estimation.diagnostics import batch_diagnostics

    per_second = batch_diagnostics(est.stamp_ns, est.valid, est.converged, est.lift_off, est.ltr,
                                   est.residual_nm, summary_counts,
                                   f'{PROG}: estimator ({mode})', PROG,
                                   speed_contradicted=est.speed_contradicted,
                                   model_fit=model_fit)
    return [(stamp, [st.as_dict() for st in statuses]) for stamp, statuses in per_second]


def _model_fit(est, drive, vehicle, observer) -> tuple[float, str] | None:
    """The drive's model-fit verdict (:func:`.fit_check.assess`), or None when the method
    is not the model's or there are too few samples."""
    from road_force_estimator.estimation.fit_check import assess

    if est.status.method != 'model':
        return None
    return finite_fit(*assess(est, vehicle, observer, drive.speed_mps))


def write(folder: Path, output: Path, input_path: Path, drive, est, extra: dict, vehicle,
          observer, options: dict, stages, whole=None, fused=None,
          road_half_track_m: float | None = None) -> EstimateResult:
    """The sinks in one call each: ``folder/bag`` and ``folder/report``; the result names
    them in ``output``. ``whole``: an articulated drive's whole-vehicle estimate
    (:mod:`.whole_vehicle`: its topics and ``/diagnostics`` status in the bag), or None;
    ``fused``: its fused profile (:class:`.whole_vehicle.FusedRoad`), or None;
    ``road_half_track_m``: the y of ``/road_profile/*`` (m; the articulated truck's front
    wheels', as the node publishes them), else half the front-axle vehicle's track."""
    from road_force_estimator import bagio
    from road_force_estimator.report import raw_road, write_report

    mode = options['mode']
    bag_dir, report_dir = folder / 'bag', folder / 'report'
    for p in (bag_dir, report_dir):
        if p.exists():
            raise InputError(f'{p} exists (use --force to replace it)')
    counts = estimate_counts(len(drive.stamps_ns), est.status, drive.rejected_total,
                             est.odometer)                       # set offline with GNSS
    folder.mkdir(parents=True, exist_ok=True)
    custom = {'road_force_estimator.mode': mode,
              'road_force_estimator.input': input_path.name,
              'road_force_estimator.writer_command': PROG}
    fit = _model_fit(est, drive, vehicle, observer)
    if fit is not None:
        extra['model fit'] = fit_note(fit)
    stages.next('writing the bag')
    diagnostics, streams = _diagnostics(est, counts, mode, fit), []
    if whole is not None:
        from road_force_estimator.pipeline import whole_vehicle
        diagnostics = whole_vehicle.add_diagnostics(diagnostics, whole)
        streams = whole_vehicle.bag_streams(whole) + whole_vehicle.fused_streams(fused)
    written = bagio.write_estimate_bag(
        bag_dir, est, track_width_m=vehicle.track_width_m if road_half_track_m is None
        else 2.0 * road_half_track_m, diagnostics=diagnostics,
        custom_data=custom, extra_streams=streams)
    if written.get('nonfinite'):
        extra['estimates not written (non-finite)'] = written['nonfinite']
    stages.next('writing the report' + (' and figures' if options['figures'] else ''))
    summary = write_report(report_dir, est, drive, vehicle, observer,
                           input_name=input_path.name, extra=extra,
                           raw_road=raw_road(drive, reader=bagio.road_from_source), **options)
    warnings = [f'{input_path}: {issue}' for issue in drive.issues]
    return EstimateResult(summary, output / 'bag', output / 'report', est, written, warnings,
                          drive)
