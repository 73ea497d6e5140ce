"""The whole vehicle's weigh in motion, rollover warning and spikes (issue 32): the static
loads from zero-load readings with the payload unknown, the trailer's quasi-static LTR
through a curve, and the cost of five 0.5 mm spikes, in every mode.

Run from the repository root::

    .venv/bin/python -m bench.accuracy.articulated_wim [--parts wim stick rollover spikes
        friction] [--duration 100] [--noise 1e-5] [--file-friction]

MODEL.md's combination (``config/tractor_semitrailer.yaml``) at 1 kHz, ISO 8608 roads seed 1,
10 um on every deflection and 10 um / 0.45 m on the rolls, simulated by the core plant and
read by its sensors; every estimate :func:`road_force_estimator.estimation.whole_vehicle.
estimate_whole_vehicle` with the package's settings, in each mode (zero latency, 10 ms,
offline).

- ``wim``: classes A and C, ``--duration`` s at 20 m/s, the sensors reading from the spring
  unloaded (``deflection_reference: zero_load``), the plant's trailer ``--payload-change`` kg
  off the file's (the estimator keeps the file's 29 t: the payload unknown to it) and 1.5 kN
  of ``tanh`` friction per spring in the plant (the estimator's file states none: the
  articulated observer does not model friction). Per mode: the gross weight's largest error
  after the first 200 m (% of the truth's), and per axle over the 100 m segments after the
  first 200 m the mean static estimate against the truth's static axle load: the share of
  segments within 2 % and the worst segment (%); the dynamic-load error (% of the true
  dynamic RMS, the worst axle, after 5 s) and the samples gated beside it. Zero latency and
  10 ms: offline the static loads are the same tracker's (the same numbers), and the
  smoother's gate, which the unmodelled friction keeps busy, recomputes chunk after chunk
  (more than 10 minutes for 100 s on a loaded machine). ``--file-friction``: the estimator's
  file states the plant's friction (and offline is run too).
- ``friction``: the WIM drives (classes C and A, ``--duration`` s, zero-load readings, the
  payload unknown) with 1.5 kN of tanh friction per spring, then with a 3 ms lag on every
  sensor on top, and the same drive without either: per mode and axle the dynamic-load error
  (% of the true dynamic RMS after 5 s, RMS over both wheels) with the estimator's file
  stating the plant's friction (and lag) and stating none.
- ``damping``: the articulated model's factors on the friction's equivalent damping
  (``FRICTION_DAMPING_FACTORS``) on separate drives (road seed 1001, 30 s, classes A and C,
  the WIM drives' settings with and without a 3 ms lag): the worst axle per factor.
- ``stick``: the same with the ``stick`` friction, the sliders loaded as parked
  (``simulator.leaf_spring_friction_start: 1``, MODEL.md "Friction that sticks") at the start
  of a drive at 20 m/s, zero latency (the static estimate is the same in every mode): each
  axle's static error (% of its static load) at 1, 5, 10, 20, 50 s and the time after which
  every axle stays within 2 %.
- ``rollover``: the family's curve (``C20-curve3``, ``B20-curve3``: a_y ramped over 3 s from
  5 s to 3 m/s^2, held 6 s; 20 s), the file's vehicle (readings from the equilibrium): the
  trailer's quasi-static LTR's largest error after 3 s against the truth's (its loads through
  the same recursion, :mod:`road_force_estimator.core.unit_loads`), and the times the
  estimate and the truth first reach 0.6.
- ``spikes``: C20 and A20, 20 s, three 0.5 mm spikes on ``drive_left_suspension`` and two on
  ``trailer_2_right_suspension`` from 3 s (``simulator.sensor_faults``): the worst axle's
  dynamic-load error spiked over clean (after 2 s) and the samples gated per channel.
"""
from __future__ import annotations

import argparse
import pathlib
import sys
import tempfile
import time

import numpy as np

REPO = pathlib.Path(__file__).resolve().parents[2]
CONFIG = REPO / 'config' / 'tractor_semitrailer.yaml'
MODES = (('0 ms', 0.0, False), ('10 ms', 0.01, False), ('offline', 0.0, True))
ZERO_LOAD = {'vehicle.deflection_reference': 'zero_load'}
TANH = {'vehicle.leaf_spring_friction': [1500.0, 1500.0]}
STICK = {'vehicle.leaf_spring_friction_model': 'stick',
         'vehicle.leaf_spring_friction': [1500.0, 1500.0],
         'simulator.leaf_spring_friction_start': 1.0}
CURVE = 'curve:start=5,ramp=3,hold=6,ay=3'
SPIKES = ('spikes@drive_left_suspension:count=3,size=5e-4,start=3;'
          'spikes@trailer_2_right_suspension:count=2,size=5e-4,start=3')
#: The parked start: standing 5 s, then 1 m/s^2 to 20 m/s, held.
PARKED = ((0.0, 5.0, 25.0, 1e4), (0.0, 0.0, 20.0, 20.0))
SEGMENT_M = 100.0
SKIP_M = 200.0


def simulate(road: str, duration_s: float, noise_m: float, values: dict,
             seed: int = 1, speed_profile: tuple | None = None) -> dict:
    """One drive at 20 m/s (or on ``speed_profile``: times (s), speeds (m/s)) of the file's
    combination with ``values`` on top: its truth (the plant's loads and its statics) and
    the sensors' readings."""
    from road_force_estimator.bagio import road_from_source
    from road_force_estimator.core.articulated_plant import simulate_articulated
    from road_force_estimator.core.articulated_setup import ArticulatedDrive
    from road_force_estimator.core.parameters import load_params_file
    from road_force_estimator.estimation.models.articulated import channel_names

    base = load_params_file(CONFIG)
    s_front = float(base.get('vehicle.axle.front.spring_half_track', 0.45))
    base.update({'simulator.road': f'iso8608:{road}:seed={seed}', 'simulator.speed': 20.0,
                 'simulator.duration': duration_s, 'simulator.noise.deflection': noise_m,
                 'simulator.noise.roll': noise_m / s_front, **values})
    with tempfile.TemporaryDirectory() as tmp:
        if speed_profile is not None:      # as bench.studies.articulated_drives writes it
            path = pathlib.Path(tmp) / 'speed.csv'
            path.write_text('time_s,speed_mps\n' + ''.join(
                f'{t:.6f},{v:.6f}\n' for t, v in zip(*speed_profile)))
            base['simulator.speed_profile'] = str(path)
        drive = ArticulatedDrive.from_values(base)
    sim = drive.sim
    tr = simulate_articulated(drive.vehicle, road_from_source(sim.road,
                                                              length_m=drive.road_length_m),
                              speed_mps=sim.speed_mps, rate_hz=sim.rate_hz,
                              duration_s=duration_s, speed_profile=drive.speed_profile,
                              lateral_acceleration=drive.lateral,
                              tire_envelope_m=sim.tire_envelope_length_m,
                              friction_start=sim.leaf_spring_friction_start, model=drive.model)
    y = drive.sensors(channel_names(drive.model)).measure(tr)
    static = drive.model.statics().output_wheel_load_n.reshape(-1)
    return {'t': tr.t_s, 'stamps': np.round(tr.t_s * 1e9).astype(np.int64), 'y': y,
            'speed': np.asarray(tr.speed_mps, float) * np.ones(len(tr)),
            'load': tr.wheel_load_n.T, 'static': static, 'distance': tr.distance_m,
            'bodies': [a.body for a in drive.vehicle.axles], 'vehicle': drive.vehicle}


def file_vehicle(values: dict):
    """The estimator's vehicle: the file's, with ``values`` (no payload, no friction)."""
    from road_force_estimator.core.articulated_setup import ArticulatedDrive
    from road_force_estimator.core.parameters import load_params_file

    base = load_params_file(CONFIG)
    base.update(values)
    return ArticulatedDrive.from_values(base).vehicle


def estimate(vehicle, drive: dict, latency_s: float, offline: bool):
    """:func:`.estimate_whole_vehicle` in one mode."""
    from road_force_estimator.core.parameters import ObserverParameters
    from road_force_estimator.estimation.whole_vehicle import estimate_whole_vehicle

    return estimate_whole_vehicle(vehicle, drive['stamps'], drive['y'], drive['speed'],
                                  observer=ObserverParameters(latency_s=latency_s),
                                  offline=offline)


def dynamic_pct(drive: dict, est, settle_s: float = 5.0) -> np.ndarray:
    """Per axle: RMS over both wheels of the load error, % of the true dynamic RMS."""
    judged = drive['t'] >= drive['t'][0] + settle_s
    true_dyn = (drive['load'] - drive['static'][:, None])[:, judged]
    err = (est.load_n - drive['load'])[:, judged]
    e = np.mean(err.reshape(-1, 2, err.shape[1]) ** 2, axis=(1, 2))
    r = np.mean(true_dyn.reshape(-1, 2, err.shape[1]) ** 2, axis=(1, 2))
    return 100.0 * np.sqrt(e / r)


def wim_figures(drive: dict, est) -> dict:
    """Gross weight's worst error after :data:`SKIP_M` (%), per axle the segments' share
    within 2 % and the worst segment (%)."""
    x = drive['distance'] - drive['distance'][0]
    true_axle = drive['static'].reshape(-1, 2).sum(axis=1)
    after = x >= SKIP_M
    gross = 100.0 * np.max(np.abs(est.gross_weight_n[after] / true_axle.sum() - 1.0))
    edges = np.arange(SKIP_M, x[-1] - SEGMENT_M + 1e-9, SEGMENT_M)
    seg = np.array([[np.mean(est.axle_load_n[j, (x >= a) & (x < a + SEGMENT_M)])
                     for a in edges] for j in range(true_axle.size)])
    err = 100.0 * (seg / true_axle[:, None] - 1.0)
    return {'gross': gross, 'share': 100.0 * np.mean(np.abs(err) <= 2.0, axis=1),
            'worst': np.max(np.abs(err), axis=1), 'segments': edges.size}


def part_wim(args) -> list[str]:
    """Weigh in motion with tanh friction, payload unknown."""
    payload = {'vehicle.trailer.mass': 29000.0 + args.payload_change}
    vehicle = file_vehicle({**ZERO_LOAD, **TANH} if args.file_friction else ZERO_LOAD)
    modes = MODES if args.file_friction else MODES[:2]
    lines = [f'Weigh in motion: {args.duration:g} s at 20 m/s, zero-load readings, the '
             f"plant's trailer {29000.0 + args.payload_change:g} kg (the file: 29000), "
             '1.5 kN tanh friction per spring in the plant '
             f'({"the file states it" if args.file_friction else "none in the file"}); '
             f'after the first {SKIP_M:g} m, {SEGMENT_M:g} m segments\n',
             '| road | mode | gross worst (%) | axle: segments within 2 % (%), worst segment '
             '(%) | dynamic-load error, worst axle (%) | samples gated (all channels) |',
             '|---|---|---:|---|---:|---:|']
    for road in ('C', 'A'):
        drive = simulate(road, args.duration, args.noise, {**ZERO_LOAD, **TANH, **payload})
        gross_true = drive['static'].sum() / 9.80665
        for label, lat, off in modes:       # offline: the same static loads (module notes)
            est = estimate(vehicle, drive, lat, off)
            f = wim_figures(drive, est)
            axles = ', '.join(f'{n} {s:.0f} / {w:.2f}' for n, s, w in
                              zip(est.axle_names, f['share'], f['worst']))
            lines.append(f'| {road} | {label} | {f["gross"]:.2f} | {axles} | '
                         f'{np.max(dynamic_pct(drive, est)):.1f} | '
                         f'{sum(est.innovations_gated)} |')
        lines.append(f'| {road} | truth | gross {gross_true:.0f} kg, {f["segments"]} '
                     'segments | | | |')
    return lines


def part_stick(args) -> list[str]:
    """The stick friction, sliders loaded as parked, class A and C: from 20 m/s at once (the
    family's stick drives) and from a standstill (:data:`PARKED`)."""
    payload = {'vehicle.trailer.mass': 29000.0 + args.payload_change}
    vehicle = file_vehicle(ZERO_LOAD)
    times = (1.0, 5.0, 10.0, 20.0, 30.0, 50.0)
    lines = ['\nStick friction (1.5 kN per spring, the sliders loaded as parked), the same '
             "payload, zero latency: each axle's static error (% of its static load; front, "
             'drive, trailer_1..3) at the times, and when every axle stays within 2 % (s)\n',
             '| road | start | ' + ' | '.join(f'{t:g} s' for t in times) +
             ' | within 2 % from |', '|---|---|' + '---|' * len(times) + '---:|']
    for road in ('A', 'C'):
        for start, profile in (('20 m/s', None), ('parked 5 s, 1 m/s^2', PARKED)):
            drive = simulate(road, args.duration, args.noise,
                             {**ZERO_LOAD, **STICK, **payload}, speed_profile=profile)
            est = estimate(vehicle, drive, 0.0, False)
            true_axle = drive['static'].reshape(-1, 2).sum(axis=1)
            err = 100.0 * (est.axle_load_n / true_axle[:, None] - 1.0)
            cells = []
            for t in times:
                k = min(int(np.searchsorted(drive['t'], t)), drive['t'].size - 1)
                cells.append(', '.join(f'{e:+.1f}' for e in err[:, k]))
            bad = np.nonzero(np.any(np.abs(err) > 2.0, axis=0))[0]
            settle = 0.0 if bad.size == 0 else (
                drive['t'][bad[-1] + 1] if bad[-1] + 1 < drive['t'].size else float('nan'))
            lines.append(f'| {road} | {start} | ' + ' | '.join(cells) + f' | {settle:.1f} |')
    return lines


def part_rollover(args) -> list[str]:
    """The trailer's quasi-static LTR through the curve, and the 0.6 warning."""
    from road_force_estimator.core.unit_loads import unit_load_transfer

    vehicle = file_vehicle({})
    lines = ["\nRollover: the family's curve (a_y to 3 m/s^2 over 3 s from 5 s, held 6 s), "
             "20 s; the trailer's quasi-static LTR: largest error after 3 s, the time it "
             'first reaches 0.6 (estimate, truth; s), the estimate when the truth reaches it\n',
             '| road | mode | worst error | peak (estimate / truth) | 0.6 reached: estimate | '
             'truth | estimate then |', '|---|---|---:|---|---:|---:|---:|']
    for road in ('C', 'B'):
        drive = simulate(road, 20.0, args.noise, {'simulator.lateral_profile': CURVE})
        true = unit_load_transfer(drive['bodies'], drive['static'].reshape(-1, 2), 1e-3,
                                  drive['load'].T)[:, 3]
        judged = drive['t'] >= 3.0
        k_true = int(np.argmax(true >= 0.6))
        t_true = drive['t'][k_true] if np.any(true >= 0.6) else np.nan
        for label, lat, off in MODES:
            est = estimate(vehicle, drive, lat, off)
            qs = est.ltr_quasi_static[1]
            worst = float(np.max(np.abs(qs - true)[judged]))
            t_est = drive['t'][np.argmax(qs >= 0.6)] if np.any(qs >= 0.6) else np.nan
            lines.append(f'| {road} | {label} | {worst:.4f} | {qs.max():.3f} / '
                         f'{true.max():.3f} | {t_est:.3f} | {t_true:.3f} | '
                         f'{qs[k_true]:.4f} |')
    return lines


def part_spikes(args) -> list[str]:
    """Five 0.5 mm spikes on two deflection sensors against the clean drive."""
    vehicle = file_vehicle({})
    lines = ['\nSpikes: three 0.5 mm on drive_left_suspension, two on '
             "trailer_2_right_suspension (from 3 s), 20 s; the worst axle's dynamic-load "
             'error (after 2 s) clean and spiked, the worst ratio over the axles, the samples '
             'gated (per channel, non-zero ones)\n',
             '| road | mode | clean (%) | spiked (%) | worst axle ratio | gated spiked | '
             'gated clean |', '|---|---|---:|---:|---:|---|---|']
    for road in ('C', 'A'):
        clean = simulate(road, 20.0, args.noise, {})
        spiked = simulate(road, 20.0, args.noise, {'simulator.sensor_faults': SPIKES})
        for label, lat, off in MODES:
            a, b = estimate(vehicle, clean, lat, off), estimate(vehicle, spiked, lat, off)
            pa, pb = dynamic_pct(clean, a, 2.0), dynamic_pct(spiked, b, 2.0)

            def counts(e) -> str:
                return ', '.join(f'{n} {g}' for n, g in zip(e.channel_names,
                                                             e.innovations_gated) if g) or '0'
            lines.append(f'| {road} | {label} | {pa.max():.2f} | {pb.max():.2f} | '
                         f'{np.max(pb / pa):.3f} | {counts(b)} | {counts(a)} |')
    return lines


LAG = {'vehicle.sensor_time_constant': [0.003, 0.003]}


def part_friction(args) -> list[str]:
    """The dynamic loads with the friction (and a lag) stated in the file or not."""
    payload = {'vehicle.trailer.mass': 29000.0 + args.payload_change}
    lines = [f'\nFriction and lag: the WIM drives ({args.duration:g} s at 20 m/s, zero-load '
             'readings, payload unknown); per axle the dynamic-load error (% of the true '
             'dynamic RMS after 5 s)\n',
             '| road | plant | file | mode | front, drive, trailer_1..3 (%) | wall (s) |',
             '|---|---|---|---|---|---:|']
    cases = (('1.5 kN tanh', {**TANH}, (('states it', TANH), ('none', {}))),
             ('1.5 kN tanh + 3 ms lag', {**TANH, **LAG},
              (('states both', {**TANH, **LAG}), ('states the friction', TANH),
               ('none', {}))),
             ('no friction', {}, (('none', {}),)))
    for road in ('C', 'A'):
        for plant, values, files in cases:
            drive = simulate(road, args.duration, args.noise, {**ZERO_LOAD, **values,
                                                               **payload})
            for file, fvalues in files:
                vehicle = file_vehicle({**ZERO_LOAD, **fvalues})
                for label, lat, off in MODES:
                    t0 = time.perf_counter()
                    est = estimate(vehicle, drive, lat, off)
                    wall = time.perf_counter() - t0
                    pct = ', '.join(f'{v:.1f}' for v in dynamic_pct(drive, est))
                    lines.append(f'| {road} | {plant} | {file} | {label} | {pct} | '
                                 f'{wall:.1f} |')
                    print(lines[-1], file=sys.stderr, flush=True)
    return lines


def part_damping(args) -> list[str]:
    """The articulated model's factors on the friction's equivalent damping, on separate
    drives (road seed 1001, 30 s)."""
    from road_force_estimator.estimation.models.articulated import ArticulatedObserverModel

    payload = {'vehicle.trailer.mass': 29000.0 + args.payload_change}
    lines = ["\nThe equivalent damping's factors (FRICTION_DAMPING_FACTORS): tuning drives "
             '(road seed 1001, 30 s, zero-load readings, payload unknown, 1.5 kN tanh per '
             "spring); the worst axle's dynamic-load error (%)\n",
             '| road | lag | mode | factor | worst axle (%) | axles (%) |',
             '|---|---|---|---:|---:|---|']
    kept = ArticulatedObserverModel.friction_damping_factors
    try:
        for road in ('A', 'C'):
            for lag in ({}, LAG):
                drive = simulate(road, 30.0, args.noise, {**ZERO_LOAD, **TANH, **lag,
                                                          **payload}, seed=1001)
                vehicle = file_vehicle({**ZERO_LOAD, **TANH, **lag})
                for label, lat, factors in (('10 ms', 0.01, (0.0, 0.25, 0.5)),
                                            ('0 ms', 0.0, (0.0, 0.5, 1.5))):
                    for f in factors:
                        ArticulatedObserverModel.friction_damping_factors = (
                            (kept[0], f) if lat else (f, kept[1]))
                        p = dynamic_pct(drive, estimate(vehicle, drive, lat, False))
                        lines.append(f'| {road} | {"3 ms" if lag else "none"} | {label} | '
                                     f'{f:g} | {p.max():.1f} | '
                                     f'{", ".join(f"{v:.1f}" for v in p)} |')
                        print(lines[-1], file=sys.stderr, flush=True)
    finally:
        ArticulatedObserverModel.friction_damping_factors = kept
    return lines


PARTS = {'wim': part_wim, 'stick': part_stick, 'rollover': part_rollover,
         'spikes': part_spikes, 'friction': part_friction, 'damping': part_damping}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--parts', nargs='*', default=list(PARTS), choices=list(PARTS))
    parser.add_argument('--duration', type=float, default=100.0,
                        help='the weigh-in-motion drives (s)')
    parser.add_argument('--noise', type=float, default=1e-5, help='deflection noise (m)')
    parser.add_argument('--payload-change', type=float, default=-4000.0,
                        help="the plant's trailer mass less the file's (kg)")
    parser.add_argument('--file-friction', action='store_true',
                        help="wim: the estimator's file states the plant's friction")
    args = parser.parse_args(argv)
    for part in args.parts:
        print('\n'.join(PARTS[part](args)), flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
