"""Is 1.3 x reachable at all? A near-optimal nonlinear reference for friction + lag at 10 ms
(issue 30): :func:`bench.accuracy.particle_peer.particle_fixed_lag` on the drives of
:mod:`bench.studies.friction_lag`, told the truth.

``.venv/bin/python -m bench.studies.friction_lag_bound [--part check|converge|drives|decompose]
[--road-seeds N ...] [--particles N ...] [--duration S] [--substeps N] [--lookahead N]
[--seed N]``

Drives: :func:`bench.studies.friction_lag.build` (class C, 20 m/s, 1 kHz, 10 um, 20 s), scored
by :func:`bench.accuracy.scenarios.score` (load error in % of the true dynamic-load RMS after
the 2 s skip), at 10 ms (the particle reference's fixed lag of 10 samples, its look-ahead 7
by default, the Kalman peer's
``kf-model-lag10ms``, ours at ``observer.latency`` 0.01 s), each given the truth's file
(friction, lag and v_f). The particle reference has the peer's tuned settings
(``tuned_peers.json``, ``kf-model-lag10ms`` at 10 um).

Parts:

- ``check``: on the matched and the lag drives (linear-Gaussian), the particle reference
  beside the Kalman peer (``--particles``, the first), road seed 1: they should agree within
  a few percent (the reference below the peer would read past the lag);
- ``converge``: the sharper truth told (``friction+lag, truth v_f 0.005, file v_f 0.005``),
  on the road seeds given, at each ``--particles``;
- ``drives``: per road seed, the matched drive, the lag, ``friction+lag`` (v_f 0.01) and the
  sharper truth told, ours, the peer and the particle reference (``--particles``, the last),
  each one's ratio to our matched drive (issue 30's) and to its own matched drive;
- ``decompose``: on the sharper truth told (road seed 1), the rate error (mm/s) and the
  friction force error (N RMS per spring) where the true rate is below 2 cm/s and elsewhere,
  ours (the file's law at our rate, as ``friction_lag --decompose``) beside the particle
  reference's posterior mean of the force.

Each particle run prints its effective sample size (mean, 5th percentile, least after the skip;
the share of samples resampled) and its CPU seconds.

What it found: docs/notes/friction_lag_bound.md.
"""
from __future__ import annotations

import argparse
from dataclasses import replace
import sys
import time

import numpy as np

#: The drives of this study, by :data:`bench.studies.friction_lag.DRIVES`' names.
MATCHED, LAG, BOTH, SHARP = ('matched', 'lag', 'friction+lag',
                             'friction+lag, truth v_f 0.005, file v_f 0.005')
TARGET = 1.3


def drive_of(name: str, duration_s: float, road_seed: int):
    """The drive ``name`` of :data:`.friction_lag.DRIVES` and the file it is told."""
    from bench.studies import friction_lag as fl

    truck, v_true, v_file = {d[0]: d[1:] for d in fl.DRIVES}[name]
    return (fl.build(truck, v_true, duration_s, road_seed),
            replace(truck, leaf_spring_friction_velocity_mps=v_file))


def tuning(noise_m: float) -> dict:
    """The peer's tuned settings at ``noise_m`` and the sensor noise (the peers' way)."""
    from bench.accuracy import tune
    from bench.accuracy.scenarios import ROLL_NOISE_PER_DEFLECTION

    out = tune.settings_for(tune.load_tuned(tune.TUNED_PATH), 'kf-model-lag10ms', noise_m)
    out.update(noise_deflection_m=noise_m, noise_roll_rad=ROLL_NOISE_PER_DEFLECTION * noise_m)
    return out


def ours(drive, vehicle) -> tuple[float, object]:
    """Our 10 ms load error (% dyn) and the estimate."""
    from bench.accuracy.run_benchmark import per_sample
    from bench.accuracy.scenarios import score
    from road_force_estimator.core.parameters import ObserverParameters
    from road_force_estimator.estimation import estimate_batch

    est = estimate_batch(drive.stamps_ns, drive.q_m, drive.roll_rad, drive.speed_mps, vehicle,
                         ObserverParameters(latency_s=0.01))
    return score(drive, per_sample(est, drive.stamps_ns))['load_rms_pct_dyn'], est


def peer(drive, vehicle, lag: int = 10) -> float:
    """The Kalman peer's (``kf-model-lag10ms``'s settings, lag states where the file has a
    lag) load error (% dyn) at a fixed lag of ``lag`` samples (0: its filter)."""
    from bench.accuracy import peers
    from bench.accuracy.scenarios import score

    settings = tuning(drive.scenario.noise_deflection_m)
    res = peers.kf_model_lag(drive.t_s, drive.q_m, drive.roll_rad, drive.speed_mps, vehicle,
                             lag_s=lag * 1e-3, **settings)
    return score(replace(drive, vehicle_observer=vehicle), res)['load_rms_pct_dyn']


def particle(drive, vehicle, n_particles: int, substeps: int, seed: int = 0, lag: int = 10,
             lookahead: int = 7):
    """The particle reference's load error (% dyn) at a fixed lag of ``lag`` samples, its
    result and a line of its effective sample size and CPU time."""
    from bench.accuracy.particle_peer import particle_fixed_lag
    from bench.accuracy.scenarios import score

    res = particle_fixed_lag(drive.t_s, drive.q_m, drive.roll_rad, drive.speed_mps, vehicle,
                             n_particles=n_particles, lag_samples=lag, seed=seed,
                             substeps=substeps, lookahead=lookahead,
                             **tuning(drive.scenario.noise_deflection_m))
    ess = res.ess[drive.skip:] / n_particles
    note = (f'N {n_particles}, seed {seed}, look-ahead {res.extra["lookahead"]}, '
            f'{substeps} sub-steps: '
            f'ESS/N mean {ess.mean():.2f}, 5th pct {np.percentile(ess, 5):.2f}, '
            f'least {ess.min():.3f}; resampled at {100 * res.resampled / len(res.ess):.0f} % '
            f'of the samples; {res.cpu_s:.0f} s CPU')
    return score(replace(drive, vehicle_observer=vehicle), res)['load_rms_pct_dyn'], res, note


def check(args, log) -> list[str]:
    """Part ``check`` (module notes)."""
    lines = ['| drive (road seed 1) | lag (samples) | Kalman peer (% dyn) | particle (% dyn) | '
             'particle / peer | the particle run |', '|---|---:|---:|---:|---:|---|']
    for name in (MATCHED, LAG):
        drive, vehicle = drive_of(name, args.duration, 1)
        for lag in (10,):
            kf = peer(drive, vehicle, lag)
            pf, _, note = particle(drive, vehicle, args.particles[0], args.substeps, lag=lag,
                                   lookahead=args.lookahead, seed=args.seed)
            lines.append(f'| {name} | {lag} | {kf:.3f} | {pf:.3f} | {pf / kf:.3f} | {note} |')
            log(lines[-1])
    return lines


def converge(args, log) -> list[str]:
    """Part ``converge`` (module notes)."""
    lines = [f'| {SHARP}, 10 ms | road seed | particle (% dyn) | the particle run |',
             '|---|---:|---:|---|']
    for seed in args.road_seeds:
        drive, vehicle = drive_of(SHARP, args.duration, seed)
        for n in args.particles:
            pf, _, note = particle(drive, vehicle, n, args.substeps,
                                   lookahead=args.lookahead, seed=args.seed)
            lines.append(f'| N {n} | {seed} | {pf:.3f} | {note} |')
            log(lines[-1])
    return lines


def drives(args, log) -> list[str]:
    """Part ``drives`` (module notes)."""
    n = args.particles[-1]
    lines = ['| drive (10 ms) | road seed | ours (% dyn) | peer (% dyn) | particle (% dyn) | '
             'particle / our matched | particle / its matched | ours / our matched | '
             'the particle run |', '|---|---:|---:|---:|---:|---:|---:|---:|---|']
    for seed in args.road_seeds:
        ref = {}
        for name in (MATCHED, LAG, BOTH, SHARP):
            drive, vehicle = drive_of(name, args.duration, seed)
            o, _ = ours(drive, vehicle)
            kf = peer(drive, vehicle)
            pf, _, note = particle(drive, vehicle, n, args.substeps,
                               lookahead=args.lookahead, seed=args.seed)
            ref = ref or {'ours': o, 'pf': pf}
            lines.append(f'| {name} | {seed} | {o:.3f} | {kf:.3f} | {pf:.3f} | '
                         f'{pf / ref["ours"]:.3f} | {pf / ref["pf"]:.3f} | '
                         f'{o / ref["ours"]:.3f} | {note} |')
            log(lines[-1])
    return lines


def decompose(args, log) -> list[str]:
    """Part ``decompose`` (module notes)."""
    drive, vehicle = drive_of(SHARP, args.duration, 1)
    k0 = drive.skip
    dq_true = np.gradient(drive.truth['q_m'], drive.t_s, axis=0)[k0:]
    f_n, v_f = float(vehicle.leaf_spring_friction_n[0]), vehicle.leaf_spring_friction_velocity_mps
    f_true = -f_n * np.tanh(dq_true / v_f)
    slow = np.abs(dq_true) < 0.02
    o, est = ours(drive, vehicle)
    pf, res, note = particle(drive, vehicle, args.particles[-1], args.substeps,
                               lookahead=args.lookahead, seed=args.seed)
    candidates = (('ours', o, np.asarray(est.dq)[k0:],
                   -f_n * np.tanh(np.asarray(est.dq)[k0:] / v_f)),
                  ('particle', pf, res.dq_mps[k0:], res.friction_n[k0:]))
    lines = [f'| {SHARP}, road seed 1, 10 ms | load (% dyn) | rate error (mm/s) | friction error, '
             '|dq| < 2 cm/s (N) | elsewhere (N) |', '|---|---:|---:|---:|---:|']

    def rms(a: np.ndarray) -> float:
        return float(np.sqrt(np.mean(a ** 2)))

    for who, err, dq, force in candidates:
        lines.append(f'| {who} | {err:.3f} | {1000 * rms(dq - dq_true):.2f} | '
                     f'{rms((force - f_true)[slow]):.0f} | {rms((force - f_true)[~slow]):.0f} |')
        log(lines[-1])
    lines.append('')
    lines.append(f'- |dq| < 2 cm/s on {100 * slow.mean():.0f} % of the samples; {note}')
    return lines


PARTS = {'check': check, 'converge': converge, 'drives': drives, 'decompose': decompose}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog='python -m bench.studies.friction_lag_bound',
                                description=__doc__.splitlines()[0])
    p.add_argument('--part', choices=list(PARTS), nargs='+', default=list(PARTS))
    p.add_argument('--duration', type=float, default=20.0, metavar='S', help='s per drive')
    p.add_argument('--road-seeds', type=int, nargs='+', default=[1], metavar='N')
    p.add_argument('--particles', type=int, nargs='+', default=[500, 2000], metavar='N',
                   help='check: the first; converge: each; drives, decompose: the last')
    p.add_argument('--substeps', type=int, default=4, metavar='N',
                   help='sub-steps of a sample (the friction held over each)')
    p.add_argument('--lookahead', type=int, default=7, metavar='N',
                   help="samples of the weights' look-ahead (at most the lag, 10)")
    p.add_argument('--seed', type=int, default=0, metavar='N', help="the particles' seed")
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    for part in args.part:
        print('\n'.join(PARTS[part](args, lambda s: print(f'.. {s}', file=sys.stderr,
                                                            flush=True))) + '\n', flush=True)
    print(f'({time.perf_counter() - t0:.0f} s; {args.duration:g} s drives)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
