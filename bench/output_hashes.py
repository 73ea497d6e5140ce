"""SHA-256 of the bags the offline commands write for fixed inputs (the no-change check).

Runs ``simulate_bag`` (a synthetic road and a bundled LPA bag), ``estimate_bag`` (online
and offline) and ``profile_to_bag`` (CSV and ERD) through their console entry points, in
child processes, into a fixed folder, and prints one line per written ``.mcap`` file:
``<sha256>  <relative path>``. Two checkouts that print the same lines write the same bytes.

    python -m bench.output_hashes [--work DIR]
"""
from __future__ import annotations

import argparse
import hashlib
import os
from pathlib import Path
import subprocess
import sys
import shutil
import tempfile

ROOT = Path(__file__).resolve().parents[1]
PARAMS = ROOT / 'config' / 'road_force_estimator.yaml'
WORK = Path(tempfile.gettempdir()) / 'road_force_estimator_output_hashes'


def _run(work: Path, *argv: str) -> None:
    """Run one console command of the package (from this interpreter's bin folder) in work."""
    exe = Path(sys.executable).parent / argv[0]
    subprocess.run([str(exe), *argv[1:]], check=True, stdout=subprocess.DEVNULL, cwd=work,
                   env={**os.environ, 'OPENBLAS_NUM_THREADS': '1'})


def _write_inputs(folder: Path) -> None:
    """A two-track CSV profile and an ERD profile (feet), both deterministic."""
    import numpy as np
    x = np.arange(0.0, 300.0, 0.1)
    left = 0.004 * np.sin(2 * np.pi * x / 7.3) + 0.002 * np.sin(2 * np.pi * x / 1.9)
    right = 0.003 * np.sin(2 * np.pi * x / 5.1 + 0.4)
    csv = folder / 'profile.csv'
    with open(csv, 'w') as out:
        out.write('distance_m,left_m,right_m\n')
        for row in zip(x, left, right):
            out.write('%.4f,%.9f,%.9f\n' % row)
    erd = folder / 'profile.erd'
    n = 1000
    with open(erd, 'w') as out:
        out.write('ERDFILEV2.00\n')
        out.write('2, %d, 1, 1, 5, 0.5, 0\n' % n)
        out.write('TITLE   hash check\nUNITSNAM ft      ft      \nXUNITS  ft\nEND\n')
        for i in range(n):
            out.write('%.6f %.6f\n' % (0.01 * np.sin(i / 9.0), 0.012 * np.cos(i / 7.0)))


def run(work: Path) -> list[tuple[str, str]]:
    """Write every bag under ``work``; return ``(sha256, relative path)`` per .mcap file."""
    _write_inputs(work)   # relative paths below: bags record their source path
    _run(work, 'simulate_bag', '--road', 'iso8608:C:seed=3', '--speed', '20', '--rate', '1000',
         '--duration', '12', '--params-file', str(PARAMS), '--output', 'drive_iso')
    # the bundled road by a relative link: the drive's metadata records the road's path as
    # given, so the bytes do not depend on where the checkout lies
    (work / 'road_lpa').symlink_to(ROOT / 'bags' / 'lpa_iso8608_b', target_is_directory=True)
    _run(work, 'simulate_bag', '--road', 'road_lpa', '--speed', '15',
         '--rate', '500', '--duration', '10', '--params-file', str(PARAMS),
         '--output', 'drive_lpa')
    for mode in ('online', 'offline'):
        _run(work, 'estimate_bag', 'drive_iso', '--params-file', str(PARAMS),
             '--output', f'est_{mode}', '--mode', mode)
    _run(work, 'profile_to_bag', 'profile.csv', '--output', 'lpa_csv')
    _run(work, 'profile_to_bag', 'profile.erd', '--output', 'lpa_erd')
    rows = []
    for path in sorted(p for p in work.rglob('*.mcap') if 'road_lpa' not in p.parts):
        rows.append((hashlib.sha256(path.read_bytes()).hexdigest(),
                     str(path.relative_to(work))))
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--work', type=Path, default=WORK,
                        help=f'folder to write into, emptied first (default {WORK})')
    args = parser.parse_args(argv)
    shutil.rmtree(args.work, ignore_errors=True)
    args.work.mkdir(parents=True)
    rows = run(args.work)
    for digest, rel in rows:
        print(f'{digest}  {rel}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
