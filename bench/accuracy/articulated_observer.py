"""The whole-vehicle observer on the articulated drive family (issue 32, in progress): every
wheel's dynamic-load error per axle, in each mode, beside a Kalman peer tuned on the truth and
the front-axle estimator run axle by axle (what a user does today).

Run from the repository root::

    .venv/bin/python -m bench.accuracy.articulated_observer [--duration 25] [--only A20 C20]
        [--noise 1e-5] [--settle 5] [--no-peer]

Each drive is :mod:`bench.studies.articulated_drives`' (MODEL.md's 5-axle 40 t combination at
1 kHz, ISO 8608 roads seed 1), simulated by the core plant (:func:`.core.articulated_plant.
simulate_articulated`) and read by its sensors (:class:`.core.articulated_sensors.
ArticulatedSensors`) with ``--noise`` on every deflection (m) and the same over the front
axle's half spring track on the rolls (rad). Estimates, in each mode (zero latency, 10 ms,
offline):

- ``articulated observer``: :func:`road_force_estimator.estimation.articulated.
  estimate_articulated`, every setting the package's (noise and roughness estimated online);
- ``Kalman peer (truth-tuned)``: :mod:`bench.accuracy.articulated_peer` (the full linear model in
  absolute coordinates, the true noise and ISO class, its two densities picked on the truth
  per drive and mode; causal, exact 10-sample fixed lag, RTS);
- ``front-axle estimator, axle by axle``: the package's front-axle estimator
  (``config/road_force_estimator.yaml``, :class:`.estimation.estimator.Estimator` /
  :func:`.estimation.offline.smooth`) on each axle's two deflections and its body's roll.

Printed per drive, mode and estimator: per axle the RMS over both wheels of the dynamic-load
error after ``--settle`` s, in % of the true dynamic-load RMS (the load less the static load)
of the same samples; offline also the road under each axle's two wheels (0.5-30 m band, RMS
over both wheel paths of the error in % of the true road's, the last 60 m left out) of the
articulated observer and of the front-axle estimator axle by axle, and the articulated
observer's fused profile (every axle's road fused by distance, fuse_roads) against the front axle's
wheel paths.
"""
from __future__ import annotations

import argparse
import math
import pathlib
import sys
import tempfile
import time

import numpy as np

REPO = pathlib.Path(__file__).resolve().parents[2]
MODES = (('0 ms', 0.0, False), ('10 ms', 0.01, False), ('offline', 0.0, True))


def simulate(case, duration_s: float, noise_m: float, seed: int = 1, imu: bool = False) -> dict:
    """One drive of the family: the plant's truth and the sensors' readings; ``imu``: also
    the tractor IMU's a_y (``'ay'``, m/s^2, the plant's IMU with its default noise)."""
    from bench.studies.articulated_drives import CONFIG
    from road_force_estimator.bagio import road_from_source
    from road_force_estimator.core.articulated_plant import simulate_articulated
    from road_force_estimator.core.articulated_setup import ArticulatedDrive
    from road_force_estimator.core.parameters import load_params_file
    from road_force_estimator.estimation.models.articulated import channel_names

    values = load_params_file(CONFIG)
    s_front = float(values.get('vehicle.axle.front.spring_half_track', 0.45))
    values.update({'simulator.road': f'iso8608:{case.road}:seed={seed}',
                   'simulator.speed': case.speed_mps, 'simulator.duration': duration_s,
                   'simulator.noise.deflection': noise_m,
                   'simulator.noise.roll': noise_m / s_front, **case.values})
    with tempfile.TemporaryDirectory() as tmp:
        if case.speed_profile is not None:       # as bench.studies.articulated_drives writes it
            path = pathlib.Path(tmp) / 'speed.csv'
            path.write_text('time_s,speed_mps\n' + ''.join(
                f'{t:.6f},{v:.6f}\n' for t, v in zip(*case.speed_profile)))
            values['simulator.speed_profile'] = str(path)
        drive = ArticulatedDrive.from_values(values)
    sim = drive.sim
    road = road_from_source(sim.road, length_m=drive.road_length_m)
    tr = simulate_articulated(drive.vehicle, road, speed_mps=sim.speed_mps, rate_hz=sim.rate_hz,
                              duration_s=duration_s, speed_profile=drive.speed_profile,
                              lateral_acceleration=drive.lateral,
                              tire_envelope_m=sim.tire_envelope_length_m, model=drive.model,
                              crossfall_rad=sim.road_crossfall_rad)
    sensors = drive.sensors(channel_names(drive.model))
    readings = sensors.measure(tr)
    static = drive.model.statics().output_wheel_load_n.reshape(-1)
    extra = {'ay': sensors.imu(tr)[:, 1]} if imu else {}
    return {**extra, 'vehicle': drive.vehicle, 't': tr.t_s,
            'stamps': np.round(tr.t_s * 1e9).astype(np.int64), 'y': readings,
            'speed': np.asarray(tr.speed_mps, float) * np.ones(len(tr)),
            'load': tr.wheel_load_n.T, 'dynamic': tr.wheel_load_n.T - static[:, None],
            'axles': drive.vehicle.axle_names, 'road': tr.road_m, 'distance': tr.distance_m}


def error_pct(t, est_dyn: np.ndarray, true_dyn: np.ndarray, settle_s: float) -> np.ndarray:
    """Per axle (pairs of rows): RMS error over both wheels, % of the true dynamic RMS."""
    judged = t >= t[0] + settle_s
    err = (est_dyn - true_dyn)[:, judged].reshape(-1, 2, int(judged.sum()))
    ref = true_dyn[:, judged].reshape(-1, 2, int(judged.sum()))
    return 100.0 * np.sqrt(np.mean(err ** 2, axis=(1, 2)) / np.mean(ref ** 2, axis=(1, 2)))


def road_pct(drive: dict, road: np.ndarray, settle_s: float) -> np.ndarray:
    """Per axle (pairs of rows of ``road`` (nw, m)): the 0.5-30 m band's RMS error over both
    wheel paths, % of the truth's, away from the drive's first ``settle_s`` s and last 60 m."""
    from road_force_estimator.core import metrics

    x = drive['distance'] - drive['distance'][0]
    mask = (drive['t'] >= drive['t'][0] + settle_s) & (x < x[-1] - 60.0)
    pe = metrics.profile_errors(x, road.T, drive['road'][:, :road.shape[0]], mask=mask)
    err = np.asarray(pe.rms_pct).reshape(-1, 2)
    return np.sqrt(np.mean(err ** 2, axis=1))


def fused_pct(drive: dict, est, settle_s: float) -> np.ndarray:
    """The fused profile's (:func:`.estimation.articulated.fuse_roads`) 0.5-30 m band error
    over both wheel paths against the front axle's road (% of its RMS), as :func:`road_pct`
    (the points the last axle has passed, away from the last 60 m of them)."""
    from road_force_estimator.core import metrics
    from road_force_estimator.estimation.articulated import fuse_roads

    fused = fuse_roads(est, [a.position_m for a in drive['vehicle'].axles])
    n = fused.distance_m.size
    x = fused.distance_m
    mask = (drive['t'][:n] >= drive['t'][0] + settle_s) & (x < x[-1] - 60.0)
    pe = metrics.profile_errors(x, np.column_stack([fused.left, fused.right]),
                                drive['road'][:n, :2], mask=mask)
    return np.array([math.sqrt(float(np.mean(np.square(pe.rms_pct))))])


def front_axle(drive: dict, axle: int, latency_s: float, offline: bool,
               road: list | None = None) -> np.ndarray:
    """The front-axle estimator (its package parameters) on one axle's two deflections and
    its body's roll (the tractor's where the trailer has no roll sensor): that axle's two
    dynamic tire forces (2, m); offline, its road (2, m) appended to ``road``."""
    from road_force_estimator.core.parameters import (
        ObserverParameters, VehicleParameters, load_params_file)
    from road_force_estimator.estimation.estimator import Estimator
    from road_force_estimator.estimation.offline import smooth

    values = load_params_file(REPO / 'config' / 'road_force_estimator.yaml')
    vehicle = VehicleParameters.from_parameters(values)
    observer = ObserverParameters.from_parameters({**values, 'observer.latency': latency_s})
    v = drive['vehicle']
    n_q = 2 * sum(a.instrumented for a in v.axles)
    trailer = v.axles[axle].body == 'trailer' and v.trailer_roll_sensor
    q, phi = drive['y'][:, 2 * axle:2 * axle + 2], drive['y'][:, n_q + int(trailer)]
    stamps, speed = drive['stamps'], drive['speed']
    if offline:
        est = smooth(stamps, q, phi, speed, vehicle, observer)
        if road is not None:
            road.append(est.road_m.T)
        return est.tire_force_dynamic_n.T
    est = Estimator(vehicle, observer)
    out = {}
    for s, qi, pi, vi in zip(stamps.tolist(), q.tolist(), phi.tolist(), speed.tolist()):
        e = est.update(s, qi, pi, vi)
        if e is not None:
            out[e.stamp_ns] = e.tire_force_dynamic_n
    for e in est.flush():
        out[e.stamp_ns] = e.tire_force_dynamic_n
    return np.array([out[s] for s in stamps.tolist()]).T


def peer(drive: dict, case, lag, noise_m: float, judged) -> tuple[np.ndarray, tuple]:
    """The Kalman peer tuned on the truth (:mod:`bench.accuracy.articulated_peer`)."""
    from bench.accuracy.articulated_peer import tuned
    from road_force_estimator.core.road import iso8608_psd

    gd = float(iso8608_psd(case.road, [0.1])[0])
    return tuned(drive['vehicle'], drive['y'], drive['dynamic'], judged, lag,
                 speed_mps=case.speed_mps, dt_s=1e-3, noise_m=noise_m,
                 noise_rad=noise_m / drive['vehicle'].axles[0].spring_half_track_m,
                 road_gd_m3=gd)


def _line(case, label: str, who: str, pct: np.ndarray, extra: str = '', axles: int = 5
          ) -> str:
    cells = ' | '.join([f'{p:.1f}' for p in pct] + [''] * (axles - len(pct)))
    return f'| {case.name} | {label} | {who} | {cells} | {extra} |'


def run(case, args) -> list[str]:
    """The table's lines of one drive."""
    from road_force_estimator.estimation.articulated import estimate_articulated

    drive = simulate(case, args.duration, args.noise)
    t = drive['t']
    judged = t >= t[0] + args.settle
    lines = []
    for label, latency, offline in MODES:
        start = time.perf_counter()
        est = estimate_articulated(drive['vehicle'], drive['stamps'], drive['y'],
                                   drive['speed'], latency_s=latency, offline=offline)
        wall = time.perf_counter() - start
        pct = error_pct(t, est.dynamic_n, drive['dynamic'], args.settle)
        lines.append(_line(case, label, 'articulated observer', pct, f'wall {wall:.1f} s'))
        ours_road = est
        if not args.no_peer:
            lag = None if offline else int(round(latency * 1e3))
            est, (factor, psd) = peer(drive, case, lag, args.noise, judged)
            pct = error_pct(t, est, drive['dynamic'], args.settle)
            lines.append(_line(case, label, 'Kalman peer (truth-tuned)', pct,
                               f'road x {factor:g}, force {psd:g} N^2 s'))
        roads: list = []
        front = np.vstack([front_axle(drive, j, latency, offline, roads)
                           for j in range(len(drive['axles']))])
        pct = error_pct(t, front, drive['dynamic'], args.settle)
        lines.append(_line(case, label, 'front-axle estimator, axle by axle', pct))
        if offline:
            lines.append(_line(case, 'offline road', 'articulated observer',
                               road_pct(drive, ours_road.road_m, args.settle),
                               '0.5-30 m band error, % of the true road'))
            lines.append(_line(case, 'offline road', 'articulated observer, fused',
                               fused_pct(drive, ours_road, args.settle),
                               'every axle fused (fuse_roads), both paths',
                               len(drive['axles'])))
            lines.append(_line(case, 'offline road', 'front-axle estimator, axle by axle',
                               road_pct(drive, np.vstack(roads), args.settle),
                               '0.5-30 m band error, % of the true road'))
    return lines


def main(argv: list[str] | None = None) -> int:
    from bench.studies.articulated_drives import family

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--duration', type=float, default=25.0, help='each drive (s)')
    parser.add_argument('--only', nargs='*', default=['A20', 'C20'], metavar='NAME')
    parser.add_argument('--noise', type=float, default=1e-5, help='deflection noise (m)')
    parser.add_argument('--settle', type=float, default=5.0, help='judged after (s)')
    parser.add_argument('--no-peer', action='store_true', help='without the Kalman peer')
    args = parser.parse_args(argv)
    cases = [c for c in family() if c.name in args.only]
    out = []
    for case in cases:
        out += run(case, args)
    from road_force_estimator.core.articulated_setup import ArticulatedDrive
    from road_force_estimator.core.parameters import load_params_file
    from bench.studies.articulated_drives import CONFIG
    names = ArticulatedDrive.from_values(load_params_file(CONFIG)).vehicle.axle_names
    print(f'Articulated observer, {args.duration:g} s drives at 1 kHz, {args.noise * 1e6:g} um '
          f'noise, judged after {args.settle:g} s: dynamic-load RMS error, % of the true '
          'dynamic-load RMS, per axle (both wheels)\n')
    head = ' | '.join(names)
    print(f'| drive | mode | estimator | {head} | |')
    print('|---|---|---|' + '---:|' * len(names) + '---|')
    print('\n'.join(out))
    return 0


if __name__ == '__main__':
    sys.exit(main())
