"""The estimator stage of the whole vehicle (``vehicle.model: articulated``, issue 32): an
articulated drive through :func:`~.estimation.whole_vehicle.estimate_whole_vehicle` beside the
front axle's stage, in one block (:mod:`.plan` says why).

Source: the readings of ``/suspension/deflections`` in the model's channel order and the
twist's speed held at each sample (:func:`~.bagio.articulated_readings.
read_articulated_readings`; samples before the first twist take its speed, as the node holds
them); with ``vehicle.tractor_imu`` the IMU's a_y of ``/imu/tractor`` as the last channel, the
latest at or before each sample (:func:`~.estimation.imu_hold.pair_imu`, the node's rule; the
samples stale or missing counted: :func:`imu_values`, the report's ``tractor_imu``).
Stage: online :class:`~.estimation.whole_vehicle.WholeVehicleEstimator` sample by
sample (the node's numbers), offline the smoother. Sinks: the estimate bag's whole-vehicle
topics (:mod:`~.bagio.whole_vehicle_estimates`), the front axle's old topics from the front
wheels (:func:`front_wheels`), one ``/diagnostics`` status per second with the axle loads and
the gross vehicle weight (:func:`add_diagnostics`; offline also the drive's model fit per
axle, :func:`fit_values`: WARN naming the axle or sensor that does not fit; every channel's
sensor flag, :func:`sensor_status_values`: WARN naming a stuck or drifting sensor; the last
with what its reader rejected, :func:`rejection_values`: WARN with the counts), and the
report's section and ``segments.csv`` columns (:mod:`~.report.whole_vehicle`); the report's
"Sensors" are the whole vehicle's channels (:func:`sensor_report`).

The front axle's estimator still runs on the front axle's sensors (package defaults for the
4-DOF model, :func:`front_axle_vehicle`) for what the whole vehicle's does not give yet: the
observer states. The axles' roads fused by distance (:func:`fused_profile`: offline
:func:`~.estimation.articulated.fuse_roads`, online the points the estimator streamed, the
node's) go to ``/road_profile/fused/left|right``; the drive's road (:func:`fused_road`:
``/road_profile/left|right``, the report's profile figures and IRI) is offline the fused one,
online the whole vehicle's front wheels' own per sample (the node's ``/road_profile/*``).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
import math
from pathlib import Path

import numpy as np

from road_force_estimator.pipeline.result import PROG, InputError

__all__ = ['is_whole_vehicle', 'front_axle_vehicle', 'estimate', 'front_wheels',
           'add_diagnostics', 'sensor_edges', 'sensor_status_values', 'sensor_report',
           'bag_streams', 'fused_profile', 'fused_streams', 'fused_road',
           'FusedRoad', 'fit_values', 'imu_values', 'MISMATCH',
           'STATUS_NAME', 'with_rejections', 'rejection_values', 'sensor_status',
           'BlockJoin', 'SpilledEstimate', 'SpilledFused', 'bag_stream_pieces', 'SINK_ROWS',
           'spilled_fit']

#: The samples of a spilled estimate the sinks read at a time (:class:`BlockJoin`).
SINK_ROWS = 1 << 16

#: The name of the whole vehicle's status in ``/diagnostics``.
STATUS_NAME = f'{PROG}: whole vehicle'


def is_whole_vehicle(vehicle) -> bool:
    """``vehicle`` is the articulated model's (an ``ArticulatedParameters``)."""
    from road_force_estimator.core.articulated_parameters import ArticulatedParameters

    return isinstance(vehicle, ArticulatedParameters)


def front_axle_vehicle():
    """The front-axle estimator's vehicle on an articulated drive: the package defaults (what
    a front-axle tool reads an articulated drive with)."""
    from road_force_estimator.core.parameters import VehicleParameters

    return VehicleParameters()


def estimate(input_path: Path, vehicle, observer, mode: str, windows: bool = False,
             blocks: bool = False, spill: SpilledEstimate | None = None):
    """The stage in one call: the drive's
    :class:`~.estimation.whole_vehicle.WholeVehicleArrays` (``mode`` 'online' or 'offline';
    ``windows``: offline, the smoother in windows; ``blocks``: online, the drive read in
    blocks and the estimator carried across them, the same bits; as :mod:`.plan` decides;
    ``spill``: online in blocks, the samples into it instead (:class:`SpilledEstimate`: it
    is returned, its ``meta`` set).

    Raises
    ------
    InputError
        No deflection topic, a channel missing from every message, no usable twist.
    """
    from road_force_estimator.bagio import BagReadError
    from road_force_estimator.bagio.articulated_readings import read_articulated_readings
    from road_force_estimator.estimation.whole_vehicle import (
        WholeVehicleEstimator, estimate_whole_vehicle)

    imu = bool(getattr(vehicle, 'tractor_imu', False))
    names = WholeVehicleEstimator(vehicle, observer).channel_names   # without the IMU's
    if mode == 'online' and (blocks or spill is not None):
        return _online(input_path, vehicle, observer, names, imu, spill)
    if spill is not None:
        return _offline(input_path, vehicle, observer, names, imu, spill, windows)
    try:
        r = read_articulated_readings(input_path, names, imu=imu)
    except BagReadError as err:
        raise InputError(str(err)) from None
    if r.stamps_ns.size == 0:
        raise InputError(f'{input_path}: no /suspension/deflections message carries every '
                         f'channel of the whole vehicle ({", ".join(names)})')
    speed = np.array(r.speed_mps, float)
    held = np.isfinite(speed)
    if not held.any():
        raise InputError('no usable /vehicle/twist message: the speed is unknown')
    speed[~held] = speed[np.argmax(held)]      # before the first twist: its speed
    readings, codes = r.readings, None
    if imu:                                    # the IMU's a_y by the node's rule, counted
        from road_force_estimator.estimation.imu_hold import pair_imu

        ay, codes = pair_imu(r.stamps_ns, r.imu_stamps_ns, r.imu_ay_mps2)
        readings = np.column_stack([readings, ay])
    wv = estimate_whole_vehicle(vehicle, r.stamps_ns, readings, speed, observer=observer,
                                offline=mode == 'offline', windows=windows, imu=imu,
                                imu_codes=codes)
    wv = replace(wv, rejected=_counts(r.rejected), messages=dict(r.messages))
    return wv if codes is None else replace(wv, imu_codes=codes)


def _online(input_path: Path, vehicle, observer, names: tuple, imu: bool,
            spill: SpilledEstimate | None = None):
    """The stage online: the drive read in blocks (:class:`~.bagio.drive_blocks.DriveBlocks`
    with the whole vehicle's channels), :func:`~.estimation.whole_vehicle.
    estimate_online_blocks` stepped across them (the same bits as the drive read whole)."""
    from road_force_estimator.bagio import BagReadError
    from road_force_estimator.bagio.drive_blocks import DriveBlocks, streamable
    from road_force_estimator.estimation.whole_vehicle import estimate_online_blocks

    reader = DriveBlocks(input_path, joints=names, imu=imu)
    codes: list = []

    def blocks():
        for b in reader:
            if not np.isfinite(b.speed_mps).all():      # only before the first twist
                raise InputError('no usable /vehicle/twist message: the speed is unknown')
            if imu:                                    # the IMU's a_y by the node's rule
                if spill is not None:
                    spill.add_codes(b.imu_codes)
                else:
                    codes.append(b.imu_codes)
                yield (b.stamps_ns, np.column_stack([b.readings, b.imu_ay_mps2]), b.speed_mps,
                       b.imu_codes)
            else:
                yield b.stamps_ns, b.readings, b.speed_mps

    try:
        wv = estimate_online_blocks(vehicle, blocks(), observer=observer, imu=imu,
                                    capacity=streamable(input_path),
                                    sink=None if spill is None else spill.add)
    except BagReadError as err:
        raise InputError(str(err)) from None
    if not (wv.stamps_ns.size if spill is None else spill.n):
        raise InputError(f'{input_path}: no /suspension/deflections message carries every '
                         f'channel of the whole vehicle ({", ".join(names)})')
    wv = replace(wv, rejected=_counts(reader.rejected), messages=dict(reader.messages))
    if spill is not None:                      # the samples' IMU codes spilled with them
        spill.meta = wv if not imu else replace(wv, imu_codes=np.zeros(0, np.int8))
        return spill
    return wv if not imu else replace(wv, imu_codes=np.concatenate(codes))


def _offline(input_path: Path, vehicle, observer, names: tuple, imu: bool,
             spill: SpilledEstimate, windows: bool):
    """The stage offline in pieces: the drive read in blocks
    (:class:`~.bagio.drive_blocks.DriveBlocks`, the inputs of the drive read whole) into
    :class:`~.estimation.whole_vehicle.WholeVehicleOfflineStream` (``windows``: its smoother
    in windows; its static loads in a file), its pieces into ``spill``; the drive's model fit
    per axle from the spilled columns (:func:`spilled_fit`). Returns ``spill``, its ``meta``
    set."""
    from road_force_estimator.bagio import BagReadError
    from road_force_estimator.bagio.drive_blocks import DriveBlocks, streamable
    from road_force_estimator.estimation.whole_vehicle import (
        ROW_FIELDS, WholeVehicleOfflineStream, take_rows)

    reader = DriveBlocks(input_path, joints=names, imu=imu)
    stream = WholeVehicleOfflineStream(vehicle, observer, eager=bool(windows), imu=imu,
                                       capacity=streamable(input_path), spill=spill.folder)
    last = None
    try:
        for b in reader:
            if not np.isfinite(b.speed_mps).all():      # only before the first twist
                raise InputError('no usable /vehicle/twist message: the speed is unknown')
            if imu:                                    # the IMU's a_y by the node's rule
                spill.add_codes(b.imu_codes)
                stream.feed(b.stamps_ns, np.column_stack([b.readings, b.imu_ay_mps2]),
                            b.speed_mps, b.imu_codes)
            else:
                stream.feed(b.stamps_ns, b.readings, b.speed_mps)
        if not stream.fed:
            raise InputError(f'{input_path}: no /suspension/deflections message carries '
                             f'every channel of the whole vehicle ({", ".join(names)})')
        for piece in stream.finish():
            spill.add(piece)
            last = piece
    except BagReadError as err:
        raise InputError(str(err)) from None
    finally:
        stream.close()                         # its files (readings, flags, static loads)
    none = take_rows(last, 0, 0)               # no sample (copies: the piece let go)
    none = replace(none, **{f: np.array(getattr(none, f)) for f in ROW_FIELDS
                            if getattr(none, f) is not None})
    meta = replace(none, innovations_gated=stream.innovations_gated,
                   rejected=_counts(reader.rejected), messages=dict(reader.messages),
                   friction_velocity=stream.friction_velocity)
    del stream, last
    spill.meta = meta if not imu else replace(meta, imu_codes=np.zeros(0, np.int8))
    spill.meta = replace(spill.meta, axle_fit=spilled_fit(spill, vehicle))
    return spill


def spilled_fit(spill: SpilledEstimate, vehicle):
    """:func:`~.estimation.whole_vehicle.fit_axles` of an offline estimate spilled in
    ``spill`` (its numbers, bit for bit): :func:`~.estimation.axle_fit.assess_pieces` on
    the spilled stamps, distances, instrumented wheels' roads and whether each carried its
    share, at most :data:`SINK_ROWS` samples at a time (held whole: the distance grid's
    arrays, not the samples' columns)."""
    from road_force_estimator.core.pieces import PIECE_ROWS
    from road_force_estimator.estimation.articulated import LIFT_OFF_FRACTION
    from road_force_estimator.estimation.axle_fit import assess_pieces

    axles = [j for j, a in enumerate(vehicle.axles) if a.instrumented]
    if 'road_m' not in (spill.cols or {}) or len(axles) < 3 or spill.n < 2:
        return None
    rows = [2 * j + s for j in axles for s in (0, 1)]
    cols = spill.cols

    def read(lo, hi, w):                     # the instrumented wheel w's road, grounded
        r = rows[w]
        return (cols['road_m'].read(lo, hi)[:, r],
                cols['load_n'].read(lo, hi)[:, r]
                >= LIFT_OFF_FRACTION * cols['static_n'].read(lo, hi)[:, r])

    return assess_pieces(spill.n, cols['stamps_ns'].read, cols['distance_m'].read, read,
                         [vehicle.axles[j].position_m for j in axles],
                         [vehicle.axles[j].name for j in axles],
                         rows=min(SINK_ROWS, PIECE_ROWS))


def _counts(rejected: dict) -> dict[str, dict[str, int]]:
    """topic -> reason -> count, sorted, zero counts left out."""
    out = {t: {k: int(c) for k, c in sorted(reasons.items()) if c}
           for t, reasons in sorted(rejected.items())}
    return {t: reasons for t, reasons in out.items() if reasons}


def with_rejections(drive, wv):
    """The front axle's ``drive`` (:class:`~.bagio.drive.Drive`) with what the whole
    vehicle's reader dropped: its counts replace the front-axle reader's for the topics it
    read (``/suspension/deflections`` over every channel, ``/vehicle/twist`` and, with the
    IMU, ``/imu/tractor``; the same checks, :mod:`~.bagio.checks`); the drive's other topics
    as they are; a topic only it read (``/imu/tractor``) joins the drive's message counts
    (the report's "Messages and rejections"). Its estimate is the drive's (loads, load
    transfer, road), so the counts of the report, the status' ``total.rejected_by_reader``
    and the fleet's tables are its."""
    from road_force_estimator.interfaces import DEFLECTIONS, IMU, TWIST

    rejected = getattr(wv, 'rejected', None)
    if rejected is None:
        return drive
    read = {DEFLECTIONS, TWIST} | ({IMU} if getattr(wv, 'imu_codes', None) is not None
                                   else set())
    merged = {t: dict(r) for t, r in drive.rejected.items() if t not in read}
    merged.update({t: dict(r) for t, r in rejected.items()})
    # the messages the front axle's reader did not read (the IMU's) counted beside its own
    messages = dict(drive.messages)
    for t, n in (getattr(wv, 'messages', None) or {}).items():
        messages.setdefault(t, int(n))
    return replace(drive, rejected=dict(sorted(merged.items())),
                   messages=dict(sorted(messages.items())))


def rejection_values(wv) -> tuple[dict, str]:
    """The whole vehicle's reader's rejections as the status' totals
    (``total.rejected.<topic>.<reason>``, ``total.rejected_by_reader``) and a message ('' when
    it dropped nothing): ``4 input messages rejected (/vehicle/twist: 1 nonfinite, ...)``."""
    rejected = getattr(wv, 'rejected', None)
    if rejected is None:
        return {}, ''
    values = {f'total.rejected.{t}.{k}': str(c) for t, reasons in rejected.items()
              for k, c in reasons.items()}
    total = sum(sum(r.values()) for r in rejected.values())
    values['total.rejected_by_reader'] = str(total)
    if not total:
        return values, ''
    parts = '; '.join(f'{t}: ' + ', '.join(f'{c} {k}' for k, c in reasons.items())
                      for t, reasons in rejected.items())
    return values, f'{total} input messages rejected ({parts})'


def imu_values(wv, k: int, since: int = 0, before: dict | None = None) -> tuple[dict, str]:
    """The tractor IMU's counts at sample ``k`` (the node's keys, :mod:`~.estimation.imu_hold`:
    ``imu.stale``, ``imu.missing`` the samples of the period ``since`` .. ``k`` with a held or
    no a_y (left out), ``total.imu.*`` the drive's so far, with ``before``'s: code -> samples
    before ``wv``'s first) and a message ('' when the period had none); none without the IMU."""
    from road_force_estimator.estimation.imu_hold import MISSING, STALE

    codes = getattr(wv, 'imu_codes', None)
    if codes is None:
        return {}, ''
    values = {}
    words = []
    for code, word in ((STALE, 'stale'), (MISSING, 'missing')):
        n = int(np.count_nonzero(codes[since:k + 1] == code))
        values[f'imu.{word}'] = str(n)
        values[f'total.imu.{word}'] = str(int(np.count_nonzero(codes[:k + 1] == code))
                                          + (before or {}).get(code, 0))
        if n:
            words.append(f'{n} {word}')
    return values, (f'tractor IMU: {", ".join(words)} samples' if words else '')


def sensor_report(est, wv):
    """The front axle's estimate ``est`` with its status' sensor fields (the report's
    "Sensors", ``report.json`` ``sensors``, the fleet's tables) those of the whole vehicle's
    channels: the flags and counts of ``wv.faults`` (:mod:`~.estimation.sensor_health`), the
    innovations gated per channel."""
    if getattr(wv, 'faults', None) is None:
        return est
    return replace(est, status=sensor_status(est.status, wv))


def sensor_status(status, wv):
    """The front axle's estimator ``status`` with the sensor fields of the whole vehicle's
    channels (:func:`sensor_report`'s; ``status`` itself without ``wv.faults``)."""
    fc = getattr(wv, 'faults', None)
    if fc is None:
        return status
    return replace(status, sensor_faults=dict(fc.flags),
                   stuck_episodes=dict(fc.stuck_episodes), stuck_samples=dict(fc.stuck_samples),
                   drift_episodes=dict(fc.drift_episodes), drift_samples=dict(fc.drift_samples),
                   fault_first_ns={n: dict(f) for n, f in fc.first_ns.items()},
                   innovations_gated=dict(zip(wv.channel_names,
                                              (int(g) for g in wv.innovations_gated))))


def front_wheels(est, wv):
    """The front axle's estimate ``est`` (:class:`~.estimation.outputs.EstimateArrays`) with
    its loads, static loads and load transfer (instantaneous and quasi-static: the whole
    vehicle's ``front_ltr``) from the whole vehicle's front wheels at the same stamps (and its
    lift-offs: a front wheel's load at zero); a row the whole vehicle has not estimated gets
    NaN (not written, counted)."""
    loads = wv.load_n[:2].T
    static = wv.static_n[:2].T
    ltr = np.asarray(wv.front_ltr, float).T
    stamps = np.asarray(est.stamp_ns, np.int64)
    at = np.clip(np.searchsorted(wv.stamps_ns, stamps), 0, max(wv.stamps_ns.size - 1, 0))
    hit = wv.stamps_ns[at] == stamps if wv.stamps_ns.size else np.zeros(stamps.size, bool)

    def take(a: np.ndarray) -> np.ndarray:
        out = np.full((stamps.size,) + a.shape[1:], np.nan)
        out[hit] = a[at[hit]]
        return out

    lift = np.zeros((stamps.size, 2), bool)
    lift[hit] = loads[at[hit]] <= 0.0
    return replace(est, wheel_load_n=take(loads), static_load_n=take(static),
                   ltr=take(ltr[:, 0]), ltr_quasi_static=take(ltr[:, 1]), lift_off=lift)


def sensor_edges(wv, first: np.ndarray | None = None) -> list | None:
    """Per channel of ``wv`` (its ``fault_flags``): the samples where a stuck and where a
    drift flag rose (sorted index arrays), or None without flags; ``first``: each channel's
    flag before ``wv``'s first sample (None: ok)."""
    from road_force_estimator.estimation.sensor_health import CODES

    flags = getattr(wv, 'fault_flags', None)
    if flags is None:
        return None
    out = []
    for c, row in enumerate(np.asarray(flags)):
        prev = np.concatenate([[0 if first is None else first[c]], row[:-1]])
        rose = row != prev
        out.append(tuple(np.flatnonzero(rose & (row == CODES[w])) for w in ('stuck', 'drift')))
    return out


def sensor_status_values(wv, k: int, edges: list,
                         before: list | None = None) -> tuple[dict, str]:
    """The sensors' status values at sample ``k`` (the node's keys: ``sensor.<channel>``,
    ``total.stuck.<channel>``, ``total.drift.<channel>``: flags raised so far, with
    ``before``'s: per channel (stuck, drift) raised before ``wv``'s first sample) and the
    fault message ('' when every sensor is ok; :func:`~.estimation.diagnostics.
    fault_message`)."""
    from road_force_estimator.estimation.diagnostics import fault_message, sensor_values
    from road_force_estimator.estimation.sensor_health import CODES

    words = {c: w for w, c in CODES.items()}
    flags = {n: words[int(c)] for n, c in zip(wv.channel_names, wv.fault_flags[:, k])}
    values = sensor_values(flags)
    for c, (n, (stuck, drift)) in enumerate(zip(wv.channel_names, edges)):
        b = (0, 0) if before is None else before[c]
        values[f'total.stuck.{n}'] = str(int(np.searchsorted(stuck, k, side='right')) + b[0])
        values[f'total.drift.{n}'] = str(int(np.searchsorted(drift, k, side='right')) + b[1])
    return values, fault_message(flags)


def _status(wv, k: int, since: int = 0, edges: list | None = None,
            ltr_predicted: np.ndarray | None = None, last: bool = False,
            before: dict | None = None) -> dict:
    """The whole vehicle's status at sample ``k``: the axle static loads, the gross vehicle
    weight (N), each unit's quasi-static LTR, and each unit's largest |LTR| over the samples
    ``since`` .. ``k`` (``max_abs_ltr_<unit>``, as the observer node's period), and of its
    predicted LTR (``max_abs_ltr_<unit>_predicted``, :mod:`~.estimation.rollover_warning`:
    WARN from :data:`~.estimation.rollover_warning.WARNING_THRESHOLD`; ``ltr_predicted`` the
    drive's, computed once by the caller); ``gaps``: those
    of the period (each restarted the estimate), ``total.gaps`` the drive's so far (the node's
    keys); ``last``: the drive's last status, with the reader's rejections
    (:func:`rejection_values`: WARN when it dropped any); ``before``: the counts of the
    samples before ``wv``'s first (``imu``, ``edges``: :func:`imu_values`',
    :func:`sensor_status_values`'), ``wv`` a part of the drive."""
    from road_force_estimator.estimation.whole_vehicle import UNITS

    axle = wv.static_n[:, k].reshape(-1, 2).sum(axis=1)
    values = {f'static_load_{name}_n': f'{float(a):.1f}' for name, a in
              zip(wv.axle_names, axle)}
    values['gross_weight_n'] = f'{float(axle.sum()):.1f}'
    from road_force_estimator.estimation.rollover_warning import WARNING_THRESHOLD

    # each unit's predicted LTR over the period (causal: the node's numbers)
    predicted = (wv.ltr_predicted if ltr_predicted is None else ltr_predicted)[:, since:k + 1]
    warned: list = []
    for u, unit in enumerate(UNITS):
        values[f'ltr_{unit}_quasi_static'] = f'{float(wv.ltr_quasi_static[u, k]):.4f}'
        period = np.abs(np.asarray(wv.ltr[u, since:k + 1], float))
        period = period[np.isfinite(period)]
        values[f'max_abs_ltr_{unit}'] = f'{float(period.max()) if period.size else 0.0:.4f}'
        ahead = np.abs(predicted[u])
        ahead = ahead[np.isfinite(ahead)]
        peak = float(ahead.max()) if ahead.size else 0.0
        values[f'max_abs_ltr_{unit}_predicted'] = f'{peak:.4f}'
        if peak >= WARNING_THRESHOLD:
            warned.append(unit)
    if getattr(wv, 'gaps', None) is not None:
        total = int(wv.gaps[k])
        values['gaps'] = str(total - (int(wv.gaps[since - 1]) if since > 0 else 0))
        values['total.gaps'] = str(total)
    gross = float(axle.sum())
    message = f'gross vehicle weight {gross / 1e3:.1f} kN over {len(axle)} axles'
    level = 0 if math.isfinite(gross) else 1
    if warned:
        level = 1
        message += (f'; rollover warning: {", ".join(warned)} predicted |LTR| >= '
                    f'{WARNING_THRESHOLD:g}')
    before = before or {}
    imu, late = imu_values(wv, k, since, before.get('imu'))
    values.update(imu)
    if late:
        level = 1
        message += f'; {late}'
    if edges is not None:
        sensors, fault = sensor_status_values(wv, k, edges, before.get('edges'))
        values.update(sensors)
        if fault:
            level = 1
            message += f'; {fault}'
    fit = fit_values(_fit_at(wv, k))
    values.update(fit)
    if fit.get('model_fit') == MISMATCH:
        level = 1
        from road_force_estimator.estimation.axle_fit import ADVICE
        message += f'; model fit: {fit["model_fit_culprits"]} {ADVICE}'
    if last:
        rejected, why = rejection_values(wv)
        values.update(rejected)
        if why:
            level = 1
            message += f'; {why}'
    return {'name': STATUS_NAME, 'hardware_id': PROG, 'level': level, 'message': message,
            'values': values}


MISMATCH = 'mismatch'


def _fit_at(wv, k: int):
    """The model fit per axle known at sample ``k``: offline the drive's, online the last
    verdict completed at or before it (the node's)."""
    fits = getattr(wv, 'axle_fits', ())
    if not fits:
        return wv.axle_fit
    stamp = int(wv.stamps_ns[k])
    known = [fit for s, fit in fits if s <= stamp]
    return known[-1] if known else None


def fit_values(fit) -> dict:
    """The status values of the model fit per axle (:meth:`.axle_fit.AxleFit.status_values`;
    none without a verdict, or before enough distance): ``model_fit``,
    ``model_fit_culprits``, ``model_fit_misfit_<axle>`` (the verdict's threshold
    :data:`~.estimation.axle_fit.THRESHOLD` offline, ``ONLINE_THRESHOLD`` online)."""
    return {} if fit is None else fit.status_values()


def add_diagnostics(diagnostics: list, wv, rows: int = 1 << 16) -> list:
    """``diagnostics`` ((stamp_ns, [status dicts]) per second) with the whole vehicle's
    status at the last sample at or before each stamp added (none before its first), its
    period the samples since the previous status; the last with the reader's rejections.
    ``wv``: the drive's arrays, or a source of their rows (``n``, ``meta``, ``rows(lo,
    hi)``: :class:`SpilledEstimate`), read ``rows`` samples at a time: only a period's
    samples and the predictor's window held (:class:`_Periods`), the same statuses."""
    from road_force_estimator.estimation.whole_vehicle import ArraysRows

    source = wv if hasattr(wv, 'rows') else ArraysRows(wv)
    if not source.n:
        return diagnostics
    periods = _Periods(source, rows)
    out = []
    since = 0
    for j, (stamp, statuses) in enumerate(diagnostics):
        k = periods.last_at(stamp)
        last = j == len(diagnostics) - 1
        out.append((stamp, list(statuses) + ([periods.status(k, since, last)]
                                             if k >= 0 else [])))
        since = max(since, k + 1)
    return out


class _Periods:
    """The rows of a drive's whole-vehicle estimate from ``source`` for its statuses in
    order (:func:`add_diagnostics`): the samples of the current period, the predictor's
    window before it (:func:`~.estimation.rollover_warning.predicted_ltr` with the drive's
    first stamp) and the IMU and sensor-flag counts of the samples before them."""

    def __init__(self, source, rows: int) -> None:
        self.source, self.step = source, max(int(rows), 1)
        self.buf = source.rows(0, min(self.step, source.n))
        self.lo = 0                          # the buffer's first sample
        self.t0 = int(self.buf.stamps_ns[0])
        self.counted = 0                     # the samples counted in the totals below
        self.imu: dict = {}
        flags = getattr(self.buf, 'fault_flags', None)
        self.edges = None if flags is None else [(0, 0)] * flags.shape[0]

    @property
    def hi(self) -> int:
        return self.lo + len(self.buf.stamps_ns)

    def _more(self) -> bool:
        from road_force_estimator.estimation.whole_vehicle import join_rows

        if self.hi >= self.source.n:
            return False
        self.buf = join_rows(self.buf, self.source.rows(self.hi, min(self.hi + self.step,
                                                                     self.source.n)))
        return True

    def last_at(self, stamp: int) -> int:
        """The last sample at or before ``stamp`` (-1: none)."""
        while int(self.buf.stamps_ns[-1]) <= stamp and self._more():
            pass
        return self.lo + int(np.searchsorted(self.buf.stamps_ns, stamp, side='right')) - 1

    def _flags_before(self, a: int):
        """Each channel's flag at sample ``a - 1`` (None at the drive's start)."""
        return self.buf.fault_flags[:, a - 1 - self.lo] if a > 0 else None

    def status(self, k: int, since: int, last: bool) -> dict:
        """:func:`_status` at sample ``k`` over ``since`` .. ``k``."""
        from road_force_estimator.estimation.rollover_warning import predicted_ltr
        from road_force_estimator.estimation.whole_vehicle import take_rows

        a = max(since - 1, 0)                # the period with the sample before it
        self._count(a)
        part = take_rows(self.buf, a - self.lo, k + 1 - self.lo)
        window = take_rows(self.buf, 0, k + 1 - self.lo)
        predicted = predicted_ltr(window.stamps_ns, window.ltr_quasi_static,
                                  t0_ns=self.t0)[:, a - self.lo:]
        edges = None if self.edges is None else sensor_edges(part, self._flags_before(a))
        st = _status(part, k - a, since - a, edges, predicted, last,
                     {'imu': self.imu, 'edges': self.edges})
        self._drop(k)
        return st

    def _count(self, a: int) -> None:
        """The IMU codes and the flags raised before sample ``a`` counted."""
        from road_force_estimator.estimation.whole_vehicle import take_rows

        if a <= self.counted:
            return
        part = take_rows(self.buf, self.counted - self.lo, a - self.lo)
        codes = getattr(part, 'imu_codes', None)
        if codes is not None:
            for c in np.unique(codes).tolist():
                self.imu[c] = self.imu.get(c, 0) + int(np.count_nonzero(codes == c))
        if self.edges is not None:
            rose = sensor_edges(part, self._flags_before(self.counted))
            self.edges = [(s0 + st.size, d0 + dr.size)
                          for (s0, d0), (st, dr) in zip(self.edges, rose)]
        self.counted = a

    def _drop(self, k: int) -> None:
        """The samples no later status needs let go: those more than the predictor's
        window and 1 s before sample ``k``, and none from the sample before the next
        period's first (the flags before it)."""
        from road_force_estimator.estimation.rollover_warning import RATE_WINDOW_S
        from road_force_estimator.estimation.whole_vehicle import take_rows

        keep = int(self.buf.stamps_ns[k - self.lo]) - int((RATE_WINDOW_S + 1.0) * 1e9)
        j = self.lo + int(np.searchsorted(self.buf.stamps_ns, keep, side='right')) - 1
        cut = min(j, self.counted - 1)
        if cut > self.lo:
            self.buf = take_rows(self.buf, cut - self.lo, len(self.buf.stamps_ns))
            self.lo = cut


def bag_stream_pieces(source, rows: int = 1 << 16):
    """:func:`bag_streams` of a drive a piece of ``rows`` samples at a time from ``source``
    (``n``, ``meta``, ``rows(lo, hi)``: :class:`SpilledEstimate`): each piece's streams, the
    same messages."""
    from road_force_estimator.bagio.whole_vehicle_estimates import whole_vehicle_streams
    from road_force_estimator.interfaces import wheel_joints

    after = None
    joints = wheel_joints(source.meta.axle_names)
    for lo in range(0, source.n, max(int(rows), 1)):
        wv = source.rows(lo, min(lo + rows, source.n))
        ok = _published(wv)
        if not ok.any():
            continue
        yield whole_vehicle_streams(wv.stamps_ns, joints, wv.load_n, wv.static_n, wv.ltr,
                                    wv.ltr_quasi_static,
                                    rows=None if ok.all() else np.flatnonzero(ok),
                                    after_ns=after)
        after = int(wv.stamps_ns[np.flatnonzero(ok)[-1]])


def _published(wv) -> np.ndarray:
    """The samples of ``wv`` whose loads, static loads and load transfer are all finite (the
    bag's topics carry those only)."""
    return (np.isfinite(wv.load_n).all(axis=0) & np.isfinite(wv.static_n).all(axis=0)
            & np.isfinite(wv.ltr).all(axis=0) & np.isfinite(wv.ltr_quasi_static).all(axis=0))


def bag_streams(wv) -> list:
    """The whole vehicle's topics, the wheels named ``<axle>_left_wheel``,
    ``<axle>_right_wheel`` (INTERFACES.md) (:func:`~.bagio.whole_vehicle_estimates.
    whole_vehicle_streams`) of its samples with every value finite."""
    from road_force_estimator.bagio.whole_vehicle_estimates import whole_vehicle_streams
    from road_force_estimator.interfaces import wheel_joints

    ok = _published(wv)
    return whole_vehicle_streams(wv.stamps_ns, wheel_joints(wv.axle_names), wv.load_n,
                                 wv.static_n, wv.ltr, wv.ltr_quasi_static,
                                 rows=None if ok.all() else np.flatnonzero(ok))


@dataclass(frozen=True)
class FusedRoad:
    """The fused profile of a drive: both wheel paths (m) at the front axle's distances
    ``distance_m`` (m), each point stamped with the sample at which the front axle passed it
    (``stamps_ns``), fused over ``axles`` axles; ``half_track_m`` the front wheels' (m)."""

    stamps_ns: np.ndarray
    distance_m: np.ndarray
    left_m: np.ndarray
    right_m: np.ndarray
    axles: int
    half_track_m: float


def fused_profile(wv, vehicle) -> FusedRoad | None:
    """Every axle's road fused by distance: online the points the estimator streamed
    (``wv.fused``, the node's), offline :func:`~.estimation.articulated.fuse_roads` (the
    points the last axle has passed; of a :class:`SpilledEstimate`, a :class:`SpilledFused`
    the caller closes); None when ``wv`` holds no road or no point is passed by every
    axle."""
    from road_force_estimator.estimation.articulated import ArticulatedEstimate, fuse_roads

    if hasattr(wv, 'rows'):                    # a source of rows: its drive's fields
        if not wv.n:
            return None
        if wv.meta.fused is None and wv.meta.road_m is not None:
            return _spilled_fused(wv, vehicle)  # offline: from the columns it needs
        wv = wv.meta
    elif not len(wv.stamps_ns):
        return None
    if wv.road_m is None:
        return None
    half_track = float(vehicle.axles[0].wheel_half_track_m)
    if wv.fused is not None:
        f = wv.fused
        ok = np.isfinite(f.distance_m) & np.isfinite(f.left_m) & np.isfinite(f.right_m)
        if not ok.any():
            return None
        return FusedRoad(f.stamps_ns[ok], f.distance_m[ok], f.left_m[ok], f.right_m[ok],
                         len(vehicle.axles), half_track)
    est = ArticulatedEstimate(np.asarray(wv.stamps_ns), np.asarray(wv.distance_m, float),
                              np.asarray(wv.converged, bool), tuple(wv.wheel_names),
                              np.asarray(wv.load_n, float),
                              np.asarray(wv.load_n, float) - np.asarray(wv.static_n, float),
                              np.asarray(wv.lateral_mps2, float), np.asarray(wv.road_m, float))
    fused = fuse_roads(est, [a.position_m for a in vehicle.axles])
    if not fused.distance_m.size:
        return None
    keep = np.flatnonzero(est.distance_m + max(a.position_m for a in vehicle.axles)
                          <= est.distance_m[-1])
    ok = np.isfinite(fused.left) & np.isfinite(fused.right)
    return FusedRoad(np.asarray(wv.stamps_ns, np.int64)[keep][ok], fused.distance_m[ok],
                     fused.left[ok], fused.right[ok], fused.axles,
                     float(vehicle.axles[0].wheel_half_track_m))


def _spilled_fused(source, vehicle) -> SpilledFused | None:
    """:func:`fused_profile` offline from a spilled estimate ``source``
    (:class:`SpilledEstimate`): :func:`~.estimation.articulated.fuse_path_pieces` per wheel
    path on the spilled distances, each axle's road on that side and whether its wheel
    carried its share (as :func:`~.estimation.articulated.fuse_roads` computes it), at most
    :data:`SINK_ROWS` samples at a time: the one-block numbers bit for bit, in a
    :class:`SpilledFused` (the caller closes it)."""
    from road_force_estimator.core.pieces import PIECE_ROWS
    from road_force_estimator.estimation.articulated import (
        LIFT_OFF_FRACTION, fuse_path_pieces)

    xi = [a.position_m for a in vehicle.axles]
    cols = source.cols
    step = min(SINK_ROWS, PIECE_ROWS)

    def read_x(lo, hi):
        return cols['distance_m'].read(lo, hi)

    paths, m = [], 0
    try:
        for side in (0, 1):
            def read(lo, hi, j, side=side):  # axle j's wheel on this side
                w = 2 * j + side
                load = cols['load_n'].read(lo, hi)[:, w]
                static = cols['static_n'].read(lo, hi)[:, w]   # fuse_roads' static
                return (cols['road_m'].read(lo, hi)[:, w],
                        load >= LIFT_OFF_FRACTION * (load - (load - static)))

            m, path = fuse_path_pieces(source.n, read_x, read, xi, source.folder, step)
            paths.append(path)
        if not m:
            return None
        fused = SpilledFused(source.folder, len(xi),
                             float(vehicle.axles[0].wheel_half_track_m))
        try:
            for lo in range(0, m, step):
                hi = min(lo + step, m)
                left, right = paths[0].read(lo, hi), paths[1].read(lo, hi)
                ok = np.isfinite(left) & np.isfinite(right)
                fused.append(cols['stamps_ns'].read(lo, hi)[ok], read_x(lo, hi)[ok],
                             left[ok], right[ok])
        except BaseException:
            fused.close()
            raise
    finally:
        for path in paths:
            path.close()
    return fused


class SpilledFused:
    """The fused profile of a spilled estimate (:func:`_spilled_fused`) in temporary files
    in ``folder`` (:class:`~.core.spill.SpillColumn`), not in memory while the front axle's
    stage runs, never read whole: a piece of points (:meth:`read`, a :class:`FusedRoad`; the
    sinks' and the report's IRI, :func:`~.report.whole_vehicle.append_estimate`), ``n``
    of them; ``axles``, ``half_track_m`` as there. :meth:`close` lets the files go."""

    FIELDS = (('stamps_ns', np.int64), ('distance_m', float), ('left_m', float),
              ('right_m', float))

    def __init__(self, folder, axles: int, half_track_m: float) -> None:
        from road_force_estimator.core.spill import SpillColumn

        self.axles, self.half_track_m, self.n = int(axles), float(half_track_m), 0
        self.cols: dict = {}
        try:
            for f, dtype in self.FIELDS:
                self.cols[f] = SpillColumn(dtype, None, folder)
        except BaseException:
            self.close()
            raise

    def append(self, *fields) -> None:
        """Points at the end (the four fields' values, stamps increasing)."""
        for (f, _), a in zip(self.FIELDS, fields):
            self.cols[f].append(a)
        self.n += len(fields[0])

    def read(self, lo: int, hi: int) -> FusedRoad:
        """The points ``lo:hi``."""
        return FusedRoad(*(self.cols[f].read(lo, hi) for f, _ in self.FIELDS), self.axles,
                         self.half_track_m)

    def close(self) -> None:
        for col in self.cols.values():
            col.close()


def fused_streams(fused: FusedRoad | None) -> list:
    """The streams of ``/road_profile/fused/left|right`` (none without a fused profile)."""
    from road_force_estimator.bagio.whole_vehicle_estimates import fused_profile_streams

    if fused is None:
        return []
    return fused_profile_streams(fused.stamps_ns, fused.distance_m, fused.left_m,
                                 fused.right_m, fused.half_track_m)


def fused_road(est, wv, fused: FusedRoad | None):
    """The front axle's estimate ``est`` with the whole vehicle's road: offline the fused
    profile at the samples it holds, the whole vehicle's front wheels' own road after them
    (the last metres, where the trailer's axles have not passed); online the front wheels'
    own road at every sample (the node's ``/road_profile/*``: the fused points come later)."""
    if wv.road_m is None:
        return est
    stamps = np.asarray(est.stamp_ns, np.int64)
    road = np.array(est.road_m, float, copy=True)
    at = np.clip(np.searchsorted(wv.stamps_ns, stamps), 0, len(wv.stamps_ns) - 1)
    hit = np.asarray(wv.stamps_ns)[at] == stamps
    road[hit] = np.asarray(wv.road_m, float)[:2, at[hit]].T
    if wv.fused is None and fused is not None and len(fused.stamps_ns):
        k = np.clip(np.searchsorted(fused.stamps_ns, stamps), 0, len(fused.stamps_ns) - 1)
        on = fused.stamps_ns[k] == stamps
        road[on, 0] = fused.left_m[k[on]]
        road[on, 1] = fused.right_m[k[on]]
    return replace(est, road_m=road)


class SpilledEstimate:
    """The whole vehicle's estimate of a drive in blocks, online: its per-sample fields
    (:data:`~.estimation.whole_vehicle.ROW_FIELDS`) in temporary files in ``folder``
    (:class:`~.core.spill.SpillColumn`) as the pieces come (:meth:`add`), what is the
    drive's (names, counts, fused points, verdicts, rejections: ``meta``, a
    :class:`~.estimation.whole_vehicle.WholeVehicleArrays` without samples) in memory; the
    sinks read it back ``rows(lo, hi)`` at a time."""

    def __init__(self, folder: Path | None) -> None:
        self.folder = folder
        self.cols: dict | None = None
        self.n = 0
        self.meta = None
        self.codes = None

    def add_codes(self, codes) -> None:
        """The tractor IMU's pairing codes of consecutive input samples (one per sample)."""
        from road_force_estimator.core.spill import SpillColumn

        if self.codes is None:
            self.codes = SpillColumn(np.int8, None, self.folder)
        self.codes.append(np.asarray(codes, np.int8))

    def add(self, piece) -> None:
        """One piece of consecutive samples (:class:`~.estimation.whole_vehicle.
        WholeVehicleOnlineStream`'s)."""
        from road_force_estimator.core.spill import SpillColumn
        from road_force_estimator.estimation.whole_vehicle import ROW_FIELDS

        if self.cols is None:
            self.cols = {}
            for f in ROW_FIELDS:
                a = getattr(piece, f)
                if a is not None:
                    self.cols[f] = SpillColumn(a.dtype, a.shape[0] if a.ndim == 2 else None,
                                               self.folder)
        for f, col in self.cols.items():
            a = getattr(piece, f)
            col.append(a.T if a.ndim == 2 else a)
        self.n += len(piece.stamps_ns)

    def rows(self, lo: int, hi: int):
        """The samples ``lo:hi`` with the drive's fields."""
        out = {}
        for f, col in (self.cols or {}).items():
            a = col.read(lo, hi)
            out[f] = np.ascontiguousarray(a.T) if a.ndim == 2 else a
        if self.codes is not None:
            out['imu_codes'] = self.codes.read(lo, hi)
        return replace(self.meta, **out)

    def column(self, name: str, rows: list | None = None) -> np.ndarray:
        """One per-sample field of every sample (``(len(rows), n)`` of a per-wheel field's
        ``rows``, or ``(n,)``), read back :data:`SINK_ROWS` samples at a time into one array."""
        col = self.cols[name]
        if not col.shape:
            return col.array()
        out = np.empty((len(rows) if rows is not None else col.shape[0], self.n), col.dtype)
        for lo in range(0, self.n, SINK_ROWS):
            a = col.read(lo, lo + SINK_ROWS)
            out[:, lo:lo + a.shape[0]] = (a if rows is None else a[:, rows]).T
        return out

    def column_of(self, f, width: int, dtype) -> np.ndarray:
        """``f`` (samples' :class:`~.estimation.whole_vehicle.WholeVehicleArrays` -> (width,
        k)) of every sample, computed :data:`SINK_ROWS` samples at a time into one
        ``(width, n)`` array."""
        out = np.empty((width, self.n), dtype)
        for lo in range(0, self.n, SINK_ROWS):
            hi = min(lo + SINK_ROWS, self.n)
            out[:, lo:hi] = f(self.rows(lo, hi))
        return out

    def close(self) -> None:
        for col in (self.cols or {}).values():
            col.close()
        if self.codes is not None:
            self.codes.close()


@dataclass
class BlockJoin:
    """The whole vehicle's estimate ``source`` (:class:`SpilledEstimate`, or the arrays as
    :class:`~.estimation.whole_vehicle.ArraysRows`) and fused profile ``fused`` joined to
    the front axle's stage in blocks (:func:`~.blocks.run_blocks`, online from the plan's
    threshold), each step as the one-block path does it on the whole arrays
    (:func:`~.run.run_drive`): every piece of the front axle's estimate with the front
    wheels' loads, load transfer and road (:meth:`piece`: the rows of its stamps read as it
    comes), the whole vehicle's topics (:meth:`write_streams`, a piece at a time) and its
    ``/diagnostics`` status (:meth:`diagnostics`) in the bag, the sensors' fields of its
    status (:meth:`status`) and its reader's rejections (:meth:`drive`) in the report;
    ``half_track_m``: the front wheels' (m), the y of ``/road_profile/*``."""

    source: object
    fused: FusedRoad | None
    half_track_m: float
    rows: int = 0                            # samples read at a time (0: SINK_ROWS)

    def __post_init__(self) -> None:
        self.rows = self.rows or SINK_ROWS
        self._buf = None
        self._lo = 0
        self._fused = None                   # a spilled fused profile's points held
        self._fused_lo = 0

    def _fused_cover(self, first: int, last: int):
        """The fused profile's points stamped ``first`` .. ``last`` and more: those of a
        :class:`SpilledFused` read a piece at a time (those before ``first`` let go)."""
        f = self.fused
        if not isinstance(f, SpilledFused):
            return f
        names = [n for n, _ in SpilledFused.FIELDS]
        if self._fused is None:
            self._fused = f.read(0, min(self.rows, f.n))
        while True:
            buf = self._fused
            cut = int(np.searchsorted(buf.stamps_ns, first))
            if cut:                          # before ``first``: never needed again
                buf = self._fused = replace(buf, **{n: getattr(buf, n)[cut:] for n in names})
                self._fused_lo += cut
            hi = self._fused_lo + len(buf.stamps_ns)
            if (len(buf.stamps_ns) and int(buf.stamps_ns[-1]) >= last) or hi >= f.n:
                return buf
            more = f.read(hi, min(hi + self.rows, f.n))
            self._fused = replace(buf, **{n: np.concatenate([getattr(buf, n), getattr(more, n)])
                                          for n in names})

    def _cover(self, first: int, last: int):
        """The whole vehicle's samples of stamps ``first`` .. ``last`` and more (those
        before ``first`` let go)."""
        from road_force_estimator.estimation.whole_vehicle import join_rows, take_rows

        src = self.source
        if self._buf is None:
            self._buf = src.rows(0, min(self.rows, src.n))
        while True:
            cut = int(np.searchsorted(self._buf.stamps_ns, first))
            if cut:                          # before ``first``: never needed again
                self._buf = take_rows(self._buf, cut, len(self._buf.stamps_ns))
                self._lo += cut
            hi = self._lo + len(self._buf.stamps_ns)
            if (len(self._buf.stamps_ns) and int(self._buf.stamps_ns[-1]) >= last) \
                    or hi >= src.n:
                return self._buf
            self._buf = join_rows(self._buf, src.rows(hi, min(hi + self.rows, src.n)))

    def piece(self, est):
        """A piece of the front axle's estimate with the whole vehicle's front wheels
        (:func:`front_wheels`, :func:`fused_road`)."""
        stamps = np.asarray(est.stamp_ns, np.int64)
        if not stamps.size or not self.source.n:
            return est
        part = self._cover(int(stamps[0]), int(stamps[-1]))
        est = front_wheels(est, part)
        if not len(part.stamps_ns):
            return est
        return fused_road(est, part, self._fused_cover(int(stamps[0]), int(stamps[-1])))

    def write_streams(self, bag) -> None:
        """The whole vehicle's topics and the fused profile's into ``bag`` (an
        :class:`~.bagio.estimate_stream.EstimateBagStream`), a piece at a time
        (:func:`bag_stream_pieces`, :func:`fused_streams`)."""
        for streams in bag_stream_pieces(self.source, self.rows):
            bag.write_streams(streams)
        f = self.fused
        if not isinstance(f, SpilledFused):
            bag.write_streams(fused_streams(f))
            return
        for lo in range(0, max(f.n, 1), self.rows):    # (no point: the topics, empty)
            bag.write_streams(fused_streams(f.read(lo, min(lo + self.rows, f.n))))

    def diagnostics(self, diagnostics: list) -> list:
        """The per-second statuses with the whole vehicle's (:func:`add_diagnostics`)."""
        return add_diagnostics(diagnostics, self.source, self.rows)

    def status(self, status):
        """:func:`sensor_status`."""
        return sensor_status(status, self.source.meta)

    def drive(self, drive):
        """:func:`with_rejections`."""
        return with_rejections(drive, self.source.meta)
