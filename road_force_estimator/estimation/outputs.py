"""What the estimators return: named output slots, one estimate, arrays of them, the status.

Every estimator (the per-sample :class:`.Estimator`, :func:`.estimate_batch`, the offline
smoothers) produces rows of :data:`N_COLUMNS` floats whose slots are named by :class:`Column`
(a pair ``(left, right)`` takes two slots); :func:`estimate_from_row` makes an
:class:`Estimate` of a row, :func:`arrays_from_table` an :class:`EstimateArrays` of a table
of rows, :func:`field_columns` the arrays of a table written slot by slot. Units SI; signs
and symbols as MODEL.md (index 1/2 there = left/right).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field
import enum
from typing import Any, NamedTuple

import numpy as np

__all__ = [
    'Column', 'N_COLUMNS', 'FIELD_COLUMNS', 'PAIR_FIELDS', 'SCALAR_FIELDS', 'FLAG_FIELDS',
    'Estimate', 'EstimatorStatus', 'EstimateArrays', 'estimate_from_row', 'field_columns',
    'arrays_from_table', 'hold_rejected',
]


class Column(enum.IntEnum):
    """Slots of an output row (the same in every estimator)."""

    DISTANCE = 0      #: travelled distance x (m)
    Q1 = 1            #: suspension extension q_1 (m)
    Q2 = 2
    DQ1 = 3           #: its rate (m/s)
    DQ2 = 4
    DDQ1 = 5          #: its acceleration (m/s^2)
    DDQ2 = 6
    PHI = 7           #: roll phi (rad), > 0 left side up
    DPHI = 8          #: (rad/s)
    DDPHI = 9         #: (rad/s^2)
    ZS = 10           #: body heave z_s, band-limited (m)
    DZS = 11          #: its rate (m/s)
    DDZS = 12         #: body acceleration dd z_s (m/s^2)
    ZU1 = 13          #: wheel heave z_u1, band-limited (m)
    ZU2 = 14
    DZU1 = 15         #: its rate (m/s)
    DZU2 = 16
    DDZU1 = 17        #: wheel acceleration (m/s^2)
    DDZU2 = 18
    U1 = 19           #: road u_1, band-limited (m)
    U2 = 20
    DF1 = 21          #: dynamic tire force dF_1 (N), upward on the wheel
    DF2 = 22
    FN1 = 23          #: wheel load F_n,1 = F_c,1 + dF_1 (N)
    FN2 = 24
    LTR = 25          #: (F_n2 - F_n1) / (F_n1 + F_n2)
    RESIDUAL = 26     #: I_x ddphi - s cos(phi) (F_b1 - F_b2) - M g h sin(phi) (N m)
    LIFT_OFF1 = 27    #: lift-off flag of the left wheel
    LIFT_OFF2 = 28
    CONVERGED = 29    #: time since (re)start >= settling time
    LTR_QUASI_STATIC = 30   #: the LTR of the loads low-passed below the wheel hop (MODEL.md 8)
    STATIC_LOAD1 = 31  #: static wheel load F_c,1 in use (N): configured, or estimated (zero_load)
    STATIC_LOAD2 = 32


N_COLUMNS = len(Column)

#: Slots of each field of :class:`Estimate` / :class:`EstimateArrays` (one, or (left, right)).
FIELD_COLUMNS: dict[str, tuple[Column, ...]] = {
    'distance_m': (Column.DISTANCE,),
    'q_m': (Column.Q1, Column.Q2),
    'dq': (Column.DQ1, Column.DQ2),
    'ddq': (Column.DDQ1, Column.DDQ2),
    'roll_rad': (Column.PHI,),
    'droll': (Column.DPHI,),
    'ddroll': (Column.DDPHI,),
    'body_heave_m': (Column.ZS,),
    'body_heave_rate': (Column.DZS,),
    'body_accel_mps2': (Column.DDZS,),
    'wheel_heave_m': (Column.ZU1, Column.ZU2),
    'wheel_heave_rate': (Column.DZU1, Column.DZU2),
    'wheel_accel_mps2': (Column.DDZU1, Column.DDZU2),
    'road_m': (Column.U1, Column.U2),
    'tire_force_dynamic_n': (Column.DF1, Column.DF2),
    'wheel_load_n': (Column.FN1, Column.FN2),
    'ltr': (Column.LTR,),
    'residual_nm': (Column.RESIDUAL,),
    'lift_off': (Column.LIFT_OFF1, Column.LIFT_OFF2),
    'converged': (Column.CONVERGED,),
    'ltr_quasi_static': (Column.LTR_QUASI_STATIC,),
    'static_load_n': (Column.STATIC_LOAD1, Column.STATIC_LOAD2),
}
#: Fields of :class:`Estimate` that are (left, right) pairs / scalars (after stamp_ns).
PAIR_FIELDS = ('q_m', 'dq', 'ddq', 'wheel_heave_m', 'wheel_heave_rate', 'wheel_accel_mps2',
               'road_m', 'tire_force_dynamic_n', 'wheel_load_n', 'lift_off', 'static_load_n')
SCALAR_FIELDS = ('distance_m', 'roll_rad', 'droll', 'ddroll', 'body_heave_m', 'body_heave_rate',
                 'body_accel_mps2', 'ltr', 'residual_nm', 'converged', 'ltr_quasi_static')
#: Boolean fields.
FLAG_FIELDS = ('lift_off', 'converged')


class Estimate(NamedTuple):
    """One estimate, at ``stamp_ns`` (SI; pairs are ``(left, right)``; signs as MODEL.md)."""

    stamp_ns: int
    distance_m: float                           #: travelled distance x (m)
    q_m: tuple[float, float]                    #: suspension extension q_i (m)
    dq: tuple[float, float]                     #: its rate (m/s)
    ddq: tuple[float, float]                    #: its acceleration (m/s^2)
    roll_rad: float                             #: phi (rad), > 0 left side up
    droll: float                                #: dphi (rad/s)
    ddroll: float                               #: ddphi (rad/s^2)
    body_heave_m: float                         #: z_s, band-limited (m)
    body_heave_rate: float                      #: dz_s, band-limited (m/s)
    body_accel_mps2: float                      #: dd z_s (m/s^2)
    wheel_heave_m: tuple[float, float]          #: z_ui, band-limited (m)
    wheel_heave_rate: tuple[float, float]       #: dz_ui (m/s)
    wheel_accel_mps2: tuple[float, float]       #: dd z_ui (m/s^2)
    road_m: tuple[float, float]                 #: u_i, band-limited profile (m)
    tire_force_dynamic_n: tuple[float, float]   #: dF_i (N), upward on the wheel
    wheel_load_n: tuple[float, float]           #: F_n,i = max(0, F_c,i + dF_i) (N)
    ltr: float                                  #: (F_n2 - F_n1) / (F_n1 + F_n2)
    residual_nm: float                          #: step 9 residual (N m)
    lift_off: tuple[bool, bool]                 #: F_n,i <= LIFT_OFF_FRACTION F_c,i
    converged: bool                             #: time since (re)start >= settling time
    ltr_quasi_static: float                     #: LTR of the low-passed loads (rollover)
    static_load_n: tuple[float, float]          #: F_c,i in use (N): configured or estimated


@dataclass
class EstimatorStatus:
    """Counters and flags of an :class:`.Estimator` (inspect after any update)."""

    accepted: int = 0               #: samples used (including the (re)starts)
    rejected_nonfinite: int = 0     #: NaN/inf or malformed value or stamp
    rejected_range: int = 0         #: physically impossible value
    rejected_speed: int = 0         #: speed negative or above MAX_SPEED_MPS
    rejected_stale: int = 0         #: values frozen (repeated exactly FROZEN_REPEATS times)
    rejected_time: int = 0          #: duplicate or backwards stamp
    resets: int = 0                 #: restarts after the first sample (gaps + numerical)
    gaps: int = 0                   #: steps longer than the gap threshold
    numerical_resets: int = 0       #: restarts after a non-finite intermediate
    converged: bool = False         #: time since the last (re)start >= settling_time_s
    time_since_start_s: float = 0.0
    settling_time_s: float = 0.0
    last_stamp_ns: int | None = None
    last_dt_s: float = 0.0
    typical_dt_s: float = 0.0       #: running average of the accepted steps (s)
    last_residual_nm: float = 0.0
    lift_off: tuple[bool, bool] = (False, False)
    negative_load_samples: int = 0  #: estimates with F_c,i + dF_i < 0 (published as 0 N)
    speed_contradicted: int = 0     #: samples whose standing speed the deflections contradict
    method: str = 'model'           #: 'model' or 'chain'
    latency_samples: int = 0        #: lag N of the published estimates (samples)
    pending: int = 0                #: accepted samples whose estimate is not out yet
    noise_deflection_m: float = 0.0  #: deflection noise std in use (model; estimated or set)
    noise_roll_rad: float = 0.0     #: roll noise std in use (model)
    road_roughness_m3: float = 0.0  #: ISO 8608 Gd(n0) in use (model)
    statistics_blocks: int = 0      #: blocks of data the noise/roughness estimates have seen
    gain_designs: int = 0           #: gain designs (model; cache misses of the operating point)
    static_load_n: tuple[float, float] = (0.0, 0.0)  #: F_c,i in use (N) (estimated: zero_load)
    sprung_mass_kg: float = 0.0     #: sprung mass M in use (kg) (estimated: zero_load)
    #: samples whose innovation the gate kept from the filter (``observer.innovation_gate``),
    #: per channel name (model method; a spike, not a rejected sample: the others were used)
    innovations_gated: dict = field(default_factory=dict)
    #: per channel name: 'ok', 'stuck' or 'drift' now (:mod:`.sensor_health`)
    sensor_faults: dict = field(default_factory=dict)
    #: per channel name: stuck / drift flags raised (episodes) and samples flagged
    stuck_episodes: dict = field(default_factory=dict)
    stuck_samples: dict = field(default_factory=dict)
    drift_episodes: dict = field(default_factory=dict)
    drift_samples: dict = field(default_factory=dict)
    #: per channel name: the stamp (ns) of its first flag of each kind
    fault_first_ns: dict = field(default_factory=dict)

    @property
    def rejected(self) -> int:
        """All rejected samples."""
        return (self.rejected_nonfinite + self.rejected_range + self.rejected_speed
                + self.rejected_stale + self.rejected_time)

    def as_dict(self) -> dict:
        return asdict(self)


@dataclass
class EstimateArrays:
    """Estimates of a batch, field by field (as :class:`Estimate`; pairs are (n, 2)).

    ``valid[k]`` is False where sample k was rejected; there every field holds the previous
    estimate (zeros before the first accepted sample) and ``stamp_ns`` is the input stamp.
    """

    stamp_ns: np.ndarray
    valid: np.ndarray
    distance_m: np.ndarray
    q_m: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    roll_rad: np.ndarray
    droll: np.ndarray
    ddroll: np.ndarray
    body_heave_m: np.ndarray
    body_heave_rate: np.ndarray
    body_accel_mps2: np.ndarray
    wheel_heave_m: np.ndarray
    wheel_heave_rate: np.ndarray
    wheel_accel_mps2: np.ndarray
    road_m: np.ndarray
    tire_force_dynamic_n: np.ndarray
    wheel_load_n: np.ndarray
    ltr: np.ndarray
    residual_nm: np.ndarray
    lift_off: np.ndarray
    converged: np.ndarray
    ltr_quasi_static: np.ndarray
    status: EstimatorStatus = field(default_factory=EstimatorStatus)
    #: (n,) bool: samples whose standing speed the deflections contradicted (:mod:`.speed_check`)
    speed_contradicted: np.ndarray | None = None
    #: (n, 2): the static wheel loads F_c,i in use (N); every estimator fills it (None: a
    #: hand-made batch without them)
    static_load_n: np.ndarray | None = None
    #: which distance ``distance_m`` is and why (an :class:`.odometer.DistanceSource`; None:
    #: not said)
    distance_source: Any = None
    #: the GNSS odometer fit (an :class:`.odometer.OdometerFit`) when one was made
    odometer: Any = None
    #: a GNSS fit was asked for or made (offline): the report gives ``odometer`` (None when
    #: the fixes were refused)
    fused: bool = False
    #: (n, channels) int8: each sample's sensor flags (:mod:`.sensor_health` CODES: 0 ok,
    #: 1 stuck, 2 drift; channels in the model's order), or None: not judged
    fault_flags: np.ndarray | None = None
    #: offline (the model's smoother), the tanh friction's ``v_f`` taken and the file's
    #: (:class:`.friction_fit.FrictionVelocity`); None: online, or no tanh friction stated
    friction_velocity: Any = None

    def __post_init__(self) -> None:
        if self.speed_contradicted is None:
            self.speed_contradicted = np.zeros(len(self.stamp_ns), bool)

    def __len__(self) -> int:
        return len(self.stamp_ns)

    @property
    def load_clipped(self) -> np.ndarray:
        """(n, 2) bool: the accepted samples whose load estimate ``F_c,i + dF_i`` went below
        zero (a lift-off; ``wheel_load_n`` holds 0 N there)."""
        return (self.wheel_load_n <= 0.0) & self.valid[:, None]

    def negative_load_samples(self) -> int:
        """Accepted samples with a load estimate below zero on either wheel."""
        return int(np.count_nonzero(self.load_clipped.any(axis=1)))

    @property
    def t_s(self) -> np.ndarray:
        """Seconds since the first stamp."""
        if len(self.stamp_ns) == 0:
            return np.zeros(0)
        return (self.stamp_ns - self.stamp_ns[0]) * 1e-9


def estimate_from_row(stamp: int, row: tuple) -> Estimate:
    """An :class:`Estimate` from an output row (slots :class:`Column`)."""
    (x, q1, q2, dq1, dq2, ddq1, ddq2, phi, dphi, ddphi, zs, dzs, ddzs, zu1, zu2, dzu1, dzu2,
     ddzu1, ddzu2, u1, u2, df1, df2, fn1, fn2, ltr, res, lo1, lo2, conv, ltr_qs, fc1, fc2) = row
    # tuple.__new__ directly: the namedtuple's generated __new__ is one Python frame more
    return _new_tuple(Estimate, (stamp, x, (q1, q2), (dq1, dq2), (ddq1, ddq2), phi, dphi, ddphi,
                                 zs, dzs, ddzs, (zu1, zu2), (dzu1, dzu2), (ddzu1, ddzu2),
                                 (u1, u2), (df1, df2), (fn1, fn2), ltr, res, (lo1, lo2), conv,
                                 ltr_qs, (fc1, fc2)))


_new_tuple = tuple.__new__


def field_columns(n: int) -> tuple[dict[str, np.ndarray], list[np.ndarray]]:
    """Zeroed arrays of the estimate fields for n rows, and the :data:`N_COLUMNS` slots as
    views into them (``columns[Column.Q2]`` is ``fields['q_m'][:, 1]``, a strided view)."""
    fields: dict[str, np.ndarray] = {}
    columns: list = [None] * N_COLUMNS
    for name, idx in FIELD_COLUMNS.items():
        dtype = bool if name in FLAG_FIELDS else float
        if len(idx) == 1:
            fields[name] = columns[idx[0]] = np.zeros(n, dtype)
        else:
            arr = fields[name] = np.zeros((n, len(idx)), dtype)
            for side, j in enumerate(idx):
                columns[j] = arr[:, side]
    return fields, columns


def arrays_from_table(table: np.ndarray, stamp_ns: np.ndarray, valid: np.ndarray,
                      status: EstimatorStatus,
                      speed_contradicted: np.ndarray | None = None) -> EstimateArrays:
    """:class:`EstimateArrays` from rows of output rows (table (n, :data:`N_COLUMNS`))."""
    out = {}
    for name, idx in FIELD_COLUMNS.items():
        arr = table[:, idx[0]] if len(idx) == 1 else table[:, list(idx)]
        if name in FLAG_FIELDS:
            arr = arr != 0.0
        out[name] = np.ascontiguousarray(arr)
    return EstimateArrays(stamp_ns=stamp_ns, valid=valid, status=status,
                          speed_contradicted=speed_contradicted, **out)


def hold_rejected(valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where rejected rows take their values from: ``(rows, sources)``, each row past the
    first accepted one taking the last accepted row at or before it (``rows`` include the
    accepted ones, their own source)."""
    idx = np.where(valid, np.arange(valid.size), -1)
    np.maximum.accumulate(idx, out=idx)
    held = np.flatnonzero(idx >= 0)
    return held, idx[held]
