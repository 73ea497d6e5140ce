"""The offline smoother in overlapping windows against one piece: how much overlap it needs.

    .venv/bin/python -m bench.studies.offline_windows [--duration 120] [--speed 20] [--window 30]
                                              [--overlaps 1 2 3 4] [--json FILE]

Simulates a noisy drive (``simulate_bag``: ISO 8608 class C, seed 1, 1 kHz, 10 um / 0.1 mrad
noise), smooths it in one piece (:func:`estimation.smoother.smooth` with a window longer than
the drive) and in windows of ``--window`` seconds with an overlap on each side of ``k``
time constants of the slowest transient (:func:`.smoother.window_samples`), for each ``k`` of
``--overlaps``; prints per overlap the largest difference of every estimated field, relative
to that field's RMS over the drive (the worst field named), and the largest differences of
the wheel loads (N), the road (m) and the LTR. The converged flags must agree exactly.

What it found: docs/notes/offline_windows.md.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
from pathlib import Path
import sys
import tempfile

import numpy as np


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--duration', type=float, default=120.0, help='drive length, s')
    p.add_argument('--speed', type=float, default=20.0, help='m/s')
    p.add_argument('--window', type=float, default=30.0, help='window length, s')
    p.add_argument('--overlaps', type=float, nargs='+', default=[8.0, 12.0, 16.0, 20.0, 24.0],
                   help='overlaps on each side, in time constants of the slowest transient '
                        '(smoother.window_samples)')
    p.add_argument('--json', metavar='FILE', help='also write the numbers as JSON')
    return p


def _drive(tmp: Path, duration_s: float, speed: float):
    from road_force_estimator import bagio
    from road_force_estimator.tools import simulate_bag

    bag = tmp / 'drive'
    sink = io.StringIO()
    with contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink):
        code = simulate_bag.main([
            '--road', 'iso8608:C:seed=1', '--speed', f'{speed:g}', '--rate', '1000',
            '--duration', f'{duration_s:g}', '--noise-deflection', '1e-5',
            '--noise-roll', '1e-4', '--seed', '1', '--no-ground-truth', '--output', str(bag),
            '--no-progress'])
    if code != 0:
        raise RuntimeError(sink.getvalue()[-300:])
    return bagio.read_drive_bag(bag)


def compare(one, win) -> dict:
    """Largest differences of the windowed estimate ``win`` from the one-piece ``one``."""
    from road_force_estimator.estimation.outputs import FIELD_COLUMNS, FLAG_FIELDS

    worst, worst_name, fields = 0.0, '', {}
    for name in FIELD_COLUMNS:
        a, b = np.asarray(getattr(one, name)), np.asarray(getattr(win, name))
        if name in FLAG_FIELDS:
            fields[name] = int(np.count_nonzero(a != b))
            continue
        rms = float(np.sqrt(np.mean(np.square(a))))
        rel = float(np.max(np.abs(a - b))) / rms if rms > 0.0 else float(np.max(np.abs(a - b)))
        fields[name] = rel
        if rel > worst:
            worst, worst_name = rel, name
    return {'max_rel_rms': worst, 'worst_field': worst_name,
            'load_n': float(np.max(np.abs(one.wheel_load_n - win.wheel_load_n))),
            'road_m': float(np.max(np.abs(one.road_m - win.road_m))),
            'ltr': float(np.max(np.abs(one.ltr - win.ltr))),
            'flags_differing': sum(fields[f] for f in FLAG_FIELDS), 'fields': fields}


def measure(duration_s: float, speed: float, window_s: float, overlaps) -> dict:
    from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
    from road_force_estimator.estimation.offline import smooth
    from road_force_estimator.estimation.smoothing.smoother import window_samples

    vehicle, observer = VehicleParameters(), ObserverParameters()
    with tempfile.TemporaryDirectory(prefix='offline_windows_') as tmp:
        drive = _drive(Path(tmp), duration_s, speed)
    speed_arr = np.array(drive.speed_mps, dtype=float)
    args = (drive.stamps_ns, drive.q_m, drive.roll_rad, speed_arr, vehicle, observer)
    n = len(drive.stamps_ns)
    one = smooth(*args, window=(n + 1, 0))
    tau = _slowest_tau(vehicle, observer, one.status, speed)
    rows = []
    for k in overlaps:
        overlap = window_samples(1e-3, speed, observer.profile_cutoff_wavelength_m, tau, k)[1]
        win = smooth(*args, window=(int(window_s * 1000.0), overlap))
        rows.append({'overlap_taus': k, 'overlap_s': overlap / 1000.0, **compare(one, win)})
    return {'samples': n, 'speed_mps': speed, 'window_s': window_s, 'tau_s': tau,
            'rows': rows}


def _slowest_tau(vehicle, observer, status, speed: float) -> float:
    """The slower of the smoother's slowest mode (the gains of the drive's noise and
    roughness) and the body heave high-pass's time constant (s)."""
    from road_force_estimator.estimation.models.front_axle import FrontAxleModel
    from road_force_estimator.estimation.observer.schedule import GainSchedule
    from road_force_estimator.estimation.smoothing.smoother import slowest_tau_s, window_samples

    sched = GainSchedule(FrontAxleModel(vehicle), observer)
    sched.set_run(1e-3, speed)
    sched.noise_deflection_m = status.noise_deflection_m
    sched.noise_roll_rad = status.noise_roll_rad
    sched.road_gd_m3 = status.road_roughness_m3
    sched.requantise_noise()
    filt = slowest_tau_s(sched.design(1e-3, 0), 1e-3)
    heave = window_samples(1e-3, speed, observer.profile_cutoff_wavelength_m, 0.0, 1.0)[1]
    return max(filt, heave * 1e-3)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    doc = measure(args.duration, args.speed, args.window, args.overlaps)
    doc['command'] = ('python -m bench.studies.offline_windows '
                      + ' '.join(argv or sys.argv[1:])).strip()
    print(f'# Offline smoother in windows against one piece: `{doc["command"]}`\n')
    print(f'ISO C, {args.speed:g} m/s, 1 kHz, {args.duration:g} s ({doc["samples"]} samples), '
          f'10 um / 0.1 mrad noise; windows of {args.window:g} s; slowest time constant '
          f'{doc["tau_s"]:.3g} s.\n')
    print('| overlap (time constants) | overlap (s) | max diff / RMS | worst field | load (N) '
          '| road (m) | LTR | flags differing |')
    print('|---|---|---|---|---|---|---|---|')
    for r in doc['rows']:
        print(f'| {r["overlap_taus"]:g} | {r["overlap_s"]:g} | {r["max_rel_rms"]:.2e} '
              f'| {r["worst_field"]} | {r["load_n"]:.2e} | {r["road_m"]:.2e} | {r["ltr"]:.2e} '
              f'| {r["flags_differing"]} |')
    if args.json:
        Path(args.json).write_text(json.dumps(doc, indent=2) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
