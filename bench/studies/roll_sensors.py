"""The roll sensor's physics and the IMU in the observer (issues 30 and 32): what a pendulum
inclinometer, a drifting gyro and a road crossfall cost the load estimate with the observer
told nothing, what ``vehicle.roll_sensor: pendulum`` gives back, and what the tractor IMU's
a_y does for the trailer's rollover estimate.

Run from the repository root::

    .venv/bin/python -m bench.studies.roll_sensors [--parts front whole rollover warning bag]
        [--duration 20]

Drives at 20 m/s, 1 kHz, 10 um on every deflection and 10 um over the front half spring track
on the rolls (the benchmark's convention), ISO 8608 roads seed 1, straight or through the
family's curve (``curve:start=5,ramp=3,hold=6,ay=3``: a_y ramped over 3 s from 5 s to
3 m/s^2, held 6 s). Roll sensors (``simulator.roll_sensor``): ``ideal``; ``pendulum``
(``phi + a_y / g``); ``gyro`` drifting by :data:`GYRO_DRIFT_RADPS`; ``crossfall``: the ideal
sensor on a road with :data:`CROSSFALL_RAD` of crossfall. The figure: per axle (front-axle
model: its one axle) the RMS over both wheels of the load error, % of the true dynamic-load
RMS, after 2 s; the whole vehicle's worst axle. Modes: zero latency, ``observer.latency``
0.01 s, offline.

- ``front``: the front-axle model (``bench.accuracy.scenarios``' plant and sensors) on classes
  A and C, straight and curve, each sensor with the file told nothing (for the front axle
  ``vehicle.roll_sensor: pendulum`` is the same model: docs/sensors.md).
- ``whole``: the same with the whole vehicle (``config/tractor_semitrailer.yaml``; both units'
  roll sensors of the kind), and the pendulums again with the tractor IMU's a_y, the file
  told nothing and stating them (``vehicle.roll_sensor: pendulum``; without the IMU the
  statement reads them as phi, as told nothing).
- ``warning``: the trailer's 0.6 warning on its quasi-static LTR and on the predictor
  (:mod:`road_force_estimator.estimation.rollover_warning`), without and with the IMU, and
  the predictor's largest rise over the quasi-static LTR on straight drives.
- ``rollover``: the family's curve on classes C and B, the ideal roll sensors, the estimate
  without and with the tractor IMU's a_y (``imu=True``, the plant's IMU with its default noise
  0.05 m/s^2): the trailer's quasi-static LTR's worst error after 3 s against the truth's
  (the plant's loads through :mod:`road_force_estimator.core.unit_loads`), its instantaneous
  LTR's RMS error, the worst axle's load error, and when the estimate and the truth first
  reach 0.6.

- ``bag``: the pendulums with the tractor IMU through ``estimate_bag``: the curve on classes
  A and C written by ``simulate_bag`` (the same plant, sensors and IMU, ``vehicle.tractor_imu:
  true`` and ``vehicle.roll_sensor: pendulum`` in the file it is given), estimated by
  ``estimate_bag`` from that bag in each mode (its ``/wheel_loads``, the IMU read from
  ``/imu/tractor``): the worst axle's load error beside ``whole``'s in-process figure, the
  samples without a fresh a_y, and whether the two estimates are the same numbers.

What it found: docs/notes/roll_sensors.md.
"""
from __future__ import annotations

import argparse
from dataclasses import replace
import pathlib
import sys
import tempfile
import time

import numpy as np

REPO = pathlib.Path(__file__).resolve().parents[2]
CONFIG = REPO / 'config' / 'tractor_semitrailer.yaml'
CURVE = 'curve:start=5,ramp=3,hold=6,ay=3'
#: The gyro's rate bias (rad/s): 0.03 deg/s, a MEMS gyro's run-to-run bias.
GYRO_DRIFT_RADPS = 5e-4
#: The road's crossfall (rad): 3 %, a little more than a carriageway's 2.5 %.
CROSSFALL_RAD = 0.03
NOISE_M = 1e-5
SETTLE_S = 2.0
MODES = (('0 ms', 0.0, False), ('10 ms', 0.01, False), ('offline', 0.0, True))
#: (label, plant's simulator values)
SENSORS = (('ideal', {}),
           ('pendulum', {'simulator.roll_sensor': 'pendulum'}),
           ('gyro', {'simulator.roll_sensor': 'gyro',
                     'simulator.roll_gyro_drift': GYRO_DRIFT_RADPS}),
           ('crossfall', {'simulator.road_crossfall': CROSSFALL_RAD}))


def _pct(err: np.ndarray, true_dyn: np.ndarray) -> float:
    """RMS of ``err`` over RMS of ``true_dyn`` (%), over every element."""
    return 100.0 * float(np.sqrt(np.mean(err ** 2) / np.mean(true_dyn ** 2)))


# -- the front axle ----------------------------------------------------------------------------
def front_drive(road: str, curve: bool, values: dict, duration_s: float) -> dict:
    """One front-axle drive: the truth and the readings."""
    from bench.accuracy import scenarios as sc
    from road_force_estimator.core.lateral_profile import parse_lateral_profile
    from road_force_estimator.core.parameters import SimulatorParameters, VehicleParameters
    from road_force_estimator.core.plant import simulate
    from road_force_estimator.core.roll_sensors import RollSensor
    from road_force_estimator.core.sensors import SensorModel

    truck = VehicleParameters()
    sim = SimulatorParameters.from_parameters(values)
    base = replace(sc.SCENARIOS[0], name=f'roll-{road}', road=road, duration_s=duration_s)
    length = base.speed_mps * duration_s + 10.0 + sc.TIRE_ENVELOPE_M
    lateral = parse_lateral_profile(CURVE) if curve else None
    tr = simulate(truck, sc.scenario_road(base, length), speed_mps=base.speed_mps,
                  rate_hz=base.rate_hz, duration_s=duration_s,
                  tire_envelope_m=sc.TIRE_ENVELOPE_M, lateral_acceleration=lateral,
                  crossfall_rad=sim.road_crossfall_rad)
    roll = RollSensor.from_simulator(sim)
    sensor = SensorModel(deflection_std_m=NOISE_M,
                         roll_std_rad=sc.ROLL_NOISE_PER_DEFLECTION * NOISE_M,
                         seed=base.noise_seed, rate_hz=base.rate_hz,
                         roll_sensor=None if roll.ideal else roll)
    q, phi = sensor.measure(tr.q_m, tr.roll_rad, np.asarray(tr.lateral_accel_mps2))
    t = np.asarray(tr.t_s)
    return {'t': t, 'stamps': np.round(t * 1e9).astype(np.int64), 'q': q, 'roll': phi,
            'speed': np.full(t.size, base.speed_mps), 'load': np.asarray(tr.wheel_load_n),
            'static': np.asarray(truck.static_load_n)}


def front_error(drive: dict, roll_sensor: str, latency_s: float, offline: bool) -> float:
    """The front axle's load error (% of the true dynamic RMS) with the file stating
    ``roll_sensor``."""
    from bench.accuracy.run_benchmark import per_sample
    from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
    from road_force_estimator.estimation import estimate_batch, estimate_recording

    vehicle = VehicleParameters(roll_sensor=roll_sensor)
    obs = ObserverParameters(latency_s=latency_s)
    args = (drive['stamps'], drive['q'], drive['roll'], drive['speed'], vehicle)
    est = (estimate_recording(*args, ObserverParameters()) if offline
           else estimate_batch(*args, obs))
    load = per_sample(est, drive['stamps']).wheel_load_n
    judged = drive['t'] >= SETTLE_S
    true = drive['load'][judged]
    return _pct(load[judged] - true, true - drive['static'])


def part_front(args) -> list[str]:
    """The front axle: each roll sensor, the file told nothing or stating the pendulum."""
    lines = ['\nThe front axle: load error (% of the true dynamic RMS, after 2 s), 0 ms / 10 ms '
             '/ offline\n', '| road | path | plant roll sensor | file | 0 ms | 10 ms | offline |',
             '|---|---|---|---|---:|---:|---:|']
    for road in ('A', 'C'):
        for curve in (False, True):
            for label, values in SENSORS:
                drive = front_drive(road, curve, values, args.duration)
                for file in ('ideal',):     # (pendulum: the same model, docs/sensors.md)
                    cells = [front_error(drive, file, lat, off) for _, lat, off in MODES]
                    lines.append(f'| {road} | {"curve" if curve else "straight"} | {label} | '
                                 f'{file} | ' + ' | '.join(f'{c:.2f}' for c in cells) + ' |')
                    print(lines[-1], file=sys.stderr, flush=True)
    return lines


# -- the whole vehicle -------------------------------------------------------------------------
def whole_drive(road: str, curve: bool, values: dict, duration_s: float) -> dict:
    """One drive of the file's combination: the truth, the readings and the IMU."""
    from road_force_estimator.core.articulated_setup import ArticulatedDrive
    from road_force_estimator.core.parameters import load_params_file
    from road_force_estimator.tools.articulated_simulation import simulate

    base = load_params_file(CONFIG)
    s_front = float(base.get('vehicle.axle.front.spring_half_track', 0.45))
    base.update({'simulator.road': f'iso8608:{road}:seed=1', 'simulator.speed': 20.0,
                 'simulator.duration': duration_s, 'simulator.noise.deflection': NOISE_M,
                 'simulator.noise.roll': NOISE_M / s_front, 'simulator.gnss.rate': 0.0,
                 'vehicle.tractor_imu': True, **values})
    if curve:
        base['simulator.lateral_profile'] = CURVE
    with tempfile.TemporaryDirectory():
        drive = ArticulatedDrive.from_values(base)
    res = simulate(drive, route=None)
    t = res.trajectory.t_s
    return {'t': t, 'stamps': np.round(t * 1e9).astype(np.int64), 'y': res.readings,
            'ay': res.imu[:, 1], 'speed': np.full(t.size, 20.0),
            'load': res.trajectory.wheel_load_n.T, 'ltr': res.truth['unit_ltr'],
            'static': drive.model.statics().output_wheel_load_n.reshape(-1)}


def file_vehicle(values: dict):
    """The estimator's vehicle: the file's with ``values``."""
    from road_force_estimator.core.articulated_setup import ArticulatedDrive
    from road_force_estimator.core.parameters import load_params_file

    base = load_params_file(CONFIG)
    base.update(values)
    return ArticulatedDrive.from_values(base).vehicle


def whole_estimate(vehicle, drive: dict, latency_s: float, offline: bool, imu: bool = False):
    """:func:`.estimate_whole_vehicle` in one mode, with the IMU's a_y as a channel or not."""
    from road_force_estimator.core.parameters import ObserverParameters
    from road_force_estimator.estimation.whole_vehicle import estimate_whole_vehicle

    y = np.column_stack([drive['y'], drive['ay']]) if imu else drive['y']
    return estimate_whole_vehicle(vehicle, drive['stamps'], y, drive['speed'],
                                  observer=ObserverParameters(latency_s=latency_s),
                                  offline=offline, imu=imu)


def whole_errors(drive: dict, est, settle_s: float = SETTLE_S) -> np.ndarray:
    """Per axle the load error (% of the true dynamic RMS, RMS over both wheels)."""
    judged = drive['t'] >= settle_s
    err = (est.load_n - drive['load'])[:, judged].reshape(-1, 2, int(judged.sum()))
    dyn = (drive['load'] - drive['static'][:, None])[:, judged].reshape(err.shape)
    return 100.0 * np.sqrt(np.mean(err ** 2, axis=(1, 2)) / np.mean(dyn ** 2, axis=(1, 2)))


def part_whole(args) -> list[str]:
    """The whole vehicle: each roll sensor, the file told nothing or stating the pendulum."""
    lines = ["\nThe whole vehicle: the worst axle's load error (% of its true dynamic RMS, "
             'after 2 s), 0 ms / 10 ms / offline\n',
             '| road | path | plant roll sensors | file | 0 ms | 10 ms | offline |',
             '|---|---|---|---|---:|---:|---:|']
    for road in ('A', 'C'):
        for curve in (False, True):
            for label, values in SENSORS:
                drive = whole_drive(road, curve, values, args.duration)
                files = ((('ideal', False), ('ideal', True), ('pendulum', True))
                         if label == 'pendulum' else (('ideal', False),))
                for file, imu in files:
                    vehicle = file_vehicle({'vehicle.roll_sensor': file})
                    cells = [float(np.max(whole_errors(drive, whole_estimate(
                        vehicle, drive, lat, off, imu)))) for _, lat, off in MODES]
                    lines.append(f'| {road} | {"curve" if curve else "straight"} | {label} | '
                                 f'{file}{" + IMU" if imu else ""} | '
                                 + ' | '.join(f'{c:.2f}' for c in cells) + ' |')
                    print(lines[-1], file=sys.stderr, flush=True)
    return lines


def rollover_figures(drive: dict, est) -> dict:
    """The trailer's QS LTR worst error after 3 s, its instantaneous LTR's RMS error after
    3 s, the worst axle's load error, when the estimate and the truth first reach 0.6 (s) and
    the estimate when the truth does."""
    t = drive['t']
    judged = t >= 3.0
    true_qs, true_ltr = drive['ltr'][:, 3], drive['ltr'][:, 2]
    qs, ltr = est.ltr_quasi_static[1], est.ltr[1]
    k_true = int(np.argmax(true_qs >= 0.6)) if np.any(true_qs >= 0.6) else None
    k_est = int(np.argmax(qs >= 0.6)) if np.any(qs >= 0.6) else None
    return {'qs': float(np.max(np.abs(qs - true_qs)[judged])),
            'ltr': float(np.sqrt(np.mean((ltr - true_ltr)[judged] ** 2))),
            'load': float(np.max(whole_errors(drive, est))),
            't_est': np.nan if k_est is None else float(t[k_est]),
            't_true': np.nan if k_true is None else float(t[k_true]),
            'then': np.nan if k_true is None else float(qs[k_true])}


def part_rollover(args) -> list[str]:
    """The trailer's LTR through the curve without and with the IMU."""
    lines = ["\nRollover: the family's curve, 20 s, ideal roll sensors; the trailer's "
             'quasi-static LTR (worst error after 3 s), its instantaneous LTR (RMS error after '
             "3 s), the worst axle's load error (%), when the estimate and the truth first "
             'reach 0.6 (s) and the estimate then\n',
             '| road | mode | IMU | QS LTR worst | LTR RMS | load (%) | 0.6: estimate | '
             'truth | estimate then |', '|---|---|---|---:|---:|---:|---:|---:|---:|']
    vehicle = file_vehicle({})
    for road in ('C', 'B'):
        drive = whole_drive(road, True, {}, 20.0)
        for label, lat, off in MODES:
            for imu in (False, True):
                f = rollover_figures(drive, whole_estimate(vehicle, drive, lat, off, imu))
                lines.append(f'| {road} | {label} | {"yes" if imu else "no"} | {f["qs"]:.4f} | '
                             f'{f["ltr"]:.4f} | {f["load"]:.2f} | {f["t_est"]:.3f} | '
                             f'{f["t_true"]:.3f} | {f["then"]:.4f} |')
                print(lines[-1], file=sys.stderr, flush=True)
    return lines


def part_warning(args) -> list[str]:
    """The 0.6 warning on the quasi-static LTR and on the predictor, without and with the IMU;
    on straight drives the predictor's largest rise over the quasi-static LTR."""
    from road_force_estimator.estimation.rollover_warning import (
        LEAD_S, first_reached, predicted_ltr)

    lines = [f"\nThe 0.6 warning: the family's curve, 20 s; the trailer's quasi-static LTR and "
             f'the predictor ({LEAD_S * 1e3:g} ms lead): when each first reaches 0.6 against '
             "the truth's quasi-static LTR (ms, < 0 = earlier), their worst error after 3 s "
             "against the truth's quasi-static LTR\n",
             '| road | mode | IMU | QS: lateness (ms) | QS worst | predictor: lateness (ms) | '
             'predictor worst |', '|---|---|---|---:|---:|---:|---:|']
    vehicle = file_vehicle({})
    for road in ('C', 'B'):
        drive = whole_drive(road, True, {}, 20.0)
        t = drive['t']
        judged = t >= 3.0
        true_qs = drive['ltr'][:, 3]
        k_true = first_reached(true_qs)
        for label, lat, off in MODES[:2]:
            for imu in (False, True):
                est = whole_estimate(vehicle, drive, lat, off, imu)
                qs = est.ltr_quasi_static[1]
                pred = predicted_ltr(est.stamps_ns, qs)
                cells = []
                for series in (qs, pred):
                    k = first_reached(series)
                    late = np.nan if k is None or k_true is None else 1e3 * (t[k] - t[k_true])
                    cells += [f'{late:+.0f}', f'{np.max(np.abs(series - true_qs)[judged]):.4f}']
                lines.append(f'| {road} | {label} | {"yes" if imu else "no"} | '
                             + ' | '.join(cells) + ' |')
                print(lines[-1], file=sys.stderr, flush=True)
    lines += ['\nStraight drives (20 s, ideal sensors): the predictor less the quasi-static LTR, '
              "its largest value after 3 s (a false alarm's margin)\n",
              '| road | mode | trailer QS peak | predictor - QS, max |', '|---|---|---:|---:|']
    for road in ('C', 'A'):
        drive = whole_drive(road, False, {}, 20.0)
        judged = drive['t'] >= 3.0
        for label, lat, off in MODES[:2]:
            est = whole_estimate(vehicle, drive, lat, off)
            qs = est.ltr_quasi_static[1]
            pred = predicted_ltr(est.stamps_ns, qs)
            lines.append(f'| {road} | {label} | {np.max(np.abs(qs[judged])):.4f} | '
                         f'{np.max((pred - qs)[judged]):.4f} |')
            print(lines[-1], file=sys.stderr, flush=True)
    return lines


def params_yaml(values: dict, path: pathlib.Path) -> pathlib.Path:
    """A parameter file (every node's) holding the flat ``values``."""
    import yaml

    nested: dict = {}
    for name, value in values.items():
        node = nested
        *parents, leaf = name.split('.')
        for key in parents:
            node = node.setdefault(key, {})
        node[leaf] = list(value) if isinstance(value, tuple) else value
    path.write_text(yaml.safe_dump({'/**': {'ros__parameters': nested}}))
    return path


def bag_loads(folder: pathlib.Path) -> tuple[np.ndarray, np.ndarray]:
    """``/wheel_loads``' stamps (ns) and loads ((wheels, m), N) of an estimate bag."""
    from road_force_estimator.bagio.reader import read_topic_columns
    from road_force_estimator.interfaces import JOINT_STATE, WHEEL_LOADS

    cols = read_topic_columns(folder, {WHEEL_LOADS: JOINT_STATE})[WHEEL_LOADS]
    stamps = np.asarray(cols.stamps_ns()[0], np.int64)
    loads = np.full((cols.count, 10), np.nan)
    for g in cols.groups:
        loads[g.index] = g.columns['effort']
    return stamps, loads.T


def part_bag(args) -> list[str]:
    """The pendulums and the IMU through simulate_bag and estimate_bag, beside in process."""
    from road_force_estimator.core.parameters import load_params_file
    from road_force_estimator.tools import estimate_bag, simulate_bag

    lines = ["\nThe whole vehicle through estimate_bag (pendulum roll sensors, the tractor IMU, "
             "the curve): the worst axle's load error (% of its true dynamic RMS, after 2 s)\n",
             '| road | mode | in process | estimate_bag | samples without a fresh a_y | '
             'same numbers |', '|---|---|---:|---:|---:|---|']
    stated = {'vehicle.roll_sensor': 'pendulum'}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        for road in ('A', 'C'):
            drive = whole_drive(road, True, {'simulator.roll_sensor': 'pendulum'},
                                args.duration)
            base = load_params_file(CONFIG)
            s_front = float(base.get('vehicle.axle.front.spring_half_track', 0.45))
            base.update({'simulator.noise.deflection': NOISE_M,
                         'simulator.noise.roll': NOISE_M / s_front,
                         'simulator.lateral_profile': CURVE, 'vehicle.tractor_imu': True,
                         'simulator.roll_sensor': 'pendulum', **stated})
            params = params_yaml(base, tmp / f'{road}.yaml')
            bag = tmp / f'drive_{road}'
            code = simulate_bag.main([
                '--params-file', str(params), '--road', f'iso8608:{road}:seed=1', '--speed',
                '20', '--rate', '1000', '--duration', str(args.duration), '--gnss-rate', '0',
                '--no-progress', '--output', str(bag)])
            assert code == 0, code
            vehicle = file_vehicle(stated)
            for label, lat, off in MODES:
                ref = whole_estimate(vehicle, drive, lat, off, imu=True)
                out = tmp / f'est_{road}_{label.replace(" ", "")}'
                code = estimate_bag.main([
                    str(bag), '--params-file', str(params), '-p', f'observer.latency:={lat}',
                    '--output', str(out), '--mode', 'offline' if off else 'online',
                    '--no-figures', '--no-progress'])
                assert code == 0, code
                import json
                report = json.loads((out / 'report' / 'report.json').read_text())
                imu = report['whole_vehicle_estimate']['tractor_imu']
                stamps, loads = bag_loads(out / 'bag')
                assert stamps.size == drive['stamps'].size
                via = replace(ref, load_n=loads)
                cells = [float(np.max(whole_errors(drive, e))) for e in (ref, via)]
                same = ('bit for bit' if np.array_equal(loads, ref.load_n) else
                        f'within {np.max(np.abs(loads - ref.load_n)):.2g} N')
                lines.append(f'| {road} | {label} | {cells[0]:.2f} | {cells[1]:.2f} | '
                             f'{imu["stale"] + imu["missing"]} | {same} |')
                print(lines[-1], file=sys.stderr, flush=True)
    return lines


PARTS = {'front': part_front, 'whole': part_whole, 'rollover': part_rollover,
         'warning': part_warning, 'bag': part_bag}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--parts', nargs='*', default=[p for p in PARTS if p != 'bag'],
                        choices=list(PARTS))
    parser.add_argument('--duration', type=float, default=20.0,
                        help='seconds per drive of front and whole (rollover: 20)')
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    for part in args.parts:
        print('\n'.join(PARTS[part](args)), flush=True)
    print(f'\n({time.perf_counter() - t0:.0f} s)')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
