"""Estimate bags: the observer's output topics for a batch of estimates, and its diagnostics.

Topics (INTERFACES.md): ``/wheel_load/left|right``, ``/wheel_load/static/left|right``,
``/road_profile/left|right``,
``/load_transfer_ratio``, ``/load_transfer``, ``/observer/states`` and ``/diagnostics``; the
fields are those of
:class:`road_force_estimator.estimation.estimator.EstimateArrays`.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from road_force_estimator.serde.cdr import TYPESTORE, ColumnRows, LazyColumns, ns_to_stamps
from road_force_estimator.serde.messages import (
    DEFAULT_TRACK_WIDTH_M,
    message_class,
    message_template,
    points_rows,
    stamp_columns,
)
from road_force_estimator.bagio.writer import BagWriter
from road_force_estimator.interfaces import (
    BASE_FRAME,
    DIAGNOSTIC_ARRAY,
    DIAGNOSTICS,
    FLOAT64,
    JOINT_STATE,
    LOAD,
    LOAD_TRANSFER,
    LTR,
    ROAD,
    ROAD_FRAME,
    STATIC_LOAD,
    STATIC_LOAD_PERIOD_NS,
    STATE_JOINTS,
    STATES,
    TOPIC_TYPES,
    VECTOR3_STAMPED,
    WHEEL_FRAMES,
    WRENCH,
    qos_kind,
)

__all__ = ['ESTIMATE_FIELDS', 'diagnostic_array', 'write_estimate_bag']

#: Estimate attributes used by :func:`write_estimate_bag` (INTERFACES.md topic in brackets).
ESTIMATE_FIELDS = {
    'stamp_ns': 'header stamps (n,) int64 [every topic]',
    'wheel_load_n': '(n, 2) [/wheel_load/left|right wrench.force.z]',
    'distance_m': '(n,) [/road_profile/* point.x]',
    'road_m': '(n, 2) band-passed road [/road_profile/* point.z]',
    'ltr': '(n,) [/load_transfer_ratio; /load_transfer vector.x]',
    'ltr_quasi_static': '(n,), optional [/load_transfer vector.y; without it no /load_transfer]',
    'static_load_n': '(n, 2), optional [/wheel_load/static/left|right wrench.force.z, the '
                     'first row of each STATIC_LOAD_PERIOD_NS; without it none]',
    'q_m, roll_rad, body_heave_m, wheel_heave_m (n, 2)': '[/observer/states position]',
    'dq, droll, body_heave_rate, wheel_heave_rate (n, 2)': '[/observer/states velocity]',
    'valid': '(n,) bool, optional: rows to write',
}


def diagnostic_array(stamp_ns: int, statuses: Iterable[Mapping[str, Any]]):
    """A diagnostic_msgs/DiagnosticArray (rosbags object) from plain dicts.

    Each status: ``name`` (str), ``level`` (0 OK, 1 WARN, 2 ERROR, 3 STALE), ``message``
    (str), optional ``hardware_id`` (str) and ``values`` (mapping, values shown with str()).
    """
    status_type = message_class('diagnostic_msgs/msg/DiagnosticStatus')
    key_value = message_class('diagnostic_msgs/msg/KeyValue')
    out = []
    for st in statuses:
        level = int(st.get('level', 0))
        if level not in (0, 1, 2, 3):
            raise ValueError(f'diagnostic level = {level!r}: one of 0 (OK), 1 (WARN), '
                             '2 (ERROR), 3 (STALE)')
        out.append(status_type(level=level, name=str(st['name']),
                               message=str(st.get('message', '')),
                               hardware_id=str(st.get('hardware_id', '')),
                               values=[key_value(key=str(k), value=str(v))
                                       for k, v in dict(st.get('values', {})).items()]))
    return message_class(DIAGNOSTIC_ARRAY)(header=_stamped_header(int(stamp_ns), ''),
                                           status=out)


def _stamped_header(stamp_ns: int, frame_id: str):
    sec, nanosec = ns_to_stamps(np.array([stamp_ns]))
    time = message_class('builtin_interfaces/msg/Time')(sec=int(sec[0]),
                                                         nanosec=int(nanosec[0]))
    return message_class('std_msgs/msg/Header')(stamp=time, frame_id=frame_id)


@dataclass
class EstimateColumns:
    """The columns of a batch of estimates that the bag carries, shaped, and which rows are
    valid and finite."""

    stamp_ns: np.ndarray
    load: np.ndarray
    road: np.ndarray
    distance: np.ndarray
    ltr: np.ndarray
    ltr_quasi_static: np.ndarray | None
    static_load: np.ndarray | None
    position: list[np.ndarray]
    velocity: list[np.ndarray]
    valid: np.ndarray
    finite: np.ndarray

    @classmethod
    def of(cls, e) -> EstimateColumns:
        """The columns of ``e`` (an :class:`EstimateArrays` or alike), checked for shape."""
        stamps = np.asarray(e.stamp_ns, dtype=np.int64).reshape(-1)
        n = stamps.size

        def arr(values, width: int | None = None) -> np.ndarray:
            a = np.asarray(values, dtype=float)
            return a.reshape(n, width) if width else a.reshape(n)

        load = arr(e.wheel_load_n, width=2)
        road = arr(e.road_m, width=2)
        dist = arr(e.distance_m)
        ltr = arr(e.ltr)
        quasi = getattr(e, 'ltr_quasi_static', None)
        quasi = None if quasi is None else arr(quasi)
        static = getattr(e, 'static_load_n', None)
        static = None if static is None else arr(static, width=2)
        position = [arr(e.q_m, width=2), arr(e.roll_rad), arr(e.body_heave_m),
                    arr(e.wheel_heave_m, width=2)]
        velocity = [arr(e.dq, width=2), arr(e.droll), arr(e.body_heave_rate),
                    arr(e.wheel_heave_rate, width=2)]
        valid = np.asarray(getattr(e, 'valid', np.ones(n, bool)), dtype=bool).reshape(n)
        finite = np.ones(n, dtype=bool)
        for values in ([load, road, dist, ltr] + [v for v in (quasi, static) if v is not None]
                       + position + velocity):
            for column in (values.T if values.ndim == 2 else [values]):
                finite &= np.isfinite(column)
        return cls(stamps, load, road, dist, ltr, quasi, static, position, velocity, valid,
                   finite)


def write_estimate_bag(path: str | Path, estimates, *,
                       track_width_m: float = DEFAULT_TRACK_WIDTH_M,
                       diagnostics: Iterable[tuple[int, Any]] = (),
                       custom_data: Mapping[str, str] | None = None,
                       overwrite: bool = False, extra_streams: Sequence = ()
                       ) -> dict[str, int]:
    """Write the observer's output topics for a batch of estimates.

    Topics (INTERFACES.md): ``/wheel_load/left|right`` (WrenchStamped, ``force.z``, frames
    ``front_left_wheel`` / ``front_right_wheel``), ``/road_profile/left|right`` (PointStamped,
    x = distance, y = +-T/2, z = estimated band-passed road, frame ``road``),
    ``/load_transfer_ratio`` (Float64), ``/load_transfer`` (Vector3Stamped, x = LTR, y =
    quasi-static LTR, z = 0, frame ``base_link``), ``/observer/states`` (JointState, names
    :data:`road_force_estimator.interfaces.STATE_JOINTS`, position and velocity),
    ``/wheel_load/static/left|right`` (WrenchStamped, ``force.z`` = F_c,i, the first row written
    in each :data:`~road_force_estimator.interfaces.STATIC_LOAD_PERIOD_NS` of the stamps), and
    ``/diagnostics`` for the given ``(stamp_ns, DiagnosticArray)`` pairs. Header stamp = log
    time = the measurement's stamp.

    Parameters
    ----------
    path : str or Path
        Bag folder to create.
    estimates : EstimateArrays or any object with the attributes of :data:`ESTIMATE_FIELDS`
        Rows where ``valid`` is False are not written; neither is a row with a non-finite
        value (nothing non-finite is published), which is counted in the result.
    track_width_m : float
        T (m) for the road points' y.
    diagnostics : iterable of (stamp_ns, DiagnosticArray or list of status dicts)
        Optional; a list of dicts is converted by :func:`diagnostic_array`.
    custom_data : mapping, optional
        Extra ``custom_data``.
    overwrite : bool
        Replace an existing bag folder.
    extra_streams : sequence of (topic, stamps, rows)
        More topics of :data:`~road_force_estimator.interfaces.TOPIC_TYPES` written beside
        (the whole vehicle's, :func:`.whole_vehicle_estimates.whole_vehicle_streams`).

    Returns
    -------
    dict
        ``{'written': rows written, 'invalid': rows not valid, 'nonfinite': rows with a
        non-finite value}``.
    """
    est = EstimateColumns.of(estimates)
    rows = est.valid & est.finite
    # The rows written are read a block at a time by the writer (no copies of whole columns).
    index = None if rows.all() else np.flatnonzero(rows)
    s = est.stamp_ns if index is None else est.stamp_ns[index]
    if s.size and np.any(np.diff(s) <= 0):
        raise ValueError('estimate stamps must be strictly increasing')
    custom = {'road_force_estimator.kind': 'estimates',
              'road_force_estimator.track_width_m': repr(float(track_width_m))}
    custom.update(custom_data or {})
    stamp_cols = stamp_columns(s)
    with BagWriter(path, overwrite=overwrite, custom_data=custom) as bag:
        streams = estimate_streams(est, s, stamp_cols, index, 0.5 * float(track_width_m))
        streams += diagnostic_streams(diagnostics)
        streams += list(extra_streams)
        for topic, _, _ in streams:
            bag.add_topic(topic, TOPIC_TYPES[topic], qos_kind(topic))
        bag.write_rows(streams)
    return {'written': int(s.size), 'invalid': int(np.count_nonzero(~est.valid)),
            'nonfinite': int(np.count_nonzero(est.valid & ~est.finite))}


def estimate_streams(est: EstimateColumns, s: np.ndarray, stamp_cols: dict,
                      index: np.ndarray | None, half: float) -> list:
    """The streams of the rows ``index`` (all when None), stamped ``s`` (header stamp columns
    ``stamp_cols``): wheel loads, road points (y = +-``half``), load transfer ratio, observer
    states."""
    m = s.size
    streams = []
    for side in (0, 1):
        cols = dict(stamp_cols, **{'wrench.force.z': LazyColumns([est.load[:, side]], index)})
        streams.append((LOAD[side], s, ColumnRows(
            WRENCH, message_template(WRENCH, WHEEL_FRAMES[side]), m, cols)))
    for side in (0, 1):
        streams.append((ROAD[side], s, points_rows(
            s, LazyColumns([est.distance], index), half if side == 0 else -half,
            LazyColumns([est.road[:, side]], index), ROAD_FRAME, stamp_cols)))
    streams.append((LTR, s, ColumnRows(FLOAT64, message_template(FLOAT64), m,
                                       {'data': LazyColumns([est.ltr], index)})))
    if est.ltr_quasi_static is not None:
        cols = dict(stamp_cols, **{'vector.x': LazyColumns([est.ltr], index),
                                   'vector.y': LazyColumns([est.ltr_quasi_static], index)})
        streams.append((LOAD_TRANSFER, s, ColumnRows(
            VECTOR3_STAMPED, message_template(VECTOR3_STAMPED, BASE_FRAME), m, cols)))
    cols = dict(stamp_cols, position=LazyColumns(est.position, index),
                velocity=LazyColumns(est.velocity, index))
    streams.append((STATES, s, ColumnRows(
        JOINT_STATE, message_template(JOINT_STATE, BASE_FRAME, STATE_JOINTS, velocity=True), m,
        cols)))
    if est.static_load is not None:
        streams += _static_streams(est, s, index)
    return streams


def _static_streams(est: EstimateColumns, s: np.ndarray, index: np.ndarray | None) -> list:
    """The /wheel_load/static/* streams: the rows written (``index``, all when None, stamped
    ``s``) that open a period of STATIC_LOAD_PERIOD_NS, as the observer node publishes them."""
    period = s // STATIC_LOAD_PERIOD_NS
    first = np.flatnonzero(np.concatenate([[True], period[1:] != period[:-1]])) if s.size \
        else np.zeros(0, np.int64)
    rows = first if index is None else index[first]
    stamps = s[first]
    cols_stamp = stamp_columns(stamps)
    streams = []
    for side in (0, 1):
        cols = dict(cols_stamp, **{'wrench.force.z': LazyColumns([est.static_load[:, side]],
                                                                 rows)})
        streams.append((STATIC_LOAD[side], stamps, ColumnRows(
            WRENCH, message_template(WRENCH, WHEEL_FRAMES[side]), stamps.size, cols)))
    return streams


def diagnostic_streams(diagnostics: Iterable[tuple[int, Any]]) -> list:
    """The /diagnostics stream (none without diagnostics), serialized message by message."""
    diagnostics = list(diagnostics)
    if not diagnostics:
        return []
    msgs = [d[1] if hasattr(d[1], '__msgtype__') else diagnostic_array(d[0], d[1])
            for d in diagnostics]
    return [(DIAGNOSTICS, [int(d[0]) for d in diagnostics],
             [TYPESTORE.serialize_cdr(msg, DIAGNOSTIC_ARRAY) for msg in msgs])]
