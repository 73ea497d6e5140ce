"""Peak memory of the whole vehicle's offline estimate (``vehicle.model: articulated``) on long
drives: one block (:func:`~road_force_estimator.estimation.whole_vehicle.estimate_whole_vehicle`)
against the stream (:class:`~road_force_estimator.estimation.whole_vehicle.
WholeVehicleOfflineStream`, fed and handed out in blocks).

    .venv/bin/python -m bench.probes.whole_vehicle_stream_memory [--minutes 2 10 20]
                                                   [--one-block 2 10] [--piece 60]
                                                   [--json FILE]

1. The plant drives ``config/tractor_semitrailer.yaml``'s combination over ISO 8608 class C
   (seed 1) at 20 m/s, 1 kHz, the file's sensor noise, for one piece of ``--piece`` seconds;
   a drive is that piece again and again (forwards, a step where pieces join), stamped on one
   1 kHz clock, written as files of 65536 samples (stamps, readings) in a temporary folder.
2. Each estimate runs as a process of its own (``bench.probes.estimate_bag_process``'s
   ``run_child``: ``/usr/bin/time``'s peak RSS, wall and CPU time): the stream reads the files
   one at a time (its columns reserved for the drive's samples at once, as a bag's metadata
   lists them) and drops each piece once summed; the one block reads them all and calls
   ``estimate_whole_vehicle(offline=True)``. Bytes per sample: the peak's growth between
   the shortest and the longest drive over the samples added.

Numbers go to stdout (Markdown) and, with ``--json``, to a file.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path
import sys
import tempfile

import numpy as np

from bench.probes.estimate_bag_process import run_child

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / 'config' / 'tractor_semitrailer.yaml'
RATE_HZ = 1000.0
SPEED_MPS = 20.0
FILE_SAMPLES = 1 << 16


def make_drive(folder: Path, minutes: float, piece_s: float) -> int:
    """Write a drive of ``minutes`` into ``folder`` (see the module notes); its samples."""
    from road_force_estimator.core.articulated_plant import simulate_articulated
    from road_force_estimator.core.articulated_setup import ArticulatedDrive
    from road_force_estimator.core.parameters import load_params_file
    from road_force_estimator.core.road import iso8608_profile
    from road_force_estimator.estimation.models.articulated import channel_names

    base = load_params_file(CONFIG)
    base.update({'simulator.duration': piece_s})
    d = ArticulatedDrive.from_values(base)
    road = iso8608_profile('C', d.road_length_m, seed=1)
    tr = simulate_articulated(d.vehicle, road, speed_mps=SPEED_MPS, rate_hz=RATE_HZ,
                              duration_s=piece_s, tire_envelope_m=0.25, model=d.model)
    piece = d.sensors(channel_names(d.model)).measure(tr)[:-1]
    n = int(round(minutes * 60.0 * RATE_HZ)) + 1
    folder.mkdir(parents=True, exist_ok=True)
    for k, a in enumerate(range(0, n, FILE_SAMPLES)):
        b = min(n, a + FILE_SAMPLES)
        idx = np.arange(a, b)
        np.save(folder / f'{k:05d}_stamps.npy', idx * int(1e9 / RATE_HZ))
        np.save(folder / f'{k:05d}_readings.npy', piece[idx % piece.shape[0]])
    return n


def _files(folder: Path) -> list[tuple[Path, Path]]:
    return [(p, p.with_name(p.name.replace('_stamps', '_readings')))
            for p in sorted(folder.glob('*_stamps.npy'))]


def child(mode: str, folder: Path) -> None:
    """One estimate over the drive in ``folder`` (``mode`` 'stream' or 'one-block')."""
    from road_force_estimator.core.articulated_setup import ArticulatedDrive
    from road_force_estimator.core.parameters import load_params_file
    from road_force_estimator.estimation.whole_vehicle import (
        WholeVehicleOfflineStream, estimate_whole_vehicle)

    vehicle = ArticulatedDrive.from_values(load_params_file(CONFIG)).vehicle
    total, samples = 0.0, 0
    if mode == 'stream':
        n = sum(np.load(s, mmap_mode='r').shape[0] for s, _ in _files(folder))
        stream = WholeVehicleOfflineStream(vehicle, capacity=n)    # (a bag's metadata)
        for s, r in _files(folder):
            stream.feed(np.load(s), np.load(r), SPEED_MPS)
        for piece in stream.finish():
            total += float(piece.load_n.sum())
            samples += piece.stamps_ns.size
    else:
        stamps = np.concatenate([np.load(s) for s, _ in _files(folder)])
        readings = np.concatenate([np.load(r) for _, r in _files(folder)])
        wv = estimate_whole_vehicle(vehicle, stamps, readings, SPEED_MPS, offline=True)
        total, samples = float(wv.load_n.sum()), wv.stamps_ns.size
    print(json.dumps({'samples': samples, 'mean_load_n': total / max(samples, 1)}))


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--minutes', type=float, nargs='+', default=[2.0, 10.0, 20.0],
                   help='drive lengths for the stream, minutes')
    p.add_argument('--one-block', type=float, nargs='*', default=[2.0, 10.0],
                   help='drive lengths for the one block, minutes')
    p.add_argument('--piece', type=float, default=60.0, help='simulated piece, s')
    p.add_argument('--json', metavar='FILE', help='also write the numbers as JSON')
    p.add_argument('--child', nargs=2, metavar=('MODE', 'DIR'), help=argparse.SUPPRESS)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.child:
        child(args.child[0], Path(args.child[1]))
        return 0
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for minutes in sorted(set(args.minutes) | set(args.one_block)):
            folder = Path(tmp) / f'{minutes:g}'
            n = make_drive(folder, minutes, args.piece)
            for mode in ('stream', 'one-block'):
                if minutes not in (args.minutes if mode == 'stream' else args.one_block):
                    continue
                r = run_child([sys.executable, '-m', 'bench.probes.whole_vehicle_stream_memory',
                               '--child', mode, str(folder)])
                rows.append({'mode': mode, 'minutes': minutes, 'samples': n, **r})
                print(f'{mode} {minutes:g} min: {r["peak_rss_mb"]:.0f} MB', file=sys.stderr)
            for p in folder.iterdir():
                p.unlink()
    print('| estimate | drive (min) | samples | peak RSS (MB) | wall (s) | CPU (s) |')
    print('|---|---:|---:|---:|---:|---:|')
    for r in rows:
        print(f'| {r["mode"]} | {r["minutes"]:g} | {r["samples"]} | {r["peak_rss_mb"]:.0f} '
              f'| {r["wall_s"]:.1f} | {r["cpu_s"]:.1f} |')
    for mode in ('stream', 'one-block'):
        mine = sorted((r for r in rows if r['mode'] == mode), key=lambda r: r['samples'])
        if len(mine) > 1:
            grow = (mine[-1]['peak_rss_mb'] - mine[0]['peak_rss_mb']) * 2 ** 20 / (
                mine[-1]['samples'] - mine[0]['samples'])
            print(f'\n{mode}: {grow:.0f} bytes per added sample')
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=2))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
