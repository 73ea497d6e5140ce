"""The estimator: from (q_1, q_2, phi) samples to wheel loads, road profile and LTR.

One sample in, one estimate out (:meth:`Estimator.update`), and a batch path
(:func:`estimate_batch`) that runs the very same step function and so gives identical numbers.
Two methods (``observer.discretization``):

- ``'model'`` (the default): the model-based sliding-mode observer of
  :mod:`.model_observer` (Kalman injection on the roll-plane model with the road as states,
  plus the Levant differentiator on the output error), its noise and road roughness estimated
  online. It leaves about 0.5 % of the dynamic-load RMS as error without noise and 17 % at
  10 um at zero latency (ISO C, 20 m/s, 1 kHz; ``bench/targets.py``), 3 % with 10 ms latency.
- ``'euler'`` (the paper's scheme), ``'taylor'``, ``'implicit'``: the differentiator chain
  below, with that scheme.

Latency (``observer.latency`` = T > 0): :meth:`Estimator.update` returns, per accepted input,
the estimate of the sample N = round(T / dt) samples back, stamped with that sample's stamp
(None for the first N inputs); :meth:`Estimator.flush` returns the rest at the end of the data,
so that every accepted input gets exactly one estimate, in order. The model method corrects
them with its exact fixed-lag smoother; the chain only delays. :func:`estimate_batch` returns
row k = the estimate of sample k whatever the latency (the flushed ones included).

The chain is MODEL.md "Reconstruction", steps 1-9 (index 1/2 there = 0/1 here = left/right):

0. Three Levant differentiators (:mod:`.differentiator`) give ``q_i, dq_i, ddq_i`` and
   ``phi, dphi, ddphi``; suspension forces ``F_bi = -(k_i q_i + c_i dq_i)``.
1. ``dd z_s = (F_b1 + F_b2) / M``.
2. ``dd z_u1 = dd z_s + s (cos(phi) ddphi - sin(phi) dphi^2) - ddq_1`` (``-s (...)`` right).
3. ``dF_i = m_i dd z_ui + F_bi``, ``F_n,i = F_c,i + dF_i``: no integration, drift-free. The
   loads are not clipped at 0, so that the total-load identity holds on the estimates
   (``F_n1 + F_n2 = F_c1 + F_c2 + M dd z_s + m_1 dd z_u1 + m_2 dd z_u2``).
4. Body heave: ``z_s = H(s) dd z_s / s^2``, a band-limited double integration
   (:mod:`.body_heave`). ``H = 1 - G`` is the high-pass complementary to ``G = (8 w^7 s +
   w^8) / (s + w)^8`` (eight real poles at ``w = 2 pi max(|v|, v_floor) / lambda_c``,
   ``lambda_c`` = ``observer.profile_cutoff_wavelength``, ``v_floor`` =
   :data:`SPEED_FLOOR_MPS`). ``H ~ 28 s^2 / w^2`` near 0, so a constant acceleration bias b
   leaves a bounded offset ``28 b / w^2`` instead of ``b t^2 / 2``; above ``w``, ``1 - H``
   falls as ``8 (w / Omega)^7``, so the 0.5-30 m band is kept in amplitude and phase. The
   second-order high-pass MODEL.md suggests leaves ``1 - H ~ 2 zeta w / Omega`` (a phase lead,
   first order in w): on ISO class C at 20 m/s with ``lambda_c`` = 100 m it costs 37 % of
   band-passed profile error (five poles: 4.2 %; eight: 3.3 % for this chain, 0.85 % for the
   model observer, ``bench.run_benchmark`` C20-1k-0um). The price: a gain of up to 2.5 around
   ``0.52 w`` (waves of ~1.9 ``lambda_c``), outside the band, and a -3 dB point near ``5.9
   lambda_c``. Implemented as eight cascaded Tustin lags ``1/(s + w)`` with outputs
   ``y_1..y_8``: ``z_s = sum_{k>=2} (k-1) w^(k-2) y_k``, ``dz_s = sum_{k<8} w^(k-1) y_k -
   7 w^7 y_8``, with the real dt.
5. ``z_u1 = z_s + s sin(phi) - q_1``, ``z_u2 = z_s - s sin(phi) - q_2`` (and their rates).
6. Road: ``kt_i (u_i - z_ui) + ct_i (du_i - dz_ui) = dF_i`` solved causally for ``u_i``: the
   tire deflection ``w_i = u_i - z_ui`` is ``dF_i / kt_i`` through the first-order lag
   ``ct_i / kt_i`` (exact exponential step, ``dF`` held over the step); ``ct_i = 0`` gives
   ``u_i = z_ui + dF_i / kt_i`` exactly. Like any inertial profilometer's, the profile is
   band-passed (judge it in the 0.5-30 m band, :mod:`.metrics`).
7. Distance ``x = integral of v dt`` (trapezoidal), continued across gaps.
8. ``LTR = (F_n2 - F_n1) / (F_n1 + F_n2)`` (right minus left) of the loads clipped at zero
   (a tire cannot pull), so ``|LTR| <= 1``; the denominator floored at 1 % of the static sum
   (:mod:`.load_transfer`).
9. Residual ``r = I_x ddphi - s cos(phi) (F_b1 - F_b2)`` (N m); it equals
   ``M h a_y cos(phi)`` under a lateral acceleration a_y; ``lift_off_i`` when ``F_n,i <=``
   :data:`LIFT_OFF_FRACTION` ``F_c,i``.

Every output refers to the stamp of the newest accepted sample (with the explicit schemes
``euler``/``taylor`` the differentiator outputs are one-step predictions that do not use that
sample's value yet; see :mod:`.differentiator`).

Robustness (counted in :class:`EstimatorStatus`; nothing non-finite ever leaves):

- the first sample initialises (differentiators at ``(f, 0, 0)``, body heave at rest at 0);
- a sample with a non-finite or malformed value or stamp (integer nanoseconds) is rejected
  (``rejected_nonfinite``), one with an impossible value (``|q| > 1 m``, ``|phi| > pi/2``,
  ``|v| > 100 m/s``) too (``rejected_range``); the last estimate is held
  (:attr:`Estimator.last`);
- a duplicate or backwards stamp is rejected (``rejected_time``);
- steps use the real dt; a step longer than ``max(gap_threshold_s, 10 typical periods)`` (the
  typical period is a running average of the accepted steps; ``gap_threshold_s`` defaults to
  :data:`GAP_THRESHOLD_S` = 0.1 s, i.e. 100 samples at 1 kHz; streams slower than ~20 Hz need
  a larger one) is a gap: the chain restarts at that sample (``resets``, ``gaps``) and
  reconverges; a non-finite intermediate (never seen, guarded anyway) also restarts it
  (``resets``, ``numerical_resets``);
- ``converged`` turns true once the time since the last (re)start reaches
  ``settling_time_s`` (see :func:`settling_time_s`); it is about the loads and LTR: the
  profile's body-heave high-pass needs a few ``lambda_c / v`` more.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field
import itertools
import math
from typing import Callable, NamedTuple

import numpy as np

from collections import deque

from road_force_estimator.estimation import body_heave
from road_force_estimator.estimation.body_heave import SPEED_FLOOR_MPS
from road_force_estimator.estimation.differentiator import step_function
from road_force_estimator.estimation.load_transfer import load_transfer_ratio
from road_force_estimator.estimation.model_observer import ModelCore
from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters

__all__ = [
    'Estimate', 'EstimateArrays', 'EstimatorStatus', 'Estimator', 'estimate_batch',
    'settling_time_s', 'GAP_THRESHOLD_S', 'SPEED_FLOOR_MPS', 'LIFT_OFF_FRACTION',
    'PAIR_FIELDS', 'SCALAR_FIELDS', 'batch_inputs', 'arrays_from_table',
]

#: Shortest step that counts as a gap (s); the threshold is max(this, 10 typical periods).
GAP_THRESHOLD_S = 0.1
#: Gap threshold in typical sample periods.
GAP_PERIODS = 10.0
#: Lift-off flag when the estimated load is at most this fraction of the static load.
LIFT_OFF_FRACTION = 0.05
#: Order n of the body-heave filter (n real poles at w_c; see the module notes).
BODY_FILTER_ORDER = body_heave.ORDER
#: Physical limits beyond which a sample is refused (m, rad, m/s).
MAX_DEFLECTION_M = 1.0
MAX_ROLL_RAD = 0.5 * math.pi
MAX_SPEED_MPS = 100.0


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
    wheel_load_n: tuple[float, float]           #: F_n,i = F_c,i + dF_i (N)
    ltr: float                                  #: (F_n2 - F_n1) / (F_n1 + F_n2)
    residual_nm: float                          #: I_x ddphi - s cos(phi)(F_b1 - F_b2) (N m)
    lift_off: tuple[bool, bool]                 #: F_n,i <= LIFT_OFF_FRACTION F_c,i
    converged: bool                             #: time since (re)start >= settling time


#: Fields of :class:`Estimate` that are (left, right) pairs / scalars (after stamp_ns).
PAIR_FIELDS = ('q_m', 'dq', 'ddq', 'wheel_heave_m', 'wheel_heave_rate', 'wheel_accel_mps2',
               'road_m', 'tire_force_dynamic_n', 'wheel_load_n', 'lift_off')
SCALAR_FIELDS = ('distance_m', 'roll_rad', 'droll', 'ddroll', 'body_heave_m', 'body_heave_rate',
                 'body_accel_mps2', 'ltr', 'residual_nm', 'converged')

# Layout of the flat tuple the step returns (the one both paths share).
_FLAT = ('distance_m', 'q_m', 'q_m', 'dq', 'dq', 'ddq', 'ddq', 'roll_rad', 'droll', 'ddroll',
         'body_heave_m', 'body_heave_rate', 'body_accel_mps2', 'wheel_heave_m', 'wheel_heave_m',
         'wheel_heave_rate', 'wheel_heave_rate', 'wheel_accel_mps2', 'wheel_accel_mps2',
         'road_m', 'road_m', 'tire_force_dynamic_n', 'tire_force_dynamic_n', 'wheel_load_n',
         'wheel_load_n', 'ltr', 'residual_nm', 'lift_off', 'lift_off', 'converged')
_N_FLAT = len(_FLAT)
#: Column indices of each field in a flat row.
_FLAT_COLUMNS: dict[str, list[int]] = {}
for _i, _name in enumerate(_FLAT):
    _FLAT_COLUMNS.setdefault(_name, []).append(_i)


@dataclass
class EstimatorStatus:
    """Counters and flags of an :class:`Estimator` (inspect after any update)."""

    accepted: int = 0               #: samples used (including the (re)starts)
    rejected_nonfinite: int = 0     #: NaN/inf or malformed value or stamp
    rejected_range: int = 0         #: physically impossible value
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
    method: str = 'model'           #: 'model' or 'chain'
    latency_samples: int = 0        #: lag N of the published estimates (samples)
    pending: int = 0                #: accepted samples whose estimate is not out yet
    noise_deflection_m: float = 0.0  #: deflection noise std in use (model; estimated or set)
    noise_roll_rad: float = 0.0     #: roll noise std in use (model)
    road_roughness_m3: float = 0.0  #: ISO 8608 Gd(n0) in use (model)
    statistics_blocks: int = 0      #: blocks of data the noise/roughness estimates have seen
    gain_designs: int = 0           #: gain designs (model; cache misses of the operating point)

    @property
    def rejected(self) -> int:
        """All rejected samples."""
        return self.rejected_nonfinite + self.rejected_range + self.rejected_time

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
    status: EstimatorStatus = field(default_factory=EstimatorStatus)

    def __len__(self) -> int:
        return len(self.stamp_ns)

    @property
    def t_s(self) -> np.ndarray:
        """Seconds since the first stamp."""
        if len(self.stamp_ns) == 0:
            return np.zeros(0)
        return (self.stamp_ns - self.stamp_ns[0]) * 1e-9


def settling_time_s(lipschitz_deflection: float, lipschitz_roll: float, dt_s: float) -> float:
    """Time after a (re)start after which the estimator reports ``converged`` (s).

    From the homogeneity of the differentiator, it absorbs an initial error ``e_2`` of the
    second derivative in a time proportional to ``e_2 / L`` (and ``e_1`` in ``(e_1/L)^(1/2)``).
    After a start at ``(f, 0, 0)`` the initial error is the signal's own ``f''``; we take the
    largest accelerations a rough road gives the front axle (:data:`_ACCEL_SCALE`: 100 m/s^2
    of deflection, 10 rad/s^2 of roll) and a factor 3, with a floor of 20 sample periods and
    of 50 ms. With the defaults (3000 m/s^3, 200 rad/s^3) that is 0.15 s; measured on ISO
    class C at 20 m/s from starts in mid-drive (``bench/observer_schemes.py``): t_0 <= 0.04 s.
    """
    t_q = 3.0 * _ACCEL_SCALE[0] / lipschitz_deflection
    t_phi = 3.0 * _ACCEL_SCALE[1] / lipschitz_roll
    return max(t_q, t_phi, 20.0 * dt_s, 0.05)


_ACCEL_SCALE = (100.0, 10.0)


class Estimator:
    """Per-sample estimator of wheel loads, road profile and LTR (MODEL.md steps 1-9).

    Parameters
    ----------
    vehicle : VehicleParameters
        The axle's parameters (masses, stiffnesses, track, static loads).
    observer : ObserverParameters
        The method (``discretization``: ``'model'`` or a chain scheme), the latency, the
        profile cutoff wavelength; for the chain L per channel (``lipschitz_deflection`` for
        both deflections, ``lipschitz_roll``); for the model the sliding-mode gain and the
        noise / roughness settings (0 = estimated online, see :mod:`.model_observer`).
    gap_threshold_s : float
        Shortest step that is a gap (s), default :data:`GAP_THRESHOLD_S`.

    Notes
    -----
    :meth:`update` returns a new immutable :class:`Estimate`, or None for a rejected sample
    or while nothing is due yet (latency). The chain runs scalar math on its state; the model
    observer one small matrix product per sample (plus one for the outputs with a latency).
    """

    def __init__(self, vehicle: VehicleParameters | None = None,
                 observer: ObserverParameters | None = None, *,
                 gap_threshold_s: float = GAP_THRESHOLD_S) -> None:
        vehicle = VehicleParameters() if vehicle is None else vehicle
        observer = ObserverParameters() if observer is None else observer
        if not (isinstance(gap_threshold_s, (int, float)) and gap_threshold_s > 0.0
                and math.isfinite(gap_threshold_s)):
            raise ValueError(f'gap_threshold_s = {gap_threshold_s!r}: must be finite and > 0 s')
        self.vehicle = vehicle
        self.observer = observer
        self.gap_threshold_s = float(gap_threshold_s)
        # The chain's differentiator scheme; the model observer's own runs 'implicit'.
        self._step = step_function('implicit' if observer.discretization == 'model'
                                   else observer.discretization)
        lq, lr = observer.lipschitz_deflection_mps3, observer.lipschitz_roll_radps3
        self._lip = (lq, lq ** (1.0 / 3.0), math.sqrt(lq), lr, lr ** (1.0 / 3.0), math.sqrt(lr))
        v = vehicle
        fc1, fc2 = v.static_load_n
        # Constants of the chain, unpacked once per step.
        self._p = (v.suspension_stiffness_npm + v.suspension_damping_nspm
                   + v.unsprung_mass_kg + (v.half_track_m, 1.0 / v.sprung_mass_kg,
                                           v.roll_inertia_kgm2, fc1, fc2)
                   + v.tire_stiffness_npm + v.tire_damping_nspm
                   + (LIFT_OFF_FRACTION * fc1, LIFT_OFF_FRACTION * fc2, 0.01 * (fc1 + fc2),
                      body_heave.cutoff_per_speed(observer.profile_cutoff_wavelength_m)))
        self._settle = settling_time_s(lq, lr, 0.0)
        self._ready: deque = deque()
        self._model: ModelCore | None = None
        if observer.discretization == 'model':
            self._model = ModelCore(vehicle, observer)
            self._ready = self._model.ready
            self._accept = self._advance_model     # no dispatch per sample
        self._status = EstimatorStatus()
        self.reset()

    # -- state ----------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget everything (counters included); the next sample initialises."""
        self._status = EstimatorStatus()
        self.last: Estimate | None = None
        self._started = False
        self._accepted = 0
        self._stamp = 0
        self._x = 0.0
        self._v = 0.0
        self._dt = 0.0
        self._t_run = 0.0
        self._dt_typ = 0.0
        self._conv = False
        # Differentiators: (z0, z1, z2, last sample) for q_1, q_2, phi.
        self._d = (0.0,) * 12
        # Body-heave filter: (dd z_s input, y_1 .. y_5, z_s, dz_s); tire deflections w_i.
        self._h = body_heave.start(0.0)
        self._w = (0.0, 0.0)
        self._decay = (-1.0, 0.0, 0.0)   # cached (dt, e_1, e_2) of the tire lag
        self._flat: tuple | None = None
        self._ready.clear()
        self._pending: deque = deque()   # chain with latency: estimates held back
        self._lag = 0
        self._lag_known = self.observer.latency_s == 0.0
        self._flushed = False
        if self._model is not None:
            self._model.reset()

    @property
    def status(self) -> EstimatorStatus:
        """Counters and flags, brought up to date when read."""
        st = self._status
        st.accepted = self._accepted
        st.time_since_start_s = self._t_run
        st.settling_time_s = self.settling_time_s
        st.converged = self._conv
        st.last_stamp_ns = self._stamp if self._started else None
        st.last_dt_s = self._dt
        st.typical_dt_s = self._dt_typ
        core = self._model
        if core is not None:
            self._flat = core.last_flat
        if self._flat is not None:
            st.last_residual_nm = self._flat[26]
            st.lift_off = (self._flat[27], self._flat[28])
        if core is None:
            st.method = 'chain'
            st.latency_samples = self._lag
            st.pending = len(self._pending) + len(self._ready)
        else:
            st.method = 'model'
            st.latency_samples = core.lag
            st.pending = len(core._pending) + len(self._ready)
            st.noise_deflection_m = core.noise_deflection_m
            st.noise_roll_rad = core.noise_roll_rad
            st.road_roughness_m3 = core.road_gd_m3
            st.statistics_blocks = core.blocks
            st.gain_designs = core.design_count
        return st

    @property
    def settling_time_s(self) -> float:
        """Current settling time (s), see :func:`settling_time_s` (model:
        :meth:`.ModelCore.settling_time_s`)."""
        if self._model is not None:
            return self._model.settling_time_s(self._dt_typ)
        return max(self._settle, 20.0 * self._dt_typ)

    def update(self, stamp_ns: int, q_m, roll_rad: float, speed_mps: float) -> Estimate | None:
        """Take one sample; return the estimate due now, or None.

        With no latency the estimate is that of this sample (at ``stamp_ns``); with
        ``observer.latency`` > 0 that of the sample N steps back, with its stamp (None while
        fewer than N samples have come). None also for a rejected sample (counted in
        :attr:`status`).

        Parameters
        ----------
        stamp_ns : int
            Measurement stamp (ns), strictly increasing.
        q_m : sequence of 2 floats
            Suspension extensions ``[q_1 (left), q_2 (right)]`` (m).
        roll_rad : float
            Roll angle (rad), > 0 when the left side goes up.
        speed_mps : float
            Vehicle speed (m/s).
        """
        try:
            q1, q2 = q_m
        except (TypeError, ValueError):
            self._status.rejected_nonfinite += 1   # malformed: not a pair
            return None
        if not self._process(stamp_ns, q1, q2, roll_rad, speed_mps) or not self._ready:
            return None
        stamp, flat = self._ready.popleft()
        est = _estimate(stamp, flat)
        self.last = est
        return est

    def flush(self) -> list[Estimate]:
        """The estimates still held back (``observer.latency`` > 0), at the end of the data.

        Each is the best estimate of its sample from the data received (the fixed-lag
        correction over the samples that did arrive). After a flush the next sample starts a
        new run (counted in ``resets``), as after a gap. With no latency: an empty list.
        """
        self._finish()
        out = [_estimate(stamp, flat) for stamp, flat in self._ready]
        self._ready.clear()
        if out:
            self.last = out[-1]
        return out

    def _finish(self) -> None:
        """Finalize every held-back estimate into the ready queue; end the run."""
        if self._model is not None:
            if self._model._running:
                self._model.finish()
                self._flushed = True
        else:
            self._ready.extend(self._pending)
            self._pending.clear()

    # -- the step shared by both paths -----------------------------------------------------
    def _process(self, stamp_ns, q1, q2, phi, v) -> bool:
        """Validate one sample and advance; False if it was rejected.

        Estimates that became final (with a latency: of earlier samples) are appended to
        ``self._ready`` as ``(stamp_ns, flat)``.
        """
        try:
            stamp = int(stamp_ns)
            q1 = float(q1)
            q2 = float(q2)
            phi = float(phi)
            v = float(v)
        except (TypeError, ValueError, OverflowError):
            self._status.rejected_nonfinite += 1
            return False
        # One chain of comparisons passes every good sample (NaN compares false).
        if not (-MAX_DEFLECTION_M <= q1 <= MAX_DEFLECTION_M
                and -MAX_DEFLECTION_M <= q2 <= MAX_DEFLECTION_M
                and -MAX_ROLL_RAD <= phi <= MAX_ROLL_RAD and -MAX_SPEED_MPS <= v <= MAX_SPEED_MPS):
            if (math.isfinite(q1) and math.isfinite(q2) and math.isfinite(phi)
                    and math.isfinite(v)):
                self._status.rejected_range += 1
            else:
                self._status.rejected_nonfinite += 1
            return False
        if not self._started:
            return self._accept(stamp, q1, q2, phi, v, 0.0, True)
        dt_ns = stamp - self._stamp
        if dt_ns <= 0:
            self._status.rejected_time += 1
            return False
        dt = dt_ns * 1e-9
        if dt > self.gap_threshold_s and dt > GAP_PERIODS * self._dt_typ:
            self._status.gaps += 1
            self._status.resets += 1
            return self._accept(stamp, q1, q2, phi, v, dt, True)
        if self._flushed:
            self._flushed = False
            self._status.resets += 1
            return self._accept(stamp, q1, q2, phi, v, dt, True)
        if not self._accept(stamp, q1, q2, phi, v, dt, False):
            self._status.numerical_resets += 1
            self._status.resets += 1
            return self._accept(stamp, q1, q2, phi, v, dt, True)
        return True

    def _accept(self, stamp: int, q1: float, q2: float, phi: float, v: float, dt: float,
                restart: bool) -> bool:
        """Advance the method's core; False (state untouched) on a non-finite result."""
        if self._model is not None:
            return self._advance_model(stamp, q1, q2, phi, v, dt, restart)
        flat = self._advance(stamp, q1, q2, phi, v, dt, restart)
        if flat is None:
            return False
        pending = self._pending
        if restart:
            self._ready.extend(pending)
            pending.clear()
            self._lag_known = self.observer.latency_s == 0.0
            self._lag = 0
        elif not self._lag_known:
            self._lag = int(round(self.observer.latency_s / dt))
            self._lag_known = True
        pending.append((stamp, flat))
        if self._lag_known:
            lag = self._lag
            while len(pending) > lag:
                self._ready.append(pending.popleft())
        return True

    def _advance_model(self, stamp: int, q1: float, q2: float, phi: float, v: float, dt: float,
                       restart: bool) -> bool:
        """One step of the model observer (:class:`.ModelCore`), or a (re)start."""
        core = self._model
        x = self._x + 0.5 * (self._v + v) * dt if self._started else 0.0
        if restart:
            t_run = 0.0
            dt_typ = 0.0
            conv = False
            core.restart(stamp, q1, q2, phi, (x, dt, v, False))
        else:
            t_run = self._t_run + dt
            dt_typ = self._dt_typ
            dt_typ = dt if dt_typ == 0.0 else dt_typ + 0.05 * (dt - dt_typ)
            conv = core.converged()
            if not core.step(stamp, dt, q1, q2, phi, v, (x, dt, v, conv)):
                return False
        self._started = True
        self._stamp = stamp
        self._x = x
        self._v = v
        self._dt = dt
        self._t_run = t_run
        self._dt_typ = dt_typ
        self._conv = conv
        self._accepted += 1
        return True

    def _advance(self, stamp: int, q1: float, q2: float, phi: float, v: float, dt: float,
                 restart: bool) -> tuple | None:
        """One step of the whole chain (or a (re)start); the flat output tuple.

        Returns None, with the state untouched, if an output came out non-finite. A restart
        sets the differentiators to ``(f, 0, 0)``, the body heave to rest at 0 and the tire
        deflections to their steady state; its ``dt`` > 0 continues the distance over a gap.
        """
        (k1, k2, c1, c2, m1, m2, s, inv_mass, ix, fc1, fc2, kt1, kt2, ct1, ct2, lift1, lift2,
         ltr_floor, wc_per_speed) = self._p
        x = self._x + 0.5 * (self._v + v) * dt if self._started else 0.0
        if restart:
            a0, a1, a2, b0, b1, b2, c0, c1_, c2_ = q1, 0.0, 0.0, q2, 0.0, 0.0, phi, 0.0, 0.0
            t_run = 0.0
            dt_typ = 0.0
            conv = False
        else:
            step = self._step
            lq, lq13, lq12, lr, lr13, lr12 = self._lip
            d = self._d
            a0, a1, a2 = step(d[0], d[1], d[2], d[3], q1, dt, lq, lq13, lq12)
            b0, b1, b2 = step(d[4], d[5], d[6], d[7], q2, dt, lq, lq13, lq12)
            c0, c1_, c2_ = step(d[8], d[9], d[10], d[11], phi, dt, lr, lr13, lr12)
            t_run = self._t_run + dt
            dt_typ = self._dt_typ
            dt_typ = dt if dt_typ == 0.0 else dt_typ + 0.05 * (dt - dt_typ)
            conv = t_run >= self._settle and t_run >= 20.0 * dt_typ
        # Steps 1-3: suspension forces, accelerations, tire forces, loads.
        fb1 = -(k1 * a0 + c1 * a1)
        fb2 = -(k2 * b0 + c2 * b1)
        ddzs = (fb1 + fb2) * inv_mass
        cphi = math.cos(c0)
        sphi = math.sin(c0)
        rot = s * (cphi * c2_ - sphi * c1_ * c1_)
        ddzu1 = ddzs + rot - a2
        ddzu2 = ddzs - rot - b2
        df1 = m1 * ddzu1 + fb1
        df2 = m2 * ddzu2 + fb2
        fn1 = fc1 + df1
        fn2 = fc2 + df2
        ltr = load_transfer_ratio(fn1, fn2, ltr_floor)
        res = ix * c2_ - s * cphi * (fb1 - fb2)
        # Step 4: body heave, band-limited double integration (body_heave.py).
        h = body_heave.start(ddzs) if restart else body_heave.step(self._h, ddzs, dt, v,
                                                                    wc_per_speed)
        zs = h[-2]
        dzs = h[-1]
        # Step 5: wheel heaves and rates.
        ssin = s * sphi
        srate = s * cphi * c1_
        zu1 = zs + ssin - a0
        zu2 = zs - ssin - b0
        # Step 6: tire deflection w_i = u_i - z_ui from ct dw + kt w = dF (exact, dF held).
        if restart or (ct1 == 0.0 and ct2 == 0.0):
            w1 = df1 / kt1
            w2 = df2 / kt2
        else:
            cache = self._decay
            if cache[0] != dt:
                cache = (dt, math.exp(-dt * kt1 / ct1) if ct1 > 0.0 else 0.0,
                         math.exp(-dt * kt2 / ct2) if ct2 > 0.0 else 0.0)
                self._decay = cache
            e1 = cache[1]
            e2 = cache[2]
            w1 = e1 * self._w[0] + (1.0 - e1) * df1 / kt1
            w2 = e2 * self._w[1] + (1.0 - e2) * df2 / kt2
        flat = (x, a0, b0, a1, b1, a2, b2, c0, c1_, c2_, zs, dzs, ddzs, zu1, zu2,
                dzs + srate - a1, dzs - srate - b1, ddzu1, ddzu2, zu1 + w1, zu2 + w2, df1, df2,
                fn1, fn2, ltr, res, fn1 <= lift1, fn2 <= lift2, conv)
        # Every output depends on one of these; nothing non-finite leaves.
        if not math.isfinite(x + fn1 + fn2 + ltr + res + zs + dzs + w1 + w2 + srate):
            return None
        self._d = (a0, a1, a2, q1, b0, b1, b2, q2, c0, c1_, c2_, phi)
        self._h = h
        self._w = (w1, w2)
        self._started = True
        self._stamp = stamp
        self._x = x
        self._v = v
        self._dt = dt
        self._t_run = t_run
        self._dt_typ = dt_typ
        self._conv = conv
        self._flat = flat
        self._accepted += 1
        return flat


def _estimate(stamp: int, flat: tuple) -> Estimate:
    """An :class:`Estimate` from the flat output tuple."""
    (x, q1, q2, dq1, dq2, ddq1, ddq2, phi, dphi, ddphi, zs, dzs, ddzs, zu1, zu2, dzu1, dzu2,
     ddzu1, ddzu2, u1, u2, df1, df2, fn1, fn2, ltr, res, lo1, lo2, conv) = flat
    # tuple.__new__ directly: the namedtuple's generated __new__ is one Python frame more
    return _new_tuple(Estimate, (stamp, x, (q1, q2), (dq1, dq2), (ddq1, ddq2), phi, dphi, ddphi,
                                 zs, dzs, ddzs, (zu1, zu2), (dzu1, dzu2), (ddzu1, ddzu2),
                                 (u1, u2), (df1, df2), (fn1, fn2), ltr, res, (lo1, lo2), conv))


_new_tuple = tuple.__new__


#: Samples between two calls of the ``progress`` callback of :func:`estimate_batch`.
PROGRESS_BLOCK = 10_000


def estimate_batch(stamps_ns, q_m, roll_rad, speed_mps, vehicle: VehicleParameters | None = None,
                   observer: ObserverParameters | None = None, *,
                   gap_threshold_s: float = GAP_THRESHOLD_S,
                   progress: Callable[[int], object] | None = None) -> EstimateArrays:
    """Run the estimator over whole arrays; identical numbers to :meth:`Estimator.update`.

    Parameters
    ----------
    stamps_ns : array_like of int, shape (n,)
        Stamps (ns); disorder, duplicates and gaps are handled as in the per-sample path.
    q_m : array_like, shape (n, 2)
        Suspension extensions [left, right] (m).
    roll_rad : array_like, shape (n,)
        Roll angle (rad).
    speed_mps : array_like, shape (n,) or scalar
        Speed (m/s).
    vehicle, observer : parameters (defaults when None).
    progress : callable, optional
        Called with the number of samples done after every :data:`PROGRESS_BLOCK` of them
        (e.g. a progress bar's ``update``).

    Returns
    -------
    EstimateArrays
        Row k is the estimate *for* sample k, whatever the latency: the per-sample path's
        outputs of :meth:`Estimator.update` followed by :meth:`Estimator.flush`, in order, are
        the rows where ``valid``. Every field per sample, the ``valid`` mask and the final
        status counters.
    """
    stamps, q, phi, speed = batch_inputs(stamps_ns, q_m, roll_rad, speed_mps)
    n = stamps.shape[0]
    est = Estimator(vehicle, observer, gap_threshold_s=gap_threshold_s)
    process = est._process
    ready = est._ready
    flats = []
    take = flats.append
    valid_list = []
    flag = valid_list.append
    stamp_list = stamps.tolist()
    columns = (stamp_list, q.tolist(), phi.tolist(), speed.tolist())
    block = PROGRESS_BLOCK if progress is not None else max(n, 1)
    for start in range(0, n, block):
        for t, (a, b), p, v in zip(*(c[start:start + block] for c in columns)):
            flag(process(t, a, b, p, v))
            while ready:
                take(ready.popleft()[1])
        if progress is not None:
            progress(min(block, n - start))
    est._finish()
    while ready:
        take(ready.popleft()[1])
    valid = np.array(valid_list, dtype=bool)
    if len(flats) != int(valid.sum()):   # never: one estimate per accepted sample
        raise RuntimeError(f'{len(flats)} estimates for {int(valid.sum())} accepted samples')
    table = np.zeros((n, _N_FLAT))
    if flats:
        table[valid] = np.fromiter(itertools.chain.from_iterable(flats), dtype=float,
                                   count=len(flats) * _N_FLAT).reshape(len(flats), _N_FLAT)
        # rejected rows hold the previous row (zeros before the first accepted sample)
        idx = np.where(valid, np.arange(n), -1)
        np.maximum.accumulate(idx, out=idx)
        held = idx >= 0
        table[held] = table[idx[held]]
    if np.issubdtype(stamps.dtype, np.integer):
        stamp_out = stamps.astype(np.int64)
    else:
        stamp_out = np.array([int(t) if _is_int(t) else 0 for t in stamp_list], dtype=np.int64)
    return arrays_from_table(table, stamp_out, valid, est.status)


def batch_inputs(stamps_ns, q_m, roll_rad, speed_mps):
    """The inputs of a batch path as arrays: stamps (n,), q (n, 2), phi (n,), speed (n,).

    Raises
    ------
    ValueError
        Shapes that do not fit; the message gives them.
    """
    stamps = np.asarray(stamps_ns)
    q = np.asarray(q_m, dtype=float)
    phi = np.asarray(roll_rad, dtype=float)
    n = stamps.shape[0] if stamps.ndim == 1 else -1
    if stamps.ndim != 1 or q.shape != (n, 2) or phi.shape != (n,):
        raise ValueError(f'stamps_ns {stamps.shape}, q_m {q.shape}, roll_rad {phi.shape}: '
                         'expected (n,), (n, 2), (n,)')
    return stamps, q, phi, np.broadcast_to(np.asarray(speed_mps, dtype=float), (n,))


def arrays_from_table(table: np.ndarray, stamp_ns: np.ndarray, valid: np.ndarray,
                      status: EstimatorStatus) -> EstimateArrays:
    """:class:`EstimateArrays` from rows of flat estimates (columns :data:`_FLAT`)."""
    out = {}
    for name, idx in _FLAT_COLUMNS.items():
        arr = table[:, idx[0]] if len(idx) == 1 else table[:, idx]
        if name in ('lift_off', 'converged'):
            arr = arr != 0.0
        out[name] = np.ascontiguousarray(arr)
    return EstimateArrays(stamp_ns=stamp_ns, valid=valid, status=status, **out)


def _is_int(t) -> bool:
    try:
        int(t)
    except (TypeError, ValueError, OverflowError):
        return False
    return True
