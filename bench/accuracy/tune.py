"""Tune every peer honestly: a sweep on a separate drive, as a capable user would.

Procedure (what ``python -m bench.accuracy.tune`` does and records in
``bench/accuracy/tuned_peers.json``):

1. The tuning drive is :data:`bench.accuracy.scenarios.TUNING`: ISO class C, 20 m/s, 1 kHz, 20 s,
   on road seed 1001 and noise seed 1002 -- neither the road nor the noise of any scored scenario.
   It is simulated once per sensor-noise level (0, 10 and 50 um of deflection noise, roll noise
   10 rad/m times that), since a user knows the noise of the sensor he bought.
2. For each peer and noise level the objective is the vertical-load RMS error (% of the true
   dynamic-load RMS, both wheels, after the 2 s convergence skip) on that drive.
3. Search: every combination of the discrete knobs (filter order, model order, road model)
   times a coarse logarithmic grid of the continuous knobs (cutoff, spectral densities), then a
   pattern search in log space from the best grid point of each discrete combination that came
   within 1.5 x of the best (multiply / divide each knob by a factor, accept improvements,
   shrink the factor to 1.1); a few knobs join only the pattern search (the Kalman road
   model's leak and velocity correlation lengths). The signal-processing peers filter the
   roll channel with its own knob (cutoff, or jerk density), tuned like the deflections' one:
   the roll sensor is another sensor, and its noise reaches the wheel accelerations through
   the half track.
4. Second stage, for the profile only (it leaves the loads unchanged): the long-wavelength
   cutoff of each peer's body-heave / profile high-pass (``profile_cutoff_wavelength_m``; 0 =
   the Kalman filter's raw road state) is swept and refined the same way, minimising the
   band-passed (0.5-30 m) profile error on the same drive.
5. The Kalman peers take the measurement noise variance from the known sensor noise; on
   noise-free data a measurement-noise floor is one more tuned knob. Process-noise densities
   are tuned (the road's as an ISO roughness Gd(n0), so that they scale with the speed).

The benchmark loads the settings of the noise level of each scenario (:func:`settings_for`).
"""
from __future__ import annotations

import argparse
from dataclasses import asdict
import itertools
import json
import math
from pathlib import Path
import sys
import time
from typing import Any, Callable

from scipy import linalg

from bench.accuracy import peers
from bench.accuracy.scenarios import TUNING, Drive, build_drive, score

__all__ = ['TUNED_PATH', 'NOISE_LEVELS_M', 'SEARCH', 'tune_peer', 'load_tuned', 'settings_for',
           'build_parser', 'main']

TUNED_PATH = Path(__file__).resolve().parent / 'tuned_peers.json'
NOISE_LEVELS_M = (0.0, 10e-6, 50e-6)


def _logspace(lo: float, hi: float, n: int) -> list[float]:
    return [lo * (hi / lo) ** (i / (n - 1)) for i in range(n)]


#: Search space per peer: 'choices' (discrete knobs, every combination), 'grid' (continuous
#: knobs, coarse logarithmic grids), 'extra' (knobs refined only, from their default),
#: 'bounds' (limits of the refinement).
SEARCH: dict[str, dict[str, Any]] = {
    'paper-euler': {
        'choices': {},
        'grid': {'lipschitz_deflection_mps3': _logspace(100.0, 1e6, 9),
                 'lipschitz_roll_radps3': _logspace(1.0, 1e4, 5)},
        'bounds': {'lipschitz_deflection_mps3': (1e-2, 1e9),
                   'lipschitz_roll_radps3': (1e-5, 1e9)},
    },
    'lowpass-fd': {
        'choices': {'order': [1, 2, 3, 4], 'differences': ['backward', 'backward2']},
        'grid': {'cutoff_hz': _logspace(5.0, 320.0, 7),
                 'roll_cutoff_hz': _logspace(2.0, 128.0, 7)},
        'bounds': {'cutoff_hz': (0.5, 450.0), 'roll_cutoff_hz': (0.2, 450.0)},
    },
    'zero-phase-offline': {
        'choices': {'order': [1, 2, 3, 4]},
        'grid': {'cutoff_hz': _logspace(5.0, 320.0, 7),
                 'roll_cutoff_hz': _logspace(2.0, 128.0, 7)},
        'bounds': {'cutoff_hz': (0.5, 450.0), 'roll_cutoff_hz': (0.2, 450.0)},
    },
    'kf-jerk': {
        'choices': {'states': [3, 4]},
        'grid': {'jerk_psd': _logspace(1e-4, 1e12, 9),
                 'roll_jerk_psd': _logspace(1e-6, 1e10, 9)},
        'bounds': {'jerk_psd': (1e-12, 1e20), 'roll_jerk_psd': (1e-14, 1e18)},
    },
}
_KF_MODEL_SEARCH = {
    'choices': {'road_model': ['position', 'velocity']},
    'grid': {'road_gd_m3': _logspace(1e-6, 1e-3, 4), 'force_psd': _logspace(1e-2, 1e4, 4)},
    'extra': ['leak_wavelength_m'],
    'bounds': {'road_gd_m3': (1e-9, 1.0), 'force_psd': (1e-6, 1e10),
               'noise_floor_m': (1e-12, 1e-4), 'road_velocity_wavelength_m': (0.02, 20.0),
               'leak_wavelength_m': (20.0, 1e4)},
}
#: Second stage: grid of the profile cutoff wavelength (m); 0 = the Kalman road state as is.
PROFILE_GRID_M = [50.0, 100.0, 200.0, 400.0, 800.0, 1600.0, 3200.0]
PROFILE_BOUNDS_M = (5.0, 1e4)
for _name in ('kf-model', 'kf-model-lag5ms', 'kf-model-lag10ms', 'kf-model-rts'):
    SEARCH[_name] = _KF_MODEL_SEARCH


def _space(peer: str, noise_m: float) -> dict[str, Any]:
    space = {k: (dict(v) if isinstance(v, dict) else list(v)) for k, v in SEARCH[peer].items()}
    if peer in peers.USES_SENSOR_NOISE and noise_m == 0.0:
        space['grid']['noise_floor_m'] = _logspace(1e-9, 1e-6, 4)
    return space


def _key(settings: dict[str, Any]) -> str:
    return json.dumps(settings, sort_keys=True)


class Objective:
    """Scores of one peer's settings on one drive (cached); call with the metric wanted."""

    def __init__(self, drive: Drive):
        self.drive = drive
        self.cache: dict[str, dict[str, float]] = {}
        self.evaluations = 0

    def __call__(self, peer: str, settings: dict[str, Any],
                 metric: str = 'load_rms_pct_dyn') -> float:
        key = peer + _key(settings)
        if key not in self.cache:
            d = self.drive
            try:
                res = peers.call_peer(peer, d.t_s, d.q_m, d.roll_rad, d.speed_mps,
                                      d.vehicle_observer, settings,
                                      noise_deflection_m=d.scenario.noise_deflection_m,
                                      noise_roll_rad=d.scenario.noise_roll_rad)
                self.cache[key] = score(d, res)
            except (ValueError, ArithmeticError, RuntimeError, linalg.LinAlgError) as exc:
                print(f'tune: {peer} {settings}: {type(exc).__name__}: {exc}',
                      file=sys.stderr)
                self.cache[key] = {}
            self.evaluations += 1
        value = self.cache[key].get(metric, math.inf)
        return value if math.isfinite(value) else math.inf


def _pattern_search(f: Callable[[dict[str, Any]], float], start: dict[str, Any],
                    knobs: list[str], bounds: dict[str, tuple[float, float]],
                    factor: float, min_factor: float = 1.1) -> tuple[dict[str, Any], float]:
    best, best_val = dict(start), f(start)
    while factor >= min_factor and knobs:
        improved = False
        for name in knobs:
            for mult in (factor, 1.0 / factor):
                lo, hi = bounds.get(name, (0.0, math.inf))
                trial = dict(best)
                trial[name] = min(max(best[name] * mult, lo), hi)
                if trial[name] == best[name]:
                    continue
                val = f(trial)
                if val < best_val:
                    best, best_val, improved = trial, val, True
                    break
        if not improved:
            factor = math.sqrt(factor)
    return best, best_val


def tune_peer(peer: str, objective: Objective, noise_m: float) -> dict[str, Any]:
    """Sweep and refine the knobs of ``peer`` on the objective's drive (both stages)."""
    space = _space(peer, noise_m)
    base = dict(peers.DEFAULT_TUNING[peer])
    choices = space['choices']
    grid = space['grid']
    results = []
    for combo in itertools.product(*choices.values()) if choices else [()]:
        fixed = dict(zip(choices.keys(), combo))
        for point in itertools.product(*grid.values()):
            settings = {**base, **fixed, **dict(zip(grid.keys(), point))}
            results.append((objective(peer, settings), settings))
    results.sort(key=lambda r: r[0])
    # stage 1: refine the best grid point of each discrete combination within 1.5x of the best
    best_val, best = results[0]
    seen = set()
    step = max(_grid_ratio(grid[k]) for k in grid) ** 0.5
    for val, settings in results:
        combo = tuple(settings.get(k) for k in choices)
        if combo in seen or val > 1.5 * results[0][0] or not math.isfinite(val):
            continue
        seen.add(combo)
        knobs = list(grid.keys()) + list(space.get('extra', []))
        if settings.get('road_model') == 'velocity':
            knobs.append('road_velocity_wavelength_m')
            settings = {'road_velocity_wavelength_m': 0.5, **settings}
        cand, cand_val = _pattern_search(lambda s: objective(peer, s), settings, knobs,
                                         space['bounds'], step)
        if cand_val < best_val:
            best, best_val = cand, cand_val
    # stage 2: the profile cutoff (loads unchanged)
    profile_grid = ([0.0] if peer.startswith('kf-model') else []) + PROFILE_GRID_M
    trials = [(objective(peer, {**best, 'profile_cutoff_wavelength_m': lam},
                         'profile_rms_pct_band'), lam) for lam in profile_grid]
    p_val, lam = min(trials)
    final = {**best, 'profile_cutoff_wavelength_m': lam}
    if lam > 0.0:
        final, p_val = _pattern_search(
            lambda s: objective(peer, s, 'profile_rms_pct_band'), final,
            ['profile_cutoff_wavelength_m'], {'profile_cutoff_wavelength_m': PROFILE_BOUNDS_M},
            2.0 ** 0.5)
    load_val = objective(peer, final)
    return {'settings': final, 'tuning_load_rms_pct_dyn': round(load_val, 4),
            'tuning_profile_rms_pct_band': round(p_val, 4)}


def _grid_ratio(values: list[float]) -> float:
    return (values[-1] / values[0]) ** (1.0 / max(1, len(values) - 1)) if len(values) > 1 else 4.0


# ----------------------------------------------------------------------------------------------
# loading


def _noise_key(noise_m: float) -> str:
    return f'{noise_m:g}'


def load_tuned(path: str | Path = TUNED_PATH) -> dict[str, Any]:
    """The tuned-settings document (empty structure if the file does not exist)."""
    path = Path(path)
    if not path.exists():
        return {'peers': {}}
    return json.loads(path.read_text())


def settings_for(tuned: dict[str, Any], peer: str, noise_m: float) -> dict[str, Any]:
    """Tuned settings of ``peer`` for the tuning noise level closest to ``noise_m``.

    Closeness: exact match first, else nearest in log scale among the noisy levels (0 only for
    noise-free data). Falls back to :data:`bench.accuracy.peers.DEFAULT_TUNING` (untuned).
    """
    levels = tuned.get('peers', {}).get(peer, {})
    if not levels:
        return dict(peers.DEFAULT_TUNING[peer])
    key = _noise_key(noise_m)
    if key not in levels:
        noisy = [float(k) for k in levels if float(k) > 0]
        if noise_m > 0 and noisy:
            key = _noise_key(min(noisy, key=lambda v: abs(math.log(v / noise_m))))
        else:
            key = min(levels, key=lambda k: abs(float(k) - noise_m))
    return dict(levels[key]['settings'])


# ----------------------------------------------------------------------------------------------
# command line


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog='python -m bench.accuracy.tune',
                                description=__doc__.split('\n')[0])
    p.add_argument('--peers', nargs='+', default=list(peers.PEERS),
                   help='peers to tune (default: all)')
    p.add_argument('--noise', nargs='+', type=float, default=list(NOISE_LEVELS_M),
                   help='deflection-noise levels (m) to tune for (default: 0 1e-5 5e-5)')
    p.add_argument('--output', type=Path, default=TUNED_PATH, help='JSON file (merged)')
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    unknown = [p for p in args.peers if p not in peers.PEERS]
    if unknown:
        print(f'tune: unknown peer(s) {", ".join(unknown)}; one of {", ".join(peers.PEERS)}',
              file=sys.stderr)
        return 2
    if any(not (n >= 0.0 and math.isfinite(n)) for n in args.noise):
        print(f'tune: --noise {args.noise}: each level must be >= 0 m', file=sys.stderr)
        return 2
    doc = load_tuned(args.output)
    doc.update({
        'command': 'python -m bench.accuracy.tune',
        'procedure': ' '.join(__doc__.split('):', 1)[1].split()),
        'objective': 'vertical-load RMS error, % of the true dynamic-load RMS, after the skip',
        'tuning_drive': {k: v for k, v in asdict(TUNING).items() if k != 'noise_deflection_m'},
    })
    doc.setdefault('peers', {})
    for noise in args.noise:
        t0 = time.perf_counter()
        drive = build_drive(TUNING, noise_deflection_m=noise)
        objective = Objective(drive)
        print(f'tune: drive with {noise * 1e6:g} um noise built in '
              f'{time.perf_counter() - t0:.1f} s', file=sys.stderr)
        for peer in args.peers:
            t0 = time.perf_counter()
            n0 = objective.evaluations
            out = tune_peer(peer, objective, noise)
            out['evaluations'] = objective.evaluations - n0
            out['seconds'] = round(time.perf_counter() - t0, 1)
            doc['peers'].setdefault(peer, {})[_noise_key(noise)] = out
            print(f'tune: {peer:20s} {noise * 1e6:4g} um: '
                  f'{out["tuning_load_rms_pct_dyn"]:7.2f} %  {out["settings"]}  '
                  f'({out["evaluations"]} runs, {out["seconds"]} s)', file=sys.stderr)
            args.output.write_text(json.dumps(doc, indent=1, sort_keys=True) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
