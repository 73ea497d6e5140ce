"""Sensor faults against the estimator (issue 30): five spikes per mode, clean against spiked,
with the spikes counted; a stuck and a drifting sensor's flag latencies; flags on clean drives.

``.venv/bin/python -m bench.studies.sensor_faults [--roads C A] [--modes online '10 ms' offline]``

Drives (:func:`bench.accuracy.scenarios.build_drive`): ISO 8608 class C and A, 20 m/s, 1 kHz,
10 um of deflection noise (100 urad of roll), road seed 1; the faults put into the readings with
the plant's own fault module (:mod:`road_force_estimator.core.sensor_faults`, the
``simulator.sensor_faults`` syntax, seed 1):

- spikes: ``spikes@left_suspension:count=3,size=5e-4,start=3;
  spikes@right_suspension:count=2,size=5e-4,start=3`` (five 0.5 mm spikes on two sensors), 20 s;
  load error (% of the dynamic RMS after the 2 s skip,
  :func:`bench.accuracy.scenarios.score`) clean and spiked, their ratio (target <= 1.1) and
  the innovations gated per sensor (target: every spike);
- stuck: ``stuck@<channel>:start=8,duration=2`` on each channel, 20 s: when the flag came
  after the sensor stuck (target <= 1 s) and the sensor named;
- drift: ``drift@<side>_suspension:rate=1.667e-5,start=10`` (1 mm/min), 60 s: when the flag
  came after the drift began (target <= 30 s) and the sensor named;
- clean drives (class C and A 20 s, the benchmark's stop ``C20-stop``, the spiked drive): the
  flags raised (target none).

Prints Markdown tables.

What it found: docs/notes/sensor_faults.md.
"""
from __future__ import annotations

import argparse
from dataclasses import replace
import sys
import time

import numpy as np

MODES = ('online', '10 ms', 'offline')
CHANNELS = ('left_suspension', 'right_suspension', 'roll')
SPIKES = ('spikes@left_suspension:count=3,size=5e-4,start=3;'
          'spikes@right_suspension:count=2,size=5e-4,start=3')
DRIFT_RATE = 1e-3 / 60.0
STUCK_AT, DRIFT_AT = 8.0, 10.0


def drive_of(road: str, duration_s: float, name: str = ''):
    from bench.accuracy.scenarios import build_drive, scenario_by_name

    base = scenario_by_name(name or f'{road}20-1k-10um')
    return build_drive(replace(base, duration_s=duration_s) if not name else base)


def with_faults(drive, spec: str):
    """The drive's readings with the faults of ``spec`` (``simulator.sensor_faults``)."""
    from road_force_estimator.core.sensor_faults import FaultPlan, parse_faults

    plan = FaultPlan(parse_faults(spec, CHANNELS), CHANNELS, drive.scenario.rate_hz,
                     float(drive.t_s[-1]), 1)
    values = plan.hold(plan.apply(np.column_stack([drive.q_m, drive.roll_rad])))
    return replace(drive, q_m=np.ascontiguousarray(values[:, :2]),
                   roll_rad=np.ascontiguousarray(values[:, 2]))


def estimate(drive, mode: str):
    from road_force_estimator.core.parameters import ObserverParameters
    from road_force_estimator.estimation import estimate_batch, estimate_recording

    args = (drive.stamps_ns, drive.q_m, drive.roll_rad, drive.speed_mps,
            drive.vehicle_observer)
    if mode == 'offline':
        return estimate_recording(*args, ObserverParameters())
    return estimate_batch(*args, ObserverParameters(latency_s=0.01 if mode == '10 ms' else 0.0))


def load_error(drive, est) -> float:
    from bench.accuracy.run_benchmark import per_sample
    from bench.accuracy.scenarios import score

    return score(drive, per_sample(est, drive.stamps_ns))['load_rms_pct_dyn']


def flags(st) -> str:
    """The flags a run raised: 'left_suspension stuck 1, ...' or 'none'."""
    out = [f'{n} {kind} {c}' for n in CHANNELS
           for kind, counts in (('stuck', st.stuck_episodes), ('drift', st.drift_episodes))
           if (c := counts.get(n, 0))]
    return ', '.join(out) or 'none'


def first_flag(st, t0_ns: int, at_s: float) -> str:
    """Each flagged sensor's first flag, s after ``at_s`` (the fault's start)."""
    out = [f'{n} {kind} +{(ns - t0_ns) * 1e-9 - at_s:.2f} s'
           for n, first in st.fault_first_ns.items() for kind, ns in sorted(first.items())]
    return ', '.join(out) or 'not flagged'


def spikes_table(roads, modes, log) -> list[str]:
    lines = ['| road | mode | clean (% dyn) | five spikes (% dyn) | ratio | innovations gated '
             '(left / right / roll; 3 / 2 / 0 put in) | flags |',
             '|---|---|---:|---:|---:|---|---|']
    for road in roads:
        clean = drive_of(road, 20.0)
        spiked = with_faults(clean, SPIKES)
        for mode in modes:
            t0 = time.perf_counter()
            a, b = estimate(clean, mode), estimate(spiked, mode)
            ea, eb = load_error(clean, a), load_error(spiked, b)
            gated = ' / '.join(str(b.status.innovations_gated.get(n, 0)) for n in CHANNELS)
            lines.append(f'| {road} | {mode} | {ea:.2f} | {eb:.2f} | {eb / ea:.3f} | {gated} | '
                         f'{flags(b.status)} |')
            log(lines[-1] + f' ({time.perf_counter() - t0:.0f} s)')
    return lines


def latency_table(roads, modes, log, faults=('stuck', 'drift')) -> list[str]:
    lines = ['| road | fault | mode | flags raised | first flag after the fault began | '
             'load error (% dyn): clean / with the fault |',
             '|---|---|---|---|---|---|']
    clean: dict = {}
    for road in roads:
        base = drive_of(road, 20.0)
        cases = [(f'stuck {ch} 2 s at {STUCK_AT:g} s', base,
                  f'stuck@{ch}:start={STUCK_AT:g},duration=2', STUCK_AT)
                 for ch in CHANNELS if 'stuck' in faults]
        long = drive_of(road, 60.0) if 'drift' in faults else None
        cases += [(f'drift {side}_suspension 1 mm/min from {DRIFT_AT:g} s', long,
                   f'drift@{side}_suspension:rate={DRIFT_RATE:.6g},start={DRIFT_AT:g}',
                   DRIFT_AT) for side in ('left', 'right') if 'drift' in faults]
        for label, drive, spec, at in cases:
            faulty = with_faults(drive, spec)
            for mode in modes:
                key = (road, len(drive.t_s), mode)
                if key not in clean:
                    clean[key] = load_error(drive, estimate(drive, mode))
                est = estimate(faulty, mode)
                st = est.status
                lines.append(f'| {road} | {label} | {mode} | {flags(st)} | '
                             f'{first_flag(st, int(drive.stamps_ns[0]), at)} | '
                             f'{clean[key]:.2f} / {load_error(drive, est):.2f} |')
                log(lines[-1])
    return lines


def clean_table(roads, modes, log) -> list[str]:
    lines = ['| drive | mode | flags raised |', '|---|---|---|']
    drives = [(f'class {r}, 20 s', drive_of(r, 20.0)) for r in roads]
    drives += [('C20-stop (braking, 10 s standing, pulling away)', drive_of('C', 0.0, 'C20-stop')),
               ('class C, five spikes', with_faults(drive_of('C', 20.0), SPIKES))]
    for label, drive in drives:
        for mode in modes:
            lines.append(f'| {label} | {mode} | {flags(estimate(drive, mode).status)} |')
            log(lines[-1])
    return lines


def main(argv=None, *, tables=None, description: str | None = None) -> int:
    """The three tables of the arguments (``tables``: the spikes', the flag latency's and the
    clean drives' table functions, this module's by default; the whole vehicle's study passes
    its own)."""
    spikes_of, latency_of, clean_of = tables or (spikes_table, latency_table, clean_table)
    ap = argparse.ArgumentParser(description=description or __doc__.splitlines()[0])
    ap.add_argument('--roads', nargs='+', default=['C', 'A'])
    ap.add_argument('--modes', nargs='+', default=list(MODES), choices=MODES)
    ap.add_argument('--only', nargs='+', default=['spikes', 'latency', 'clean'],
                    choices=['spikes', 'latency', 'clean'])
    ap.add_argument('--faults', nargs='+', default=['stuck', 'drift'],
                    choices=['stuck', 'drift'], help="the latency table's faults")
    args = ap.parse_args(argv)

    def log(text: str) -> None:
        print(text, file=sys.stderr, flush=True)

    t0 = time.perf_counter()
    out = []
    if 'spikes' in args.only:
        out += ['### Five 0.5 mm spikes on two sensors', ''] + spikes_of(
            args.roads, args.modes, log) + ['']
    if 'latency' in args.only:
        out += ['### Stuck and drifting sensors: flag latency', ''] + latency_of(
            args.roads, args.modes, log, tuple(args.faults)) + ['']
    if 'clean' in args.only:
        out += ['### Clean drives: flags raised', ''] + clean_of(
            args.roads, args.modes, log) + ['']
    print('\n'.join(out))
    print(f'({time.perf_counter() - t0:.0f} s)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
