"""The online chain per sample against its floor: what limits ``estimate_bag --mode online``.

    .venv/bin/python -m bench.probes.online_floor [--duration 30] [--repeats 5]

On a drive as :mod:`bench.probes.estimate_bag_process` records it (ISO 8608 C, 20 m/s, 1 kHz,
10 um / 0.1 mrad noise, GNSS 10 Hz), one BLAS thread, best of ``--repeats`` (CPU time):

1. ``Estimator.update`` per sample (the observer node's call) and ``estimate_batch`` (the
   batch online path: the same steps, bit for bit).
2. The floor: a bare loop over the same samples doing only what is sequential and must stay
   bit-identical, per sample, with the estimator's own step matrices: the load filter's
   product ``M row`` (and its finiteness check), the profile filter's ``M_p prow`` and the two
   body-heave recursions (:func:`.body_heave.step`), nothing else (no checks of the inputs,
   no speed check, no output row, no quasi-static LTR). The products cannot be batched or
   reordered without changing the bits (a gemv with other columns or rows rounds
   differently: checked on random matrices), and the recursions run sample by sample in
   Python floats, so no batch path that gives the same numbers can beat this loop.
"""
from __future__ import annotations

import argparse
import math
import os
from pathlib import Path
import sys
import tempfile
import time

for _name in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(_name, '1')     # one BLAS thread (before numpy is imported)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--duration', type=float, default=30.0,
                   help='drive, s (long enough that the gain designs of a fresh estimator do '
                        'not count)')
    p.add_argument('--repeats', type=int, default=5, help='runs of each (best CPU time)')
    return p


def _best(fn, repeats: int) -> float:
    best = math.inf
    for _ in range(repeats):
        t0 = time.process_time()
        fn()
        best = min(best, time.process_time() - t0)
    return best


def _floor_loop(core, y: list, dt: float, v: float):
    """The bare loop of the module notes, with ``core``'s matrices (a finished run)."""
    import numpy as np

    from road_force_estimator.estimation import body_heave

    m, mp = core._m, core._pm
    x0, y0 = core._x0i, core._y0i
    n = len(y)
    buf = np.zeros((n + 1, m.shape[1]))
    prow = np.zeros(mp.shape[1])
    sv, sp = np.empty(m.shape[0]), np.empty(mp.shape[0])
    sv_x, sp_x, sp_o = sv[:y0 - x0], sp[:y0 - x0], sp[y0 - x0:]
    dot, step = np.dot, body_heave.step
    wc, wr = core._wc_per_speed, core._road.wc

    def run() -> None:
        h = hr = body_heave.start(0.0)
        for i, (q1, q2, phi) in enumerate(y):
            row = buf[i]
            row[y0] = q1
            row[y0 + 1] = q2
            row[y0 + 2] = phi
            dot(m, row, out=sv)
            s = sv.tolist()
            if not math.isfinite(sum(s)):
                break
            buf[i + 1, x0:y0] = sv_x
            prow[y0] = q1
            prow[y0 + 1] = q2
            prow[y0 + 2] = phi
            dot(mp, prow, out=sp)
            prow[x0:y0] = sp_x
            o = sp_o.tolist()
            h = step(h, s[y0 - x0 + 10], dt, v, wc)
            hr = step(hr, o[10], dt, v, wr)
    return run


def measure(duration_s: float, repeats: int) -> dict:
    from bench.probes.estimate_bag_process import simulate
    from road_force_estimator import bagio
    from road_force_estimator.estimation import Estimator, estimate_batch
    from road_force_estimator.tools.estimate_bag import drive_speed

    with tempfile.TemporaryDirectory(prefix='online_floor_') as tmp:
        bag = Path(tmp) / 'drive'
        simulate(bag, duration_s)
        drive = bagio.read_drive_bag(bag)
    speed, _ = drive_speed(drive)
    stamps, q, phi = drive.stamps_ns, drive.q_m, drive.roll_rad
    n = len(stamps)
    args = (stamps.tolist(), q.tolist(), phi.tolist(), speed.tolist())

    made: list = []

    def per_sample() -> None:      # a fresh estimator, as the batch path's (its designs)
        est = Estimator()
        made.append(est)
        update = est.update
        for t, qq, p, v in zip(*args):
            update(t, qq, p, v)

    doc = {'samples': n, 'repeats': repeats}
    doc['update_us'] = _best(per_sample, repeats) / n * 1e6
    doc['batch_us'] = _best(lambda: estimate_batch(stamps, q, phi, speed), repeats) / n * 1e6
    core = made[-1].core
    y = [(a, b, p) for (a, b), p in zip(args[1], args[2])]
    dt = float(core.gains.dt_s)
    doc['floor_us'] = _best(_floor_loop(core, y, dt, float(speed[-1])), repeats) / n * 1e6
    return doc


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    doc = measure(args.duration, args.repeats)
    cmd = 'python -m bench.probes.online_floor ' + ' '.join(argv if argv is not None
                                                     else sys.argv[1:])
    print(f'# The online chain against its floor: `{cmd.strip()}`\n')
    print(f'{doc["samples"]} samples, one BLAS thread, best of {doc["repeats"]} (CPU time).\n')
    print('| path | us/sample | samples/s |')
    print('|---|---|---|')
    for key, name in (('update_us', 'Estimator.update per sample (the node)'),
                      ('batch_us', 'estimate_batch (estimate_bag online)'),
                      ('floor_us', 'floor: the two products and two body heaves only')):
        print(f'| {name} | {doc[key]:.2f} | {1e6 / doc[key]:,.0f} |')
    return 0


if __name__ == '__main__':
    sys.exit(main())
