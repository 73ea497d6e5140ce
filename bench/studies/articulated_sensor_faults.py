"""Sensor faults against the whole vehicle's estimator (issue 30 on the articulated model):
five spikes per mode, clean against spiked, with the spikes counted; each kind of channel
stuck for 2 s and a deflection drifting by 1 mm/min, when flagged and whom; flags on clean
drives and a stop.

``.venv/bin/python -m bench.studies.articulated_sensor_faults [--roads C A]
[--modes online '10 ms' offline] [--only spikes latency clean]``

Drives (:func:`bench.accuracy.articulated_observer.simulate`): the 5-axle tractor and
semi-trailer of ``config/tractor_semitrailer.yaml``, ISO 8608 class C and A, 20 m/s, 1 kHz,
10 um of deflection noise (the roll's 10 um over the front spring's half track), road seed 1;
the faults put into the readings with the plant's own fault module
(:mod:`road_force_estimator.core.sensor_faults`, the ``simulator.sensor_faults`` syntax,
seed 1):

- spikes: three 0.5 mm spikes on ``front_left_suspension`` and two on
  ``trailer_2_right_suspension`` from 3 s, 20 s: the dynamic-load error per axle (% of its
  dynamic RMS over both wheels after 5 s, the worst axle), clean and spiked, their ratio
  (target <= 1.1) and the innovations gated on those two sensors (target: every spike);
- stuck: ``stuck@<channel>:start=8,duration=2`` for a tractor deflection
  (``drive_left_suspension``), a trailer deflection (``trailer_1_right_suspension``), the
  tractor's roll and the trailer's roll, 20 s: when the flag came after the sensor stuck
  (target <= 1 s) and the sensor named;
- drift: ``drift@<channel>:rate=1.667e-5,start=10`` (1 mm/min) on a trailer deflection at each
  place of the tri-axle group (``trailer_1_left``, ``trailer_2_right``, ``trailer_3_left``), on
  a tractor deflection of each axle (``front_left``, ``drive_right``), and (1 mrad/min) on each
  roll sensor, 60 s: when flagged after the drift began (target <= 30 s), named;
- clean drives (class C and A 20 s, the family's ``C20-stop``, ``C20-curve3``, and
  ``C20-stick`` and ``A20-stick`` (1.5 kN of sticking friction per spring) at 40 s): the flags
  raised (target none).

Prints Markdown tables. ``--balances [--seconds 60]`` prints instead the tractor's drift
balances (:class:`~road_force_estimator.estimation.sensor_health.TractorDrift`) on every drive
of the family, clean (10 um, seed 1): per drive the largest judged kingpin pitch P (mm of the
front deflection), the two units' a_y difference A (m/s^2) and the front-drive cross-level T
(mrad), P and T also over a plain 12 s mean (the window the rigid fit used) at 8 m/s or more,
the largest offset of the best candidate over its limit (a flag needs > 1 for 6 s), the drift
flags raised. ``--balances --imu``: the same with the tractor IMU's a_y (the plant's IMU, its
default noise; A replaced by each unit's roll balance against it, I_t and I_r, m/s^2) on the
family and :data:`IMU_DRIVES` (a 3 % crossfall straight and in the curve), then the roll
sensors' drifts (:data:`ROLL_DRIFTS`: 1 mrad/min on each, on both with either sign, the
plant's gyro drift on both) on C20, A20 and the curve on the crossfall: the drift flags and
when, with and without the IMU. ``--balances --imu --pendulum``: the same with pendulum roll
sensors in the plant and the file (:data:`PENDULUM`; the gyro's row left out).
``--balances --pendulum``: pendulums without the IMU, each unit's balance on its pendulum (I_t,
I_r) on the same drives, then the same drifts and a tractor deflection's
(:data:`DEFLECTION_DRIFTS`), with the IMU and without. ``--drives NAME ...``: only those.

What it found: docs/notes/articulated_sensor_faults.md.
"""
from __future__ import annotations

import sys
import time

import numpy as np

MODES = ('online', '10 ms', 'offline')
SPIKES = ('spikes@front_left_suspension:count=3,size=5e-4,start=3;'
          'spikes@trailer_2_right_suspension:count=2,size=5e-4,start=3')
SPIKED = ('front_left_suspension', 'trailer_2_right_suspension')
STUCK = ('drive_left_suspension', 'trailer_1_right_suspension', 'tractor_roll', 'trailer_roll')
DRIFTING = ('trailer_1_left_suspension', 'trailer_2_right_suspension',
            'trailer_3_left_suspension', 'front_left_suspension', 'drive_right_suspension',
            'tractor_roll', 'trailer_roll')
#: 1 mm/min on a deflection, 1 mrad/min on a roll sensor (m/s or rad/s)
DRIFT_RATE = 1e-3 / 60.0
STUCK_AT, DRIFT_AT = 8.0, 10.0
SETTLE_S = 5.0


def drive_of(road: str, duration_s: float, name: str = '') -> dict:
    """A drive of the family (:mod:`bench.studies.articulated_drives`): ``<road>20`` or
    ``name``."""
    from bench.accuracy.articulated_observer import simulate
    from bench.studies.articulated_drives import family

    case = {c.name: c for c in family()}[name or f'{road}20']
    return simulate(case, duration_s, 1e-5)


def with_faults(drive: dict, spec: str) -> dict:
    """The drive with its readings faulted by ``spec`` (``simulator.sensor_faults``)."""
    from road_force_estimator.core.sensor_faults import FaultPlan, parse_faults
    from road_force_estimator.estimation.models.articulated import (
        ArticulatedObserverModel)

    names = ArticulatedObserverModel(drive['vehicle']).channel_names
    plan = FaultPlan(parse_faults(spec, names), names, 1000.0, float(drive['t'][-1]), 1)
    return {**drive, 'y': plan.hold(plan.apply(np.array(drive['y'], float)))}


def estimate(drive: dict, mode: str):
    """The whole vehicle's estimate in ``mode`` (package defaults)."""
    from road_force_estimator.core.parameters import ObserverParameters
    from road_force_estimator.estimation.whole_vehicle import estimate_whole_vehicle

    obs = ObserverParameters(latency_s=0.01 if mode == '10 ms' else 0.0)
    return estimate_whole_vehicle(drive['vehicle'], drive['stamps'], drive['y'],
                                  drive['speed'], observer=obs, offline=mode == 'offline')


def load_error(drive: dict, wv) -> float:
    """The worst axle's dynamic-load error (% of its dynamic RMS, both wheels) after
    :data:`SETTLE_S`."""
    from bench.accuracy.articulated_observer import error_pct

    static = drive['load'] - drive['dynamic']
    return float(np.max(error_pct(drive['t'], wv.load_n - static, drive['dynamic'],
                                  SETTLE_S)))


def flags(wv) -> str:
    """The flags a run raised: 'trailer_roll stuck 1, ...' or 'none'."""
    fc = wv.faults
    out = [f'{n} {kind} {c}' for n in wv.channel_names
           for kind, counts in (('stuck', fc.stuck_episodes), ('drift', fc.drift_episodes))
           if (c := counts.get(n, 0))]
    return ', '.join(out) or 'none'


def first_flag(wv, t0_ns: int, at_s: float) -> str:
    """Each flagged sensor's first flag, s after ``at_s`` (the fault's start)."""
    out = [f'{n} {kind} +{(ns - t0_ns) * 1e-9 - at_s:.2f} s'
           for n, first in wv.faults.first_ns.items() for kind, ns in sorted(first.items())]
    return ', '.join(out) or 'not flagged'


def spikes_table(roads, modes, log) -> list[str]:
    lines = ['| road | mode | clean (% dyn, worst axle) | five spikes | ratio | innovations '
             'gated (front_left / trailer_2_right; 3 / 2 put in) | flags |',
             '|---|---|---:|---:|---:|---|---|']
    for road in roads:
        clean = drive_of(road, 20.0)
        spiked = with_faults(clean, SPIKES)
        for mode in modes:
            t0 = time.perf_counter()
            a, b = estimate(clean, mode), estimate(spiked, mode)
            ea, eb = load_error(clean, a), load_error(spiked, b)
            gated = dict(zip(b.channel_names, b.innovations_gated))
            lines.append(f'| {road} | {mode} | {ea:.2f} | {eb:.2f} | {eb / ea:.3f} | '
                         f'{" / ".join(str(gated[n]) for n in SPIKED)} | {flags(b)} |')
            log(lines[-1] + f' ({time.perf_counter() - t0:.0f} s)')
    return lines


def latency_table(roads, modes, log, faults=('stuck', 'drift')) -> list[str]:
    lines = ['| road | fault | mode | flags raised | first flag after the fault began | '
             'load error (% dyn, worst axle): clean / with the fault |',
             '|---|---|---|---|---|---|']
    clean: dict = {}
    for road in roads:
        base = drive_of(road, 20.0)
        cases = [(f'stuck {ch} 2 s at {STUCK_AT:g} s', base,
                  f'stuck@{ch}:start={STUCK_AT:g},duration=2', STUCK_AT)
                 for ch in STUCK if 'stuck' in faults]
        long = drive_of(road, 60.0) if 'drift' in faults else None
        cases += [(f'drift {ch} 1 {"mrad" if ch.endswith("roll") else "mm"}/min from '
                   f'{DRIFT_AT:g} s', long,
                   f'drift@{ch}:rate={DRIFT_RATE:.6g},start={DRIFT_AT:g}', DRIFT_AT)
                  for ch in DRIFTING if 'drift' in faults]
        for label, drive, spec, at in cases:
            faulty = with_faults(drive, spec)
            for mode in modes:
                key = (road, len(drive['t']), mode)
                if key not in clean:
                    clean[key] = load_error(drive, estimate(drive, mode))
                wv = estimate(faulty, mode)
                lines.append(f'| {road} | {label} | {mode} | {flags(wv)} | '
                             f'{first_flag(wv, int(drive["stamps"][0]), at)} | '
                             f'{clean[key]:.2f} / {load_error(drive, wv):.2f} |')
                log(lines[-1])
    return lines


def clean_table(roads, modes, log) -> list[str]:
    lines = ['| drive | mode | flags raised |', '|---|---|---|']
    drives = [(f'class {r}, 20 s', drive_of(r, 20.0)) for r in roads]
    drives += [('C20-stop (braking, 5 s standing, pulling away), 40 s',
                drive_of('C', 40.0, 'C20-stop')),
               ('C20-curve3 (a curve ramping to 3 m/s^2), 40 s',
                drive_of('C', 40.0, 'C20-curve3')),
               ('C20-stick (1.5 kN sticking friction per spring), 40 s',
                drive_of('C', 40.0, 'C20-stick')),
               ('A20-stick (1.5 kN sticking friction per spring), 40 s',
                drive_of('A', 40.0, 'A20-stick'))]
    for label, drive in drives:
        for mode in modes:
            lines.append(f'| {label} | {mode} | {flags(estimate(drive, mode))} |')
            log(lines[-1])
    return lines


def plain_peaks(drive: dict, rows: np.ndarray, ax: np.ndarray, window_s: float,
                cross: int = 2) -> tuple:
    """The largest |P| and |T| (row ``cross``) over a plain mean of ``window_s`` every 0.1 s,
    at 8 m/s or more over it (m, rad)."""
    y, v, t = np.asarray(drive['y'], float), np.asarray(drive['speed'], float), drive['t']
    n = int(round(window_s / (t[1] - t[0])))
    if rows.shape[1] > y.shape[1]:               # the IMU's a_y, the last channel
        y = np.column_stack([y, drive['ay']])
    z = y @ rows.T
    c = np.vstack([np.zeros((1, z.shape[1])), np.cumsum(z, axis=0)])
    ends = np.arange(n, len(t) + 1, max(1, n // 120))
    ok = np.array([v[e - n:e].min() >= 8.0 for e in ends])
    a_x = (v[ends - 1] - v[ends - n]) / (t[ends - 1] - t[ends - n])
    mean = (c[ends] - c[ends - n]) / n + a_x[:, None] * ax
    return float(np.abs(mean[ok, 0]).max()), float(np.abs(mean[ok, cross]).max())


#: ``--imu``: drives beside the family's (name, the family's drive, parameter overrides): a
#: road crossfall (``simulator.road_crossfall``, rad)
IMU_DRIVES = (('C20-crossfall', 'C20', {'simulator.road_crossfall': 0.03}),
              ('C20-curve3-crossfall', 'C20-curve3', {'simulator.road_crossfall': 0.03}))


#: ``--pendulum``: pendulum roll sensors, the plant's and the file's
PENDULUM = {'simulator.roll_sensor': 'pendulum', 'vehicle.roll_sensor': 'pendulum'}


def imu_cases(extra: dict | None = None) -> list:
    """The family's drives and :data:`IMU_DRIVES` (each with ``extra``'s values)."""
    from bench.studies.articulated_drives import Case, family

    cases = family()
    by = {c.name: c for c in cases}
    for name, base, values in IMU_DRIVES:
        c = by[base]
        cases.append(Case(name, c.road, c.speed_mps, speed_profile=c.speed_profile,
                          values={**c.values, **values}))
    return [Case(c.name, c.road, c.speed_mps, speed_profile=c.speed_profile,
                 values={**c.values, **(extra or {})}) for c in cases]


def detector_run(drive: dict, imu: bool):
    """The whole vehicle's fault detector over a drive (the readings, with the IMU's a_y as the
    last channel when ``imu``): the detector after its last sample."""
    from road_force_estimator.core.parameters import ObserverParameters
    from road_force_estimator.estimation.models.articulated import (
        ArticulatedObserverModel)
    from road_force_estimator.estimation.sensor_health import FaultDetector, FaultSettings

    y = np.column_stack([drive['y'], drive['ay']]) if imu else np.asarray(drive['y'])
    det = FaultDetector(FaultSettings.of_whole_vehicle(ObserverParameters(), (
        ArticulatedObserverModel(drive['vehicle'], imu=imu))))
    for stamp, row, v in zip(drive['stamps'].tolist(), y.tolist(), drive['speed'].tolist()):
        det.step(stamp, row, (v,))
    return det


def balances_table(seconds: float, log, imu: bool = False,
                   extra: dict | None = None, drives: tuple = ()) -> list[str]:
    """The tractor's drift balances on the family's clean drives (module notes); ``imu``:
    with the tractor IMU (A replaced by each unit's balance against the IMU's a_y), on
    :func:`imu_cases` (with ``extra``'s values); pendulums (``extra``) without it: each
    unit's balance on its pendulum, on :func:`imu_cases` too. ``drives``: only those named."""
    from bench.accuracy.articulated_observer import simulate
    from bench.studies.articulated_drives import family
    from road_force_estimator.core.parameters import ObserverParameters
    from road_force_estimator.estimation.sensor_health import UNIT_WINDOW_FACTOR

    units = imu or bool(extra)          # each unit's balance: I_t, I_r
    middle = 'I_t (m/s^2) | I_r (m/s^2)' if units else 'A (m/s^2)'
    lines = [f'| drive ({seconds:g} s) | P plain 12 s (mm) | P (mm) | T plain 12 s (mrad) | '
             f'T (mrad) | {middle} | largest offset / limit | units (mm) | drift flags |',
             '|---|' + '---:|' * (8 if units else 7) + '---|']
    obs = ObserverParameters()
    for case in (imu_cases(extra) if units else family()):
        if drives and case.name not in drives:
            continue
        drive = simulate(case, seconds, 1e-5, imu=imu)
        det = detector_run(drive, imu)
        settings = det.settings
        rows, ax = np.asarray(settings.tractor[0]), np.asarray(settings.tractor[1])
        cross = 1 if units else 2
        p, t = plain_peaks(drive, rows, ax, UNIT_WINDOW_FACTOR * obs.fault_drift_window_s,
                           cross)
        peak = det.tractor.peak
        unit_mm, unit_ch = det.units.peak
        unit = f'{unit_mm * 1e3:.3f} ({settings.channels[unit_ch]})' if unit_ch >= 0 else 'n/a'
        raised = ', '.join(n for n, c in det.counts().drift_episodes.items() if c) or 'none'
        cells = (f'{peak[2]:.4f} | {peak[3]:.4f}' if units else f'{peak[1]:.4f}')
        lines.append(f'| {case.name} | {p * 1e3:.3f} | {peak[0] * 1e3:.3f} | {t * 1e3:.3f} | '
                     f'{peak[cross] * 1e3:.3f} | {cells} | {peak[-1]:.2f} | {unit} | '
                     f'{raised} |')
        log(lines[-1])
    return lines


#: ``--imu``: the roll sensors' drifts (1 mrad/min from :data:`DRIFT_AT`, or the plant's gyro
#: drift on both from 0 s), named with and without the IMU
ROLL_DRIFTS = (('tractor_roll +1 mrad/min', f'drift@tractor_roll:rate={DRIFT_RATE:.6g},'
                f'start={DRIFT_AT:g}', {}),
               ('trailer_roll -1 mrad/min', f'drift@trailer_roll:rate={-DRIFT_RATE:.6g},'
                f'start={DRIFT_AT:g}', {}),
               ('both +1 mrad/min', f'drift@tractor_roll:rate={DRIFT_RATE:.6g},'
                f'start={DRIFT_AT:g};drift@trailer_roll:rate={DRIFT_RATE:.6g},'
                f'start={DRIFT_AT:g}', {}),
               ('both -1 mrad/min', f'drift@tractor_roll:rate={-DRIFT_RATE:.6g},'
                f'start={DRIFT_AT:g};drift@trailer_roll:rate={-DRIFT_RATE:.6g},'
                f'start={DRIFT_AT:g}', {}),
               ('gyro drift 1 mrad/min on both (plant)', '',
                {'simulator.roll_sensor': 'gyro', 'simulator.roll_gyro_drift': DRIFT_RATE}))


#: ``--pendulum``: also a tractor deflection's drift (1 mm/min from :data:`DRIFT_AT`), named
#: beside the pendulums' candidates
DEFLECTION_DRIFTS = (('front_left_suspension +1 mm/min', f'drift@front_left_suspension:rate='
                      f'{DRIFT_RATE:.6g},start={DRIFT_AT:g}', {}),
                     ('drive_right_suspension -1 mm/min', f'drift@drive_right_suspension:rate='
                      f'{-DRIFT_RATE:.6g},start={DRIFT_AT:g}', {}))


def roll_table(seconds: float, log, extra: dict | None = None,
               drives: tuple = ('C20', 'A20', 'C20-curve3-crossfall')) -> list[str]:
    """The roll sensors' drifts (:data:`ROLL_DRIFTS`) on ``drives`` (C20, A20 and
    C20-curve3-crossfall): the drift flags raised and the first, s after the drift began,
    with and without the IMU (pendulums, ``extra``: also :data:`DEFLECTION_DRIFTS`)."""
    from bench.accuracy.articulated_observer import simulate
    from bench.studies.articulated_drives import Case

    lines = ['| drive | drift | with the IMU: flags (first, s after the drift began) | '
             'without: flags (first) |', '|---|---|---|---|']
    by = {c.name: c for c in imu_cases(extra)}
    for name in drives:
        for label, spec, values in ROLL_DRIFTS + (DEFLECTION_DRIFTS if extra else ()):
            if extra and not spec:          # (the plant's gyro is another roll sensor)
                continue
            c = by[name]
            drive = simulate(Case(c.name, c.road, c.speed_mps, speed_profile=c.speed_profile,
                                  values={**c.values, **values}), seconds, 1e-5, imu=True)
            if spec:
                drive = with_faults(drive, spec)
            at = DRIFT_AT if spec else 0.0
            cells = []
            for imu in (True, False):
                counts = detector_run(drive, imu).counts()
                t0 = int(drive['stamps'][0])
                cells.append(', '.join(
                    f'{n} +{(f["drift"] - t0) * 1e-9 - at:.2f}' for n, f in
                    counts.first_ns.items() if 'drift' in f) or 'none')
            lines.append(f'| {name} | {label} | {cells[0]} | {cells[1]} |')
            log(lines[-1])
    return lines


def main(argv=None) -> int:
    from bench.studies import sensor_faults

    argv = list(sys.argv[1:] if argv is None else argv)
    if '--balances' in argv:
        import argparse

        ap = argparse.ArgumentParser(description="the tractor's drift balances")
        ap.add_argument('--balances', action='store_true')
        ap.add_argument('--seconds', type=float, default=60.0)
        ap.add_argument('--imu', action='store_true',
                        help="with the tractor IMU's a_y; then also the roll drifts' table")
        ap.add_argument('--pendulum', action='store_true',
                        help='pendulum roll sensors (plant and file), with or without --imu; '
                             "then also the roll drifts' table")
        ap.add_argument('--drives', nargs='+', default=(),
                        help='only these drives (e.g. C20 C20-curve3-crossfall)')
        args = ap.parse_args(argv)
        extra = PENDULUM if args.pendulum else None

        def log(text: str) -> None:
            print(text, file=sys.stderr, flush=True)

        print('\n'.join(balances_table(args.seconds, log, args.imu, extra,
                                        tuple(args.drives))))
        if args.imu or args.pendulum:
            print()
            rolled = tuple(d for d in ('C20', 'A20', 'C20-curve3-crossfall')
                           if not args.drives or d in args.drives)
            print('\n'.join(roll_table(args.seconds, log, extra, rolled)))
        return 0
    return sensor_faults.main(argv, tables=(spikes_table, latency_table, clean_table),
                              description=__doc__.splitlines()[0])


if __name__ == '__main__':
    sys.exit(main())
