"""Does the sliding-mode term earn its place? Its weight and noise scale swept on drives with
bounded, non-Gaussian inputs (a pothole, parameter errors, the real-truck family's (e)) and on
the matched ones, zero latency.

``.venv/bin/python -m bench.studies.sliding_mode [--duration S]``

Per drive and setting (``observer.sliding_mode_gain``, ``estimation.model_core.SM_NOISE_SCALE``
and ``SM_DEAD_ZONE``; the weight is ``gain / (1 + (sigma_q / SM_NOISE_SCALE)^2)``): the load
error (% of the true dynamic-load RMS) / profile error (% of the 0.5-30 m band RMS). The
defaults are (1, 1e-7, 3); gain 0 is the ablation.

What it found: docs/notes/sliding_mode.md.
"""
from __future__ import annotations

import argparse
from dataclasses import replace
import sys

#: (gain, noise scale (m), dead zone (sigma)): the defaults, the ablation, then stronger terms.
SETTINGS = ((1.0, 1e-7, 3.0), (0.0, 1e-7, 3.0), (1.0, 1e-5, 3.0), (1.0, 1e-4, 3.0),
            (3.0, 1e-5, 3.0), (10.0, 1e-4, 3.0), (1.0, 1e-4, 1.0), (3.0, 1e-4, 0.3))


def _drives(duration_s: float):
    from bench.accuracy import real_truck as rt
    from bench.accuracy.scenarios import build_drive, scenario_by_name
    out = {}
    for name in ('C20-1k-10um', 'C20-1k-0um', 'B20-pothole', 'C20-params-10'):
        sc = scenario_by_name(name)
        if name != 'B20-pothole':     # (the pothole is at 200 m: the whole drive)
            sc = replace(sc, duration_s=duration_s)
        out[name] = build_drive(sc)
    for name in ('B20-pothole', 'C20-params-10'):
        sc = replace(scenario_by_name(name), noise_deflection_m=0.0)
        if name != 'B20-pothole':
            sc = replace(sc, duration_s=duration_s)
        out[name + ' (no noise)'] = build_drive(sc)
    e = next(d for d in rt.DRIVES if d.name == 'params-15')
    drive, stamps = rt.build(e, duration_s)
    drive.vehicle_observer = rt.files_for(e, drive.vehicle_plant)['nominal']
    out['real-truck (e), nominal file'] = drive
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog='bench.studies.sliding_mode',
                                description=__doc__.splitlines()[0])
    p.add_argument('--duration', type=float, default=10.0, metavar='S')
    args = p.parse_args(argv)
    from road_force_estimator.core.parameters import ObserverParameters
    import road_force_estimator.estimation.observer.online as core
    from road_force_estimator.estimation import estimate_batch
    from bench.accuracy.run_benchmark import per_sample
    from bench.accuracy.scenarios import score
    head = ' | '.join(f'{g:g} / {s:g} / {z:g}' for g, s, z in SETTINGS)
    print('| drive (gain / noise scale / dead zone) | ' + head + ' |')
    print('|---|' + '---:|' * len(SETTINGS))
    defaults = (core.SM_NOISE_SCALE, core.SM_DEAD_ZONE)
    try:
        for name, d in _drives(args.duration).items():
            cells = []
            for gain, scale, zone in SETTINGS:
                core.SM_NOISE_SCALE, core.SM_DEAD_ZONE = scale, zone
                obs = replace(ObserverParameters(), sliding_mode_gain=gain)
                est = estimate_batch(d.stamps_ns, d.q_m, d.roll_rad, d.speed_mps,
                                     d.vehicle_observer, obs)
                f = score(d, per_sample(est, d.stamps_ns))
                cells.append(f"{f['load_rms_pct_dyn']:.3f} / {f['profile_rms_pct_band']:.2f}")
            print(f'| {name} | ' + ' | '.join(cells) + ' |', flush=True)
    finally:
        core.SM_NOISE_SCALE, core.SM_DEAD_ZONE = defaults
    return 0


if __name__ == '__main__':
    sys.exit(main())
