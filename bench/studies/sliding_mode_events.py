"""The sliding-mode injection of the model observer at full strength, on the events where
theory says it wins and on those where it loses (issue 30).

``.venv/bin/python -m bench.studies.sliding_mode_events [--duration S] [--only NAME ...]``

The injection (:mod:`road_force_estimator.estimation.observer.online`, "Sliding-mode injection")
is weighted by ``observer.sliding_mode_gain / (1 + (sigma_q / SM_NOISE_SCALE)^2)``: about
1e-4 at 10 um of noise. Three settings, same drive: ``off`` (``observer.sliding_mode_gain =
0``, the Kalman unknown-input observer alone), ``weighted`` (gain 1 with that weighting: the
package default until issue 30) and ``full`` (gain 1, the weighting removed:
``SM_NOISE_SCALE`` set to infinity for the run), each at zero latency and at 10 ms.

Drives (20 m/s, 1 kHz, the event at 200 m; roll noise 10 rad/m x the deflection noise):

- wins, in theory (a bounded, sharp unknown input, little noise): a one-sided pothole
  (0.6 m long, 3 cm deep) and a one-sided step (2 cm over 2 cm) on class B at point contact
  (no tire envelope), at 0, 1, 3 and 10 um of noise; friction switching: class C with
  1.5 kN of leaf-spring friction per spring stated in the file, the truth's tanh as the
  file's (v_f = 0.01 m/s) and sharper than the file's (0.005 m/s, patched in the plant for
  the simulation only), 1 and 10 um;
- loses, in theory: the same pothole with the tire's 0.25 m envelope; class C (the tire
  envelope); five spikes of 0.5 mm on the left deflection (class C, 10 um; at 3, 5, 7, 9,
  11 s); heavy-tailed noise (Student t, 3 degrees of freedom, scaled to 10 um RMS).

Figures: the load error in % of the true dynamic-load RMS over the drive (after 2 s), and
the RMS load error (N) in a window of +-0.25 s around the event (for the spikes: the
+-0.1 s windows around them; for the roads without an event and the friction drives: the
drive's RMS in N). Prints a Markdown table.

What it found: docs/notes/sliding_mode_events.md.
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass, replace
import math
import sys
import time

import numpy as np

from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters

SPEED = 20.0
RATE = 1000.0
EVENT_M = 200.0
SPIKES_S = (3.0, 5.0, 7.0, 9.0, 11.0)
SPIKE_M = 5e-4
SETTINGS = ('off', 'weighted', 'full')
LATENCIES = (0.0, 0.01)


@dataclass(frozen=True)
class EventDrive:
    """One drive of the table."""

    name: str
    road: str = 'B'
    event: tuple | None = None           # (kind, side, start_m, length_m, height_m)
    envelope_m: float = 0.0
    noise_m: float = 1e-5
    noise: str = 'gauss'                 # 'gauss', 'student3', 'spikes'
    friction_n: float = 0.0
    truth_vf_mps: float = 0.01
    wins: bool = True                    # where theory says the injection should win


POTHOLE = ('pothole', 'left', EVENT_M, 0.6, 0.03)
STEP = ('step', 'left', EVENT_M, 0.02, 0.02)


def _drives() -> list[EventDrive]:
    out = []
    for noise in (0.0, 1e-6, 3e-6, 1e-5):
        um = f'{noise * 1e6:g} um'
        out.append(EventDrive(f'pothole, point contact, {um}', event=POTHOLE, noise_m=noise))
        out.append(EventDrive(f'step, point contact, {um}', event=STEP, noise_m=noise))
    for noise in (1e-6, 1e-5):
        um = f'{noise * 1e6:g} um'
        out.append(EventDrive(f'friction stated, C, {um}', road='C', envelope_m=0.25,
                              noise_m=noise, friction_n=1500.0))
        out.append(EventDrive(f'friction, truth v_f 0.005, C, {um}', road='C', envelope_m=0.25,
                              noise_m=noise, friction_n=1500.0, truth_vf_mps=0.005))
    out += [
        EventDrive('pothole, enveloped 0.25 m, 1 um', event=POTHOLE, envelope_m=0.25,
                   noise_m=1e-6, wins=False),
        EventDrive('pothole, enveloped 0.25 m, 10 um', event=POTHOLE, envelope_m=0.25,
                   wins=False),
        EventDrive('class C, enveloped, 0 um', road='C', envelope_m=0.25, noise_m=0.0,
                   wins=False),
        EventDrive('class C, enveloped, 10 um', road='C', envelope_m=0.25, wins=False),
        EventDrive('spikes 5 x 0.5 mm, C, 10 um', road='C', envelope_m=0.25, noise='spikes',
                   wins=False),
        EventDrive('Student t noise (3 dof), C, 10 um RMS', road='C', envelope_m=0.25,
                   noise='student3', wins=False),
    ]
    return out


DRIVES = _drives()


def build(d: EventDrive, duration_s: float):
    """(bench.accuracy.scenarios.Drive, the windows (sample index ranges) scored locally)."""
    from bench.accuracy import scenarios as sc
    from road_force_estimator.core.plant import simulate

    truck = VehicleParameters(leaf_spring_friction_n=(d.friction_n, d.friction_n))
    # the plant's v_f only (issue 30): the observer is given the file's
    plant_truck = replace(truck, leaf_spring_friction_velocity_mps=d.truth_vf_mps)
    base = replace(sc.SCENARIOS[0], name=d.name, road=d.road, event=d.event,
                   duration_s=duration_s, noise_deflection_m=d.noise_m, noise_seed=7)
    road = sc.scenario_road(base, SPEED * duration_s + 10.0 + d.envelope_m)
    tr = simulate(plant_truck, road, speed_mps=SPEED, rate_hz=RATE, duration_s=duration_s,
                  tire_envelope_m=d.envelope_m)
    q, roll = _measure(d, np.asarray(tr.q_m), np.asarray(tr.roll_rad))
    t = np.asarray(tr.t_s)
    load = np.asarray(tr.wheel_load_n)
    truth = {'wheel_load_n': load, 'tire_force_dynamic_n': np.asarray(tr.tire_force_dynamic_n),
             'road_m': np.asarray(tr.road_m), 'distance_m': np.asarray(tr.distance_m),
             'ltr': (load[:, 1] - load[:, 0]) / load.sum(axis=1), 'q_m': np.asarray(tr.q_m),
             'roll_rad': np.asarray(tr.roll_rad)}
    drive = sc.Drive(base, t, q, roll, np.full(t.size, SPEED), truck, truck, truth)
    if d.event is not None:
        k = int(np.searchsorted(truth['distance_m'], d.event[2] - road.start_m))
        windows = [(max(0, k - 250), min(t.size, k + 250))]
    elif d.noise == 'spikes':
        windows = [(int(s * RATE) - 100, int(s * RATE) + 100) for s in SPIKES_S]
    else:
        windows = [(int(2.0 * RATE), t.size)]
    return drive, windows


def _measure(d: EventDrive, q: np.ndarray, roll: np.ndarray):
    rng = np.random.default_rng(1234)
    sigma_r = 10.0 * d.noise_m
    if d.noise == 'student3':       # t(3) has variance 3: scaled to the stated RMS
        nq = rng.standard_t(3.0, q.shape) / math.sqrt(3.0) * d.noise_m
        nr = rng.standard_t(3.0, roll.shape) / math.sqrt(3.0) * sigma_r
    else:
        nq = rng.standard_normal(q.shape) * d.noise_m
        nr = rng.standard_normal(roll.shape) * sigma_r
    q = q + nq
    roll = roll + nr
    if d.noise == 'spikes':
        for s in SPIKES_S:
            q[int(s * RATE), 0] += SPIKE_M
    return q, roll


def run(drive, setting: str, latency_s: float):
    """The estimate of ``drive`` by the model observer with a sliding-mode ``setting``."""
    from bench.accuracy.run_benchmark import per_sample
    import road_force_estimator.estimation.observer.online as core
    from road_force_estimator.estimation import estimate_batch

    obs = ObserverParameters(latency_s=latency_s,
                             sliding_mode_gain=0.0 if setting == 'off' else 1.0)
    saved = core.SM_NOISE_SCALE
    if setting == 'full':
        core.SM_NOISE_SCALE = math.inf
    try:
        est = estimate_batch(drive.stamps_ns, drive.q_m, drive.roll_rad, drive.speed_mps,
                             drive.vehicle_observer, obs)
    finally:
        core.SM_NOISE_SCALE = saved
    return per_sample(est, drive.stamps_ns)


def figures(drive, windows, est) -> tuple[float, float]:
    """(load error % of the dynamic RMS after 2 s, RMS load error (N) in the windows)."""
    from bench.accuracy.scenarios import score
    whole = score(drive, est)['load_rms_pct_dyn']
    err = np.asarray(est.wheel_load_n) - drive.truth['wheel_load_n']
    local = np.concatenate([err[a:b] for a, b in windows])
    return whole, float(np.sqrt(np.mean(local ** 2)))


def measure(duration_s: float, only=None, log=None) -> dict:
    """``{drive name: {(setting, latency): (whole %, local N)}}``."""
    out = {}
    for d in DRIVES:
        if only and d.name not in only:
            continue
        t0 = time.perf_counter()
        drive, windows = build(d, duration_s)
        out[d.name] = {(s, lat): figures(drive, windows, run(drive, s, lat))
                       for s in SETTINGS for lat in LATENCIES}
        if log:
            log(f'.. {d.name}: {time.perf_counter() - t0:.0f} s')
    return out


def table(res: dict) -> list[str]:
    head = ' | '.join(f'{s}, {"0" if lat == 0 else "10 ms"}' for lat in LATENCIES
                      for s in SETTINGS)
    lines = ['Load error over the drive, % of the dynamic RMS / RMS in the event windows (N); '
             'full against off in the last columns (local change, %).', '',
             f'| drive | theory | {head} | full vs off, 0 | full vs off, 10 ms |',
             '|---|---|' + '---:|' * (len(SETTINGS) * len(LATENCIES) + 2)]
    wins = {d.name: d.wins for d in DRIVES}
    for name, row in res.items():
        cells = [f'{row[s, lat][0]:.2f} / {row[s, lat][1]:.0f}' for lat in LATENCIES
                 for s in SETTINGS]
        rel = [100.0 * (row['full', lat][1] / row['off', lat][1] - 1.0) for lat in LATENCIES]
        lines.append(f'| {name} | {"wins" if wins[name] else "loses"} | ' + ' | '.join(cells)
                     + ' | ' + ' | '.join(f'{r:+.1f} %' for r in rel) + ' |')
    return lines


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog='python -m bench.studies.sliding_mode_events',
                                description=__doc__.splitlines()[0])
    p.add_argument('--duration', type=float, default=14.0, metavar='S',
                   help='s per drive (the event at 200 m = 10 s; >= 12)')
    p.add_argument('--only', nargs='+', default=None, metavar='NAME')
    args = p.parse_args(argv)
    if args.duration < 12.0:
        print('sliding_mode_events: --duration must be >= 12 s (the event is at 10 s)',
              file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    res = measure(args.duration, args.only, log=lambda s: print(s, file=sys.stderr,
                                                                 flush=True))
    print('\n'.join(table(res)))
    print(f'\n({time.perf_counter() - t0:.0f} s, {args.duration:g} s drives)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
