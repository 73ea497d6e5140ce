"""Offline replay: accuracy of the two estimate_bag modes and end-to-end speed.

    .venv/bin/python bench/probes/offline_speed.py [--duration 30] [--repeats 3] [--json FILE]

1. Simulates a noisy drive with ``simulate_bag`` (default: ISO 8608 class C, seed 1, 20 m/s,
   1 kHz, 30 s, 10 um deflection and 0.1 mrad roll noise, noise seed 1, GNSS 10 Hz).
2. Accuracy: ``estimate_bag`` online and offline on it; the wheel-load error (% of the true
   dynamic-load RMS, both wheels pooled), the band-passed profile error (0.5-30 m, % of the
   band-passed truth's RMS) and the LTR error, from each report.
3. Speed: ``estimate_bag`` end to end (read the bag, estimate, write the bag of estimates and
   the report), report figures excluded and included, samples per second, the median of
   ``--repeats`` runs; for the offline mode also the stages (read, estimate, write bag).

Numbers depend on the machine; the command line and the numbers go to stdout (Markdown) and,
with ``--json``, to a file.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path
import statistics
import sys
import tempfile
import time

REPO = Path(__file__).resolve().parents[2]
PARAMS = REPO / 'config' / 'road_force_estimator.yaml'


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--road', default='iso8608:C:seed=1', help='road source (simulate_bag)')
    p.add_argument('--speed', type=float, default=20.0, help='m/s')
    p.add_argument('--rate', type=float, default=1000.0, help='Hz')
    p.add_argument('--duration', type=float, default=30.0, help='s')
    p.add_argument('--noise', type=float, default=1e-5,
                   help='deflection noise std, m (roll: 10 rad/m times it)')
    p.add_argument('--seed', type=int, default=1, help='noise seed')
    p.add_argument('--params-file', default=str(PARAMS),
                   help='parameter file (default: config/road_force_estimator.yaml)')
    p.add_argument('--repeats', type=int, default=3, help='timed runs per case (median)')
    p.add_argument('--json', metavar='FILE', help='also write the numbers as JSON')
    return p


def _timed(func, repeats: int) -> tuple[float, list[float]]:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        func()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), times


def main(argv: list[str] | None = None) -> int:
    from road_force_estimator import bagio
    from road_force_estimator.tools import estimate_bag
    from road_force_estimator.tools import simulate_bag
    from road_force_estimator.estimation import estimate_offline

    args = build_parser().parse_args(argv)
    vehicle, observer = estimate_bag.load_parameters(args.params_file)
    out: dict = {'command': 'bench/probes/offline_speed.py ' + ' '.join(argv or sys.argv[1:]),
                 'observer': observer.to_parameters(),
                 'drive': {'road': args.road, 'speed_mps': args.speed, 'rate_hz': args.rate,
                           'duration_s': args.duration, 'noise_deflection_m': args.noise,
                           'noise_roll_rad': 10.0 * args.noise, 'seed': args.seed}}
    with tempfile.TemporaryDirectory(prefix='offline_speed_') as tmp:
        tmp = Path(tmp)
        drive = tmp / 'drive'
        code = simulate_bag.main([
            '--road', args.road, '--speed', str(args.speed), '--rate', str(args.rate),
            '--duration', str(args.duration), '--params-file', str(PARAMS),
            '--noise-deflection', str(args.noise), '--noise-roll', str(10.0 * args.noise),
            '--seed', str(args.seed), '--output', str(drive), '--no-progress'])
        if code != 0:
            return code
        n = len(bagio.read_drive_bag(drive).stamps_ns)
        out['samples'] = n

        accuracy = {}
        for mode in ('online', 'offline'):
            res = estimate_bag.run(drive, tmp / f'acc_{mode}', vehicle=vehicle,
                                   observer=observer, mode=mode, figures=False)
            a = res.summary['accuracy']
            accuracy[mode] = {
                'load_rms_pct_dynamic': a['load_rms_pct_dynamic_both'],
                'load_rms_pct_static': sum(a['load_rms_pct_static']) / 2.0,
                'profile_rms_pct_band': a['profile_rms_pct_band_both'],
                'ltr_rms_error': a['ltr_rms_error'],
                'iri_estimated': res.summary['iri_m_per_km']['estimated'],
                'iri_true': res.summary['iri_m_per_km']['true']}
        out['accuracy'] = accuracy

        speed = {}
        count = [0]
        for mode in ('offline', 'online'):
            for figures in (False, True):
                def once(mode=mode, figures=figures):
                    count[0] += 1
                    estimate_bag.run(drive, tmp / f'speed_{count[0]}', vehicle=vehicle,
                                     observer=observer, mode=mode, figures=figures)
                med, times = _timed(once, args.repeats)
                speed[f'{mode}, figures {"included" if figures else "excluded"}'] = {
                    'median_s': med, 'samples_per_s': n / med, 'runs_s': times}
        d = bagio.read_drive_bag(drive)
        speed_stage = {}
        est = None

        def read():
            bagio.read_drive_bag(drive)

        def estimate():
            nonlocal est
            est = estimate_offline(d.stamps_ns, d.q_m, d.roll_rad, d.speed_mps, vehicle,
                                   observer)

        def write():
            count[0] += 1
            bagio.write_estimate_bag(tmp / f'w_{count[0]}', est)

        for name, func in (('read drive bag', read), ('estimate (offline core)', estimate),
                           ('write estimate bag', write)):
            med, times = _timed(func, args.repeats)
            speed_stage[name] = {'median_s': med, 'samples_per_s': n / med, 'runs_s': times}
        out['speed'] = speed
        out['offline_stages'] = speed_stage

    print(f'# estimate_bag offline/online: {out["command"]}\n')
    dr = out['drive']
    print(f'Drive: {dr["road"]}, {dr["speed_mps"]:g} m/s, {dr["rate_hz"]:g} Hz, '
          f'{dr["duration_s"]:g} s ({n} samples), noise {1e6 * dr["noise_deflection_m"]:g} um / '
          f'{1e3 * dr["noise_roll_rad"]:g} mrad, seed {dr["seed"]}; online = observer.'
          f'discretization {observer.discretization!r}.\n')
    print('| mode | load error, % dyn RMS | % static | profile error, % band | LTR RMS error '
          '| IRI est. L/R (true) |')
    print('|---|---|---|---|---|---|')
    for mode, a in accuracy.items():
        print(f'| {mode} | {a["load_rms_pct_dynamic"]:.2f} | {a["load_rms_pct_static"]:.2f} | '
              f'{a["profile_rms_pct_band"]:.2f} | {a["ltr_rms_error"]:.4f} | '
              f'{a["iri_estimated"][0]:.2f}/{a["iri_estimated"][1]:.2f} '
              f'({a["iri_true"][0]:.2f}/{a["iri_true"][1]:.2f}) |')
    print(f'\nSpeed, end to end (bag in, bag + report out), median of {args.repeats}:\n')
    print('| case | median (s) | samples/s |')
    print('|---|---|---|')
    for case, v in list(speed.items()) + list(speed_stage.items()):
        print(f'| {case} | {v["median_s"]:.3f} | {v["samples_per_s"]:,.0f} |')
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(out, indent=2) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
