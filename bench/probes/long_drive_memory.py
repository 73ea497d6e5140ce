"""Peak memory of ``estimate_bag`` on a long drive (default 4 hours at 1 kHz, 14.4 M samples).

    .venv/bin/python -m bench.probes.long_drive_memory [--hours 4] [--piece 300]
                                                [--modes offline online] [--keep DIR]
                                                [--drive BAG] [--json FILE]

1. Makes the drive bag in bounded memory: the plant (:func:`core.plant.simulate`, ISO 8608
   class C, seed 1, 20 m/s, 1 kHz) drives one piece of ``--piece`` seconds; the drive is that
   piece forwards, then backwards in time, then forwards... (so that the deflections join
   without a step), each with its own sensor noise (10 um / 0.1 mrad, seed = piece number),
   stamped on one 1 kHz clock, written piece after piece into one bag
   (``/suspension/deflections`` and ``/vehicle/twist``, no ground truth, no GNSS) with
   :class:`bagio.BagWriter`. Its own peak RSS is printed. ``--truth`` adds simulate_bag's
   four ground-truth topics (wheel loads and road under each wheel: such a drive goes in
   blocks too, issue 27); ``--forward`` plays every piece forwards in time (a physical drive,
   with a step where pieces join: a piece played backwards is no motion the model allows, and
   the offline innovation gate then re-runs nearly every sample).
2. ``estimate_bag`` runs on it as a process, figures on, once per mode, and on a 1 s drive of
   the same kind; per run the wall and CPU time and the peak RSS (``/usr/bin/time``), and the
   bytes per added sample. ``--drive BAG`` takes a long drive made before (``--keep``) instead.

Numbers go to stdout (Markdown) and, with ``--json``, to a file. A 4-hour bag is ~4.3 GB on
disk (``--keep`` puts it in a folder of your choice; default: the system temp folder).
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
import resource
import shutil
import sys
import tempfile
from typing import NamedTuple

import numpy as np

from bench.probes.estimate_bag_process import estimate, simulate

RATE_HZ = 1000.0
SPEED_MPS = 20.0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--hours', type=float, default=4.0, help='drive length, hours')
    p.add_argument('--piece', type=float, default=300.0, help='simulated piece, s')
    p.add_argument('--modes', nargs='+', choices=('offline', 'online'),
                   default=['offline', 'online'])
    p.add_argument('--keep', metavar='DIR', help='make (and keep) the bags in DIR')
    p.add_argument('--drive', metavar='BAG',
                   help='a long drive made before (by this command with --keep): not made again')
    p.add_argument('--json', metavar='FILE', help='also write the numbers as JSON')
    p.add_argument('--truth', action='store_true', help='with the ground-truth topics')
    p.add_argument('--forward', action='store_true', help='every piece forwards in time')
    return p


def make_drive(bag: Path, hours: float, piece_s: float, truth: bool = False,
               forward: bool = False) -> int:
    """Write the long drive of the module notes into ``bag``; the samples written."""
    from road_force_estimator.bagio import BagWriter
    from road_force_estimator.bagio.drive import measurement_streams, truth_streams
    from road_force_estimator.serde.messages import DEFAULT_START_STAMP_NS, stamp_columns
    from road_force_estimator.core.parameters import VehicleParameters
    from road_force_estimator.core.plant import simulate as plant
    from road_force_estimator.core.road import iso8608_profile
    from road_force_estimator.core.sensors import SensorModel
    from road_force_estimator.interfaces import TOPIC_TYPES, qos_kind

    m = int(round(piece_s * RATE_HZ))
    road = iso8608_profile('C', SPEED_MPS * piece_s + 50.0, seed=1)
    tr = plant(VehicleParameters(), road, speed_mps=SPEED_MPS, rate_hz=RATE_HZ,
               duration_s=(m - 1) / RATE_HZ, tire_envelope_m=0.25)
    q_true, roll_true = np.array(tr.q_m), np.array(tr.roll_rad)
    load, road_m = np.array(tr.wheel_load_n), np.array(tr.road_m)
    del tr
    total = int(round(hours * 3600.0 * RATE_HZ)) + 1
    step_ns = int(round(1e9 / RATE_HZ))
    with BagWriter(bag, custom_data={'road_force_estimator.kind': 'drive'}) as out:
        topics = None
        for k in range(int(math.ceil(total / m))):
            a, b = k * m, min(total, (k + 1) * m)
            order = slice(None) if k % 2 == 0 or forward else slice(None, None, -1)
            q_piece, roll_piece = q_true[order][:b - a], roll_true[order][:b - a]
            q, roll = SensorModel(deflection_std_m=1e-5, roll_std_rad=1e-4,
                                  seed=k + 1).measure(q_piece, roll_piece)
            stamps = DEFAULT_START_STAMP_NS + step_ns * np.arange(a, b, dtype=np.int64)
            cols = stamp_columns(stamps)
            streams = measurement_streams(stamps, cols, q, roll, np.full(b - a, SPEED_MPS))
            if truth:
                streams += truth_streams(TruthPiece(load[order][:b - a], road_m[order][:b - a],
                                                    SPEED_MPS * np.arange(a, b) / RATE_HZ),
                                         stamps, cols, VehicleParameters().track_width_m)
            if topics is None:
                topics = [topic for topic, _, _ in streams]
                for topic in topics:
                    out.add_topic(topic, TOPIC_TYPES[topic], qos_kind(topic))
            out.write_rows(streams)
    return total


class TruthPiece(NamedTuple):
    """A piece's ground truth as :func:`bagio.drive.truth_streams` takes it."""

    wheel_load_n: np.ndarray
    road_m: np.ndarray
    distance_m: np.ndarray


def _samples(bag: Path) -> int:
    """The deflection messages a bag's metadata lists."""
    from road_force_estimator.bagio.drive_blocks import streamable

    return streamable(bag)


def measure(hours: float, piece_s: float | None, modes, folder: Path, drive: Path | None = None,
            truth: bool = False, forward: bool = False) -> dict:
    """Make the drives (``drive``: the long one given), run the command (see the module
    notes)."""
    long_bag, short_bag = folder / 'long_drive', folder / 'drive_1s'
    shutil.rmtree(short_bag, ignore_errors=True)
    if drive is None:
        shutil.rmtree(long_bag, ignore_errors=True)
        n = make_drive(long_bag, hours, piece_s, truth, forward)
    else:
        long_bag = Path(drive)
        n = _samples(long_bag)
        hours = (n - 1) / RATE_HZ / 3600.0
        piece_s = None                            # made before: not known here
    made_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    simulate(short_bag, 1.0)
    size = sum(p.stat().st_size for p in long_bag.iterdir())
    doc = {'hours': hours, 'samples': n, 'bag_bytes': size, 'piece_s': piece_s,
           'making_peak_rss_mb': made_mb, 'modes': {}}
    for mode in modes:
        short = estimate(short_bag, folder / 'out_short', mode)
        long = estimate(long_bag, folder / 'out_long', mode)
        doc['modes'][mode] = {
            'short': short, 'long': long, 'samples_per_cpu_s': (n - 1001) / max(
                long['cpu_s'] - short['cpu_s'], 1e-9),
            'bytes_per_sample': (long['peak_rss_mb'] - short['peak_rss_mb']) * 2.0 ** 20
            / (n - 1001)}
    return doc


def markdown(doc: dict) -> list[str]:
    lines = [f'# estimate_bag on a long drive: `{doc["command"]}`', '',
             f'{doc["hours"]:g} h at 1 kHz = {doc["samples"]:,} samples, '
             f'{doc["bag_bytes"] / 1e9:.2f} GB of bag, '
             + (f'made in pieces of {doc["piece_s"]:g} s with a peak RSS of '
                f'{doc["making_peak_rss_mb"]:.0f} MB' if doc.get('piece_s') is not None
                else 'made before (--drive)') + '; figures on '
             '(drives of at least 2^21 samples are estimated block by block, both modes: '
             '`pipeline/plan.py`).', '',
             '| mode | peak RSS (MB), long drive | peak RSS (MB), 1 s drive | added B/sample '
             '| wall (s) | CPU (s) | samples per CPU s |', '|---|---|---|---|---|---|---|']
    for mode, m in doc['modes'].items():
        lines.append(f'| {mode} | {m["long"]["peak_rss_mb"]:,.0f} | '
                     f'{m["short"]["peak_rss_mb"]:.0f} | {m["bytes_per_sample"]:.0f} | '
                     f'{m["long"]["wall_s"]:.1f} | {m["long"]["cpu_s"]:.1f} | '
                     f'{m["samples_per_cpu_s"]:,.0f} |')
    return lines


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.keep:
        folder = Path(args.keep)
        folder.mkdir(parents=True, exist_ok=True)
        doc = measure(args.hours, args.piece, args.modes, folder, args.drive, args.truth,
                      args.forward)
    else:
        with tempfile.TemporaryDirectory(prefix='long_drive_memory_') as tmp:
            doc = measure(args.hours, args.piece, args.modes, Path(tmp), args.drive, args.truth,
                          args.forward)
    doc['command'] = ('python -m bench.probes.long_drive_memory '
                      + ' '.join(argv if argv is not None else sys.argv[1:])).strip()
    print('\n'.join(markdown(doc)))
    if args.json:
        Path(args.json).write_text(json.dumps(doc, indent=2) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
