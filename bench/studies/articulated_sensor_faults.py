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

Prints Markdown tables.

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


def latency_table(roads, modes, log) -> list[str]:
    lines = ['| road | fault | mode | flags raised | first flag after the fault began | '
             'load error (% dyn, worst axle): clean / with the fault |',
             '|---|---|---|---|---|---|']
    clean: dict = {}
    for road in roads:
        base = drive_of(road, 20.0)
        cases = [(f'stuck {ch} 2 s at {STUCK_AT:g} s', base,
                  f'stuck@{ch}:start={STUCK_AT:g},duration=2', STUCK_AT) for ch in STUCK]
        long = drive_of(road, 60.0)
        cases += [(f'drift {ch} 1 {"mrad" if ch.endswith("roll") else "mm"}/min from '
                   f'{DRIFT_AT:g} s', long,
                   f'drift@{ch}:rate={DRIFT_RATE:.6g},start={DRIFT_AT:g}', DRIFT_AT)
                  for ch in DRIFTING]
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


def main(argv=None) -> int:
    from bench.studies import sensor_faults

    return sensor_faults.main(argv, tables=(spikes_table, latency_table, clean_table),
                              description=__doc__.splitlines()[0])


if __name__ == '__main__':
    sys.exit(main())
