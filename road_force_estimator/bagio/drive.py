"""Drive bags: the estimator's inputs (deflections, speed), the ground truth, GNSS fixes.

:func:`write_drive_bag` writes a (simulated) drive as the plant_simulator node publishes it;
:func:`read_drive_bag` reads one back into a :class:`Drive`, rejecting and counting what cannot
be trusted (:mod:`.checks`) and describing the breaks of a cut or corrupt file.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

import numpy as np

from road_force_estimator.serde.cdr import NS_PER_S, ColumnRows
from road_force_estimator.bagio.checks import (
    Rejects,
    accept_in_order,
    basic_checks,
    read_joint_state,
    read_points,
    read_scalar,
)
from road_force_estimator.bagio.errors import BagReadError
from road_force_estimator.serde.messages import (
    DEFAULT_START_STAMP_NS,
    DEFAULT_TRACK_WIDTH_M,
    check_finite,
    message_template,
    points_rows,
    stamp_columns,
)
from road_force_estimator.bagio.reader import bag_custom_data, read_topic_columns
from road_force_estimator.bagio.vehicle_layout import front_axle_joints
from road_force_estimator.bagio.writer import BagWriter
from road_force_estimator.interfaces import (
    BASE_FRAME,
    DEFLECTION_JOINTS,
    DEFLECTIONS,
    FIX,
    JOINT_STATE,
    NAVSATFIX,
    POINT,
    ROAD_FRAME,
    TOPIC_TYPES,
    TRUE_LOAD,
    TRUE_ROAD,
    TWIST,
    TWIST_STAMPED,
    WHEEL_FRAMES,
    WRENCH,
    qos_kind,
)

__all__ = ['GroundTruth', 'Fixes', 'Drive', 'write_drive_bag', 'read_drive_bag', 'fix_stream',
           'measurement_streams', 'truth_streams']

@dataclass(frozen=True)
class GroundTruth:
    """Ground truth of a simulated drive, on the union of its stamps (NaN where a topic has
    no sample at that stamp).

    Attributes: ``stamps_ns`` (m,) int64 increasing; ``wheel_load_n`` (m, 2) true vertical
    loads [left, right] (N); ``road_m`` (m, 2) true road elevation under each tire (m);
    ``distance_m`` (m,) distance travelled (m, from the road points).
    """

    stamps_ns: np.ndarray
    wheel_load_n: np.ndarray
    road_m: np.ndarray
    distance_m: np.ndarray

    def at(self, stamps_ns: np.ndarray) -> GroundTruth:
        """The truth at the given stamps (NaN where it has no sample at exactly that stamp)."""
        want = np.asarray(stamps_ns, dtype=np.int64)
        hit = np.zeros(want.size, bool)
        pos = np.zeros(want.size, np.int64)
        if self.stamps_ns.size:
            pos = np.minimum(np.searchsorted(self.stamps_ns, want), self.stamps_ns.size - 1)
            hit = self.stamps_ns[pos] == want

        def pick(a: np.ndarray) -> np.ndarray:
            out = np.full((want.size,) + a.shape[1:], np.nan)
            out[hit] = a[pos[hit]]
            return out
        return GroundTruth(want.copy(), pick(self.wheel_load_n), pick(self.road_m),
                           pick(self.distance_m))


@dataclass(frozen=True)
class Fixes:
    """GNSS fixes: ``stamps_ns`` (k,), ``latitude_deg``, ``longitude_deg`` (WGS84),
    ``altitude_m`` (NaN allowed: NavSatFix's "unknown")."""

    stamps_ns: np.ndarray
    latitude_deg: np.ndarray
    longitude_deg: np.ndarray
    altitude_m: np.ndarray


@dataclass(frozen=True)
class Drive:
    """A drive read from a bag: the estimator's inputs, the truth if any, what was rejected.

    Attributes
    ----------
    stamps_ns : ndarray (n,) int64
        Header stamps of the accepted ``/suspension/deflections``, strictly increasing.
    q_m : ndarray (n, 2)
        Suspension deflections [q_1 left, q_2 right] (m), mapped by joint name.
    roll_rad : ndarray (n,)
        Roll angle phi (rad), > 0 when the left side is up.
    speed_mps : ndarray (n,)
        Speed held from the latest accepted ``/vehicle/twist`` stamped at or before each
        sample (m/s); NaN before the first one.
    twist_stamps_ns, twist_speed_mps : ndarray (k,)
        The accepted twist messages.
    truth : GroundTruth or None
    fixes : Fixes or None
    messages : dict
        ``topic -> messages read``.
    rejected : dict
        ``topic -> {reason -> count}``: reasons ``undecodable``, ``wrong_type (...)``,
        ``bad_stamp``, ``missing_name``, ``duplicate_name``, ``length_mismatch``,
        ``nonfinite``, ``no_fix``, ``duplicate_stamp``, ``backwards_stamp``.
    issues : tuple of str
        Breaks: a truncated or corrupt file (read up to the break), missing files.
    custom_data : dict
        metadata.yaml ``custom_data``.
    noted : dict
        ``topic -> {reason -> count}``: messages kept with a caveat: ``fix_status_unknown``
        (a NavSatFix of status -2, STATUS_UNKNOWN, with a finite position).
    notes : tuple of str
        What the reader took (an articulated drive: its front axle, :mod:`.vehicle_layout`).
    """

    stamps_ns: np.ndarray
    q_m: np.ndarray
    roll_rad: np.ndarray
    speed_mps: np.ndarray
    twist_stamps_ns: np.ndarray
    twist_speed_mps: np.ndarray
    truth: GroundTruth | None
    fixes: Fixes | None
    messages: dict[str, int] = field(default_factory=dict)
    rejected: dict[str, dict[str, int]] = field(default_factory=dict)
    issues: tuple[str, ...] = ()
    custom_data: dict[str, str] = field(default_factory=dict)
    noted: dict[str, dict[str, int]] = field(default_factory=dict)
    notes: tuple[str, ...] = ()

    @property
    def rejected_total(self) -> int:
        """Messages rejected over all topics."""
        return sum(sum(r.values()) for r in self.rejected.values())

    def summary_lines(self) -> list[str]:
        """Human-readable lines: messages per topic, rejections and breaks."""
        lines = [f'{topic}: {count} messages' for topic, count in sorted(self.messages.items())]
        for topic, reasons in sorted(self.rejected.items()):
            for reason, count in sorted(reasons.items()):
                lines.append(f'{topic}: {count} rejected ({reason})')
        for topic, reasons in sorted(self.noted.items()):
            for reason, count in sorted(reasons.items()):
                lines.append(f'{topic}: {count} kept ({reason})')
        lines.extend(self.issues)
        return lines


def _trajectory_stamps(trajectory, start_stamp_ns: int) -> np.ndarray:
    if hasattr(trajectory, 'stamps_ns'):
        return np.asarray(trajectory.stamps_ns, dtype=np.int64)
    t = np.asarray(trajectory.t_s, dtype=float)
    check_finite('trajectory.t_s', t)
    return int(start_stamp_ns) + np.round(t * NS_PER_S).astype(np.int64)


def _fix_arrays(fixes, start_stamp_ns: int):
    if hasattr(fixes, 'stamps_ns'):
        stamps = np.asarray(fixes.stamps_ns, dtype=np.int64)
    else:
        stamps = int(start_stamp_ns) + np.round(np.asarray(fixes.time_s, float) * NS_PER_S).astype(
            np.int64)
    lat = np.asarray(fixes.latitude_deg, dtype=float)
    lon = np.asarray(fixes.longitude_deg, dtype=float)
    alt = np.asarray(getattr(fixes, 'altitude_m', np.zeros(lat.shape)), dtype=float)
    check_finite('fix latitude', lat)
    check_finite('fix longitude', lon)
    check_finite('fix altitude', alt)
    return stamps, lat, lon, np.broadcast_to(alt, lat.shape)


def write_drive_bag(path: str | Path, trajectory, q_meas: np.ndarray, roll_meas: np.ndarray,
                    *, fixes=None, speed_mps: float | np.ndarray | None = None,
                    track_width_m: float = DEFAULT_TRACK_WIDTH_M,
                    start_stamp_ns: int = DEFAULT_START_STAMP_NS, ground_truth: bool = True,
                    custom_data: Mapping[str, str] | None = None,
                    overwrite: bool = False) -> int:
    """Write a (simulated) drive: measurements, ground truth, optional GNSS fixes.

    Topics (INTERFACES.md): ``/suspension/deflections`` (JointState ``[left_suspension,
    right_suspension, roll]``, frame ``base_link``, sensor-data QoS), ``/vehicle/twist``
    (``twist.linear.x`` = speed), and with ``ground_truth`` ``/ground_truth/wheel_load/left``,
    ``.../right`` (``wrench.force.z``, frames ``front_left_wheel`` / ``front_right_wheel``),
    ``/ground_truth/road_profile/left``, ``.../right`` (x = distance, y = +-T/2, z = road
    elevation, frame ``road``); ``/fix`` (NavSatFix) when ``fixes`` is given. Every sample's
    messages share its stamp (header stamp = log time); at equal stamps the twist is written
    before the deflections, so a replay delivers the speed first.

    Parameters
    ----------
    path : str or Path
        Bag folder to create.
    trajectory : Trajectory
        From ``plant.simulate``: ``t_s`` (n,) (s from the start; or ``stamps_ns``),
        ``distance_m`` (n,), ``wheel_load_n`` (n, 2), ``road_m`` (n, 2), and ``speed_mps``
        (n,) if it has one.
    q_meas : array (n, 2)
        Measured deflections [left, right] (m).
    roll_meas : array (n,)
        Measured roll angle (rad).
    fixes : object, optional
        ``stamps_ns`` or ``time_s``, ``latitude_deg``, ``longitude_deg`` [, ``altitude_m``,
        default 0] (e.g. ``gnss.GnssRoute``); written as NavSatFix with status FIX, frame
        ``gnss``, covariance type unknown, as the plant_simulator node publishes them.
    speed_mps : float or array (n,), optional
        Speed (m/s); default the trajectory's ``speed_mps``, else d(distance)/dt.
    track_width_m : float
        T (m): the road points' lateral positions +-T/2.
    start_stamp_ns : int
        Stamp of t = 0 (ns).
    ground_truth : bool
        Write the ground-truth topics.
    custom_data : mapping, optional
        Extra ``custom_data`` (e.g. the parameters used).
    overwrite : bool
        Replace an existing bag folder.

    Returns
    -------
    int
        Messages written.
    """
    stamps = _trajectory_stamps(trajectory, start_stamp_ns)
    q, roll, speed = _measurements(trajectory, stamps, q_meas, roll_meas, speed_mps)
    custom = {'road_force_estimator.kind': 'drive',
              'road_force_estimator.track_width_m': repr(float(track_width_m))}
    custom.update(custom_data or {})
    stamp_cols = stamp_columns(stamps)
    with BagWriter(path, overwrite=overwrite, custom_data=custom) as bag:
        streams = measurement_streams(stamps, stamp_cols, q, roll, speed)
        if ground_truth:
            streams += truth_streams(trajectory, stamps, stamp_cols, track_width_m)
        if fixes is not None:
            streams.append(fix_stream(fixes, start_stamp_ns))
        for topic, _, _ in streams:
            bag.add_topic(topic, TOPIC_TYPES[topic], qos_kind(topic))
        bag.write_rows(streams)
        return bag.message_count


def _measurements(trajectory, stamps: np.ndarray, q_meas, roll_meas, speed_mps):
    """``(q (n, 2), roll (n,), speed (n,))`` checked: the speed given, else the trajectory's,
    else d(distance)/dt."""
    n = stamps.size
    if n == 0:
        raise ValueError('trajectory has no sample')
    if np.any(np.diff(stamps) <= 0):
        raise ValueError('trajectory stamps must be strictly increasing')
    q = np.asarray(q_meas, dtype=float).reshape(n, 2)
    roll = np.asarray(roll_meas, dtype=float).reshape(n)
    if speed_mps is None:
        speed_mps = getattr(trajectory, 'speed_mps', None)
    if speed_mps is None:
        t = (stamps - stamps[0]) / NS_PER_S
        speed = np.gradient(np.asarray(trajectory.distance_m, float), t) if n > 1 \
            else np.zeros(1)
    else:
        speed = np.broadcast_to(np.asarray(speed_mps, dtype=float), (n,))
    for name, values in (('q_meas', q), ('roll_meas', roll), ('speed', speed)):
        check_finite(name, values)
    return q, roll, speed


def measurement_streams(stamps, stamp_cols, q, roll, speed) -> list:
    """The /vehicle/twist and /suspension/deflections streams (twist first: at equal stamps a
    replay delivers the speed before the deflections)."""
    n = stamps.size
    twist = ColumnRows(TWIST_STAMPED, message_template(TWIST_STAMPED, BASE_FRAME), n,
                       dict(stamp_cols, **{'twist.linear.x': speed}))
    deflections = ColumnRows(JOINT_STATE, message_template(JOINT_STATE, BASE_FRAME,
                                                           DEFLECTION_JOINTS), n,
                             dict(stamp_cols, position=np.column_stack([q, roll])))
    return [(TWIST, stamps, twist), (DEFLECTIONS, stamps, deflections)]


def truth_streams(trajectory, stamps, stamp_cols, track_width_m: float) -> list:
    """The ground-truth streams: wheel loads (left, right), then road points (left, right)."""
    n = stamps.size
    load = np.asarray(trajectory.wheel_load_n, dtype=float).reshape(n, 2)
    road = np.asarray(trajectory.road_m, dtype=float).reshape(n, 2)
    x = np.asarray(trajectory.distance_m, dtype=float).reshape(n)
    for name, values in (('wheel_load_n', load), ('road_m', road), ('distance_m', x)):
        check_finite('trajectory.' + name, values)
    half = 0.5 * float(track_width_m)
    streams = []
    for side in (0, 1):
        cols = dict(stamp_cols, **{'wrench.force.z': load[:, side]})
        streams.append((TRUE_LOAD[side], stamps, ColumnRows(
            WRENCH, message_template(WRENCH, WHEEL_FRAMES[side]), n, cols)))
    for side in (0, 1):
        streams.append((TRUE_ROAD[side], stamps, points_rows(
            stamps, x, half if side == 0 else -half, road[:, side], ROAD_FRAME, stamp_cols)))
    return streams


def fix_stream(fixes, start_stamp_ns: int):
    """The /fix stream: NavSatFix, frame ``gnss``, status 0 (FIX)."""
    fs, lat, lon, alt = _fix_arrays(fixes, start_stamp_ns)
    cols = stamp_columns(fs)
    cols.update({'latitude': lat, 'longitude': lon, 'altitude': alt})
    return FIX, fs, ColumnRows(NAVSATFIX, message_template(NAVSATFIX, 'gnss'), fs.size, cols)

def _union_truth(parts: dict[str, tuple[np.ndarray, np.ndarray]]) -> GroundTruth | None:
    if not parts:
        return None
    first = next(iter(parts.values()))[0]
    if all(s is first or np.array_equal(s, first) for s, _ in parts.values()):
        stamps = first          # every topic at every stamp (a simulated drive)
    else:
        stamps = np.sort(np.concatenate([s for s, _ in parts.values()]))
        stamps = stamps[np.concatenate([[True], stamps[1:] != stamps[:-1]])]
    m = stamps.size

    def place(key: str) -> np.ndarray:
        if key not in parts:
            return np.full(m, np.nan)
        s, v = parts[key]
        if s is stamps or s.size == m:          # every stamp (parts' stamps are unique)
            return np.array(v, dtype=float)
        out = np.full(m, np.nan)
        out[np.searchsorted(stamps, s)] = v
        return out
    load = np.column_stack([place('load_l'), place('load_r')])
    road = np.column_stack([place('road_l'), place('road_r')])
    dist = place('x_l')
    dist = np.where(np.isnan(dist), place('x_r'), dist)
    return GroundTruth(stamps, load, road, dist)


_STAMP = ('header.stamp.sec', 'header.stamp.nanosec')
#: The number fields read_drive_bag uses (and checks) of each topic.
_DRIVE_FIELDS = {
    DEFLECTIONS: _STAMP + ('position', 'velocity', 'effort'),
    TWIST: _STAMP + ('twist.linear.x',),
    FIX: _STAMP + ('latitude', 'longitude', 'altitude', 'status.status'),
    **{t: _STAMP + ('wrench.force.z',) for t in TRUE_LOAD},
    **{t: _STAMP + ('point.x', 'point.y', 'point.z') for t in TRUE_ROAD},
}


def read_drive_bag(path: str | Path) -> Drive:
    """Read a drive: measurements, speed, ground truth and fixes, rejecting what is bad.

    JointStates are mapped by name (a missing name or an array of another length than
    ``name`` rejects the message); non-finite values, undecodable messages and invalid
    stamps are rejected; per topic, in file order, a stamp equal to the latest accepted one
    (duplicate) or before it (backwards) is dropped. Every rejection is counted by topic and
    reason in :attr:`Drive.rejected`. A truncated or corrupt file is read up to the break,
    which is described in :attr:`Drive.issues`.

    Raises
    ------
    BagReadError
        Not a bag, or no ``/suspension/deflections`` topic.
    """
    path = Path(path)
    issues: list[str] = []
    wanted = {DEFLECTIONS: JOINT_STATE, TWIST: TWIST_STAMPED, FIX: NAVSATFIX}
    wanted.update({t: WRENCH for t in TRUE_LOAD})
    wanted.update({t: POINT for t in TRUE_ROAD})
    cols = read_topic_columns(path, wanted, issues=issues, fields=_DRIVE_FIELDS)
    if DEFLECTIONS not in cols:
        raise BagReadError(f'{path}: no {DEFLECTIONS} topic'
                           + (f' ({issues[0]})' if issues else ''))
    rejects = Rejects()
    custom = bag_custom_data(path)
    groups = cols[DEFLECTIONS].groups
    joints, note = front_axle_joints(custom, groups[0].layout.strings.get('name')
                                     if groups else None)
    stamps, pos = read_joint_state(cols[DEFLECTIONS], joints, rejects)
    if TWIST in cols:
        twist_ns, twist_v = read_scalar(cols[TWIST], 'twist.linear.x', rejects)
    else:
        twist_ns, twist_v = np.zeros(0, np.int64), np.zeros(0)
    if np.array_equal(twist_ns, stamps):        # a twist with every sample
        speed = twist_v.copy()
    else:
        held = np.searchsorted(twist_ns, stamps, side='right') - 1
        speed = np.where(held >= 0, twist_v[np.clip(held, 0, None)] if twist_v.size
                         else np.nan, np.nan)
    parts = {}
    for side, key in ((0, 'l'), (1, 'r')):
        if TRUE_LOAD[side] in cols:
            parts['load_' + key] = read_scalar(cols[TRUE_LOAD[side]], 'wrench.force.z',
                                                rejects)
        if TRUE_ROAD[side] in cols:
            s, x, _, z = read_points(cols[TRUE_ROAD[side]], rejects)
            parts['road_' + key] = (s, z)
            parts['x_' + key] = (s, x)
    fixes, noted = read_fixes(cols[FIX], rejects) if FIX in cols else (None, {})
    return Drive(
        stamps_ns=stamps, q_m=pos[:, :2].copy(), roll_rad=pos[:, 2].copy(), speed_mps=speed,
        twist_stamps_ns=twist_ns, twist_speed_mps=twist_v, truth=_union_truth(parts),
        fixes=fixes, messages={t: c.count for t, c in cols.items()}, rejected=rejects.counts,
        issues=tuple(issues), custom_data=custom, noted=noted, notes=(note,) if note else ())


#: NavSatStatus: no fix (rejected), and unknown (ROS 2 Jazzy: a fix of unknown quality, kept).
_STATUS_NO_FIX, _STATUS_UNKNOWN = -1, -2


def read_fixes(c, rejects: Rejects) -> tuple[Fixes, dict[str, dict[str, int]]]:
    """The accepted fixes and the caveats counted: a non-finite position and status -1
    (NO_FIX, or any other negative but -2) are rejected; status -2 (UNKNOWN) with a finite
    position is kept and counted as ``fix_status_unknown``."""
    s, ok = basic_checks(c, rejects)
    lat, _ = c.column('latitude')
    lon, _ = c.column('longitude')
    alt, _ = c.column('altitude')
    status, _ = c.column('status.status', dtype=np.int64)
    finite = np.isfinite(lat) & np.isfinite(lon)
    rejects.add(FIX, 'nonfinite', np.count_nonzero(ok & ~finite))
    unknown = status == _STATUS_UNKNOWN
    nofix = ok & finite & (status < 0) & ~unknown
    rejects.add(FIX, 'no_fix', np.count_nonzero(nofix))
    keep = accept_in_order(s, ok & finite & ~nofix, FIX, rejects)
    kept_unknown = int(np.count_nonzero(keep & unknown))
    noted = {FIX: {'fix_status_unknown': kept_unknown}} if kept_unknown else {}
    return Fixes(s[keep], lat[keep], lon[keep], alt[keep]), noted
