"""Benchmark scenarios: drives generated with the package's plant, and their scoring.

Every scenario is a :class:`Scenario` (a frozen description); :func:`build_drive` simulates it
with :func:`road_force_estimator.core.plant.simulate` and measures it with
:class:`road_force_estimator.core.sensors.SensorModel`, returning a :class:`Drive` (measurements,
the vehicle parameters the observer believes, and the ground truth). :func:`score` compares an
estimate with the truth after the convergence skip.

Conventions
-----------
- Roll noise "to match" the deflection noise: ``sigma_phi = ROLL_NOISE_PER_DEFLECTION *
  sigma_q`` = 10 rad/m x sigma_q, the ratio of the package's default simulator settings
  (``simulator.noise.deflection = 1e-5 m``, ``simulator.noise.roll = 1e-4 rad``).
- The tire follows the road enveloped over ``TIRE_ENVELOPE_M`` (0.25 m, the simulator's
  default); the true profile of the scoring is the road under the tire the plant reports.
- Parameter-error scenarios scale the observer's dynamic parameters (M, I_x, m_i, k_i, c_i,
  kt_i) by ``1 + param_error``; the static loads stay the plant's (known from weighing), so
  that the figure measures the dynamics, not a static-load offset common to every method.
- Scored drives use road seed 1 (the simulator default) and noise seed 1 + scenario index;
  the tuning drive (:data:`TUNING`) uses road seed 1001 and noise seed 1002.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
import math
from pathlib import Path
from typing import Any, Callable

import numpy as np
from scipy import signal

from road_force_estimator.core.parameters import VehicleParameters

__all__ = [
    'Scenario', 'Drive', 'SCENARIOS', 'TUNING', 'SHARED_DATA', 'ROLL_NOISE_PER_DEFLECTION',
    'TIRE_ENVELOPE_M', 'PROFILE_BAND_M', 'build_drive', 'observer_vehicle', 'score',
    'scenario_by_name',
]

#: Roll-sensor noise per unit of deflection-sensor noise (rad/m); see the module notes.
ROLL_NOISE_PER_DEFLECTION = 10.0
#: Tire envelope length (m), the simulator's default.
TIRE_ENVELOPE_M = 0.25
#: Profile band judged (wavelengths, m): MODEL.md "Metrics".
PROFILE_BAND_M = (0.5, 30.0)
#: ../shared/data beside the checkout.
SHARED_DATA = Path(__file__).resolve().parents[3] / 'shared' / 'data'


@dataclass(frozen=True)
class Scenario:
    """One benchmark drive.

    Attributes
    ----------
    name : short identifier used in the tables.
    road : ISO 8608 class 'A'..'H', 'profile_1' (../shared/data/profile_1.txt), or 'jpcp' (a
        jointed concrete road, :func:`road_force_estimator.core.road_jpcp.jpcp_profile` with
        its defaults and ``road_seed``).
    road_seed : seed of the synthetic road.
    speed_mps, rate_hz, duration_s : drive (duration clipped to the road's length).
    noise_deflection_m : std of the deflection noise (m); roll noise follows (module notes).
    noise_seed : seed of the sensor noise.
    param_error : relative error of the observer's dynamic parameters (0.1 = +10 %).
    event : None or (kind, side, start_m, length_m, height_m) for ``road.add_event``.
    lateral_step_mps2, lateral_step_s : a_y step (m/s^2, + = left) at that time (s).
    skip_s : convergence skip before scoring (s).
    speed_dropout : None or (start_s, length_s): the recorded speed reads 0 there while the
        truck drives on (a CAN speed drop-out; the truth and the deflections are the drive's).
    speed_profile : None or ((time_s...), (speed_mps...)): the truck's speed varies (the
        plant's ``simulator.speed_profile``, linearly interpolated; stops allowed), and the
        recorded speed is that speed.
    """

    name: str
    road: str = 'C'
    road_seed: int = 1
    speed_mps: float = 20.0
    rate_hz: float = 1000.0
    duration_s: float = 20.0
    noise_deflection_m: float = 1e-5
    noise_seed: int = 1
    param_error: float = 0.0
    event: tuple | None = None
    lateral_step_mps2: float = 0.0
    lateral_step_s: float = 10.0
    skip_s: float = 2.0
    speed_dropout: tuple | None = None
    speed_profile: tuple | None = None
    description: str = ''

    @property
    def noise_roll_rad(self) -> float:
        return ROLL_NOISE_PER_DEFLECTION * self.noise_deflection_m


def _scenarios() -> tuple[Scenario, ...]:
    base = Scenario('C20-1k-10um', description='MODEL.md scenario: ISO C, 20 m/s, 1 kHz, 10 um')
    out = [
        base,
        replace(base, name='C20-1k-0um', noise_deflection_m=0.0, description='noise-free'),
        replace(base, name='C20-1k-50um', noise_deflection_m=50e-6, description='50 um noise'),
        replace(base, name='A20-1k-10um', road='A', description='ISO class A'),
        replace(base, name='B20-1k-10um', road='B', description='ISO class B'),
        replace(base, name='D20-1k-10um', road='D', description='ISO class D'),
        replace(base, name='D20-1k-0um', road='D', noise_deflection_m=0.0,
                description='ISO class D, noise-free'),
        replace(base, name='C10-1k-10um', speed_mps=10.0, duration_s=30.0,
                description='10 m/s'),
        replace(base, name='C30-1k-10um', speed_mps=30.0, description='30 m/s'),
        replace(base, name='C20-500-10um', rate_hz=500.0, description='500 Hz'),
        replace(base, name='C20-200-10um', rate_hz=200.0, description='200 Hz'),
        replace(base, name='C20-params+10', param_error=0.1,
                description='observer parameters +10 %'),
        replace(base, name='C20-params-10', param_error=-0.1,
                description='observer parameters -10 %'),
        replace(base, name='B20-pothole', road='B', event=('pothole', 'left', 200.0, 0.6, 0.03),
                description='ISO B + one-sided pothole (left, 0.6 m long, 3 cm deep)'),
        replace(base, name='C20-lateral', lateral_step_mps2=3.0, lateral_step_s=10.0,
                description='a_y step of 3 m/s^2 to the left at 10 s'),
        replace(base, name='profile_1', road='profile_1', duration_s=28.0,
                description='measured track (profile_1.txt, both wheels), detrended'),
        # (appended: the noise seeds of the scenarios above stay)
        replace(base, name='C20-speed-dropout', duration_s=30.0, speed_dropout=(10.0, 10.0),
                description='recorded speed 0 for 10 s (10-20 s) while the truck drives on'),
        replace(base, name='C20-stop', duration_s=34.0,
                speed_profile=((0.0, 8.0, 12.0, 22.0, 26.0, 34.0),
                               (20.0, 20.0, 0.0, 0.0, 20.0, 20.0)),
                description='a consistent stop: braking at 5 m/s^2 to 0 (8-12 s), standing '
                            '10 s, pulling away to 20 m/s (22-26 s)'),
        replace(base, name='jpcp', road='jpcp',
                description='jointed concrete (jpcp:seed=1): 4.6 m slabs, joints faulted '
                            '1-3 mm, curl 1 mm, ISO A underneath'),
        # (issue 30: the headline moves to a road class that users survey)
        replace(base, name='A20-1k-0um', road='A', noise_deflection_m=0.0,
                description='ISO class A, noise-free'),
    ]
    return tuple(replace(s, noise_seed=1 + i) for i, s in enumerate(out))


SCENARIOS: tuple[Scenario, ...] = _scenarios()

#: The tuning drive: the MODEL.md scenario on another road and noise seed (noise set per sweep).
TUNING = Scenario('tuning', road='C', road_seed=1001, noise_seed=1002,
                  description='tuning drive: ISO C, 20 m/s, 1 kHz, road seed 1001')


def scenario_by_name(name: str) -> Scenario:
    for s in SCENARIOS:
        if s.name == name:
            return s
    raise ValueError(f'scenario {name!r}: unknown; one of {", ".join(s.name for s in SCENARIOS)}')


@dataclass
class Drive:
    """A simulated, measured drive with its ground truth (row k = sample k)."""

    scenario: Scenario
    t_s: np.ndarray                 #: (n,) s
    q_m: np.ndarray                 #: (n, 2) measured deflections (m)
    roll_rad: np.ndarray            #: (n,) measured roll (rad)
    speed_mps: np.ndarray           #: (n,) m/s
    vehicle_plant: VehicleParameters
    vehicle_observer: VehicleParameters
    truth: dict[str, np.ndarray] = field(default_factory=dict)
    #: wheel_load_n (n, 2), tire_force_dynamic_n (n, 2), road_m (n, 2), distance_m (n,),
    #: ltr (n,), q_m (n, 2), roll_rad (n,)
    #: results kept while the drive is benchmarked (e.g. the package defaults' estimate, which
    #: other columns compare against); not part of the drive's description
    cache: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)

    @property
    def skip(self) -> int:
        return int(round(self.scenario.skip_s * self.scenario.rate_hz))

    @property
    def stamps_ns(self) -> np.ndarray:
        """(n,) int64 stamps (ns) of the samples, as a bag or the node would carry them."""
        return np.round(self.t_s * 1e9).astype(np.int64)


def observer_vehicle(plant: VehicleParameters, param_error: float) -> VehicleParameters:
    """The parameters the observer believes: dynamic ones scaled by ``1 + param_error``."""
    if param_error == 0.0:
        return plant
    f = 1.0 + param_error

    def pair(p):
        return tuple(f * v for v in p)

    return replace(plant, sprung_mass_kg=f * plant.sprung_mass_kg,
                   roll_inertia_kgm2=f * plant.roll_inertia_kgm2,
                   unsprung_mass_kg=pair(plant.unsprung_mass_kg),
                   suspension_stiffness_npm=pair(plant.suspension_stiffness_npm),
                   suspension_damping_nspm=pair(plant.suspension_damping_nspm),
                   tire_stiffness_npm=pair(plant.tire_stiffness_npm),
                   static_load_setting_n=tuple(plant.static_load_n))


def scenario_road(scenario: Scenario, length_m: float):
    from road_force_estimator.core import road as road_mod
    from road_force_estimator.core.road_files import read_text_profile

    if scenario.road == 'profile_1':
        prof = read_text_profile(SHARED_DATA / 'profile_1.txt')
        # absolute elevation with the grade: remove mean and grade, then a gentle high-pass
        # (2nd-order Butterworth at 100 m wavelength, zero phase) as the README asks
        x = prof.distance_m - prof.start_m
        z = signal.detrend(prof.elevation_m, axis=0, type='linear')
        dx = float(np.median(np.diff(x)))
        sos = signal.butter(2, 1.0 / 100.0, btype='highpass', fs=1.0 / dx, output='sos')
        z = signal.sosfiltfilt(sos, z, axis=0)
        prof = road_mod.RoadProfile(x, z, name='profile_1 (detrended, high-passed 100 m)')
    elif scenario.road == 'jpcp':
        from road_force_estimator.core.road_jpcp import jpcp_profile

        prof = jpcp_profile(length_m, seed=scenario.road_seed)
    else:
        prof = road_mod.iso8608_profile(scenario.road, length_m, seed=scenario.road_seed)
    if scenario.event is not None:
        kind, side, start, length, height = scenario.event
        prof = road_mod.add_event(prof, kind, side, start, length, height)
    return prof


def build_drive(scenario: Scenario, *, noise_deflection_m: float | None = None,
                vehicle: VehicleParameters | None = None) -> Drive:
    """Simulate and measure ``scenario`` (``noise_deflection_m`` overrides its noise)."""
    from road_force_estimator.core.plant import simulate
    from road_force_estimator.core.sensors import SensorModel

    plant_vehicle = vehicle or VehicleParameters()
    noise = scenario.noise_deflection_m if noise_deflection_m is None else noise_deflection_m
    margin_m = 5.0
    length = scenario.speed_mps * scenario.duration_s + 2.0 * margin_m + TIRE_ENVELOPE_M
    road = scenario_road(scenario, length)
    duration = min(scenario.duration_s,
                   (road.end_m - road.start_m - TIRE_ENVELOPE_M - 0.5) / scenario.speed_mps)
    lateral: Callable[[float], float] | None = None
    if scenario.lateral_step_mps2:
        a_y, t_step = scenario.lateral_step_mps2, scenario.lateral_step_s

        def lateral(t_s: float) -> float:
            return a_y if t_s >= t_step else 0.0

    traj = simulate(plant_vehicle, road, speed_mps=scenario.speed_mps,
                    rate_hz=scenario.rate_hz, duration_s=duration,
                    lateral_acceleration=lateral, tire_envelope_m=TIRE_ENVELOPE_M,
                    speed_profile=scenario.speed_profile)
    q_true = np.asarray(traj.q_m, dtype=float)
    roll_true = np.asarray(traj.roll_rad, dtype=float)
    sensor = SensorModel(deflection_std_m=noise, roll_std_rad=ROLL_NOISE_PER_DEFLECTION * noise,
                         seed=scenario.noise_seed)
    q_meas, roll_meas = sensor.measure(q_true, roll_true)
    n = q_true.shape[0]
    t_s = np.asarray(traj.t_s, dtype=float)
    wheel_load = np.asarray(traj.wheel_load_n, dtype=float)
    truth = {
        'wheel_load_n': wheel_load,
        'tire_force_dynamic_n': np.asarray(traj.tire_force_dynamic_n, dtype=float),
        'road_m': np.asarray(traj.road_m, dtype=float),
        'distance_m': np.asarray(traj.distance_m, dtype=float),
        'ltr': (wheel_load[:, 1] - wheel_load[:, 0]) / wheel_load.sum(axis=1),
        'q_m': q_true,
        'roll_rad': roll_true,
    }
    speed = np.full(n, scenario.speed_mps)
    if scenario.speed_profile is not None:
        speed = np.interp(t_s, *scenario.speed_profile)
    if scenario.speed_dropout is not None:
        start, length = scenario.speed_dropout
        speed[(t_s >= start) & (t_s < start + length)] = 0.0
    return Drive(replace(scenario, noise_deflection_m=noise), t_s,
                 np.asarray(q_meas, dtype=float), np.asarray(roll_meas, dtype=float),
                 speed, plant_vehicle,
                 observer_vehicle(plant_vehicle, scenario.param_error), truth)


# ----------------------------------------------------------------------------------------------
# scoring, with road_force_estimator.core.metrics (band-pass, error statistics) and .iri


def combined_rms(stats) -> tuple[float, float]:
    """RMS over both wheels and the matching reference RMS from per-wheel statistics."""
    rms = float(np.sqrt(np.mean(np.square(stats.rms))))
    ref = float(np.sqrt(np.mean(np.square(stats.reference_rms))))
    return rms, ref


def _xcorr_figures(x: np.ndarray, road_est: np.ndarray, road_true: np.ndarray,
                   segment_m: float) -> dict[str, float]:
    """``xcorr`` and ``xcorr_seg_min``: both profiles through the IRI filter from the skip on
    (the same start, so the same initial transient), judged from 30 m after it (:func:`score`).
    NaN when the estimate is not finite or the stretch is too short."""
    from road_force_estimator.core import profile_correlation as pc

    start = float(x[0]) + PROFILE_BAND_M[1]
    if not np.all(np.isfinite(road_est)) or x[-1] - start < 0.5 * segment_m:
        return {'xcorr': math.nan, 'xcorr_seg_min': math.nan}
    whole, seg = [], []
    for side in (0, 1):
        res = pc.segment_correlation(x, road_est[:, side], x, road_true[:, side],
                                     segment_length_m=segment_m, start_m=start)
        whole.append(res.whole.rating)
        seg += [c.rating for c in res.segments]
    return {'xcorr': float(min(whole)), 'xcorr_seg_min': float(np.nanmin(seg))}


def score(drive: Drive, result: Any, *, iri_segment_m: float = 100.0) -> dict[str, float]:
    """Error figures of a peer's (or the estimator's) result against the truth.

    ``result`` has ``wheel_load_n`` (n, 2), ``road_m`` (n, 2) and ``ltr`` (n,), row k = the
    estimate for sample k. Loads and LTR are scored from the convergence skip on; the profile
    from ``PROFILE_BAND_M[1]`` (30 m) after the skip to 30 m before the end (the band-pass's
    edge transients). Both wheels are pooled (RMS over both).

    Returns
    -------
    dict
        ``load_rms_pct_dyn`` (% of the true dynamic-load RMS), ``load_rms_pct_static``
        (% of the static load), ``load_rms_n``, ``load_peak_n``; ``profile_rms_pct_band``
        (0.5-30 m band, % of the band-passed true profile's RMS); ``iri_err_pct_mean`` and
        ``iri_err_pct_max`` (|IRI error| per 100 m segment of the scored stretch, % of the true
        segment IRI, both wheels); ``xcorr`` and ``xcorr_seg_min`` (the IRI-filtered cross
        correlation of ProVAL, :mod:`road_force_estimator.core.profile_correlation`, at the
        samples' true distance: the lower wheel's rating over the stretch from 30 m after the
        skip, and the lowest rating of its 100 m segments, both wheels); ``ltr_rms``,
        ``ltr_peak``; ``convergence_s`` (start-up: time after which the 100 ms trailing RMS of
        the load error stays below max(2 x its scored RMS, 1 % of the static load) until
        skip + 3 s, before any scripted event; inf if it is still above then); the drive's
        own ``iri_true_mpkm`` (the true profile's IRI, mean over the 100 m segments and both
        wheels, m/km), ``load_dyn_rms_n`` (the true dynamic-load RMS, N) and
        ``static_load_n`` (the mean static load, N).
    """
    from road_force_estimator.core import iri as iri_mod
    from road_force_estimator.core import metrics

    t = drive.truth
    n = len(drive.t_s)
    k0 = drive.skip
    mask = np.zeros(n, dtype=bool)
    mask[k0:] = True
    static = np.asarray(drive.vehicle_plant.static_load_n)
    load = np.asarray(result.wheel_load_n, dtype=float)
    st = metrics.load_errors(load, t['wheel_load_n'], static, mask=mask)
    load_rms, dyn_rms = combined_rms(st)
    out = {
        'load_rms_pct_dyn': 100.0 * load_rms / dyn_rms,
        'load_rms_pct_static': 100.0 * load_rms / float(np.mean(static)),
        'load_rms_n': load_rms,
        'load_peak_n': float(np.max(st.peak)),
        'load_dyn_rms_n': dyn_rms,
        'static_load_n': float(np.mean(static)),
    }
    x = t['distance_m']
    road_est = np.asarray(result.road_m, dtype=float)
    pmask = (x >= x[k0] + PROFILE_BAND_M[1]) & (x <= x[-1] - PROFILE_BAND_M[1])
    if np.all(np.isfinite(road_est)) and np.count_nonzero(pmask) > 10:
        pe = metrics.profile_errors(x, road_est, t['road_m'], mask=pmask)
        prms, pref = combined_rms(pe)
        out['profile_rms_pct_band'] = 100.0 * prms / pref
    else:
        out['profile_rms_pct_band'] = math.nan
    # IRI per segment over the scored stretch (from the skip on)
    xs = x[k0:]
    if xs[-1] - xs[0] >= 0.5 * iri_segment_m and np.all(np.isfinite(road_est)):
        edges = np.arange(xs[0], xs[-1] + 1e-9, iri_segment_m)
        if xs[-1] - edges[-1] > 0.5 * iri_segment_m or edges.size == 1:
            edges = np.append(edges, xs[-1])
        else:
            edges[-1] = xs[-1]
        iri_true = iri_mod.iri_segments(xs, t['road_m'][k0:], edges)
        out['iri_true_mpkm'] = float(np.nanmean(iri_true))
        iri_est = iri_mod.iri_segments(xs, road_est[k0:], edges)
        rel = 100.0 * np.abs(iri_est - iri_true) / iri_true
        out['iri_err_pct_mean'] = float(np.nanmean(rel))
        out['iri_err_pct_max'] = float(np.nanmax(rel))
    else:
        out['iri_err_pct_mean'] = out['iri_err_pct_max'] = math.nan
    out.update(_xcorr_figures(x[k0:], road_est[k0:], t['road_m'][k0:], iri_segment_m))
    ls = metrics.ltr_stats(np.asarray(result.ltr, dtype=float), t['ltr'], mask=mask)
    out['ltr_rms'] = ls['rms_error']
    out['ltr_peak'] = ls['peak_error']
    # convergence (start-up): 100 ms trailing RMS of the load error (both wheels) from the
    # start to the end of the convergence window (skip + 3 s, before any scripted event)
    w = max(1, int(round(0.1 * drive.scenario.rate_hz)))
    k1 = min(n, int(round((drive.scenario.skip_s + 3.0) * drive.scenario.rate_hz)))
    e2 = np.mean(np.square(load - t['wheel_load_n']), axis=1)
    mov = np.sqrt(np.convolve(e2, np.ones(w) / w, mode='full')[:n])
    tol = max(2.0 * load_rms, 0.01 * float(np.mean(static)))
    out['convergence_s'] = metrics.convergence_time(drive.t_s[:k1] - drive.t_s[0], mov[:k1],
                                                    tol)
    return out
