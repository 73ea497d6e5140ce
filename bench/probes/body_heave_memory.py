"""Peak memory of :func:`.body_heave.offline_profile` beyond its inputs, per sample.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -m bench.probes.body_heave_memory [--samples 3600000]
                                                                      [--impl MODULE:FUNC]

Two runs at dt = 1 ms, ``cutoff_wavelength_m=100, ratio=100, degree=3, speed_mps=20``:

* ``steady``: 20 m/s throughout, the acceleration white noise (1 m/s^2) plus a 0.5 Hz sine of
  0.1 m/s^2 (the steady path: :func:`.zero_phase` and the run's polynomial);
* ``stop``: the same acceleration, 20 m/s with two stops of 10 s at exactly 0 m/s (at 1/3 and
  2/3 of the run), each between ramps of 1/30 of the run (120 s at 3.6 M samples; the stop
  path: :func:`.in_distance`).

``level`` is white noise (1 mm). Each case runs in a fresh process twice: once under
``tracemalloc`` (peak traced beyond what was traced before the call, the result included), once
without it for the peak RSS (``VmHWM``, reset by ``/proc/self/clear_refs`` before the call, and
``ru_maxrss``, both less the RSS before the call). ``--impl`` measures another implementation
with the same signature (``package.module:function``).
"""
from __future__ import annotations

import argparse
import importlib
import json
import resource
import subprocess
import sys

import numpy as np

DT = 1e-3
IMPL = 'road_force_estimator.estimation.body_heave:offline_profile'


def inputs(case: str, n: int, seed: int = 1) -> tuple:
    """``(accel, level, t, v)`` of a case (see the module notes), built without large
    temporaries."""
    rng = np.random.default_rng(seed)
    t = np.arange(n, dtype=float)
    t *= DT
    accel = np.sin(t * (2.0 * np.pi * 0.5))
    accel *= 0.1
    accel += rng.standard_normal(n)
    level = rng.standard_normal(n)
    level *= 1e-3
    v = np.full(n, 20.0)
    if case == 'stop':
        ramp, rest = n * DT / 30.0, 10.0             # ramps of 1/30 of the run: 120 s
        for c in (t[-1] / 3.0, 2.0 * t[-1] / 3.0):
            a = np.searchsorted(t, c - rest / 2.0 - ramp)
            b = np.searchsorted(t, c + rest / 2.0 + ramp)
            d = np.abs(t[a:b] - c)
            d -= rest / 2.0
            np.clip(d, 0.0, ramp, out=d)
            v[a:b] = d * (20.0 / ramp)
    return accel, level, t, v


def _rss_kb(field: str) -> int:
    with open('/proc/self/status') as f:
        for line in f:
            if line.startswith(field + ':'):
                return int(line.split()[1])
    raise KeyError(field)


def measure(case: str, n: int, impl: str, traced: bool) -> dict:
    """One measurement in this process (see the module notes); bytes."""
    mod, name = impl.split(':')
    fn = getattr(importlib.import_module(mod), name)
    warm = inputs(case, 400_000)                 # long enough for the same path
    fn(*warm, DT, 20.0, 100.0, 100.0, 3)         # imports (scipy.signal) out of the way
    args = inputs(case, n)
    if traced:
        import tracemalloc
        tracemalloc.start()
        before = tracemalloc.get_traced_memory()[0]
        out = fn(*args, DT, 20.0, 100.0, 100.0, 3)
        peak = tracemalloc.get_traced_memory()[1] - before
        tracemalloc.stop()
        return {'traced_peak': peak, 'out_bytes': int(np.asarray(out).nbytes)}
    rss0 = _rss_kb('VmRSS')
    with open('/proc/self/clear_refs', 'w') as f:
        f.write('5')
    out = fn(*args, DT, 20.0, 100.0, 100.0, 3)
    return {'hwm_peak': 1024 * (_rss_kb('VmHWM') - rss0),
            'maxrss_peak': 1024 * (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss0),
            'out_bytes': int(np.asarray(out).nbytes)}


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--samples', type=int, default=3_600_000)
    p.add_argument('--impl', default=IMPL)
    p.add_argument('--cases', nargs='+', default=['steady', 'stop'])
    p.add_argument('--child', nargs=2, metavar=('CASE', 'TRACED'), help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.child:
        print(json.dumps(measure(a.child[0], a.samples, a.impl, a.child[1] == '1')))
        return
    n = a.samples
    print(f'{a.impl}, {n} samples; bytes per sample beyond the inputs (result included)')
    print('| case | tracemalloc peak | VmHWM peak | ru_maxrss peak |')
    print('|---|---|---|---|')
    for case in a.cases:
        r = {}
        for traced in ('1', '0'):
            cmd = [sys.executable, '-m', 'bench.probes.body_heave_memory', '--samples', str(n),
                   '--impl', a.impl, '--child', case, traced]
            r.update(json.loads(subprocess.run(cmd, check=True, capture_output=True,
                                               text=True).stdout))
        print(f"| {case} | {r['traced_peak'] / n:.1f} | {r['hwm_peak'] / n:.1f} | "
              f"{r['maxrss_peak'] / n:.1f} |")


if __name__ == '__main__':
    main()
