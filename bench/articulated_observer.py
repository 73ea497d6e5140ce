"""The whole-vehicle observer on the articulated drive family (issue 32, in progress): every
wheel's dynamic-load error per axle, in each mode, beside the front-axle estimator on the
front axle (what a user does today).

Run from the repository root::

    .venv/bin/python -m bench.articulated_observer [--duration 25] [--only A20 C20]
        [--noise 1e-5] [--settle 5]

Each drive is :mod:`bench.articulated_drives`' (MODEL.md's 5-axle 40 t combination at 1 kHz,
ISO 8608 roads seed 1), simulated by the core plant (:func:`.core.articulated_plant.
simulate_articulated`) and read by its sensors (:class:`.core.articulated_sensors.
ArticulatedSensors`) with ``--noise`` on every deflection (m) and the same over the front
axle's half spring track on the rolls (rad). Estimates:

- ``articulated``: :func:`road_force_estimator.estimation.articulated.estimate_articulated`
  at zero latency, 10 ms and offline, every setting the package's (noise and roughness
  estimated online);
- ``front axle``: the front-axle estimator (``config/road_force_estimator.yaml``, the
  model observer, :class:`.estimation.estimator.Estimator` / :func:`.estimation.offline.
  smooth`) on the front axle's two deflections and the tractor's roll, the loads of its two
  wheels.

Printed per drive and mode: per axle the RMS over both wheels of the dynamic-load error
after ``--settle`` s, in % of the true dynamic-load RMS (the load less the static load) of
the same samples.
"""
from __future__ import annotations

import argparse
import pathlib
import sys
import time

import numpy as np

REPO = pathlib.Path(__file__).resolve().parents[1]
MODES = (('0 ms', 0.0, False), ('10 ms', 0.01, False), ('offline', 0.0, True))


def simulate(case, duration_s: float, noise_m: float) -> dict:
    """One drive of the family: the plant's truth and the sensors' readings."""
    from bench.articulated_drives import CONFIG
    from road_force_estimator.bagio import road_from_source
    from road_force_estimator.core.articulated_plant import simulate_articulated
    from road_force_estimator.core.articulated_setup import ArticulatedDrive
    from road_force_estimator.core.parameters import load_params_file
    from road_force_estimator.estimation.models.articulated import channel_names

    values = load_params_file(CONFIG)
    s_front = float(values.get('vehicle.axle.front.spring_half_track', 0.45))
    values.update({'simulator.road': f'iso8608:{case.road}:seed=1',
                   'simulator.speed': case.speed_mps, 'simulator.duration': duration_s,
                   'simulator.noise.deflection': noise_m,
                   'simulator.noise.roll': noise_m / s_front, **case.values})
    drive = ArticulatedDrive.from_values(values)
    sim = drive.sim
    road = road_from_source(sim.road, length_m=drive.road_length_m)
    tr = simulate_articulated(drive.vehicle, road, speed_mps=sim.speed_mps, rate_hz=sim.rate_hz,
                              duration_s=duration_s, lateral_acceleration=drive.lateral,
                              tire_envelope_m=sim.tire_envelope_length_m, model=drive.model)
    readings = drive.sensors(channel_names(drive.model)).measure(tr)
    static = drive.model.statics().output_wheel_load_n.reshape(-1)
    return {'vehicle': drive.vehicle, 't': tr.t_s, 'stamps': np.round(tr.t_s * 1e9).astype(
        np.int64), 'y': readings, 'speed': np.asarray(tr.speed_mps, float) * np.ones(len(tr)),
        'load': tr.wheel_load_n.T, 'dynamic': tr.wheel_load_n.T - static[:, None],
        'axles': drive.vehicle.axle_names}


def error_pct(t, est_dyn: np.ndarray, true_dyn: np.ndarray, settle_s: float) -> np.ndarray:
    """Per axle (pairs of rows): RMS error over both wheels, % of the true dynamic RMS."""
    judged = t >= t[0] + settle_s
    err = (est_dyn - true_dyn)[:, judged].reshape(-1, 2, int(judged.sum()))
    ref = true_dyn[:, judged].reshape(-1, 2, int(judged.sum()))
    return 100.0 * np.sqrt(np.mean(err ** 2, axis=(1, 2)) / np.mean(ref ** 2, axis=(1, 2)))


def front_axle(drive: dict, latency_s: float, offline: bool) -> np.ndarray:
    """The front-axle estimator on the front axle: its two wheels' dynamic tire forces
    (2, m)."""
    from road_force_estimator.core.parameters import (
        ObserverParameters, VehicleParameters, load_params_file)
    from road_force_estimator.estimation.estimator import Estimator
    from road_force_estimator.estimation.offline import smooth

    values = load_params_file(REPO / 'config' / 'road_force_estimator.yaml')
    vehicle = VehicleParameters.from_parameters(values)
    observer = ObserverParameters.from_parameters({**values, 'observer.latency': latency_s})
    roll = drive['y'].shape[1] - (2 if drive['vehicle'].trailer_roll_sensor else 1)
    q, phi = drive['y'][:, :2], drive['y'][:, roll]
    stamps, v = drive['stamps'], drive['speed']
    if offline:
        return smooth(stamps, q, phi, v, vehicle, observer).tire_force_dynamic_n.T
    est = Estimator(vehicle, observer)
    out = {}
    for s, qi, pi, vi in zip(stamps.tolist(), q.tolist(), phi.tolist(), v.tolist()):
        e = est.update(s, qi, pi, vi)
        if e is not None:
            out[e.stamp_ns] = e.tire_force_dynamic_n
    for e in est.flush():
        out[e.stamp_ns] = e.tire_force_dynamic_n
    return np.array([out[s] for s in stamps.tolist()]).T


def run(case, args) -> list[str]:
    """The table's lines of one drive."""
    from road_force_estimator.estimation.articulated import estimate_articulated

    drive = simulate(case, args.duration, args.noise)
    lines = []
    for label, latency, offline in MODES:
        start = time.perf_counter()
        est = estimate_articulated(drive['vehicle'], drive['stamps'], drive['y'],
                                   drive['speed'], latency_s=latency, offline=offline)
        wall = time.perf_counter() - start
        pct = error_pct(drive['t'], est.dynamic_n, drive['dynamic'], args.settle)
        front = front_axle(drive, latency, offline)
        fpct = error_pct(drive['t'], front, drive['dynamic'][:2], args.settle)[0]
        cells = ' | '.join(f'{p:.1f}' for p in pct)
        lines.append(f'| {case.name} | {label} | {cells} | {fpct:.1f} | {wall:.1f} |')
    return lines


def main(argv: list[str] | None = None) -> int:
    from bench.articulated_drives import family

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--duration', type=float, default=25.0, help='each drive (s)')
    parser.add_argument('--only', nargs='*', default=['A20', 'C20'], metavar='NAME')
    parser.add_argument('--noise', type=float, default=1e-5, help='deflection noise (m)')
    parser.add_argument('--settle', type=float, default=5.0, help='judged after (s)')
    args = parser.parse_args(argv)
    cases = [c for c in family() if c.name in args.only]
    out = []
    for case in cases:
        out += run(case, args)
    from road_force_estimator.core.articulated_setup import ArticulatedDrive
    from road_force_estimator.core.parameters import load_params_file
    from bench.articulated_drives import CONFIG
    names = ArticulatedDrive.from_values(load_params_file(CONFIG)).vehicle.axle_names
    print(f'Articulated observer, {args.duration:g} s drives at 1 kHz, {args.noise * 1e6:g} um '
          f'noise, judged after {args.settle:g} s: dynamic-load RMS error, % of the true '
          'dynamic-load RMS, per axle (both wheels)\n')
    head = ' | '.join(names)
    print(f'| drive | mode | {head} | front-axle estimator, front axle | wall (s) |')
    print('|---|---|' + '---:|' * (len(names) + 2))
    print('\n'.join(out))
    return 0


if __name__ == '__main__':
    sys.exit(main())
