"""The "real truck" benchmark family (issue 19): drives that the estimator's own model does not
make, each estimated with three parameter files, our observer beside the Kalman peers.

``.venv/bin/python -m bench.accuracy.real_truck [--duration S] [--drives a b ...] [--json FILE]``

prints a Markdown table for the README (and writes the JSON of every figure).

Drives (:data:`DRIVES`; ISO 8608 class C unless said, 20 m/s, 1 kHz, 10 um / 0.1 mrad noise,
road seed 1, 10 s (``--duration``); the truth's parameters by their dotted names, so that
the plant takes each effect from the package's parameter table):

- (a) ``payload+40``: sprung mass and roll inertia 40 % above nominal, the deflections read
  from the mechanical zero (``vehicle.deflection_reference: zero_load``);
- (b) ``friction-A``, ``friction-C``: leaf-spring friction 1.5 kN per side
  (``vehicle.leaf_spring_friction``) on class A and class C;
- (c) ``stop``: braking at 5 m/s^2 to a stop, standing 10 s, pulling away (bench C20-stop);
- (d) ``sensors``: a 3 ms first-order lag (``vehicle.sensor_time_constant``), scale errors
  of +2 / -2 / +2 % (``simulator.sensor_scale_error.*``) and +-50 us stamp jitter
  (``simulator.stamp_jitter``);
- (e) ``params-15``: every dynamic parameter off by 15 %, signs from a fixed seeded draw
  (:data:`PARAM_SEED`), the static loads the truth's (weighed);
- (f) ``all``: (a) to (e) at once, with a shorter stop (4 s standing, 20 s in all).

A drive whose parameter is not in :data:`road_force_estimator.core.parameters.SPECS` yet is
listed as "needs <name>" and skipped.

Files (what the estimators are told): ``nominal`` (the package defaults, the truth's static
loads unless the deflections are read from the mechanical zero, the truth's deflection
reference), ``stated`` (nominal + the friction and the sensor lag of the truth, what
calibration gives; shown only where it differs from nominal) and ``true`` (the truth's
parameters). Columns: our observer at zero latency, 10 ms (``observer.latency``) and offline
(what ``estimate_bag --mode offline`` runs), the sliding-mode ablation
(``observer.sliding_mode_gain = 0``, zero latency), the peers ``kf-model``,
``kf-model-lag10ms``, ``kf-model-rts`` (settings of ``bench/accuracy/tuned_peers.json``) given the
same file (a sensor lag the file states: their model's lag states, :class:`bench.accuracy.peers.
RollPlaneKalman`; deflections read from the mechanical zero: taken back to the file's
equilibrium, its static loads, which the peers cannot estimate); load error in % of the true
dynamic-load RMS, profile error in % of the 0.5-30 m band (:func:`bench.accuracy.scenarios.score`);
the model-fit verdict (:mod:`road_force_estimator.estimation.fit_check`) of the zero-latency run.
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass, field, fields, replace
import json
import math
from pathlib import Path
import sys
import time
from typing import Any

import numpy as np

from bench.accuracy import peers, tune
from bench.accuracy.run_benchmark import g3, per_sample
from bench.accuracy.scenarios import (
    ROLL_NOISE_PER_DEFLECTION, TIRE_ENVELOPE_M, Drive, Scenario, scenario_road, score)

__all__ = ['TruckDrive', 'DRIVES', 'PARAM_SEED', 'FILES', 'METHODS', 'missing', 'truth_vehicle',
           'build', 'files_for', 'estimate_ours', 'run_drive', 'markdown', 'main']

#: Seed of the signs of (e).
PARAM_SEED = 15
#: Dynamic parameters of (e), by their dotted names.
PERTURBED = ('vehicle.sprung_mass', 'vehicle.roll_inertia', 'vehicle.cg_height_above_roll_axis',
             'vehicle.unsprung_mass', 'vehicle.suspension_stiffness',
             'vehicle.suspension_damping', 'vehicle.tire_stiffness')
#: The stop of (c): bench scenario C20-stop's speed profile (time_s, speed_mps).
STOP_PROFILE = ((0.0, 8.0, 12.0, 22.0, 26.0, 34.0), (20.0, 20.0, 0.0, 0.0, 20.0, 20.0))
#: The stop of (f), shorter (the run time): braking at 5 m/s^2, standing 4 s, pulling away.
SHORT_STOP_PROFILE = ((0.0, 5.0, 9.0, 13.0, 17.0, 20.0), (20.0, 20.0, 0.0, 0.0, 20.0, 20.0))
#: What the "stated" file takes from the truth (what calibration gives).
STATED = ('vehicle.leaf_spring_friction', 'vehicle.sensor_time_constant')
FILES = ('nominal', 'stated', 'true')
#: Columns: (name, kind, latency in the table).
METHODS = (('ours', 'online', '0'), ('ours-10ms', 'latency', '10 ms'),
           ('ours-offline', 'offline', 'offline'), ('ours-no-smo', 'no-smo', '0'),
           ('kf-model', 'peer', '0'), ('kf-model-lag10ms', 'peer', '10 ms'),
           ('kf-model-rts', 'peer', 'offline'))


@dataclass(frozen=True)
class TruckDrive:
    """One drive of the family: the truth as dotted parameters (``vehicle.*``: the plant's
    vehicle, ``simulator.*``: the sensors), the road class, the speed or a speed profile."""

    key: str
    name: str
    description: str
    truth: dict[str, Any] = field(default_factory=dict)
    road: str = 'C'
    speed_profile: tuple | None = None
    perturb: float = 0.0
    duration_s: float | None = None


def _drives() -> tuple[TruckDrive, ...]:
    payload = {'vehicle.sprung_mass': 7000.0, 'vehicle.roll_inertia': 4200.0,
               'vehicle.deflection_reference': 'zero_load'}
    friction = {'vehicle.leaf_spring_friction': [1500.0, 1500.0]}
    sensors = {'vehicle.sensor_time_constant': [0.003, 0.003],
               'simulator.sensor_scale_error.deflection': [0.02, -0.02],
               'simulator.sensor_scale_error.roll': 0.02, 'simulator.stamp_jitter': 5e-5}
    return (
        TruckDrive('a', 'payload+40', 'payload +40 %, deflections from the mechanical zero',
                   payload),
        TruckDrive('b', 'friction-A', 'leaf-spring friction 1.5 kN per side, class A',
                   friction, road='A'),
        TruckDrive('b', 'friction-C', 'leaf-spring friction 1.5 kN per side, class C',
                   friction),
        TruckDrive('c', 'stop', 'braking at 5 m/s^2 to a stop, 10 s standing, pulling away',
                   speed_profile=STOP_PROFILE, duration_s=34.0),
        TruckDrive('d', 'sensors', '3 ms sensor lag, scale errors +-2 %, stamp jitter +-50 us',
                   sensors),
        TruckDrive('e', 'params-15', f'every parameter off by 15 % (signs: seed {PARAM_SEED})',
                   perturb=0.15),
        TruckDrive('f', 'all', '(a) to (e) at once (the stop: 4 s standing)',
                   {**payload, **friction, **sensors}, speed_profile=SHORT_STOP_PROFILE,
                   perturb=0.15, duration_s=20.0),
    )


DRIVES: tuple[TruckDrive, ...] = _drives()


def _field_of(cls, param: str) -> str | None:
    for f in fields(cls):
        if f.metadata.get('param') == param:
            return f.name
    return None


def missing(drive: TruckDrive) -> list[str]:
    """Parameters of the drive the package does not have yet (not in SPECS)."""
    from road_force_estimator.core.parameters import SPECS
    return [name for name in drive.truth if name not in SPECS]


def _apply(obj, values: dict[str, Any]):
    """``obj`` (a parameters dataclass) with dotted parameters replaced (tuples for lists)."""
    kwargs = {}
    for param, value in values.items():
        name = _field_of(type(obj), param)
        if name is not None:
            kwargs[name] = tuple(value) if isinstance(value, list) else value
    return replace(obj, **kwargs) if kwargs else obj


def _perturbation(frac: float) -> dict[str, Any]:
    """Every parameter of :data:`PERTURBED` times 1 +- frac (signs: :data:`PARAM_SEED`)."""
    from road_force_estimator.core.parameters import VehicleParameters
    nominal = VehicleParameters()
    rng = np.random.default_rng(PARAM_SEED)
    out: dict[str, Any] = {}
    for param in PERTURBED:
        value = getattr(nominal, _field_of(VehicleParameters, param))
        if isinstance(value, tuple):
            out[param] = [v * (1.0 + frac * float(rng.choice([-1.0, 1.0]))) for v in value]
        else:
            out[param] = value * (1.0 + frac * float(rng.choice([-1.0, 1.0])))
    return out


def truth_vehicle(drive: TruckDrive):
    """``(VehicleParameters, SimulatorParameters)`` of the drive's truth."""
    from road_force_estimator.core.parameters import SimulatorParameters, VehicleParameters
    values = dict(drive.truth)
    if drive.perturb:
        base = _perturbation(drive.perturb)
        for name in ('vehicle.sprung_mass', 'vehicle.roll_inertia'):
            if name in values:   # the payload on top of the perturbed truck
                nominal = getattr(VehicleParameters(), _field_of(VehicleParameters, name))
                base[name] = base[name] * values.pop(name) / nominal
        values = {**base, **values}
    sim = _apply(SimulatorParameters(), {'simulator.noise.deflection': 1e-5,
                                         'simulator.noise.roll': 1e-5
                                         * ROLL_NOISE_PER_DEFLECTION, 'simulator.seed': 7,
                                         **{k: v for k, v in values.items()
                                            if k.startswith('simulator.')}})
    vehicle = _apply(VehicleParameters(), {k: v for k, v in values.items()
                                           if k.startswith('vehicle.')})
    # the static loads stated as they are (the same physics: a file can equal the truth)
    return replace(vehicle, static_load_setting_n=tuple(vehicle.static_load_n)), sim


def _sensors(sim, vehicle):
    from road_force_estimator.core.sensors import SensorModel
    try:
        return SensorModel.from_simulator(sim, vehicle)
    except TypeError:        # a package whose sensors know no vehicle (no lag, no zero)
        return SensorModel.from_simulator(sim)


def build(drive: TruckDrive, duration_s: float) -> tuple[Drive, np.ndarray]:
    """The drive simulated and measured: ``(Drive, stamps_ns)`` (stamps with the jitter)."""
    from road_force_estimator.core.plant import simulate
    vehicle, sim = truth_vehicle(drive)
    duration = drive.duration_s if drive.duration_s is not None else duration_s
    sc = Scenario(drive.name, road=drive.road, duration_s=duration, noise_deflection_m=1e-5,
                  noise_seed=sim.seed, speed_profile=drive.speed_profile,
                  description=drive.description)
    road = scenario_road(sc, 20.0 * duration + 10.0 + TIRE_ENVELOPE_M)
    traj = simulate(vehicle, road, speed_mps=20.0, rate_hz=1000.0, duration_s=duration,
                    tire_envelope_m=TIRE_ENVELOPE_M, speed_profile=drive.speed_profile)
    sensors = _sensors(sim, vehicle)
    q, phi = sensors.measure(np.asarray(traj.q_m), np.asarray(traj.roll_rad))
    t = np.asarray(traj.t_s, dtype=float)
    jitter = getattr(sensors, 'stamp_offsets_s', lambda n: np.zeros(n))(t.size)
    stamps = np.round((t + jitter) * 1e9).astype(np.int64)
    load = np.asarray(traj.wheel_load_n, dtype=float)
    truth = {'wheel_load_n': load, 'road_m': np.asarray(traj.road_m, dtype=float),
             'distance_m': np.asarray(traj.distance_m, dtype=float),
             'ltr': (load[:, 1] - load[:, 0]) / load.sum(axis=1)}
    speed = (np.full(t.size, 20.0) if drive.speed_profile is None
             else np.interp(t, *drive.speed_profile))
    return Drive(sc, t, np.asarray(q), np.asarray(phi), speed, vehicle, vehicle, truth), stamps


def files_for(drive: TruckDrive, truth) -> dict[str, Any]:
    """The parameter files of the drive: ``{'nominal', 'stated', 'true'}`` ->
    VehicleParameters, each only where it differs from those before it (the table then says
    'nominal = true' and so on)."""
    from road_force_estimator.core.parameters import VehicleParameters
    nominal = VehicleParameters()
    ref = drive.truth.get('vehicle.deflection_reference')
    if ref is not None:
        nominal = _apply(nominal, {'vehicle.deflection_reference': ref})
    if ref != 'zero_load':   # weighed: the truth's static loads
        nominal = replace(nominal, static_load_setting_n=tuple(truth.static_load_n))
    stated = _apply(nominal, {k: list(getattr(truth, _field_of(type(truth), k)))
                              for k in STATED if _field_of(type(truth), k)})
    out = {'nominal': nominal}
    if stated != nominal:
        out['stated'] = stated
    if truth != nominal and truth != stated:
        out['true'] = truth
    return out


def estimate_ours(kind: str, d: Drive, stamps: np.ndarray, vehicle):
    from road_force_estimator.core.parameters import ObserverParameters
    from road_force_estimator.estimation import estimate_batch, estimate_recording
    obs = ObserverParameters()
    if kind == 'latency':
        obs = replace(obs, latency_s=0.01)
    elif kind == 'no-smo':   # the sliding-mode term switched: off, or on (gain 1) where the
        # default has it off (since issue 30)
        obs = replace(obs, sliding_mode_gain=0.0 if obs.sliding_mode_gain else 1.0)
    fn = estimate_recording if kind == 'offline' else estimate_batch
    est = fn(stamps, d.q_m, d.roll_rad, d.speed_mps, vehicle, obs)
    return est, per_sample(est, stamps)


def _figures(d: Drive, res) -> dict[str, float]:
    f = score(d, res)
    return {'load': f['load_rms_pct_dyn'], 'profile': f['profile_rms_pct_band']}


def run_drive(drive: TruckDrive, duration_s: float, tuned: dict[str, Any], log=None
              ) -> dict[str, Any]:
    """Every file x every column on one drive: ``{'files': {file: {column: figures}},
    'model_fit': {file: [ratio, verdict]}, 'seconds': s}`` or ``{'needs': [names]}``."""
    from road_force_estimator.core.parameters import ObserverParameters
    from road_force_estimator.estimation.fit_check import assess
    need = missing(drive)
    if need:
        return {'needs': need}
    t0 = time.perf_counter()
    d, stamps = build(drive, duration_s)
    out: dict[str, Any] = {'files': {}, 'model_fit': {}}
    # the peers need an even grid: the stamps' (a 1 kHz sensor's), jitter not corrected
    grid = stamps[0] * 1e-9 + np.arange(stamps.size) * float(np.median(np.diff(stamps))) * 1e-9
    for fname, vehicle in files_for(drive, d.vehicle_plant).items():
        row: dict[str, Any] = {}
        dv = replace(d, vehicle_observer=vehicle)
        for name, kind, _ in METHODS:
            try:
                if kind == 'peer':
                    settings = tune.settings_for(tuned, name, d.scenario.noise_deflection_m)
                    # readings from the mechanical zero: the peers take them back to the
                    # file's equilibrium (its static loads), as a user of them would
                    q_peer = d.q_m - np.asarray(getattr(vehicle, 'deflection_offset_m',
                                                        (0.0, 0.0)))
                    res = peers.call_peer(name, grid, q_peer, d.roll_rad, d.speed_mps,
                                          vehicle, settings, noise_deflection_m=1e-5,
                                          noise_roll_rad=1e-4)
                else:
                    est, res = estimate_ours(kind, dv, stamps, vehicle)
                    if kind == 'online':
                        ratio, word = assess(est, vehicle, ObserverParameters(), d.speed_mps)
                        out['model_fit'][fname] = [ratio, word]
                row[name] = _figures(dv, res)
            except Exception as exc:   # noqa: BLE001 - a failing column must not stop the run
                row[name] = {'error': f'{type(exc).__name__}: {exc}'[:200]}
        out['files'][fname] = row
    out['seconds'] = time.perf_counter() - t0
    if log:
        log(f'{drive.name}: {out["seconds"]:.1f} s')
    return out


def _cell(fig: dict[str, Any], key: str) -> str:
    if 'error' in fig:
        return 'error'
    v = fig.get(key, math.nan)
    return g3(v) if isinstance(v, float) and math.isfinite(v) else 'n/a'


def markdown(results: dict[str, Any], duration_s: float) -> str:
    """The README table: one row per drive and file, load / profile error per column."""
    head = ' | '.join(f'{n} ({lat})' for n, _, lat in METHODS)
    lines = ['| drive | file | ' + head + ' | model_fit |',
             '|---|---|' + '---:|' * len(METHODS) + '---|']
    for drive in DRIVES:
        r = results.get(drive.name, {})
        label = f'({drive.key}) {drive.name}'
        if 'needs' in r:
            lines.append(f'| {label} | needs {", ".join(r["needs"])} |'
                         + ' |' * (len(METHODS) + 1))
            continue
        names = list(r.get('files', {}))
        for fname, row in r.get('files', {}).items():
            same = []     # the files after it, up to the next one present, are the same file
            for f in FILES[FILES.index(fname) + 1:]:
                if f in names:
                    break
                same.append(f)
            fname = ' = '.join([fname, *same])
            cells = ' | '.join(f'{_cell(row[n], "load")} / {_cell(row[n], "profile")}'
                               for n, _, _ in METHODS)
            ratio, word = r['model_fit'].get(fname.split(' = ')[0], [math.nan, 'n/a'])
            lines.append(f'| {label} | {fname} | {cells} | {word} ({ratio:.2f}) |')
    lines += ['', f'Cells: load error (% of the true dynamic-load RMS) / profile error (% of '
              f'the 0.5-30 m band RMS); drives of {duration_s:g} s (the stops: 34 s, (f) '
              '20 s), ISO C '
              'unless said, 20 m/s, 1 kHz, 10 um noise. model_fit: the verdict of the '
              'zero-latency run and its ratio (mismatch above 0.1). Reproduce: '
              '`.venv/bin/python -m bench.accuracy.real_truck`.']
    return '\n'.join(lines)


def ablation(results: dict[str, Any]) -> list[str]:
    """Plain lines: where the sliding-mode term changes the zero-latency load error (the
    column ``ours-no-smo`` switches it: on where the default has it off)."""
    from road_force_estimator.core.parameters import ObserverParameters
    off_by_default = ObserverParameters().sliding_mode_gain == 0.0
    out = []
    for name, r in results.items():
        for fname, row in r.get('files', {}).items():
            a, b = row.get('ours', {}).get('load'), row.get('ours-no-smo', {}).get('load')
            if isinstance(a, float) and isinstance(b, float):
                if off_by_default:
                    a, b = b, a
                out.append(f'{name} / {fname}: with {a:.3f} %, without {b:.3f} % '
                           f'({b - a:+.3f} points for the term)')
    return out


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog='bench.accuracy.real_truck',
                                description=__doc__.splitlines()[0])
    p.add_argument('--duration', type=float, default=10.0, metavar='S',
                   help='drive length (s) of the constant-speed drives (default 10)')
    p.add_argument('--drives', nargs='+', default=None, help='drive names (default all)')
    p.add_argument('--json', type=Path, default=None, help='write every figure as JSON')
    p.add_argument('--tuned', type=Path, default=tune.TUNED_PATH, help='tuned peer settings')
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    tuned = tune.load_tuned(args.tuned)
    t0 = time.perf_counter()
    results = {}
    for drive in DRIVES:
        if args.drives and drive.name not in args.drives:
            continue
        results[drive.name] = run_drive(drive, args.duration, tuned,
                                        log=lambda s: print(s, file=sys.stderr))
    print(markdown(results, args.duration))
    print('\nSliding-mode ablation (zero latency, load error):')
    for line in ablation(results):
        print(f'- {line}')
    print(f'\nwall time {time.perf_counter() - t0:.0f} s')
    if args.json:
        args.json.write_text(json.dumps(results, indent=1, default=float))
    return 0


if __name__ == '__main__':
    sys.exit(main())
