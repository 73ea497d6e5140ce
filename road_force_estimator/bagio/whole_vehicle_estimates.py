"""The whole vehicle's topics in an estimate bag (``vehicle.model: articulated``, INTERFACES.md
"The whole vehicle"): the streams :func:`.estimates.write_estimate_bag` writes beside the
front axle's.

``/wheel_loads`` (JointState, one per sample: ``name`` = the wheels, ``effort`` = load, N),
``/wheel_loads/static`` (the same with the static loads F_c, the first sample of each
:data:`~road_force_estimator.interfaces.STATIC_LOAD_PERIOD_NS`, as the node publishes
``/wheel_load/static/*``) and ``/load_transfer/tractor|trailer|combination``
(Vector3Stamped, frame ``base_link``: x = LTR, right minus left over their sum, y =
quasi-static LTR, z = 0). Header stamp = log time = the sample's stamp. Offline,
``/road_profile/fused/left|right`` (PointStamped, frame ``road`` as ``/road_profile/*``: x = the
point's distance in the front axle's frame, m; y = +/- the front wheels' half track, m; z = the
fused elevation, m), stamped with the sample at
which the front axle passed the point (:func:`fused_profile_streams`).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from road_force_estimator.interfaces import (
    BASE_FRAME, JOINT_STATE, ROAD_FRAME, ROAD_FUSED, STATIC_LOAD_PERIOD_NS, STATIC_WHEEL_LOADS,
    UNIT_LOAD_TRANSFER, VECTOR3_STAMPED, WHEEL_LOADS)
from road_force_estimator.serde.cdr import ColumnRows, LazyColumns
from road_force_estimator.serde.messages import message_template, points_rows, stamp_columns

__all__ = ['static_rows', 'whole_vehicle_streams', 'fused_profile_streams']


def static_rows(stamps_ns: np.ndarray, after_ns: int | None = None) -> np.ndarray:
    """The rows opening a period of STATIC_LOAD_PERIOD_NS (the ~10 Hz topics' samples);
    ``after_ns``: the last stamp written before these (its period not opened again; None:
    none)."""
    s = np.asarray(stamps_ns, np.int64)
    if not s.size:
        return np.zeros(0, np.int64)
    period = s // STATIC_LOAD_PERIOD_NS
    opens = after_ns is None or int(period[0]) != int(after_ns) // STATIC_LOAD_PERIOD_NS
    return np.flatnonzero(np.concatenate([[opens], period[1:] != period[:-1]]))


def whole_vehicle_streams(stamps_ns, wheel_names: Sequence[str], load_n, static_n, ltr,
                          ltr_quasi_static, rows: np.ndarray | None = None,
                          after_ns: int | None = None) -> list:
    """The streams (topic, stamps, rows) of the samples ``stamps_ns`` (m,), strictly
    increasing: ``load_n`` and ``static_n`` (wheels, m; N), ``ltr`` and ``ltr_quasi_static``
    (3, m; tractor, trailer, combination); ``rows``: only these samples (indices, increasing;
    None: all), the messages read from the arrays a block at a time as the bag is written
    (:class:`~.serde.cdr.LazyColumns`: no copy of the columns); ``after_ns``: the last
    stamp written before these samples (a drive written piece by piece: the static loads'
    period it opened not opened again).

    Raises
    ------
    ValueError
        Shapes that disagree, stamps not increasing or a value not finite (nothing
        non-finite is published: the caller drops such samples first).
    """
    every = np.asarray(stamps_ns, np.int64).reshape(-1)
    m, k = every.size, len(wheel_names)
    s = every if rows is None else every[rows]
    loads = np.asarray(load_n, float).reshape(k, m)
    static = np.asarray(static_n, float).reshape(k, m)
    x = np.asarray(ltr, float).reshape(len(UNIT_LOAD_TRANSFER), m)
    y = np.asarray(ltr_quasi_static, float).reshape(len(UNIT_LOAD_TRANSFER), m)
    if s.size and np.any(np.diff(s) <= 0):
        raise ValueError('whole-vehicle stamps must be strictly increasing')
    for name, a in (('load', loads), ('static load', static), ('LTR', x),
                    ('quasi-static LTR', y)):
        if not _finite(a, rows):
            raise ValueError(f'whole-vehicle {name}: not finite')
    n = s.size
    cols = stamp_columns(s)
    streams = [(WHEEL_LOADS, s, ColumnRows(
        JOINT_STATE, message_template(JOINT_STATE, BASE_FRAME, tuple(wheel_names), effort=True),
        n, dict(cols, effort=LazyColumns(list(loads), rows))))]
    first = static_rows(s, after_ns)
    streams.append((STATIC_WHEEL_LOADS, s[first], ColumnRows(
        JOINT_STATE, message_template(JOINT_STATE, BASE_FRAME, tuple(wheel_names), effort=True),
        first.size, dict(stamp_columns(s[first]), effort=LazyColumns(
            list(static), first if rows is None else rows[first])))))
    for u, topic in enumerate(UNIT_LOAD_TRANSFER):
        streams.append((topic, s, ColumnRows(
            VECTOR3_STAMPED, message_template(VECTOR3_STAMPED, BASE_FRAME), n,
            dict(cols, **{'vector.x': LazyColumns([x[u]], rows),
                          'vector.y': LazyColumns([y[u]], rows)}))))
    return streams


#: The samples checked at a time by :func:`_finite` (bounded temporaries).
_CHECK_ROWS = 1 << 16


def _finite(a: np.ndarray, rows: np.ndarray | None) -> bool:
    """Every value of ``a`` (k, m) finite at the samples ``rows`` (None: all)."""
    for r0 in range(0, a.shape[1] if rows is None else rows.size, _CHECK_ROWS):
        part = (a[:, r0:r0 + _CHECK_ROWS] if rows is None
                else a[:, rows[r0:r0 + _CHECK_ROWS]])
        if not np.isfinite(part).all():
            return False
    return True


def fused_profile_streams(stamps_ns, distance_m, left_m, right_m,
                          half_track_m: float) -> list:
    """The two fused wheel paths' streams (topic, stamps, rows): one point per stamp (m,),
    strictly increasing; distances (m) and elevations (m) finite; ``half_track_m``: y of the
    left path (m), the right's its negative.

    Raises
    ------
    ValueError
        Shapes that disagree, stamps not increasing or a value not finite.
    """
    s = np.asarray(stamps_ns, np.int64).reshape(-1)
    x = np.asarray(distance_m, float).reshape(-1)
    paths = [np.asarray(p, float).reshape(-1) for p in (left_m, right_m)]
    if any(a.size != s.size for a in (x, *paths)):
        raise ValueError('fused profile: stamps, distances and elevations differ in length')
    if s.size and np.any(np.diff(s) <= 0):
        raise ValueError('fused profile stamps must be strictly increasing')
    if not (np.isfinite(x).all() and all(np.isfinite(p).all() for p in paths)):
        raise ValueError('fused profile: not finite')
    cols = stamp_columns(s)
    return [(ROAD_FUSED[side], s, points_rows(s, x, half_track_m if side == 0 else
                                              -half_track_m, paths[side], ROAD_FRAME, cols))
            for side in (0, 1)]
