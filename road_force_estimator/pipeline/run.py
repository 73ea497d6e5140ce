"""One drive through the pipeline: :func:`run_drive`, the one downward pass of
``estimate_bag`` and of each ``estimate_fleet`` drive.

Source (the drive bag, with its ground truth and fixes) -> estimator stage (online or
offline, with or without a latency) -> sinks (the estimate bag, the diagnostics, the
report's segments, IRI and summary, the figures), closed once at the end. The plan
(:func:`.plan.plan_drive`: one block or many, from the drive's length and the memory limit)
picks the stages' form: :mod:`.one_block` (one call each) or :mod:`.blocks` (fed block by
block). With articulated parameters the whole vehicle's stage (:mod:`.whole_vehicle`, one
block; from the plan's threshold, online and offline, both stages in pieces) runs
beside the front axle's and its estimate, with the truth where the drive has it,
joins the bag and the report (what its reader rejected counted as the drive's:
:func:`.whole_vehicle.with_rejections`); with front-axle parameters an articulated drive's
whole-vehicle truth joins the report (:mod:`~.report.whole_vehicle`).
"""
from __future__ import annotations

from pathlib import Path

from road_force_estimator.pipeline.result import EstimateResult

__all__ = ['run_drive']


def run_drive(folder: Path, output: Path, input_path: Path, vehicle, observer, options: dict,
              stages, *, progress: bool = False,
              memory_limit_bytes: float | None = None) -> EstimateResult:
    """Estimate the drive bag ``input_path`` and write ``folder/bag`` and ``folder/report``
    (the result names them in ``output``).

    ``options``: ``mode``, ``reference``, ``reference_offset_m``, ``segment_length_m``,
    ``figures``, ``units``, ``run_info`` (:func:`~.report.write_report`'s);
    ``stages``: the progress display (:class:`.result.Stages`); ``memory_limit_bytes``: the
    memory the run may take (an ``estimate_fleet`` worker's limit; None: none given).

    Raises
    ------
    InputError
        Not a drive bag, no usable sample or speed, no sample estimated, an output exists.
    """
    from road_force_estimator.pipeline import blocks, one_block, whole_vehicle
    from road_force_estimator.pipeline.plan import plan_drive

    whole = None
    if whole_vehicle.is_whole_vehicle(vehicle):
        whole, vehicle = vehicle, whole_vehicle.front_axle_vehicle()
    plan = plan_drive(input_path, options['mode'], observer, options['reference'],
                      memory_limit_bytes=memory_limit_bytes, vehicle=whole)
    wv = fused = None
    if plan.blocks:
        joined = None
        try:
            if whole is not None:            # the whole vehicle's stage first
                stages.next(f'estimating the whole vehicle ({options["mode"]})')
                folder.mkdir(parents=True, exist_ok=True)    # its samples spilled there
                wv = whole_vehicle.SpilledEstimate(folder)
                whole_vehicle.estimate(input_path, whole, observer, options['mode'],
                                       windows=plan.whole_vehicle_windows, spill=wv)
                fused = whole_vehicle.fused_profile(wv, whole)
                joined = whole_vehicle.BlockJoin(wv, fused,
                                                 float(whole.axles[0].wheel_half_track_m))
            result = blocks.run_blocks(folder, output, input_path, vehicle, observer,
                                       options, stages, progress, samples=plan.samples,
                                       whole=joined)
            return _whole_vehicle(result, input_path, folder, wv, fused)
        finally:
            if wv is not None:                 # its temporary files
                wv.close()
            if fused is not None and hasattr(fused, 'close'):
                fused.close()
    else:
        stages.next('reading the bag')
        drive, speed, early = one_block.read(input_path, options['segment_length_m'])
        stages.next(f'estimating ({options["mode"]})')
        est = one_block.estimate(input_path, drive, speed, vehicle, observer, options['mode'],
                                 stages)
        extra = {'samples before the first twist (given its speed)': early} if early else {}
        if whole is not None:
            stages.next(f'estimating the whole vehicle ({options["mode"]})')
            wv = whole_vehicle.estimate(input_path, whole, observer, options['mode'],
                                        windows=plan.whole_vehicle_windows,
                                        blocks=plan.whole_vehicle_blocks)
            est = whole_vehicle.front_wheels(est, wv)
            fused = whole_vehicle.fused_profile(wv, whole)
            est = whole_vehicle.fused_road(est, wv, fused)
            est = whole_vehicle.sensor_report(est, wv)     # the report's "Sensors"
            drive = whole_vehicle.with_rejections(drive, wv)   # and its rejections
        result = one_block.write(folder, output, input_path, drive, est, extra, vehicle,
                                 observer, options, stages, whole=wv, fused=fused,
                                 road_half_track_m=None if whole is None else
                                 float(whole.axles[0].wheel_half_track_m))
    return _whole_vehicle(result, input_path, folder, wv, fused)


def _whole_vehicle(result: EstimateResult, input_path: Path, folder: Path,
                   wv=None, fused=None) -> EstimateResult:
    """An articulated drive: the note of what was estimated, the whole vehicle's estimate
    ``wv`` (its arrays or a :class:`.whole_vehicle.SpilledEstimate`; None: not estimated)
    and the truth of every axle in the report (:mod:`~.report.whole_vehicle`)."""
    from road_force_estimator import bagio
    from road_force_estimator.bagio.articulated_drive import read_articulated_truth
    from road_force_estimator.bagio.vehicle_layout import front_axle_joints, is_articulated

    custom = bagio.bag_custom_data(input_path)
    if wv is not None:
        from road_force_estimator.report.whole_vehicle import append_estimate
        truth = read_articulated_truth(input_path)
        append_estimate(folder / 'report', wv, truth, result.summary, fused=fused)
        road = (f'the road fused over the {fused.axles} axles' if fused is not None
                else 'its road by the front-axle estimator')
        n = wv.n if hasattr(wv, 'rows') else len(wv.stamps_ns)
        names = (wv.meta if hasattr(wv, 'rows') else wv).axle_names
        result.notes.append(f'the whole vehicle estimated ({len(names)} axles, '
                            f"{n} samples); the front axle's loads and load "
                            f'transfer from its wheels, {road}')
        return result
    if result.drive.notes:
        result.notes += list(result.drive.notes)
    elif is_articulated(custom):
        result.notes.append(front_axle_joints(custom, None)[1])
    truth = read_articulated_truth(input_path) if is_articulated(custom) or result.notes \
        else None
    if truth is not None and len(truth.stamps_ns):
        from road_force_estimator.report.whole_vehicle import append_to_report
        append_to_report(folder / 'report', truth, result.summary)
    return result
