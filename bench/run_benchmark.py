"""The benchmark: our estimator beside its peers on every scenario, and its speed, in one run.

``.venv/bin/python -m bench.run_benchmark --output bench/results/benchmark.md``

writes the Markdown (and prints it): a headline table (the MODEL.md scenario), a plain line per
target of issue 11 (met or not, with the numbers), where our estimator loses, one wide table
per figure (methods as columns, grouped by latency), and a speed section; the wall time last.

Columns (:data:`METHODS`):

- the peers of :mod:`bench.peers`, with the settings of ``bench/tuned_peers.json`` (tuned on a
  separate drive by :mod:`bench.tune`, per sensor-noise level);
- the package's own estimator, read from its public API at run time, so that a rerun picks up
  whatever the package does then: ``ours-online`` (``estimate_batch`` with
  ``ObserverParameters()`` defaults, whatever the default method is), ``ours-chain-implicit``
  (the differentiator chain, implicit scheme), ``ours-no-smo`` (the defaults with the
  sliding-mode injection off, when the parameter exists), ``ours-latency-5ms`` and
  ``ours-latency-10ms`` (``observer.latency`` = 5 / 10 ms; 'n/a' while it changes nothing),
  ``ours-offline`` (what ``estimate_bag --mode offline`` runs:
  :func:`estimation.estimate_recording`) and ``ours-model-smoother``
  (:func:`estimation.smooth`). A column that cannot
  run shows 'n/a' and the reason.

Figures per scenario (:mod:`bench.scenarios`) and method: vertical-load RMS error (% of the
true dynamic-load RMS, % of the static load), band-passed (0.5-30 m) profile error (% of the
band's RMS; the same filter on estimate and truth, :mod:`road_force_estimator.core.metrics`), IRI
error per 100 m segment (:mod:`road_force_estimator.core.iri` on estimate and truth: mean and max
|relative error|), LTR RMS error, start-up convergence time.

Speed (timeit, median of repeats): microseconds per sample of :meth:`Estimator.update` per
scheme, end-to-end ``estimate_bag`` samples per second (bag in, bag out) on a simulated bag,
the observer node's latency and CPU at 1 kHz (``bench/node_latency.py``, in a subprocess), and
every column's batch run time.
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass, fields, replace
import json
import math
from pathlib import Path
import platform
import statistics
import subprocess
import sys
import tempfile
import time
import timeit
from types import SimpleNamespace
from typing import Any, Callable

import numpy as np

from bench import peers, tune
from bench.scenarios import SCENARIOS, Drive, build_drive, scenario_by_name, score

__all__ = [
    'Method', 'NotAvailable', 'METHODS', 'FIGURES', 'TIMING_SCENARIO', 'HEADLINE_SCENARIOS',
    'COMMAND', 'peer_method', 'ours_observer', 'per_sample', 'run', 'core_cost',
    'end_to_end_speed', 'node_latency', 'speed', 'targets', 'losses', 'markdown',
    'readme_section', 'build_parser', 'main',
]

_T_START = time.perf_counter()
REPO = Path(__file__).resolve().parents[1]
#: The command the README quotes.
COMMAND = '.venv/bin/python -m bench.run_benchmark --output bench/results/benchmark.md'
#: Scenario of the per-method batch timing and of the core cost.
TIMING_SCENARIO = 'C20-1k-10um'
#: The README's headline: the MODEL.md scenario with and without sensor noise.
HEADLINE_SCENARIOS = ('C20-1k-10um', 'C20-1k-0um')
#: Latency groups, in column order.
GROUPS = ('zero latency', 'low latency', 'offline')


def g3(v: float) -> str:
    """About three significant digits for a percentage (0.123, 2.45, 17.5, 102)."""
    a = abs(v)
    return (f'{v:.0f}' if a >= 100 else f'{v:.1f}' if a >= 10 else f'{v:.2f}' if a >= 1
            else f'{v:.3f}')


class NotAvailable(Exception):
    """The package cannot run this column as it is now (shown as 'n/a' with the reason)."""


@dataclass(frozen=True)
class Method:
    """A column of the benchmark.

    ``run(drive, tuned)`` returns an object with ``wheel_load_n`` (n, 2), ``road_m`` (n, 2) and
    ``ltr`` (n,), row k = the estimate for sample k, or raises :class:`NotAvailable`.
    ``latency`` is shown in the table header ('0', '10 ms', 'offline'), ``group`` is one of
    :data:`GROUPS`, ``description`` may hold ``{default}`` (the package's default method).
    """

    name: str
    run: Callable[[Drive, dict[str, Any]], Any]
    latency: str = '0'
    group: str = 'zero latency'
    description: str = ''
    ours: bool = False


# ----------------------------------------------------------------------------------------------
# the peers


_PEER_LATENCY = {'zero-phase-offline': ('offline', 'offline'), 'kf-model-rts': ('offline',
                                                                                'offline'),
                 'kf-model-lag5ms': ('5 ms', 'low latency'),
                 'kf-model-lag10ms': ('10 ms', 'low latency')}
_PEER_TEXT = {
    'paper-euler': "the package's differentiator chain with the paper's explicit-Euler scheme "
                   '(L tuned)',
    'lowpass-fd': 'causal Butterworth low-pass + backward differences, then the MODEL.md '
                  'reconstruction',
    'kf-jerk': 'causal Kalman filter per channel (integrated random walk), then the '
               'reconstruction',
    'kf-model': 'causal Kalman filter on the linearised roll-plane model, road velocity as an '
                'augmented state',
    'kf-model-lag5ms': "kf-model's exact fixed-lag smoother, 5 ms",
    'kf-model-lag10ms': "kf-model's exact fixed-lag smoother, 10 ms",
    'kf-model-rts': "kf-model's Rauch-Tung-Striebel smoother over the whole drive",
    'zero-phase-offline': 'zero-phase Butterworth + central differences, then the '
                          'reconstruction',
}


def peer_method(name: str) -> Method:
    """The benchmark column of peer ``name`` (tuned settings for the drive's noise level)."""

    def run_peer(drive: Drive, tuned: dict[str, Any]):
        settings = tune.settings_for(tuned, name, drive.scenario.noise_deflection_m)
        return peers.call_peer(name, drive.t_s, drive.q_m, drive.roll_rad, drive.speed_mps,
                               drive.vehicle_observer, settings,
                               noise_deflection_m=drive.scenario.noise_deflection_m,
                               noise_roll_rad=drive.scenario.noise_roll_rad)

    latency, group = _PEER_LATENCY.get(name, ('0', 'zero latency'))
    return Method(name, run_peer, latency, group, _PEER_TEXT.get(name, ''))


# ----------------------------------------------------------------------------------------------
# the package's own estimator, read from its public API at run time


def _observer_field(param: str) -> str | None:
    """Field of ObserverParameters that carries the dotted parameter ``param`` (or None)."""
    from road_force_estimator.core.parameters import ObserverParameters

    for f in fields(ObserverParameters):
        if f.metadata.get('param') == param:
            return f.name
    return None


def _sliding_mode_param() -> str | None:
    """Dotted name of the sliding-mode weight of the default observer, if the package has one."""
    from road_force_estimator.core.parameters import SPECS

    names = [n for n in SPECS if n.startswith('observer.') and 'sliding' in n]
    return names[0] if names else None


def ours_observer(changes: dict[str, Any] | None = None):
    """``ObserverParameters()`` (the package defaults) with dotted parameters changed.

    Raises
    ------
    NotAvailable
        A parameter the package does not have, or a value it does not accept (the message
        says which).
    """
    from road_force_estimator.core.parameters import ObserverParameters

    kwargs = {}
    for param, value in (changes or {}).items():
        name = _observer_field(param)
        if name is None:
            raise NotAvailable(f'the package has no parameter {param}')
        kwargs[name] = value
    try:
        return replace(ObserverParameters(), **kwargs)
    except ValueError as exc:
        raise NotAvailable(str(exc)) from None


def default_method() -> str:
    """The package's default ``observer.discretization`` (its default estimator)."""
    from road_force_estimator.core.parameters import ObserverParameters

    return str(getattr(ObserverParameters(), 'discretization', '?'))


def per_sample(est, stamps_ns: np.ndarray):
    """Rows of ``est`` placed on the samples whose stamps they carry (row k = sample k).

    ``est`` has ``stamp_ns``, ``wheel_load_n``, ``road_m``, ``ltr`` (and optionally ``valid``).
    Samples without an estimate hold the previous one (the first estimate before it).
    """
    s = np.asarray(est.stamp_ns, dtype=np.int64)
    n = len(stamps_ns)
    if s.shape == (n,) and np.array_equal(s, stamps_ns):
        return est
    valid = np.asarray(getattr(est, 'valid', np.ones(len(s), bool)), dtype=bool)
    idx = np.searchsorted(stamps_ns, s)
    ok = valid & (idx < n)
    ok[ok] = stamps_ns[idx[ok]] == s[ok]
    rows = np.full(n, -1)
    rows[idx[ok]] = np.flatnonzero(ok)
    have = rows >= 0
    if not have.any():
        raise RuntimeError('no estimate carries the stamp of an input sample')
    fill = np.where(have, np.arange(n), -1)
    np.maximum.accumulate(fill, out=fill)
    fill[fill < 0] = int(np.flatnonzero(have)[0])
    take = rows[fill]
    return SimpleNamespace(stamp_ns=stamps_ns, wheel_load_n=np.asarray(est.wheel_load_n)[take],
                           road_m=np.asarray(est.road_m)[take], ltr=np.asarray(est.ltr)[take])


def _batch(drive: Drive, observer):
    from road_force_estimator.estimation import estimate_batch

    stamps = drive.stamps_ns
    est = estimate_batch(stamps, drive.q_m, drive.roll_rad, drive.speed_mps,
                         drive.vehicle_observer, observer)
    return per_sample(est, stamps)


def _ours_default(drive: Drive):
    """The package defaults' estimate of ``drive`` (cached on the drive)."""
    if 'ours-online' not in drive.cache:
        drive.cache['ours-online'] = _batch(drive, ours_observer())
    return drive.cache['ours-online']


def _run_ours_online(drive: Drive, tuned: dict[str, Any]):
    res = _batch(drive, ours_observer())
    drive.cache['ours-online'] = res
    return res


def _run_ours_chain(drive: Drive, tuned: dict[str, Any]):
    return _batch(drive, ours_observer({'observer.discretization': 'implicit'}))


def _run_ours_no_smo(drive: Drive, tuned: dict[str, Any]):
    from road_force_estimator.estimation import SCHEMES

    param = _sliding_mode_param()
    if param is None:
        raise NotAvailable('the package has no sliding-mode switch (observer.sliding_mode_*)')
    if default_method() in SCHEMES:
        raise NotAvailable(f'the default method is the differentiator chain '
                           f'({default_method()!r}): no sliding-mode injection to switch off')
    return _batch(drive, ours_observer({param: 0.0}))


def _run_ours_latency(drive: Drive, tuned: dict[str, Any], lag_s: float = 0.01):
    res = _batch(drive, ours_observer({'observer.latency': lag_s}))
    base = _ours_default(drive)
    if np.array_equal(np.asarray(res.wheel_load_n), np.asarray(base.wheel_load_n)):
        raise NotAvailable(f'observer.latency = {lag_s:g} s gives the zero-latency numbers '
                           f'(no fixed-lag estimate for the default method {default_method()!r})')
    return res


def _offline_function() -> tuple[str, Callable]:
    """``(name, function)`` that ``estimate_bag --mode offline`` runs."""
    from road_force_estimator.estimation import estimate_recording
    return 'estimation.estimate_recording', estimate_recording


def _run_ours_smoother(drive: Drive, tuned: dict[str, Any]):
    from road_force_estimator.estimation import smooth as fn
    stamps = drive.stamps_ns
    est = fn(stamps, drive.q_m, drive.roll_rad, drive.speed_mps, drive.vehicle_observer,
             ours_observer())
    return per_sample(est, stamps)


def _run_ours_offline(drive: Drive, tuned: dict[str, Any]):
    _, fn = _offline_function()
    stamps = drive.stamps_ns
    est = fn(stamps, drive.q_m, drive.roll_rad, drive.speed_mps, drive.vehicle_observer,
             ours_observer())
    return per_sample(est, stamps)


_OURS = (
    Method('ours-online', _run_ours_online, '0', 'zero latency',
           "package defaults: estimate_batch with ObserverParameters() "
           "(observer.discretization = '{default}'), never tuned per drive", True),
    Method('ours-chain-implicit', _run_ours_chain, '0', 'zero latency',
           "the package's differentiator chain, implicit scheme, default L", True),
    Method('ours-no-smo', _run_ours_no_smo, '0', 'zero latency',
           'ablation: the defaults with the sliding-mode injection off '
           '(observer.sliding_mode_gain = 0)', True),
    Method('ours-latency-5ms', lambda d, t: _run_ours_latency(d, t, 0.005), '5 ms',
           'low latency', 'the defaults with observer.latency = 0.005 s', True),
    Method('ours-latency-10ms', _run_ours_latency, '10 ms', 'low latency',
           'the defaults with observer.latency = 0.01 s (each estimate 10 ms after its sample)',
           True),
    Method('ours-offline', _run_ours_offline, 'offline', 'offline',
           'estimate_bag --mode offline: road_force_estimator.{offline} with the defaults',
           True),
    Method('ours-model-smoother', _run_ours_smoother, 'offline', 'offline',
           "road_force_estimator.estimation.smooth called directly: the model "
           "observer's "
           'RTS smoother with the defaults (for comparison with ours-offline)', True),
)


def _methods() -> dict[str, Method]:
    cols = [peer_method(n) for n in peers.PEERS] + list(_OURS)
    order = {g: i for i, g in enumerate(GROUPS)}
    cols.sort(key=lambda m: order[m.group])       # stable: peers before ours in each group
    return {m.name: m for m in cols}


#: Columns, in table order (zero latency, low latency, offline; peers first in each group).
METHODS: dict[str, Method] = _methods()

#: Figures reported: (key of :func:`bench.scenarios.score`, title, format, second key or None).
FIGURES = (
    ('load_rms_pct_dyn', 'Vertical-load RMS error, % of the true dynamic-load RMS', g3, None),
    ('load_rms_pct_static', 'Vertical-load RMS error, % of the static load', '{:.2f}', None),
    ('profile_rms_pct_band', 'Profile RMS error in the 0.5-30 m band, % of the band RMS', g3,
     None),
    ('iri_err_pct_mean', 'IRI error per 100 m segment, |relative error| in %: mean / max over '
     'the segments and both wheels', g3, 'iri_err_pct_max'),
    ('xcorr', 'Profile as profilers are judged: IRI-filtered cross correlation with the true '
     'profile (ProVAL, AASHTO R56; 1 = identical), the lower wheel over the drive / the lowest '
     '100 m segment', '{:.3f}', 'xcorr_seg_min'),
    ('ltr_rms', 'LTR RMS error', '{:.4f}', None),
    ('convergence_s', 'Start-up convergence time (s): load error settles within 2x its RMS',
     '{:.2f}', None),
)


# ----------------------------------------------------------------------------------------------
# accuracy


def run(scenarios, methods: list[Method], tuned: dict[str, Any], *, timing_repeats: int = 5,
        duration_s: float | None = None, log=None, keep_drive: str | None = None
        ) -> dict[str, Any]:
    """Score every method on every scenario; time each method on :data:`TIMING_SCENARIO`.

    Returns ``{'results': {scenario: {method: figures}}, 'us_per_sample': {method: us},
    'drive': the Drive of keep_drive or None}``; figures hold ``'na'`` (reason) for a column
    that cannot run and ``'error'`` for one that failed.
    """
    results: dict[str, dict[str, dict[str, Any]]] = {}
    timing: dict[str, float] = {}
    kept = None
    for sc in scenarios:
        if duration_s is not None:   # quick checks: shorter drives, events kept inside them
            d = duration_s
            if sc.event is not None:
                d = max(d, (sc.event[2] + sc.event[3] + 20.0) / sc.speed_mps)
            sc = replace(sc, duration_s=d, skip_s=min(sc.skip_s, 0.25 * d),
                         lateral_step_s=min(sc.lateral_step_s, 0.6 * d))
        t0 = time.perf_counter()
        drive = build_drive(sc)
        results[sc.name] = {}
        for m in methods:
            t1 = time.perf_counter()
            try:
                res = m.run(drive, tuned)
                figures: dict[str, Any] = score(drive, res)
            except NotAvailable as exc:
                figures = {'na': str(exc)}
            except Exception as exc:   # noqa: BLE001 - a failing column must not stop the run
                figures = {'error': f'{type(exc).__name__}: {exc}'}
            figures['seconds'] = time.perf_counter() - t1
            results[sc.name][m.name] = figures
            if sc.name == TIMING_SCENARIO and 'error' not in figures and 'na' not in figures:
                times = [figures['seconds']]
                for _ in range(max(0, timing_repeats - 1)):
                    t2 = time.perf_counter()
                    m.run(drive, tuned)
                    times.append(time.perf_counter() - t2)
                timing[m.name] = 1e6 * statistics.median(times) / len(drive.t_s)
        if sc.name == keep_drive:
            drive.cache.clear()
            kept = drive
        if log:
            log(f'{sc.name}: {len(drive.t_s)} samples, {time.perf_counter() - t0:.1f} s')
    return {'results': results, 'us_per_sample': timing, 'drive': kept}


# ----------------------------------------------------------------------------------------------
# speed


def _update_cost(drive: Drive, observer, *, samples: int, warmup: int,
                 repeats: int) -> tuple[float, float, float]:
    """Microseconds per :meth:`Estimator.update` over ``samples`` samples: the median and min
    wall time (timeit, perf_counter) and the median process CPU time of ``repeats`` runs."""
    from road_force_estimator.estimation import Estimator

    n = len(drive.t_s)
    warmup = min(warmup, n // 4)
    stop = min(n, warmup + samples)
    st = drive.stamps_ns.tolist()
    q = drive.q_m.tolist()
    phi = drive.roll_rad.tolist()
    v = drive.speed_mps.tolist()
    holder: dict[str, Any] = {}
    cpu: list[float] = []

    def setup():
        est = Estimator(drive.vehicle_observer, observer)
        for k in range(warmup):
            est.update(st[k], q[k], phi[k], v[k])
        holder['update'] = est.update

    def stmt():
        update = holder['update']
        c0 = time.process_time()
        for k in range(warmup, stop):
            update(st[k], q[k], phi[k], v[k])
        cpu.append(time.process_time() - c0)

    times = timeit.Timer(stmt, setup).repeat(repeat=repeats, number=1)
    per = 1e6 / (stop - warmup)
    return statistics.median(times) * per, min(times) * per, statistics.median(cpu) * per


def core_cost(drive: Drive, *, samples: int = 5000, warmup: int = 1000,
              repeats: int = 7) -> list[dict[str, Any]]:
    """Microseconds per sample of :meth:`Estimator.update`, per scheme and for the latency mode.

    Every choice of ``observer.discretization`` (the rest at the defaults), and the defaults
    with ``observer.latency = 0.01`` when the package has it; after ``warmup`` samples, the
    median (and min) of ``repeats`` timeit runs of ``samples`` samples each.
    """
    from road_force_estimator.core.parameters import SPECS

    default = default_method()
    variants = [(f'observer.discretization = {c}' + (' (default)' if c == default else ''),
                 {'observer.discretization': c})
                for c in SPECS['observer.discretization'].choices]
    if _observer_field('observer.latency') is not None:
        variants.append(('defaults, observer.latency = 0.01 s', {'observer.latency': 0.01}))
    rows = []
    for label, change in variants:
        row: dict[str, Any] = {'variant': label, 'default': change.get(
            'observer.discretization') == default}
        try:
            med, best, cpu = _update_cost(drive, ours_observer(change), samples=samples,
                                          warmup=warmup, repeats=repeats)
            row.update(us_median=med, us_min=best, us_cpu=cpu)
        except NotAvailable as exc:
            row['error'] = str(exc)
        except Exception as exc:   # noqa: BLE001
            row['error'] = f'{type(exc).__name__}: {exc}'
        rows.append(row)
    return rows


def end_to_end_speed(*, duration_s: float = 600.0, online_duration_s: float = 60.0,
                     repeats: int = 3) -> dict[str, Any]:
    """``estimate_bag`` end to end (bag in, bag + report without figures out), samples/s.

    :func:`bench.estimate_bag_speed.measure`: a drive recorded as a truck would (deflections,
    twist, fixes; ISO C, 20 m/s, 1 kHz), ``estimate_bag.run`` timed in a child process pinned
    to one CPU with one BLAS thread, the median of ``repeats`` runs after the first; bags in
    /dev/shm when there is one (the disk out of the figures). Offline on ``duration_s``,
    online (per-sample Python) on ``online_duration_s``.
    """
    import os

    from bench import estimate_bag_speed

    tmp_dir = '/dev/shm' if os.path.isdir('/dev/shm') else None
    out: dict[str, Any] = {'source': 'bench/estimate_bag_speed.py', 'modes': {}, 'detail': {}}
    for mode, duration in (('offline', duration_s), ('online', online_duration_s)):
        try:
            doc = estimate_bag_speed.measure(duration_s=duration, repeats=repeats, mode=mode,
                                             tmp_dir=tmp_dir)
        except Exception as exc:   # noqa: BLE001 - reported in the table
            out['modes'][mode] = {'error': f'{type(exc).__name__}: {exc}'}
            continue
        run = doc['median_run']
        out['modes'][mode] = {'median_s': run['wall_s'], 'samples': doc['samples'],
                              'samples_per_s': doc['samples'] / run['wall_s'],
                              'samples_per_cpu_s': doc['samples'] / run['cpu_s'],
                              'cpu_per_wall': run['cpu_s'] / run['wall_s'],
                              'drive_s': duration}
        out['detail'][mode] = doc
    return out


def node_latency(*, seconds: float = 10.0, timeout_s: float = 240.0) -> dict[str, Any]:
    """The observer node at 1 kHz: ``bench/node_latency.py`` run in a subprocess (its JSON)."""
    script = REPO / 'bench' / 'node_latency.py'
    if not script.exists():
        return {'error': 'bench/node_latency.py is not there'}
    with tempfile.TemporaryDirectory(prefix='run_benchmark_node_') as tmp:
        path = Path(tmp) / 'node.json'
        cmd = [sys.executable, str(script), '--rate', '1000', '--seconds', f'{seconds:g}',
               '--sweep', '1000,2000,5000,8000', '--sweep-seconds', '2', '--json', str(path)]
        try:
            proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True,
                                  timeout=timeout_s)
        except subprocess.TimeoutExpired:
            return {'error': f'bench/node_latency.py did not finish in {timeout_s:g} s'}
        if proc.returncode != 0 or not path.exists():
            tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or ['']
            return {'error': f'bench/node_latency.py exit {proc.returncode}: {tail[0][:300]}'}
        doc = json.loads(path.read_text())
    main_run = doc.get('main', {})
    return {'rate_hz': main_run.get('rate_hz'), 'seconds': seconds,
            'sent': main_run.get('sent'), 'lost': main_run.get('lost'),
            'median_ms': main_run.get('median_ms'), 'p99_ms': main_run.get('p99_ms'),
            'cpu_percent': main_run.get('observer_cpu_percent_of_one_core'),
            'sustained_rate_hz': doc.get('sustained_rate_hz'),
            'executor': doc.get('executor')}


#: Environment of the one-thread measurements: numpy's BLAS and OpenMP pools held to 1 thread.
ONE_THREAD_ENV = {'OPENBLAS_NUM_THREADS': '1', 'OMP_NUM_THREADS': '1', 'MKL_NUM_THREADS': '1'}


def core_cost_one_thread(*, timeout_s: float = 300.0) -> list[dict[str, Any]] | dict[str, str]:
    """:func:`core_cost` on :data:`TIMING_SCENARIO` in a subprocess with one BLAS thread.

    numpy's BLAS may run a small matrix product on several threads: the wall time then falls
    below the CPU time spent. This is the "on one core" figure.
    """
    import os

    env = {**os.environ, **ONE_THREAD_ENV}
    try:
        proc = subprocess.run([sys.executable, '-m', 'bench.run_benchmark', '--core-cost-json'],
                              cwd=REPO, env=env, capture_output=True, text=True,
                              timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return {'error': f'no answer in {timeout_s:g} s'}
    if proc.returncode != 0:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or ['']
        return {'error': f'exit {proc.returncode}: {tail[0][:300]}'}
    return json.loads(proc.stdout)


def speed(drive: Drive | None, *, node: bool = True, core_repeats: int = 7,
          log=None) -> dict[str, Any]:
    """The speed section: core cost per scheme (as the process runs, and on one BLAS thread),
    end-to-end estimate_bag, node latency."""
    out: dict[str, Any] = {}
    if drive is not None:
        t0 = time.perf_counter()
        out['core'] = core_cost(drive, repeats=core_repeats)
        one = core_cost_one_thread()
        if isinstance(one, dict):
            for row in out['core']:
                row['one_thread_error'] = one['error']
        else:
            by_variant = {r['variant']: r for r in one}
            for row in out['core']:
                r1 = by_variant.get(row['variant'], {})
                if 'us_median' in r1:
                    row['us_one_thread'] = r1['us_median']
        if log:
            log(f'speed: core cost, {time.perf_counter() - t0:.1f} s')
    t0 = time.perf_counter()
    try:
        out['end_to_end'] = end_to_end_speed()
    except Exception as exc:   # noqa: BLE001
        out['end_to_end'] = {'error': f'{type(exc).__name__}: {exc}'}
    if log:
        log(f'speed: estimate_bag end to end, {time.perf_counter() - t0:.1f} s')
    if node:
        t0 = time.perf_counter()
        out['node'] = node_latency()
        if log:
            log(f'speed: observer node, {time.perf_counter() - t0:.1f} s')
    return out


# ----------------------------------------------------------------------------------------------
# verdicts


def _fig(out, sc: str, m: str, key: str = 'load_rms_pct_dyn') -> float | None:
    f = out['results'].get(sc, {}).get(m, {})
    v = f.get(key)
    return float(v) if isinstance(v, (int, float)) and math.isfinite(v) else None


def _why_missing(out, m: str) -> str:
    for row in out['results'].values():
        f = row.get(m, {})
        if 'na' in f:
            return f'{m} n/a: {f["na"]}'
        if 'error' in f:
            return f'{m} fails: {f["error"]}'
    return f'{m} not in this run'


def _compare(out, scenarios, ours: str, ref: str, factor: float, key: str = 'load_rms_pct_dyn'):
    """[(scenario, ours, ref)] where both exist, and those with ours > factor x ref."""
    rows = [(s.name, _fig(out, s.name, ours, key), _fig(out, s.name, ref, key))
            for s in scenarios]
    rows = [r for r in rows if r[1] is not None and r[2] is not None]
    return rows, [r for r in rows if r[1] > factor * r[2]]


def _worst(rows) -> str:
    sc, o, r = max(rows, key=lambda x: x[1] / max(x[2], 1e-12))
    return f'worst {sc}: {g3(o)} % vs {g3(r)} % (ratio {o / max(r, 1e-12):.2f})'


def _same_numbers(out, a: str, b: str) -> bool:
    """Columns a and b have the same figures on every scenario (one runs the other)."""
    rows = [(r.get(a), r.get(b)) for r in out['results'].values()]
    keys = ('load_rms_pct_dyn', 'profile_rms_pct_band', 'ltr_rms')
    return bool(rows) and all(
        fa is not None and fb is not None and all(fa.get(k) == fb.get(k) for k in keys)
        for fa, fb in rows)


def _verdict(ok: bool | None) -> str:
    return {True: 'MET', False: 'NOT MET', None: 'NOT MEASURED'}[ok]


def targets(out, scenarios, speed_out: dict[str, Any] | None) -> list[str]:
    """One plain line per target of issue 11: met / not met, with the numbers."""
    lines = []
    names = [s.name for s in scenarios]
    # zero latency
    rows, bad = _compare(out, scenarios, 'ours-online', 'kf-model', 1.0)
    if rows:
        ok = not bad and len(rows) == len(names)
        text = (f'**Zero latency** (ours-online load error <= kf-model on every scenario): '
                f'{_verdict(ok)}: no worse on {len(rows) - len(bad)} of {len(rows)} scenarios'
                f'; {_worst(rows)}')
        if bad:
            text += '; worse on ' + ', '.join(f'{s} ({g3(o)} vs {g3(r)})' for s, o, r in bad)
        lp_rows = [(s.name, _fig(out, s.name, 'ours-online'), _fig(out, s.name, 'lowpass-fd'),
                    _fig(out, s.name, 'kf-model')) for s in scenarios if s.noise_deflection_m]
        allowed = [r for r in lp_rows if None not in r and r[3] <= 0.7 * r[2]]
        if allowed:
            good = [r for r in allowed if r[1] <= 0.7 * r[2]]
            text += (f'. Against 0.7 x lowpass-fd where kf-model itself gets there '
                     f'({len(allowed)} noisy scenarios): {len(good)} of {len(allowed)}')
        lines.append(text + '.')
    else:
        lines.append('**Zero latency**: NOT MEASURED (' + _why_missing(out, 'ours-online') + ').')
    # low latency
    noisy = [s for s in scenarios if s.noise_deflection_m > 0]
    rows, bad = _compare(out, noisy, 'ours-latency-10ms', 'kf-model-lag10ms', 1.1)
    head = _fig(out, 'C20-1k-10um', 'ours-latency-10ms')
    if rows:
        ok = not bad and len(rows) == len(noisy) and head is not None and head < 5.0
        text = (f'**Low latency** (observer.latency = 10 ms: <= 1.1 x kf-model-lag10ms on '
                f'every noisy scenario, < 5 % on C20-1k-10um): {_verdict(ok)}: within 1.1 x on '
                f'{len(rows) - len(bad)} of {len(rows)} noisy scenarios; {_worst(rows)}')
        if head is not None:
            text += f'; C20-1k-10um: {head:.2f} %'
        if bad:
            text += '; above on ' + ', '.join(f'{s} ({g3(o)} vs {g3(r)})' for s, o, r in bad)
        lines.append(text + '.')
    else:
        lines.append('**Low latency**: NOT MEASURED (' + _why_missing(out, 'ours-latency-10ms')
                     + ').')
    # offline: what estimate_bag --mode offline runs; the model smoother as information
    for i, m in enumerate(('ours-offline', 'ours-model-smoother')):
        rows_z, bad_z = _compare(out, scenarios, m, 'zero-phase-offline', 1.0)
        rows_r, bad_r = _compare(out, scenarios, m, 'kf-model-rts', 1.3)
        if i and (not (rows_z and rows_r) or _same_numbers(out, 'ours-offline', m)):
            continue
        if rows_z and rows_r:
            ok = not bad_z and not bad_r and len(rows_z) == len(rows_r) == len(names)
            text = (f'{_verdict(ok)}: <= zero-phase-offline on {len(rows_z) - len(bad_z)} of '
                    f'{len(rows_z)} scenarios ({_worst(rows_z)}); within 1.3 x kf-model-rts on '
                    f'{len(rows_r) - len(bad_r)} of {len(rows_r)} ({_worst(rows_r)})')
        else:
            text = f'NOT MEASURED ({_why_missing(out, m)})'
        if i == 0:
            lines.append('**Offline** (ours-offline, what estimate_bag --mode offline runs: <= '
                         'zero-phase-offline and <= 1.3 x kf-model-rts on every scenario): '
                         f'{text}.')
        else:
            lines[-1] += (' For information, by the same rule, the smoother of the model '
                          f'observer called directly (ours-model-smoother): {text}.')
    # profile
    prof = [(n, _fig(out, n, 'ours-online', 'profile_rms_pct_band')) for n in names]
    prof = [p for p in prof if p[1] is not None]
    iri = [(n, _fig(out, n, 'ours-online', 'iri_err_pct_max')) for n in names]
    iri = [p for p in iri if p[1] is not None]
    if prof:
        p_bad = [p for p in prof if p[1] >= 10.0]
        i_bad = [p for p in iri if p[1] >= 5.0]
        ok = not p_bad and not i_bad and len(prof) == len(names)
        pw = max(prof, key=lambda p: p[1])
        text = (f'**Profile** (ours-online: band-passed profile error < 10 %, IRI per 100 m '
                f'within 5 %): {_verdict(ok)}: profile < 10 % on {len(prof) - len(p_bad)} of '
                f'{len(prof)} scenarios (worst {pw[0]}: {g3(pw[1])} %)')
        if iri:
            iw = max(iri, key=lambda p: p[1])
            text += (f'; every segment within 5 % on {len(iri) - len(i_bad)} of {len(iri)} '
                     f'(worst {iw[0]}: {g3(iw[1])} %)')
        for m in ('ours-latency-10ms', 'ours-offline'):
            vals = [_fig(out, n, m, 'profile_rms_pct_band') for n in names]
            vals = [v for v in vals if v is not None]
            if vals:
                text += f'; {m}: profile worst {g3(max(vals))} %'
        lines.append(text + '.')
    else:
        lines.append('**Profile**: NOT MEASURED (' + _why_missing(out, 'ours-online') + ').')
    lines.append(_xcorr_target(out, names))
    # robust defaults
    ran = [n for n in names if _fig(out, n, 'ours-online') is not None]
    lines.append(f'**Robust defaults**: every ours-* column ran with the package defaults '
                 f'(ObserverParameters(); only its own switch changed) on {len(ran)} of '
                 f'{len(names)} scenarios, with no setting per drive (noise level, roughness, '
                 f'rate, speed and parameter errors vary); that the derivation is documented is '
                 'not judged by the benchmark.')
    # speed
    lines.append(_speed_target(speed_out))
    return lines


#: Issue 21: the IRI-filtered cross correlation each mode must reach on every scenario.
XCORR_TARGETS = (('ours-offline', 0.99), ('ours-latency-10ms', 0.98))


def _xcorr_target(out, names: list[str]) -> str:
    """Issue 21's profile target: the cross correlation per mode on every scenario."""
    parts, ok, measured = [], True, 0
    for m, goal in XCORR_TARGETS:
        vals = [(n, _fig(out, n, m, 'xcorr')) for n in names]
        vals = [v for v in vals if v[1] is not None]
        if not vals:
            parts.append(f'{m}: not measured ({_why_missing(out, m)})')
            ok = False
            continue
        measured += 1
        low = [v for v in vals if v[1] < goal]
        ok = ok and not low and len(vals) == len(names)
        worst = min(vals, key=lambda v: v[1])
        segs = [_fig(out, n, m, 'xcorr_seg_min') for n, _ in vals]
        segs = [v for v in segs if v is not None]
        text = (f'{m} >= {goal:g} on {len(vals) - len(low)} of {len(vals)} (worst {worst[0]}: '
                f'{worst[1]:.3f}')
        text += f'; lowest 100 m segment {min(segs):.3f})' if segs else ')'
        parts.append(text)
    online = [v for v in (_fig(out, n, 'ours-online', 'xcorr') for n in names) if v is not None]
    if online:
        parts.append(f'ours-online worst {min(online):.3f}')
    return ('**Profile as profilers are judged** (issue 21: IRI-filtered cross correlation with '
            'the true profile, exact distance, >= 0.99 offline and >= 0.98 at 10 ms on every '
            f'scenario): {_verdict(ok if measured else None)}: ' + '; '.join(parts) + '.')


def _speed_target(sp: dict[str, Any] | None) -> str:
    if not sp:
        return '**Speed**: NOT MEASURED (run without the speed section).'
    parts, oks = [], []
    core = [r for r in sp.get('core', []) if r.get('default')]
    if core and 'us_median' in core[0]:
        r = core[0]
        us = r.get('us_one_thread', max(r['us_median'], r.get('us_cpu', 0.0)))
        oks.append(us <= 10.0)
        parts.append(f'core update {us:.1f} us/sample on one core ({r["variant"]}, one BLAS '
                     f'thread; {r["us_median"]:.1f} us wall with {r.get("us_cpu", math.nan):.1f} '
                     'us of CPU as the process runs; target <= 10)')
    else:
        oks.append(None)
        parts.append('core update not measured' + (f' ({core[0]["error"]})' if core else ''))
    e2e = sp.get('end_to_end', {}).get('modes', {}).get('offline', {})
    if 'samples_per_s' in e2e:
        rate = min(e2e['samples_per_s'], e2e.get('samples_per_cpu_s', math.inf))
        oks.append(rate >= 5e5)
        parts.append(f'offline estimate_bag {rate:,.0f} samples/s end to end on one core (the '
                     'lower of the wall and the CPU-time rates; target >= 500,000)')
    else:
        oks.append(None)
        err = e2e.get('error') or sp.get('end_to_end', {}).get('error', 'not measured')
        parts.append(f'offline estimate_bag: {err}')
    node = sp.get('node')
    if node and node.get('p99_ms') is not None and math.isfinite(node['p99_ms']):
        oks.append(node['p99_ms'] < 2.0 and node.get('lost') == 0)
        parts.append(f'observer node at 1 kHz: p99 latency {node["p99_ms"]:.2f} ms, '
                     f'{node.get("lost")} of {node.get("sent")} lost (target p99 < 2 ms, '
                     'no drop)')
    else:
        oks.append(None if not node or 'error' in node else False)
        why = (node or {}).get('error', 'not run' if not node else
                               f'no output received, {node.get("lost")} of {node.get("sent")} '
                               'lost')
        parts.append(f'observer node: {why} (see bench/node_latency.py)')
    ok = False if False in oks else (None if None in oks else True)
    return f'**Speed**: {_verdict(ok)}: ' + '; '.join(parts) + '.'


#: Our modes judged in "where our estimator loses" (the ablation and the chain are not modes
#: a user runs by default).
_JUDGED = ('ours-online', 'ours-latency-5ms', 'ours-latency-10ms', 'ours-offline',
           'ours-model-smoother')


def _latency_rank(latency: str) -> float:
    """'0' -> 0, '5 ms' -> 5, 'offline' -> inf."""
    if latency == 'offline':
        return math.inf
    try:
        return float(latency.split()[0])
    except (ValueError, IndexError):
        return math.inf
_LOSS_FIGURES = (('load_rms_pct_dyn', 'vertical load'), ('profile_rms_pct_band', 'profile'),
                 ('iri_err_pct_mean', 'IRI per 100 m'), ('ltr_rms', 'LTR'))
#: A loss counts when ours is above the best comparable peer by more than this factor (ties
#: within a few per cent are noise of one drive, not a loss).
LOSS_MARGIN = 1.05


def losses(out, scenarios, methods: list[Method], *, limit: int = 6) -> list[str]:
    """Plain statements of where our modes do worse than a peer of no greater latency.

    A loss: ours above the best such peer by more than :data:`LOSS_MARGIN` on that scenario
    and figure.
    """
    lines = []
    by_name = {m.name: m for m in methods}
    for ours in _JUDGED:
        if ours not in by_name:
            continue
        rank = _latency_rank(by_name[ours].latency)
        rivals = [m.name for m in methods if not m.ours and _latency_rank(m.latency) <= rank]
        if not any(_fig(out, s.name, ours) is not None for s in scenarios):
            lines.append(f'{ours}: not measured ({_why_missing(out, ours)}).')
            continue
        if ours == 'ours-model-smoother' and _same_numbers(out, 'ours-offline', ours):
            lines.append(f'**{ours}**: the same numbers as ours-offline (the offline mode of '
                         'estimate_bag runs this smoother).')
            continue
        parts = []
        for key, what in _LOSS_FIGURES:
            lost = []
            for s in scenarios:
                o = _fig(out, s.name, ours, key)
                vals = [(_fig(out, s.name, r, key), r) for r in rivals]
                vals = [v for v in vals if v[0] is not None]
                if o is None or not vals:
                    continue
                best, who = min(vals)
                if o > LOSS_MARGIN * best:
                    lost.append((o / max(best, 1e-12), s.name, o, best, who))
            if not lost:
                continue
            lost.sort(reverse=True)
            fmt = '{:.4f}'.format if key == 'ltr_rms' else g3
            shown = ', '.join(f'{sc} ({fmt(o)} vs {who} {fmt(b)})'
                              for _, sc, o, b, who in lost[:limit])
            more = f' and {len(lost) - limit} more' if len(lost) > limit else ''
            parts.append(f'{what} on {len(lost)} of {len(scenarios)} scenarios: {shown}{more}')
        peers_txt = ', '.join(rivals)
        if parts:
            lines.append(f'**{ours}** is more than {100 * (LOSS_MARGIN - 1):.0f} % worse than '
                         f'the best peer of no greater latency ({peers_txt}) on '
                         + '; '.join(parts) + '.')
        else:
            lines.append(f'**{ours}** is never more than {100 * (LOSS_MARGIN - 1):.0f} % '
                         f'worse than a peer of no greater latency ({peers_txt}) on vertical '
                         'load, profile, IRI or LTR.')
    return lines


def ablation(out, scenarios) -> list[str]:
    """What the sliding-mode term contributes: ours-online against ours-no-smo."""
    rows = []
    for s in scenarios:
        vals = [_fig(out, s.name, m, k) for k in ('load_rms_pct_dyn', 'profile_rms_pct_band')
                for m in ('ours-online', 'ours-no-smo')]
        if vals[0] is not None and vals[1] is not None:
            rows.append((s.name, *vals))
    if not rows:
        return [f'Not measured ({_why_missing(out, "ours-no-smo")}).']
    same = [r for r in rows if g3(r[1]) == g3(r[2])
            and (r[3] is None or r[4] is None or g3(r[3]) == g3(r[4]))]
    gain = max(rows, key=lambda r: r[2] - r[1])
    lines = [f'The defaults (ours-online) against the same observer with the sliding-mode '
             f'injection off (ours-no-smo): equal to the digits shown on {len(same)} of '
             f'{len(rows)} scenarios; the largest load-error reduction by the sliding-mode term '
             f'is {gain[2] - gain[1]:+.3f} % points on {gain[0]} '
             f'({g3(gain[2])} % without, {g3(gain[1])} % with).', '',
             '| scenario | load, ours-online | load, ours-no-smo | profile, ours-online | '
             'profile, ours-no-smo |', '|---|---:|---:|---:|---:|']
    for name, lo, ln, po, pn in rows:
        lines.append(f'| {name} | {g3(lo)} | {g3(ln)} | '
                     f'{"-" if po is None else g3(po)} | {"-" if pn is None else g3(pn)} |')
    return lines


# ----------------------------------------------------------------------------------------------
# Markdown


def _cell(fig: dict[str, Any] | None, key: str, fmt, key2: str | None = None) -> str:
    """A table cell; ``fmt`` a format string or a function of the value."""
    fmt = fmt.format if isinstance(fmt, str) else fmt
    if fig is None:
        return '-'
    if 'na' in fig:
        return 'n/a'
    if 'error' in fig:
        return 'fails'

    def one(k):
        v = fig.get(k, math.nan)
        if v is None or (isinstance(v, float) and math.isnan(v)):
            return '-'
        if isinstance(v, float) and math.isinf(v):
            return 'never'
        return fmt(v)

    return one(key) + (' / ' + one(key2) if key2 else '')


def _tuning_paragraph(tuned: dict[str, Any]) -> str:
    proc = tuned.get('procedure')
    if not proc:
        return ('The peers ran with their untuned defaults (`bench/tuned_peers.json` is missing: '
                'run `.venv/bin/python -m bench.tune`).')
    drive = tuned.get('tuning_drive', {})
    levels = sorted({float(k) for v in tuned.get('peers', {}).values() for k in v})
    um = ', '.join(f'{1e6 * x:g}' for x in levels) or '?'
    return (f'Each peer was tuned by `{tuned.get("command", "python -m bench.tune")}` on a '
            f'separate drive (ISO class {drive.get("road", "C")}, road seed '
            f'{drive.get("road_seed", "?")}, noise seed {drive.get("noise_seed", "?")}: no '
            f'scored road or noise) per sensor-noise level ({um} um), minimising the '
            'vertical-load RMS error: a grid over its discrete and continuous knobs (the roll '
            'channel with its own cutoff, jerk density or L), then a pattern search in log '
            'space; then its profile high-pass cutoff, minimising the band-passed profile '
            'error. The Kalman peers are given the true sensor noise. The '
            'settings and their tuning-drive scores are in `bench/tuned_peers.json`. Our '
            'columns are never tuned: package defaults on every drive.')


def _describe(m: Method) -> str:
    """The column's description with the package's names at run time filled in."""
    try:
        offline = _offline_function()[0]
    except NotAvailable:
        offline = 'offline (no entry point)'
    return m.description.format(default=default_method(), offline=offline)


def headline_table(out, methods: list[Method]) -> list[str]:
    """Methods as rows: load and profile error on :data:`HEADLINE_SCENARIOS`."""
    scs = [s for s in HEADLINE_SCENARIOS if s in out['results']]
    if not scs:
        return []
    head = '| method | latency | ' + ' | '.join(
        f'load, {s} | profile, {s}' for s in scs) + ' |'
    lines = [head, '|---|---|' + '---:|---:|' * len(scs)]
    for m in methods:
        cells = []
        for s in scs:
            f = out['results'][s].get(m.name)
            cells += [_cell(f, 'load_rms_pct_dyn', g3), _cell(f, 'profile_rms_pct_band', g3)]
        name = f'**{m.name}**' if m.ours else m.name
        lines.append(f'| {name} | {m.latency} | ' + ' | '.join(cells) + ' |')
    return lines


def _env_text(env: dict[str, str]) -> str:
    return ' '.join(f'{k}={v}' for k, v in env.items())


def speed_lines(sp: dict[str, Any] | None, timing: dict[str, float],
                methods: list[Method]) -> list[str]:
    lines: list[str] = []
    if sp:
        core = sp.get('core', [])
        if core:
            lines += [f'Core: `Estimator.update` per sample on `{TIMING_SCENARIO}` (timeit, '
                      'wall time, median and min of 7 repeats of 5000 samples after 1000 of '
                      'warm-up; the median process CPU time, all threads; and the wall time in '
                      f'a subprocess with {_env_text(ONE_THREAD_ENV)}, the one-core figure):',
                      '',
                      '| variant | us/sample, wall (median) | wall (min) | CPU (median) | '
                      'one BLAS thread, wall (median) |', '|---|---:|---:|---:|---:|']
            for r in core:
                if 'error' in r:
                    lines.append(f'| {r["variant"]} | fails: {r["error"][:120]} | | | |')
                else:
                    one = (f'{r["us_one_thread"]:.2f}' if 'us_one_thread' in r
                           else r.get('one_thread_error', '-')[:120])
                    lines.append(f'| {r["variant"]} | {r["us_median"]:.2f} | '
                                 f'{r["us_min"]:.2f} | {r["us_cpu"]:.2f} | {one} |')
            lines.append('')
        e2e = sp.get('end_to_end', {})
        if 'error' in e2e:
            lines += [f'End to end: {e2e["error"]}', '']
        elif e2e:
            lines += ['End to end: `estimate_bag.run` (read the bag, estimate, write the bag of '
                      'estimates with /diagnostics and the report without figures) on a drive '
                      'recorded as a truck would (deflections, twist, fixes: two messages per '
                      'sample; ISO C, 20 m/s, 1 kHz), in a child process pinned to one CPU with '
                      'one BLAS thread, median of 3 runs after the first '
                      f'(`python -m bench.estimate_bag_speed`, {e2e.get("source")}):', '',
                      '| mode | drive (s) | median wall (s) | samples/s (wall) | samples per CPU '
                      'second | process CPU / wall |', '|---|---:|---:|---:|---:|---:|']
            for mode, r in e2e.get('modes', {}).items():
                if 'error' in r:
                    lines.append(f'| {mode} | fails: {r["error"][:120]} | | | | |')
                else:
                    lines.append(f'| {mode} | {r["drive_s"]:g} | {r["median_s"]:.3f} | '
                                 f'{r["samples_per_s"]:,.0f} | '
                                 f'{r.get("samples_per_cpu_s", math.nan):,.0f} | '
                                 f'{r["cpu_per_wall"]:.2f} |')
            off = e2e.get('detail', {}).get('offline')
            if off:
                stages = ', '.join(f'{k} {v["wall_s"]:.3f} s' for k, v in off['stages'].items())
                lines += ['', f'Offline, stage by stage ({off["samples"]} samples): {stages}; '
                          f'first run in the process {off["first_run"]["wall_s"]:.2f} s (fresh '
                          f'memory), the `estimate_bag` command as a process '
                          f'{off["cli"]["wall_s"]:.2f} s (interpreter start and imports).']
            lines.append('')
        node = sp.get('node')
        if node is not None:
            if 'error' in node:
                lines += [f'Observer node: {node["error"]}; see bench/node_latency.py.', '']
            else:
                def num(v, f='{:.3f}'):
                    return f.format(v) if isinstance(v, (int, float)) and math.isfinite(v) \
                        else 'n/a'
                lines += ['Observer node (`bench/node_latency.py`, its own process, '
                          f'{node.get("executor")} executor): publish of /suspension/deflections '
                          'to receipt of /observer/states, one clock:', '',
                          '| rate (Hz) | s | sent | lost | median (ms) | p99 (ms) | '
                          'CPU (% of one core) | highest sustained rate (Hz) |',
                          '|---:|---:|---:|---:|---:|---:|---:|---:|',
                          f'| {num(node.get("rate_hz"), "{:g}")} | '
                          f'{num(node.get("seconds"), "{:g}")} | {node.get("sent")} | '
                          f'{node.get("lost")} | {num(node.get("median_ms"))} | '
                          f'{num(node.get("p99_ms"))} | {num(node.get("cpu_percent"), "{:.1f}")} '
                          f'| {node.get("sustained_rate_hz")} |', '']
        else:
            lines += ['Observer node: not run here (`--no-node`); see bench/node_latency.py.', '']
    names = [m.name for m in methods if m.name in timing]
    if names:
        lines += [f'Batch run time of every column on `{TIMING_SCENARIO}` (us/sample, whole drive '
                  'incl. set-up, median of repeats; peers are vectorised numpy, ours run '
                  'sample by sample in Python):', '', '| ' + ' | '.join(names) + ' |',
                  '|' + '---:|' * len(names),
                  '| ' + ' | '.join(f'{timing[n]:.2f}' for n in names) + ' |', '']
    return lines


def markdown(out: dict[str, Any], scenarios, methods: list[Method], tuned: dict[str, Any], *,
             speed_out: dict[str, Any] | None = None, command: str = COMMAND) -> str:
    """The whole Markdown document of a :func:`run` (+ :func:`speed`) result."""
    names = [m.name for m in methods]
    default = default_method()
    lines = ['# Benchmark: road_force_estimator beside its peers', '',
             f'Command: `{command}` ({platform.python_implementation()} '
             f'{platform.python_version()}, numpy {np.__version__}, '
             f'{time.strftime("%Y-%m-%d %H:%M")}). The package default at run time: '
             f"`observer.discretization = '{default}'`.", '']
    hl = headline_table(out, methods)
    if hl:
        lines += ['## Headline: the MODEL.md scenario (ISO 8608 class C, 20 m/s, 1 kHz), with '
                  '10 um and without sensor noise', '',
                  'Vertical-load RMS error (% of the true dynamic-load RMS) and band-passed '
                  '(0.5-30 m) profile RMS error (% of the band RMS), both wheels:', ''] + hl + ['']
    lines += ['## Targets of issue 11', ''] + [f'- {t}' for t in targets(out, scenarios,
                                                                          speed_out)] + ['']
    lines += ['## Where our estimator loses', ''] + [f'- {t}' for t in losses(
        out, scenarios, methods)] + ['']
    lines += ['## Ablation: the sliding-mode term', ''] + ablation(out, scenarios) + ['']
    lines += ['## Methods', '', '| column | latency | what |', '|---|---|---|']
    lines += [f'| {m.name} | {m.latency} | {_describe(m)} |'
              for m in methods]
    lines += ['', '### How the peers were tuned', '', _tuning_paragraph(tuned), '']
    lines += ['## Scenarios', '', 'Simulated by the package plant (tire envelope 0.25 m); '
              'sensor noise by `SensorModel` (roll noise 10 rad/m x the deflection noise); '
              'scored after the 2 s convergence skip, both wheels pooled; the observer is given '
              'the vehicle parameters (off by +-10 % where said).', '']
    lines += [f'- `{s.name}`: {s.description}' for s in scenarios] + ['']
    head = '| scenario | ' + ' | '.join(names) + ' |'
    lat = '| latency | ' + ' | '.join(m.latency for m in methods) + ' |'
    sep = '|---|' + '---:|' * len(names)
    lines += ['## Accuracy', '', 'Columns: zero latency, then low latency, then offline; '
              "ours in each group after the peers. 'n/a': the package cannot run that column "
              "yet (reasons below); 'fails': it raised.", '']
    for key, title, fmt, key2 in FIGURES:
        lines += [f'### {title}', '', head, sep, lat]
        for sc in scenarios:
            row = out['results'].get(sc.name, {})
            lines.append(f'| {sc.name} | ' + ' | '.join(
                _cell(row.get(n), key, fmt, key2) for n in names) + ' |')
        lines.append('')
    notes = {}
    for sc, row in out['results'].items():
        for n, f in row.items():
            for kind in ('na', 'error'):
                if kind in f:
                    notes.setdefault((n, kind, f[kind]), []).append(sc)
    if notes:
        lines += ['Notes:', '']
        for (n, kind, text), scs in notes.items():
            where = 'every scenario' if len(scs) == len(scenarios) else ', '.join(scs)
            lines.append(f'- {n} {"n/a" if kind == "na" else "fails"} ({where}): {text}')
        lines.append('')
    lines += ['## Speed', ''] + speed_lines(speed_out, out.get('us_per_sample', {}), methods)
    return '\n'.join(lines)


def readme_section(out: dict[str, Any], scenarios, methods: list[Method], tuned: dict[str, Any],
                   *, speed_out: dict[str, Any] | None, wall_s: float) -> str:
    """The README "Results" section: headline table, speed, targets, losses, the command."""
    lines = ['## Results', '',
             f'Every figure below comes from one run of `{COMMAND}` (from a fresh clone, after '
             f'`scripts/setup`; {wall_s / 60:.1f} minutes on 2 cores), which prints and writes '
             f'the full tables: {len(scenarios)} scenarios (ISO 8608 classes A-D, 10-30 m/s, '
             '200-1000 Hz, 0-50 um of noise, +-10 % parameter errors, a pothole, a lateral '
             'step, the measured profile_1, a speed dropout, a stop, a jointed concrete road) '
             'and, per scenario and method, the load, profile, IRI per 100 m, the IRI-filtered '
             'cross correlation, LTR and convergence figures. The peers run in the same process '
             'on the same data.', '',
             'Headline, ISO 8608 class C at 20 m/s and 1 kHz, with 10 um of deflection noise '
             '(0.1 mrad of roll) and without: vertical-load RMS error in % of the true '
             'dynamic-load RMS and band-passed (0.5-30 m) profile RMS error in % of the band '
             'RMS (lower is better; ours in bold):', '']
    lines += headline_table(out, methods) + ['']
    lines += ['Columns: ' + '; '.join(f'`{m.name}` {_describe(m)}'
                                      for m in methods) + '.', '']
    lines += ['Targets (issue 11):', ''] + [f'- {t}' for t in targets(out, scenarios,
                                                                       speed_out)] + ['']
    lines += ['Where we lose (worst cases; all of them in the full output):', ''] + [
        f'- {t}' for t in losses(out, scenarios, methods, limit=2)] + ['']
    lines += ['Ablation: ' + ablation(out, scenarios)[0], '']
    lines += ['Speed:', ''] + speed_lines(speed_out, out.get('us_per_sample', {}), methods)
    lines += ['How the peers were tuned: ' + _tuning_paragraph(tuned), '']
    return '\n'.join(lines)


# ----------------------------------------------------------------------------------------------
# command line


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog='python -m bench.run_benchmark',
                                description='Every method on every scenario, side by side, and '
                                            'the speed section; Markdown to stdout.')
    p.add_argument('--scenarios', nargs='+', default=None, help='scenario names (default all)')
    p.add_argument('--methods', nargs='+', default=None, help='column names (default all)')
    p.add_argument('--tuned', type=Path, default=tune.TUNED_PATH, help='tuned settings JSON')
    p.add_argument('--output', type=Path, default=None, help='write the Markdown here too')
    p.add_argument('--json', type=Path, default=None, help='write all figures as JSON')
    p.add_argument('--readme', type=Path, default=None,
                   help='write the README "Results" section here')
    p.add_argument('--duration', type=float, default=None, metavar='S',
                   help='override every scenario duration (s; quick checks only)')
    p.add_argument('--timing-repeats', type=int, default=5,
                   help='batch runs per column on the timing scenario (median)')
    p.add_argument('--no-speed', action='store_true', help='skip the speed section')
    p.add_argument('--no-node', action='store_true', help='skip the observer-node latency')
    p.add_argument('--core-cost-json', action='store_true', help=argparse.SUPPRESS)
    return p


def main(argv: list[str] | None = None) -> int:
    t_start = time.perf_counter()
    args = build_parser().parse_args(argv)
    if args.core_cost_json:   # the one-thread core cost, for core_cost_one_thread()
        drive = build_drive(scenario_by_name(TIMING_SCENARIO))
        print(json.dumps(core_cost(drive)))
        return 0
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
    if args.duration is not None and not (args.duration >= 3.0 and math.isfinite(args.duration)):
        print(f'run_benchmark: --duration {args.duration!r}: must be >= 3 s', file=sys.stderr)
        return 2
    if args.timing_repeats < 1:
        print(f'run_benchmark: --timing-repeats {args.timing_repeats}: must be >= 1',
              file=sys.stderr)
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
    for path in (args.output, args.json, args.readme):
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)

    def log(s: str) -> None:
        print(f'run_benchmark: [{time.perf_counter() - t_start:6.1f} s] {s}', file=sys.stderr)

    keep = TIMING_SCENARIO if any(s.name == TIMING_SCENARIO for s in scenarios) else (
        scenarios[0].name if scenarios else None)
    out = run(scenarios, methods, tuned, timing_repeats=args.timing_repeats,
              duration_s=args.duration, log=log, keep_drive=keep)
    drive = out.pop('drive')
    speed_out = None if args.no_speed else speed(drive, node=not args.no_node, log=log)
    command = 'python -m bench.run_benchmark ' + ' '.join(
        sys.argv[1:] if argv is None else argv)
    text = markdown(out, scenarios, methods, tuned, speed_out=speed_out, command=command.strip())
    wall = time.perf_counter() - _T_START if argv is None else time.perf_counter() - t_start
    text += (f'\n\nWall time of this run: {wall:.0f} s ({wall / 60:.1f} min), '
             f'{len(scenarios)} scenarios x {len(methods)} columns'
             f'{"" if args.no_speed else " + speed section"}.\n')
    print(text)
    if args.output:
        args.output.write_text(text)
    if args.json:
        doc = {**out, 'speed': speed_out, 'wall_s': wall,
               'targets': targets(out, scenarios, speed_out),
               'losses': losses(out, scenarios, methods), 'default_method': default_method()}
        args.json.write_text(json.dumps(doc, indent=1, default=float) + '\n')
    if args.readme:
        args.readme.write_text(readme_section(out, scenarios, methods, tuned,
                                              speed_out=speed_out, wall_s=wall) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
