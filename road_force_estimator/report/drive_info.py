"""What a report says about the run and its reference profile.

:func:`run_description`: what was run (the command line, the parameter file and its overrides,
the package version, the mode and latency, the road source, the speed, the static loads).

:func:`true_profile_iri`: the IRI of the reference ("true") profile. The reference is the
ground truth's road profile, which is the road **enveloped** by the simulated tire (a moving
average over ``simulator.tire_envelope_length``, 0.25 m by default: what the tire follows and
what the estimator can see); it is taken on the truth's own samples (every sample of the drive,
whatever the estimator accepted), so the online and offline reports of a drive show the same
true IRI. The **raw** profile (the road before the envelope) is shown beside it when the drive
bag names a synthetic road or a profile file that can be read again.
"""
from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

from road_force_estimator.core import iri as iri_mod

__all__ = ['run_description', 'true_profile_iri', 'true_segment_iri', 'raw_road']


def _floats(a) -> list[float]:
    return [float(v) for v in np.ravel(a)]


def run_description(drive, est, vehicle, observer, mode: str,
                    run_info: dict[str, Any] | None) -> dict[str, Any]:
    """What was run: ``command``, ``params_file``, ``overrides``, ``package_version``,
    ``mode``, ``latency_s``, ``road_source``, ``speed_mps`` (mean, min, max of the accepted
    samples) and ``static_load_n`` (left, right)."""
    from road_force_estimator import __version__

    info = dict(run_info or {})
    speed = np.asarray(getattr(drive, 'speed_mps', np.zeros(0)), dtype=float)
    valid = np.asarray(est.valid, dtype=bool)
    if speed.shape == valid.shape:
        speed = speed[valid]
    speed = speed[np.isfinite(speed)]
    if speed.size == 0 and drive is not None and len(getattr(drive, 'twist_speed_mps', ())):
        speed = np.asarray(drive.twist_speed_mps, dtype=float)
    custom = getattr(drive, 'custom_data', None) or {}
    return {
        'command': info.get('command'),
        'params_file': info.get('params_file'),
        'overrides': list(info.get('overrides') or ()),
        'package_version': __version__,
        'mode': mode,
        'latency_s': float(observer.latency_s),
        'road_source': custom.get('road_force_estimator.road_name'),
        'speed_mps': ({'mean': float(np.mean(speed)), 'min': float(np.min(speed)),
                       'max': float(np.max(speed))} if speed.size else None),
        'static_load_n': _floats(vehicle.static_load_n),
    }


def raw_road(drive, reader=None):
    """The road the drive was simulated over, before the tire envelope (a RoadProfile), or
    None: no simulator parameters in the bag, or a source that cannot be read (a file that
    moved; an LPA bag unless ``reader`` reads bags).

    ``reader(source, length_m=...)`` reads the source (default
    :func:`road_force_estimator.core.road_files.road_from_source`; ``estimate_bag`` passes
    :func:`road_force_estimator.bagio.road_from_source`)."""
    from road_force_estimator.core.road_files import road_from_source

    reader = road_from_source if reader is None else reader
    custom = getattr(drive, 'custom_data', None) or {}
    try:
        used = json.loads(custom.get('road_force_estimator.parameters', '') or 'null')
        source = used['simulator.road']
        length = (used['simulator.speed'] * used['simulator.duration']
                  + 2.0 * used['simulator.tire_envelope_length'] + 1.0)
        return reader(source, length_m=length)
    except Exception:   # noqa: BLE001 - any unreadable source: no raw profile, said so
        return None


def _truth_track(drive) -> tuple[np.ndarray, np.ndarray] | None:
    """The truth's distances (m) and enveloped profile (m, (n, 2)) on its own samples."""
    truth = getattr(drive, 'truth', None)
    if truth is None:
        return None
    x = np.asarray(truth.distance_m, dtype=float)
    z = np.asarray(truth.road_m, dtype=float)
    ok = np.isfinite(x) & np.isfinite(z).all(axis=1)
    x, z = x[ok], z[ok]
    if x.size < 2:
        return None
    keep = np.concatenate([[True], np.diff(x) > 0])
    return x[keep], z[keep]


def _truth_offset(drive, al) -> float | None:
    """Truth distance minus the estimate's distance (m), median over the common stamps."""
    truth = drive.truth.at(al.stamps_ns)
    d = np.asarray(truth.distance_m, dtype=float) - al.x_m
    d = d[np.isfinite(d)]
    return float(np.median(d)) if d.size else None


def true_profile_iri(drive, al, road=None) -> dict[str, Any] | None:
    """Whole-drive IRI (m/km, left and right) of the reference profile on the truth's own
    samples (``enveloped``) and of the raw road under the same span (``raw``: of ``road``,
    else :func:`raw_road`; None when unknown); None without a profile truth."""
    track = _truth_track(drive)
    if track is None or al.true_road_m is None:
        return None
    x, z = track
    try:
        enveloped = _floats(iri_mod.iri(x, z))
    except ValueError:
        return None
    raw = None
    road = raw_road(drive) if road is None else road
    if road is not None:
        inside = (x >= road.start_m) & (x <= road.end_m)
        try:
            raw = _floats(iri_mod.iri(x[inside], road.elevation_at(x[inside])))
        except ValueError:
            raw = None
    return {'enveloped': enveloped, 'raw': raw,
            'envelope_m': _envelope_length(drive)}


def _envelope_length(drive) -> float | None:
    custom = getattr(drive, 'custom_data', None) or {}
    try:
        value = json.loads(custom.get('road_force_estimator.parameters', '') or 'null')
        return float(value['simulator.tire_envelope_length'])
    except (TypeError, KeyError, ValueError):
        return None


def true_segment_iri(drive, al, edges_m: np.ndarray) -> np.ndarray | None:
    """IRI (m/km, (k, 2)) of the reference profile per segment (edges in the estimate's
    distance), on the truth's own samples; None without a profile truth."""
    track = _truth_track(drive)
    if track is None or al.true_road_m is None or len(edges_m) < 2:
        return None
    offset = _truth_offset(drive, al)
    if offset is None or not math.isfinite(offset):
        return None
    x, z = track
    x = x - offset
    try:
        return np.asarray(iri_mod.iri_segments(x, z, np.asarray(edges_m, dtype=float)),
                          dtype=float).reshape(-1, 2)
    except ValueError:
        return None
