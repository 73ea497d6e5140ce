"""LPA profile bags: a measured (or synthetic) road profile as ``/lpa/left`` and ``/lpa/right``.

Each sample is a geometry_msgs/PointStamped in frame ``road``: ``x`` distance along the road
(m), ``y`` = +T/2 (left) / -T/2 (right), ``z`` elevation (m), stamped as if surveyed at a
constant speed.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from road_force_estimator.serde.cdr import NS_PER_S
from road_force_estimator.bagio.checks import Rejects, accept_in_order, read_points
from road_force_estimator.bagio.errors import BagReadError
from road_force_estimator.serde.messages import (
    DEFAULT_START_STAMP_NS,
    DEFAULT_TRACK_WIDTH_M,
    check_finite,
    points_rows,
)
from road_force_estimator.bagio.reader import bag_custom_data, read_topic_columns
from road_force_estimator.bagio.writer import BagWriter
from road_force_estimator.core.road import RoadProfile
from road_force_estimator.interfaces import LPA, POINT, ROAD, ROAD_FRAME, ROAD_FUSED, qos_kind

__all__ = ['DEFAULT_SURVEY_SPEED_MPS', 'PROFILE_TOPICS', 'write_lpa_bag', 'read_lpa_bag',
           'read_profile_bag']

#: Default survey speed of an LPA profile bag (m/s).
DEFAULT_SURVEY_SPEED_MPS = 20.0


def write_lpa_bag(path: str | Path, profile, *,
                  survey_speed_mps: float = DEFAULT_SURVEY_SPEED_MPS,
                  track_width_m: float = DEFAULT_TRACK_WIDTH_M,
                  start_stamp_ns: int = DEFAULT_START_STAMP_NS,
                  overwrite: bool = False) -> None:
    """Write a measured (or synthetic) road profile as an LPA bag.

    Topics ``/lpa/left`` and ``/lpa/right`` (geometry_msgs/PointStamped, frame ``road``):
    ``x`` = distance along the road (m), ``y`` = +T/2 (left) / -T/2 (right), ``z`` =
    elevation (m); stamps as if surveyed at ``survey_speed_mps`` from ``start_stamp_ns``.
    The profile's name, the survey speed and the track width go to ``custom_data``.

    Parameters
    ----------
    path : str or Path
        Bag folder to create.
    profile : RoadProfile
        ``distance_m`` (n,) strictly increasing, ``elevation_m`` (n, 2) or (n,), ``name``.
    survey_speed_mps : float
        Survey speed (m/s), > 0; sets the stamps only.
    track_width_m : float
        Lateral distance between the wheel paths T (m), > 0.
    start_stamp_ns : int
        Stamp of the first sample (ns).
    overwrite : bool
        Replace an existing bag folder.
    """
    if not (survey_speed_mps > 0.0 and math.isfinite(survey_speed_mps)):
        raise ValueError(f'survey_speed_mps = {survey_speed_mps!r} m/s: must be > 0')
    if not (track_width_m > 0.0 and math.isfinite(track_width_m)):
        raise ValueError(f'track_width_m = {track_width_m!r} m: must be > 0')
    x = np.asarray(profile.distance_m, dtype=float)
    z = np.asarray(profile.elevation_m, dtype=float)
    if z.ndim == 1:
        z = np.column_stack([z, z])
    if x.ndim != 1 or z.shape != (x.size, 2) or x.size < 2:
        raise ValueError(f'profile shapes {x.shape}, {z.shape}: need (n,) and (n, 2), n >= 2')
    check_finite('profile distance', x)
    check_finite('profile elevation', z)
    if np.any(np.diff(x) <= 0.0):
        raise ValueError('profile distance_m must be strictly increasing')
    stamps = int(start_stamp_ns) + np.round((x - x[0]) / survey_speed_mps * NS_PER_S).astype(
        np.int64)
    if np.any(np.diff(stamps) <= 0):
        raise ValueError(f'survey_speed_mps = {survey_speed_mps!r} m/s: two samples get the '
                         'same stamp (ns); use a lower speed')
    custom = {'road_force_estimator.kind': 'lpa_profile',
              'road_force_estimator.profile_name': str(getattr(profile, 'name', '') or ''),
              'road_force_estimator.survey_speed_mps': repr(float(survey_speed_mps)),
              'road_force_estimator.track_width_m': repr(float(track_width_m))}
    half = 0.5 * track_width_m
    with BagWriter(path, overwrite=overwrite, custom_data=custom) as bag:
        streams = []
        for side, topic in enumerate(LPA):
            bag.add_topic(topic, POINT, qos_kind(topic))
            streams.append((topic, stamps, points_rows(stamps, x, half if side == 0 else -half,
                                                        z[:, side], ROAD_FRAME)))
        bag.write_rows(streams)


def read_lpa_bag(path: str | Path, *, issues: list[str] | None = None):
    """Read an LPA bag back into a :class:`road_force_estimator.core.road.RoadProfile`.

    Samples are kept in file order while their distance increases; a NaN, undecodable,
    duplicate or backward sample is dropped and counted in ``issues``. The two tracks are
    joined on equal distances (a bag with one track uses it for both wheel paths).

    Raises
    ------
    BagReadError
        No ``/lpa/left`` nor ``/lpa/right`` topic, or fewer than 2 usable samples.
    """
    path = Path(path)
    sink = issues if issues is not None else []
    cols = read_topic_columns(path, {t: POINT for t in LPA}, issues=sink)
    if not cols:
        raise BagReadError(f'{path}: no {LPA[0]} or {LPA[1]} topic: not an LPA bag')
    return _profile(path, cols, LPA, sink)


#: The profile topics of a bag, in the order :func:`read_profile_bag` looks for them.
PROFILE_TOPICS = (LPA, ROAD_FUSED, ROAD)


def read_profile_bag(path: str | Path, *, issues: list[str] | None = None):
    """The road profile a bag holds: an LPA bag's ``/lpa/*``, else an estimate bag's fused
    profile ``/road_profile/fused/*`` (an articulated truck's), else its ``/road_profile/*``
    (the estimated road under the front wheels, by the estimator's distance).

    As :func:`read_lpa_bag` (the same checks; an estimate's repeated distances, where the
    truck stood, keep their first sample); ``issues`` says which topics were read.

    Raises
    ------
    BagReadError
        None of those topics, or fewer than 2 usable samples.
    """
    path = Path(path)
    sink = issues if issues is not None else []
    for topics in PROFILE_TOPICS:
        cols = read_topic_columns(path, {t: POINT for t in topics}, issues=sink)
        if cols:
            break
    else:
        names = ', '.join(f'{a} / {b}' for a, b in PROFILE_TOPICS)
        raise BagReadError(f'{path}: no profile topic ({names}): neither an LPA bag nor a bag '
                           'of estimates')
    if topics != LPA:
        sink.append(f'the estimated profile of {topics[0]} and {topics[1]} (band-passed, by '
                    "the estimator's distance)")
    return _profile(path, cols, topics, sink)


def _profile(path: Path, cols: dict, topics: tuple[str, str], sink: list[str]):
    """The RoadProfile of the point columns ``cols`` of ``topics`` (left, right)."""
    rejects = Rejects()
    tracks = {}
    for topic, c in cols.items():
        _, x, _, z = read_points(c, rejects)
        # Distance must increase along the file: drop what does not, as for stamps.
        keep = accept_in_order(x, np.ones(x.size, bool), topic + ' (distance)', rejects)
        tracks[topic] = (x[keep], z[keep])
    for topic, reasons in rejects.counts.items():
        for reason, count in reasons.items():
            sink.append(f'{topic}: {count} samples dropped ({reason})')
    if len(tracks) == 1:
        (topic, (x, z)), = tracks.items()
        sink.append(f'only {topic} in the bag: used for both wheel paths')
        elevation = np.column_stack([z, z])
    else:
        (xl, zl), (xr, zr) = tracks[topics[0]], tracks[topics[1]]
        if xl.size == xr.size and np.array_equal(xl, xr):
            x, elevation = xl, np.column_stack([zl, zr])
        else:
            x, il, ir = np.intersect1d(xl, xr, assume_unique=True, return_indices=True)
            sink.append(f'left and right tracks differ in distance: kept the {x.size} common '
                        f'samples ({xl.size - x.size} left and {xr.size - x.size} right '
                        'dropped)')
            elevation = np.column_stack([zl[il], zr[ir]])
    if x.size < 2:
        raise BagReadError(f'{path}: fewer than 2 usable profile samples')
    name = bag_custom_data(path).get('road_force_estimator.profile_name') or path.name
    return RoadProfile(distance_m=x, elevation_m=elevation, name=name, notes=tuple(sink))
