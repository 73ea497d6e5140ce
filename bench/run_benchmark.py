"""The benchmark: every method on every scenario, side by side, as Markdown tables.

``python -m bench.run_benchmark [--output bench/results.md] [--json FILE]``

Methods are the peers of :mod:`bench.peers` with the settings of ``bench/tuned_peers.json``
(tuned on a separate drive by :mod:`bench.tune`, per sensor-noise level), and whatever else is
registered in :data:`METHODS` (the package's own estimator modes). Scenarios are those of
:mod:`bench.scenarios`. Figures per scenario and method: vertical-load RMS error (% of the true
dynamic-load RMS and % of the static load), band-passed (0.5-30 m) profile error (% of the
band's RMS), IRI error per 100 m, LTR RMS error, convergence time; and the run time of each
method (microseconds per sample, median of repeats on the MODEL.md scenario).
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass
import json
import math
from pathlib import Path
import platform
import statistics
import sys
import time
from typing import Any, Callable

import numpy as np

from bench import peers, tune
from bench.scenarios import SCENARIOS, Drive, build_drive, scenario_by_name, score

__all__ = ['Method', 'METHODS', 'peer_method', 'run', 'markdown', 'build_parser', 'main']


@dataclass(frozen=True)
class Method:
    """A column of the benchmark.

    ``run(drive, tuned)`` returns an object with ``wheel_load_n`` (n, 2), ``road_m`` (n, 2) and
    ``ltr`` (n,), row k = the estimate for sample k. ``latency`` is shown in the table header
    ('0', '5 ms', 'offline', ...).
    """

    name: str
    run: Callable[[Drive, dict[str, Any]], Any]
    latency: str = '0'


def peer_method(name: str) -> Method:
    """The benchmark column of peer ``name`` (tuned settings for the drive's noise level)."""

    def run_peer(drive: Drive, tuned: dict[str, Any]):
        settings = tune.settings_for(tuned, name, drive.scenario.noise_deflection_m)
        return peers.call_peer(name, drive.t_s, drive.q_m, drive.roll_rad, drive.speed_mps,
                               drive.vehicle_observer, settings,
                               noise_deflection_m=drive.scenario.noise_deflection_m,
                               noise_roll_rad=drive.scenario.noise_roll_rad)

    latency = {'zero-phase-offline': 'offline', 'kf-model-rts': 'offline',
               'kf-model-lag5ms': '5 ms', 'kf-model-lag10ms': '10 ms'}.get(name, '0')
    return Method(name, run_peer, latency)


#: Columns, in table order. Add the package's estimator modes here (same signature).
METHODS: dict[str, Method] = {name: peer_method(name) for name in peers.PEERS}

#: Figures reported, in table order: (key of :func:`bench.scenarios.score`, title, format).
FIGURES = (
    ('load_rms_pct_dyn', 'Vertical-load RMS error, % of the true dynamic-load RMS', '{:.1f}'),
    ('load_rms_pct_static', 'Vertical-load RMS error, % of the static load', '{:.2f}'),
    ('profile_rms_pct_band', 'Profile RMS error in the 0.5-30 m band, % of the band RMS',
     '{:.1f}'),
    ('iri_err_pct_mean', 'IRI error per 100 m segment (mean |error|), % of the true IRI',
     '{:.1f}'),
    ('ltr_rms', 'LTR RMS error', '{:.4f}'),
    ('convergence_s', 'Start-up convergence time (s): load error settles within 2x its RMS',
     '{:.2f}'),
)

TIMING_SCENARIO = 'C20-1k-10um'


def run(scenarios, methods: list[Method], tuned: dict[str, Any], *, timing_repeats: int = 5,
        log=None) -> dict[str, Any]:
    """Score every method on every scenario; time each method on :data:`TIMING_SCENARIO`."""
    results: dict[str, dict[str, dict[str, float]]] = {}
    timing: dict[str, float] = {}
    for sc in scenarios:
        t0 = time.perf_counter()
        drive = build_drive(sc)
        results[sc.name] = {}
        for m in methods:
            t1 = time.perf_counter()
            try:
                res = m.run(drive, tuned)
                figures = score(drive, res)
            except (ValueError, ArithmeticError, RuntimeError) as exc:
                figures = {'error': f'{type(exc).__name__}: {exc}'}
            figures['seconds'] = time.perf_counter() - t1
            results[sc.name][m.name] = figures
            if sc.name == TIMING_SCENARIO and 'error' not in figures:
                times = [figures['seconds']]
                for _ in range(max(0, timing_repeats - 1)):
                    t2 = time.perf_counter()
                    m.run(drive, tuned)
                    times.append(time.perf_counter() - t2)
                timing[m.name] = 1e6 * statistics.median(times) / len(drive.t_s)
        if log:
            log(f'{sc.name}: {len(drive.t_s)} samples, {time.perf_counter() - t0:.1f} s')
    return {'results': results, 'us_per_sample': timing}


def _cell(fig: dict[str, float], key: str, fmt: str) -> str:
    if 'error' in fig:
        return 'fails'
    v = fig.get(key, math.nan)
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return '-'
    if isinstance(v, float) and math.isinf(v):
        return 'never'
    return fmt.format(v)


def markdown(out: dict[str, Any], scenarios, methods: list[Method], *,
             command: str = 'python -m bench.run_benchmark') -> str:
    """The Markdown tables of a :func:`run` result."""
    names = [m.name for m in methods]
    lines = [f'Command: `{command}` ({platform.python_implementation()} '
             f'{platform.python_version()}, numpy {np.__version__}). Peers tuned on a separate '
             'drive (`bench/tuned_peers.json`, `python -m bench.tune`).', '']
    lines += ['Scenarios: ' + '; '.join(f'`{s.name}` {s.description}' for s in scenarios), '']
    head = '| scenario | ' + ' | '.join(names) + ' |'
    lat = '| latency | ' + ' | '.join(m.latency for m in methods) + ' |'
    sep = '|---|' + '---:|' * len(names)
    for key, title, fmt in FIGURES:
        lines += [f'### {title}', '', head, sep, lat]
        for sc in scenarios:
            row = out['results'].get(sc.name, {})
            lines.append(f'| {sc.name} | ' + ' | '.join(
                _cell(row.get(n, {'error': 'missing'}), key, fmt) for n in names) + ' |')
        lines.append('')
    lines += ['### Run time (microseconds per sample, batch, median of repeats on '
              f'`{TIMING_SCENARIO}`)', '', '| ' + ' | '.join(names) + ' |',
              '|' + '---:|' * len(names),
              '| ' + ' | '.join(f'{out["us_per_sample"].get(n, math.nan):.2f}'
                                for n in names) + ' |', '']
    return '\n'.join(lines)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog='python -m bench.run_benchmark',
                                description='Run every method on every scenario; Markdown.')
    p.add_argument('--scenarios', nargs='+', default=None, help='scenario names (default all)')
    p.add_argument('--methods', nargs='+', default=None, help='method names (default all)')
    p.add_argument('--tuned', type=Path, default=tune.TUNED_PATH, help='tuned settings JSON')
    p.add_argument('--output', type=Path, default=None, help='write the Markdown here too')
    p.add_argument('--json', type=Path, default=None, help='write all figures as JSON')
    p.add_argument('--timing-repeats', type=int, default=5)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        scenarios = ([scenario_by_name(n) for n in args.scenarios] if args.scenarios
                     else list(SCENARIOS))
    except ValueError as exc:
        print(f'run_benchmark: {exc}', file=sys.stderr)
        return 2
    unknown = [n for n in (args.methods or []) if n not in METHODS]
    if unknown:
        print(f'run_benchmark: unknown method(s) {", ".join(unknown)}; one of '
              f'{", ".join(METHODS)}', file=sys.stderr)
        return 2
    methods = [METHODS[n] for n in (args.methods or METHODS)]
    try:
        tuned = tune.load_tuned(args.tuned)
    except (OSError, ValueError) as exc:
        print(f'run_benchmark: cannot read {args.tuned}: {exc}', file=sys.stderr)
        return 2
    if not tuned.get('peers'):
        print(f'run_benchmark: {args.tuned} has no tuned settings: peers run untuned '
              '(run python -m bench.tune)', file=sys.stderr)
    t0 = time.perf_counter()
    out = run(scenarios, methods, tuned, timing_repeats=args.timing_repeats,
              log=lambda s: print(f'run_benchmark: {s}', file=sys.stderr))
    text = markdown(out, scenarios, methods)
    text += f'\nTotal run time: {time.perf_counter() - t0:.0f} s.\n'
    print(text)
    if args.output:
        args.output.write_text(text)
    if args.json:
        args.json.write_text(json.dumps(out, indent=1, default=float) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
