"""Traced peak of the streamed report's whole-drive numbers: the segment table (IRI per
segment, coverage, with ``--fixes`` the segments' coordinates), the whole drive's IRI, the
speed's statistics and the model fit's medians of a drive estimated in pieces.

    .venv/bin/python -m bench.probes.streamed_report_memory [--samples 1000000 2000000]
                                                           [--piece 65536] [--uniform]
                                                           [--fixes]

:class:`road_force_estimator.report.streamed.StreamedSummary` as ``estimate_bag`` builds it in
blocks (100 m segments, its per-sample columns spilled to temporary files) fed a synthetic
drive of ``--samples`` samples in pieces of ``--piece``: 1 kHz, the speed 20 +- 5 m/s (a
sine of 60 s period; ``--uniform``: 20 m/s, evenly spaced), every sample accepted and
converged, a random-walk road (seed 1); ``--fixes``: the stamps kept (``with_stamps``) and
GNSS fixes at 10 Hz from 0.05 s to the drive's last 0.1 s on a straight road heading 30 deg
east of north (:func:`fixes`). Per size: the peak traced by :mod:`tracemalloc` while
:meth:`~.StreamedSummary.segment_table`, :meth:`~.StreamedSummary.whole_iri`,
:meth:`~.StreamedSummary.speed_stats` and :meth:`~.StreamedSummary.fit_speed_and_step` run
(not the accumulators' own arrays, made before), and the growth per sample between the first
two sizes (after a first run of 200 000 samples for the one-time caches: imports, the
IRI filter's design); a SHA-256 of the table, the IRI, the speed's statistics and the
fit's medians (the same bits before and after a change).
"""
from __future__ import annotations

import argparse
import gc
import hashlib
import sys
import tempfile
import tracemalloc
from types import SimpleNamespace

import numpy as np

RATE_HZ = 1000.0
#: The fixes' rate (Hz) and the road's heading (deg east of north) with ``--fixes``.
FIX_HZ, HEADING_DEG = 10.0, 30.0


def fixes(n: int, uniform: bool):
    """:class:`~road_force_estimator.bagio.drive.Fixes` of the drive of ``n`` samples: every
    0.1 s from 0.05 s on, before its last sample; the distance the speed's integral."""
    from road_force_estimator.bagio.drive import Fixes

    t = np.arange(0.05, (n - 1) / RATE_HZ, 1.0 / FIX_HZ)
    x = 20.0 * t if uniform else 20.0 * t + 5.0 * 60.0 / (2.0 * np.pi) * (
        1.0 - np.cos(2.0 * np.pi * t / 60.0))
    north, east = x * np.cos(np.radians(HEADING_DEG)), x * np.sin(np.radians(HEADING_DEG))
    lat = 48.0 + north / 111_195.0
    lon = 11.0 + east / (111_195.0 * np.cos(np.radians(48.0)))
    return Fixes(np.round(t * 1e9).astype(np.int64), lat, lon, np.full(t.size, np.nan))


def feed(acc, n: int, piece: int, uniform: bool) -> None:
    """``n`` samples of the synthetic drive into ``acc`` (a StreamedSummary), ``piece`` at a
    time."""
    rng = np.random.default_rng(1)
    x_end, z_end = 0.0, np.zeros(2)
    for lo in range(0, n, piece):
        k = min(piece, n - lo)
        t = (lo + np.arange(k)) / RATE_HZ
        v = np.full(k, 20.0) if uniform else 20.0 + 5.0 * np.sin(2.0 * np.pi * t / 60.0)
        x = x_end + np.cumsum(v / RATE_HZ)
        z = z_end + 1e-4 * np.cumsum(rng.standard_normal((k, 2)), axis=0)
        x_end, z_end = x[-1], z[-1]
        load = 30000.0 + 1000.0 * rng.standard_normal((k, 2))
        ones = np.ones(k, bool)
        acc.add(SimpleNamespace(
            stamp_ns=np.round(t * 1e9).astype(np.int64), valid=ones, converged=ones,
            distance_m=x, road_m=z, wheel_load_n=load, ltr=(load[:, 1] - load[:, 0]) / 6e4,
            ltr_quasi_static=np.zeros(k), lift_off=np.zeros((k, 2), bool),
            load_clipped=np.zeros((k, 2), bool), static_load_n=np.full((k, 2), 3e4),
            speed_contradicted=np.zeros(k, bool)), v)


def measure(n: int, piece: int, uniform: bool, with_fixes: bool = False) -> tuple[int, str]:
    """(traced peak in bytes, SHA-256 of the table, the IRI and the speed's statistics) of
    a drive of ``n``."""
    from road_force_estimator.report.streamed import StreamedSummary

    fix = fixes(n, uniform) if with_fixes else None
    with tempfile.TemporaryDirectory() as folder:
        acc = StreamedSummary(100.0, with_stamps=with_fixes, capacity=n, spill=folder)
        feed(acc, n, piece, uniform)
        gc.collect()
        tracemalloc.start()
        try:
            table = acc.segment_table(fix)
            iri = acc.whole_iri(table)
            speed = acc.speed_stats()
            fit = acc.fit_speed_and_step()
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        for col in (acc.x_up, acc.road_up, acc.stamps, acc.speed, acc.stamps_up, acc.x_valid):
            if col is not None:
                col.close()
    h = hashlib.sha256()
    for name in sorted(table):
        h.update(name.encode() + np.ascontiguousarray(table[name]).tobytes())
    h.update(np.asarray(iri, float).tobytes())
    h.update(np.array([speed[k] for k in sorted(speed)] + list(fit)).tobytes())
    return peak, h.hexdigest()[:12]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog='python -m bench.probes.streamed_report_memory',
                                description=__doc__.splitlines()[0])
    p.add_argument('--samples', type=int, nargs='+', default=[1_000_000, 2_000_000])
    p.add_argument('--piece', type=int, default=65536)
    p.add_argument('--uniform', action='store_true', help='20 m/s: evenly spaced')
    p.add_argument('--fixes', action='store_true',
                   help="the stamps kept and GNSS fixes at 10 Hz: the segments' coordinates")
    args = p.parse_args(argv)
    print('| samples | traced peak (MB) | bytes a sample | table, IRI, speed, fit (sha256) |')
    print('|---:|---:|---:|---|')
    measure(200_000, args.piece, args.uniform, args.fixes)   # one-time caches (imports, designs)
    peaks = []
    for n in args.samples:
        peak, digest = measure(n, args.piece, args.uniform, args.fixes)
        peaks.append(peak)
        print(f'| {n} | {peak / 1e6:.1f} | {peak / n:.1f} | {digest} |')
    if len(peaks) > 1:
        growth = (peaks[1] - peaks[0]) / (args.samples[1] - args.samples[0])
        print(f'\n(growth {growth:.1f} bytes a sample from {args.samples[0]} to '
              f'{args.samples[1]} samples)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
