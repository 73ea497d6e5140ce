"""Offline (non-causal) estimation: the whole recording at once, for the best accuracy.

The online estimator (:mod:`.estimator`) must answer at once; a recorded bag need not. This
mode keeps the reconstruction of MODEL.md (steps 1-9, the same equations as the estimator)
and replaces its two causal parts by zero-phase ones:

1. **Derivatives.** Each measured channel (q_1, q_2, phi) goes through a zero-phase
   Butterworth low-pass (order :data:`FILTER_ORDER`, run forward and backward with
   :func:`scipy.signal.sosfiltfilt`, so no lag at all); then ``dq`` is the central difference
   and ``ddq`` the three-point second difference of the smoothed signal.
2. **Cut-off per channel, from the data.** The sensor noise is estimated from the recording
   itself (the median absolute value of the fourth difference, which white noise dominates:
   ``sigma = MAD / 0.6745 / sqrt(70)``), the signal's spectrum by Welch's method (about 1 s
   segments). The cut-off is the lowest frequency at which the measured spectrum falls to
   :data:`NOISE_CROSSING` times the noise floor ``2 sigma^2 / fs``, i.e. where the signal's
   power equals the noise's: keeping a band where the signal is weaker than the noise adds more
   error (the same weight ``omega^4`` multiplies both in ``ddq``) than dropping it. Noise-free
   data get a cut-off near the Nyquist frequency (no smoothing to speak of); noisy data, a low
   one. The cut-off is clipped to [:data:`MIN_CUTOFF_HZ`, :data:`MAX_CUTOFF_FRACTION` x fs]
   (above that band no filter is applied); it can also be given explicitly.
3. **Body heave, band-limited without phase.** ``z_s`` is ``dd z_s`` through
   ``|H|^2 / s^2`` with ``H`` a Butterworth high-pass (order
   :data:`~.body_heave.ZERO_PHASE_ORDER`) at ``w_c = 2 pi v / lambda_c`` (``lambda_c`` =
   ``observer.profile_cutoff_wavelength``, ``v`` the run's median speed, floored at
   :data:`~.body_heave.SPEED_FLOOR_MPS`), run forward and backward
   (:func:`~.body_heave.zero_phase`): no phase error, and at 30 m wavelength with
   ``lambda_c`` = 100 m ``|H|^2`` = 0.99994. ``dz_s`` is its central difference.

Everything else is the estimator's chain, vectorised: suspension and tire forces, wheel
accelerations and the tire deflection with tire damping here, then the reconstruction of
:mod:`.reconstruction` (wheel heaves, road, distance, loads, LTR, residual, lift-off).

Robustness is the estimator's (:func:`.acceptance.accept_arrays`): the same rejections
(non-finite, impossible values, duplicate or backward stamps; counted in
:class:`~.outputs.EstimatorStatus`), the same gap rule (a step longer than
``max(gap_threshold_s, 10 typical steps)`` starts a new run; each run is estimated on its own
and ``resets`` / ``gaps`` count the restarts), distance continued across gaps.
Unevenly sampled runs are resampled on their median step, estimated, and interpolated back.
``converged`` is False within :func:`edge_time_s` of each run's start and end, where the
zero-phase filters lack data on one side.

``estimate_bag --mode offline`` runs this chain when ``observer.discretization`` is a chain
scheme (by default it runs the model observer's smoother, :func:`..offline.estimate_recording`,
whose accuracy ``python -m bench.accuracy.run_benchmark --docs docs/benchmark.md`` gives as
ours-offline). Two alternatives built on the package's differentiator were measured and
dropped: the average of a forward and a time-reversed pass of the Levant differentiators, and
that average low-passed with zero phase: a sliding-mode differentiator's error under noise is
not a lag that a backward pass cancels.

The default offline estimate is the model observer's smoother
(:mod:`road_force_estimator.estimation.smoothing`); this chain is the offline form of the
paper's differentiator schemes (:mod:`road_force_estimator.estimation.offline` dispatches).

This module imports numpy and scipy only (core).
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math

import numpy as np

from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
from road_force_estimator.core.scipy_signal import signal as _signal
import road_force_estimator.estimation.body_heave as body_heave
from road_force_estimator.estimation.acceptance import (
    GAP_THRESHOLD_S, accept_arrays, batch_inputs, check_gap_threshold, output_stamps)
from road_force_estimator.estimation.body_heave import SPEED_FLOOR_MPS
from road_force_estimator.estimation.outputs import (
    Column, EstimateArrays, EstimatorStatus, field_columns, hold_rejected)
from road_force_estimator.estimation.reconstruction import (
    Reconstruction, distance_m, tire_deflections)
from road_force_estimator.estimation.static_load import track_recording

__all__ = [
    'FILTER_ORDER', 'NOISE_CROSSING', 'MIN_CUTOFF_HZ', 'MAX_CUTOFF_FRACTION', 'MIN_RUN_SAMPLES',
    'RunInfo', 'OfflineEstimateArrays', 'noise_std', 'auto_cutoff_hz', 'zero_phase_derivatives',
    'zero_phase_body_heave', 'edge_time_s', 'estimate_offline',
]

#: Butterworth order of the channel low-pass (run forward and backward: twice the roll-off).
FILTER_ORDER = 4
#: The cut-off is where the measured PSD falls to this multiple of the noise floor (2: the
#: signal's power equals the noise's).
NOISE_CROSSING = 2.0
#: Lowest automatic cut-off (Hz).
MIN_CUTOFF_HZ = 2.0
#: Cut-offs at or above this fraction of the sample rate mean "no low-pass".
MAX_CUTOFF_FRACTION = 0.4
#: Runs shorter than this are not smoothed (too short for the zero-phase filter).
MIN_RUN_SAMPLES = 32
#: Fewest samples for the automatic cut-off (below: no low-pass).
MIN_AUTO_SAMPLES = 256
#: Relative spread of the steps beyond which a run is resampled on its median step.
RESAMPLE_RTOL = 1e-3


@dataclass(frozen=True)
class RunInfo:
    """One contiguous run (between restarts) of the offline estimate.

    ``first``/``last``: indices (inclusive) of its first and last accepted sample in the input;
    ``samples``; ``dt_s`` the median step; ``cutoff_hz`` (q_1, q_2, phi) low-pass cut-offs used
    (``inf`` = no low-pass); ``speed_mps`` the median |speed| of the body-heave cut-off;
    ``resampled`` whether the run was resampled on an even grid.
    """

    first: int
    last: int
    samples: int
    dt_s: float
    cutoff_hz: tuple[float, float, float]
    speed_mps: float
    resampled: bool


@dataclass
class OfflineEstimateArrays(EstimateArrays):
    """:class:`~.outputs.EstimateArrays` plus what the offline mode chose.

    ``noise_std`` (q_1 (m), q_2 (m), phi (rad)): sensor noise estimated from the data;
    ``cutoff_hz`` the low-pass cut-offs (q_1, q_2, phi) in Hz (``inf`` = none); ``runs`` one
    :class:`RunInfo` per run.
    """

    noise_std: tuple[float, float, float] = (math.nan, math.nan, math.nan)
    cutoff_hz: tuple[float, float, float] = (math.inf, math.inf, math.inf)
    runs: list[RunInfo] = field(default_factory=list)


# ----------------------------------------------------------------------------------------------
# building blocks

def noise_std(x) -> float:
    """White-noise standard deviation of a sampled signal, from its fourth differences.

    ``d = diff(x, 4)`` has variance ``70 sigma^2`` for white noise, while a smooth signal's
    fourth difference is ``x'''' dt^4``, negligible at the rates the sensors run at; the median
    absolute deviation makes it robust to the odd outlier: ``sigma = MAD / 0.6745 / sqrt(70)``.

    Parameters
    ----------
    x : array_like, shape (n,)
        Evenly sampled signal.

    Returns
    -------
    float
        The estimate (units of ``x``); 0 for fewer than 5 samples.
    """
    x = np.asarray(x, dtype=float)
    if x.size < 5:
        return 0.0
    d = np.diff(x, 4)
    return float(np.median(np.abs(d - np.median(d))) / 0.6744897501960817 / math.sqrt(70.0))


def auto_cutoff_hz(x, rate_hz: float, *, sigma: float | None = None,
                   crossing: float = NOISE_CROSSING) -> float:
    """Low-pass cut-off (Hz) where the signal's spectrum meets the noise floor.

    Parameters
    ----------
    x : array_like, shape (n,)
        Evenly sampled measured signal.
    rate_hz : float
        Sample rate (Hz).
    sigma : float, optional
        Noise standard deviation; default :func:`noise_std` of ``x``.
    crossing : float
        Multiple of the noise floor that ends the pass band (default :data:`NOISE_CROSSING`).

    Returns
    -------
    float
        The lowest frequency above DC at which the Welch PSD (about 1 s segments, linear
        detrend, smoothed over 3 bins) drops below ``crossing * 2 sigma^2 / rate_hz``, clipped
        below at :data:`MIN_CUTOFF_HZ`; ``inf`` when it never does below
        ``MAX_CUTOFF_FRACTION * rate_hz``, when ``sigma`` is 0, or with fewer than
        :data:`MIN_AUTO_SAMPLES` samples.
    """
    x = np.asarray(x, dtype=float)
    if x.size < MIN_AUTO_SAMPLES:
        return math.inf
    sigma = noise_std(x) if sigma is None else float(sigma)
    if not sigma > 0.0:
        return math.inf
    nperseg = int(min(x.size, max(MIN_AUTO_SAMPLES, 2 ** round(math.log2(rate_hz)))))
    f, p = _signal().welch(x, fs=rate_hz, nperseg=nperseg, detrend='linear')
    p = np.convolve(p, np.ones(3) / 3.0, mode='same')
    floor = 2.0 * sigma * sigma / rate_hz
    below = np.nonzero((f > 0.0) & (p < crossing * floor))[0]
    if below.size == 0:
        return math.inf
    cut = float(f[below[0]])
    if cut >= MAX_CUTOFF_FRACTION * rate_hz:
        return math.inf
    return max(cut, MIN_CUTOFF_HZ)


def zero_phase_derivatives(x, dt_s: float, cutoff_hz: float, *,
                           order: int = FILTER_ORDER) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Zero-phase low-pass of an evenly sampled signal and its first two derivatives.

    Parameters
    ----------
    x : array_like, shape (n,) or (n, c)
        Samples (columns filtered independently).
    dt_s : float
        Sample step (s).
    cutoff_hz : float
        Butterworth cut-off (Hz; -6 dB after the forward-backward pass); ``inf`` or at least
        :data:`MAX_CUTOFF_FRACTION` of the rate = no low-pass.
    order : int
        Butterworth order of one pass.

    Returns
    -------
    y, dy, ddy : ndarray, shape of ``x``
        The smoothed signal, its central difference ``(y[k+1] - y[k-1]) / (2 dt)`` and its
        second difference ``(y[k+1] - 2 y[k] + y[k-1]) / dt^2`` (one-sided second-order
        differences at the ends for ``dy``, the neighbour's value for ``ddy``).
    """
    x = np.asarray(x, dtype=float)
    n = x.shape[0]
    rate = 1.0 / dt_s
    if n >= MIN_RUN_SAMPLES and cutoff_hz < MAX_CUTOFF_FRACTION * rate:
        signal = _signal()
        sos = signal.butter(order, cutoff_hz, fs=rate, output='sos')
        padlen = min(n - 1, int(math.ceil(6.0 * rate / cutoff_hz)))
        y = signal.sosfiltfilt(sos, x, axis=0, padtype='odd', padlen=padlen)
    else:
        y = x.copy()
    if n >= 3:
        dy = np.gradient(y, dt_s, axis=0, edge_order=2)
        ddy = np.empty_like(y)
        ddy[1:-1] = (y[2:] - 2.0 * y[1:-1] + y[:-2]) / (dt_s * dt_s)
        ddy[0] = ddy[1]
        ddy[-1] = ddy[-2]
    else:
        dy = np.zeros_like(y)
        ddy = np.zeros_like(y)
    return y, dy, ddy


def zero_phase_body_heave(accel_mps2, dt_s: float, cutoff_rad_s: float) -> np.ndarray:
    """Band-limited double integral of the body acceleration, without phase error.

    :func:`estimation.body_heave.zero_phase`: ``1 / s^2`` times ``|H|^2``, ``H``
    the Butterworth high-pass (order :data:`~.body_heave.ZERO_PHASE_ORDER`) at ``w``.

    Parameters
    ----------
    accel_mps2 : array_like, shape (n,)
        Body heave acceleration dd z_s (m/s^2), evenly sampled.
    dt_s : float
        Step (s).
    cutoff_rad_s : float
        ``w`` (rad/s), > 0.

    Returns
    -------
    ndarray, shape (n,)
        z_s (m).
    """
    return body_heave.zero_phase(accel_mps2, dt_s, cutoff_rad_s)


def edge_time_s(cutoffs_hz, dt_s: float) -> float:
    """Time (s) at each end of a run within which ``converged`` is False.

    Four periods of the lowest finite cut-off (the low-pass's impulse response has decayed
    there), at least 20 steps and 50 ms (the estimator's floor).
    """
    finite = [c for c in cutoffs_hz if math.isfinite(c) and c > 0.0]
    low = 4.0 / min(finite) if finite else 0.0
    return max(low, 20.0 * dt_s, 0.05)


# ----------------------------------------------------------------------------------------------
# the estimate

def _estimate_run(t, q, phi, v, vehicle: VehicleParameters, observer: ObserverParameters,
                  cutoffs) -> dict[str, np.ndarray]:
    """Steps 0-4 over one even-or-not run; arrays per sample (times ``t`` in s)."""
    n = t.size
    steps = np.diff(t)
    dt = float(np.median(steps)) if n > 1 else 1e-3
    resampled = bool(n > 2 and np.max(np.abs(steps - dt)) > RESAMPLE_RTOL * dt)
    if resampled:
        tg = t[0] + dt * np.arange(int(math.floor((t[-1] - t[0]) / dt + 1e-9)) + 1)
        qg = np.column_stack([np.interp(tg, t, q[:, i]) for i in (0, 1)])
        pg = np.interp(tg, t, phi)
    else:
        tg, qg, pg = t, q, phi
    speed = max(float(np.median(np.abs(v))), SPEED_FLOOR_MPS)
    wc = 2.0 * math.pi * speed / observer.profile_cutoff_wavelength_m
    q0, dq0, ddq0 = zero_phase_derivatives(qg[:, 0], dt, cutoffs[0])
    q1, dq1, ddq1 = zero_phase_derivatives(qg[:, 1], dt, cutoffs[1])
    ph, dph, ddph = zero_phase_derivatives(pg, dt, cutoffs[2])
    qq = np.column_stack([q0, q1])
    dq = np.column_stack([dq0, dq1])
    ddq = np.column_stack([ddq0, ddq1])
    veh = vehicle
    k = np.asarray(veh.suspension_stiffness_npm)
    c = np.asarray(veh.suspension_damping_nspm)
    fb = -(k * qq + c * dq)
    ddzs = fb.sum(axis=1) / veh.sprung_mass_kg
    zs = zero_phase_body_heave(ddzs, dt, wc)
    dzs = np.gradient(zs, dt, edge_order=2) if zs.size >= 3 else np.zeros_like(zs)
    out = {'q_m': qq, 'dq': dq, 'ddq': ddq, 'roll_rad': ph, 'droll': dph, 'ddroll': ddph,
           'body_heave_m': zs, 'body_heave_rate': dzs, 'body_accel_mps2': ddzs}
    if resampled:
        out = {name: (np.interp(t, tg, a) if a.ndim == 1 else
                      np.column_stack([np.interp(t, tg, a[:, i]) for i in range(a.shape[1])]))
               for name, a in out.items()}
    out['resampled'] = resampled
    out['dt'] = dt
    out['speed'] = speed
    return out


def _run_columns(r: dict, t: np.ndarray, vehicle: VehicleParameters, rec: Reconstruction,
                 out: list) -> None:
    """Steps 1-3 and 6 of one run from its smoothed channels ``r`` (:func:`_estimate_run`),
    then the reconstruction (steps 5, 8, 9) into the columns ``out``."""
    veh = vehicle
    s = veh.half_track_m
    k = np.asarray(veh.suspension_stiffness_npm)
    c = np.asarray(veh.suspension_damping_nspm)
    mu = np.asarray(veh.unsprung_mass_kg)
    kt = np.asarray(veh.tire_stiffness_npm)
    ct = np.asarray(veh.tire_damping_nspm)
    qq, dq, ddq = r['q_m'], r['dq'], r['ddq']
    ph, dph, ddph = r['roll_rad'], r['droll'], r['ddroll']
    # Steps 1-3 (MODEL.md): forces, accelerations, tire forces.
    fb = -(k * qq + c * dq)
    rot = s * (np.cos(ph) * ddph - np.sin(ph) * dph * dph)
    ddzu = r['body_accel_mps2'][:, None] + np.column_stack([rot, -rot]) - ddq
    df = mu * ddzu + fb
    w = tire_deflections(df, t, kt, ct)

    def pair(a):
        return a[:, 0], a[:, 1]
    rec.columns(out, pair(qq), pair(dq), pair(ddq), ph, dph, ddph, r['body_accel_mps2'],
                pair(ddzu), pair(w), pair(df), pair(fb),
                (r['body_heave_m'], r['body_heave_rate']))


def _channel_settings(q, phi, stamp_i, acc, bounds, cutoff_hz):
    """Noise (q_1, q_2, phi) and the low-pass cut-offs (Hz), from the longest run (the
    sensors are the same throughout) or ``cutoff_hz``."""
    noise = (math.nan, math.nan, math.nan)
    cut = (math.inf, math.inf, math.inf)
    if bounds:
        a, b = max(bounds, key=lambda ab: ab[1] - ab[0])
        rows = acc[a:b]
        dt_long = float(np.median(np.diff(stamp_i[rows]))) * 1e-9 if rows.size > 1 else 1e-3
        channels = (q[rows, 0], q[rows, 1], phi[rows])
        noise = tuple(noise_std(x) for x in channels)
        if cutoff_hz is None:
            cut = tuple(auto_cutoff_hz(x, 1.0 / dt_long, sigma=s)
                        for x, s in zip(channels, noise))
        else:
            given = np.broadcast_to(np.asarray(cutoff_hz, dtype=float), (3,))
            if np.any(np.isnan(given)) or np.any(given <= 0.0):
                raise ValueError(f'cutoff_hz = {cutoff_hz!r}: each must be > 0 Hz (inf = none)')
            cut = tuple(float(c) for c in given)
    return noise, cut


def estimate_offline(stamps_ns, q_m, roll_rad, speed_mps, vehicle: VehicleParameters | None = None,
                     observer: ObserverParameters | None = None, *,
                     cutoff_hz=None, gap_threshold_s: float = GAP_THRESHOLD_S
                     ) -> OfflineEstimateArrays:
    """Estimate over a whole recording, non-causally (see the module notes).

    Parameters
    ----------
    stamps_ns : array_like of int, shape (n,)
        Stamps (ns); disorder, duplicates and gaps are handled as by the estimator.
    q_m : array_like, shape (n, 2)
        Suspension extensions [left, right] (m).
    roll_rad : array_like, shape (n,)
        Roll angle (rad), > 0 when the left side goes up.
    speed_mps : array_like, shape (n,) or scalar
        Speed (m/s).
    vehicle, observer : parameters (defaults when None). ``observer.profile_cutoff_wavelength``
        sets the body-heave band; the Lipschitz constants and the discretization are not used.
    cutoff_hz : None, float or (float, float, float)
        Low-pass cut-offs (Hz) for (q_1, q_2, phi): None = from the data
        (:func:`auto_cutoff_hz`, on the longest run, used for every run); one number for all
        three; ``inf`` = no low-pass.
    gap_threshold_s : float
        Shortest step that is a gap (s).

    Returns
    -------
    OfflineEstimateArrays
        The fields of :class:`~.EstimateArrays` (row k = the estimate for sample k;
        rejected rows hold the previous estimate, zeros before the first), the status counters,
        and the noise estimates, cut-offs and runs.
    """
    vehicle = VehicleParameters() if vehicle is None else vehicle
    observer = ObserverParameters() if observer is None else observer
    stamps, q, phi, v = batch_inputs(stamps_ns, q_m, roll_rad, speed_mps)
    n = stamps.shape[0]
    gap_threshold_s = check_gap_threshold(gap_threshold_s)
    valid, restart, stamp_i, cnt = accept_arrays(stamps, q, phi, v, gap_threshold_s)
    status = EstimatorStatus(**cnt)
    acc = np.flatnonzero(valid)
    # zero_load: the static loads (the online estimator's numbers), the offset off the readings
    q, static, vehicle = track_recording(vehicle, q, acc, stamp_i, restart)
    starts = np.flatnonzero(restart[acc]).tolist()
    bounds = list(zip(starts, starts[1:] + [acc.size]))
    fields, columns = field_columns(n)
    noise, cut = _channel_settings(q, phi, stamp_i, acc, bounds, cutoff_hz)
    # Distance over every accepted sample (continued across gaps), as the estimator's.
    columns[Column.DISTANCE][acc] = distance_m(np.diff(stamp_i[acc]) * 1e-9, v[acc])
    rec = Reconstruction(vehicle, observer.rollover_cutoff_frequency_hz)
    runs: list[RunInfo] = []
    edge = math.inf
    for a, b in bounds:
        rows = acc[a:b]
        t = (stamp_i[rows] - stamp_i[rows[0]]) * 1e-9
        r = _estimate_run(t, q[rows], phi[rows], v[rows], vehicle, observer, cut)
        edge = edge_time_s(cut, r['dt'])
        part = field_columns(rows.size)[1]
        _run_columns(r, t, vehicle, rec, part)
        rec.add_quasi_static(part, t)
        if static is not None:
            rec.restatic(part, static[a:b], t)
        part[Column.CONVERGED][:] = (t >= edge) & (t <= t[-1] - edge)
        for j, col in enumerate(columns):
            if j != Column.DISTANCE:
                col[rows] = part[j]
        runs.append(RunInfo(int(rows[0]), int(rows[-1]), int(rows.size), r['dt'], cut,
                            r['speed'], r['resampled']))
    # Rejected rows hold the previous estimate (zeros before the first), as estimate_batch.
    if n and not valid.all():
        held, src = hold_rejected(valid)
        for arr in fields.values():
            arr[held] = arr[src]
    _fill_status(status, fields, stamp_i, acc, starts, runs, edge)
    status.sprung_mass_kg = vehicle.sprung_mass_kg
    status.static_load_n = (tuple(float(f) for f in fields['static_load_n'][acc[-1]])
                            if acc.size else vehicle.static_load_n)
    out = OfflineEstimateArrays(stamp_ns=output_stamps(stamps), valid=valid, status=status,
                                noise_std=noise, cutoff_hz=cut, runs=runs, **fields)
    status.negative_load_samples = out.negative_load_samples()
    return out


def _fill_status(status: EstimatorStatus, fields: dict, stamp_i, acc, starts, runs,
                 edge: float) -> None:
    """The status of the last accepted sample, as the estimator's."""
    status.accepted = int(acc.size)
    if acc.size:
        j = int(acc[-1])
        a0 = acc[starts[-1]]
        status.last_stamp_ns = int(stamp_i[j])
        status.time_since_start_s = (stamp_i[j] - stamp_i[a0]) * 1e-9
        status.last_dt_s = (stamp_i[j] - stamp_i[acc[-2]]) * 1e-9 if acc.size > 1 else 0.0
        status.typical_dt_s = runs[-1].dt_s
        status.converged = bool(fields['converged'][j])
        status.last_residual_nm = float(fields['residual_nm'][j])
        status.lift_off = (bool(fields['lift_off'][j, 0]), bool(fields['lift_off'][j, 1]))
    status.settling_time_s = edge if math.isfinite(edge) else 0.0
