"""road_profile_iri: IRI per segment as CSV on stdout, from files and LPA bags."""
import csv
import io
from pathlib import Path
import shutil
import subprocess
import sys

import numpy as np
import pytest

from road_force_estimator import bagio
from road_force_estimator.core.road_files import read_text_profile
from road_force_estimator.tools.road_profile_iri import build_parser, main

HEADER = ['start_m', 'end_m', 'iri_left_m_per_km', 'iri_right_m_per_km']


def run(argv, capsys):
    code = main(argv)
    out, err = capsys.readouterr()
    return code, list(csv.reader(io.StringIO(out))), err


def test_profile_1_whole_and_per_segment(shared_data, capsys):
    code, rows, _ = run([str(shared_data / 'profile_1.txt'), '--segment-length', '1000'],
                        capsys)
    assert code == 0 and rows[0] == HEADER and len(rows) == 2
    assert [float(v) for v in rows[1][:2]] == [478.0, 1022.0]
    assert float(rows[1][2]) == pytest.approx(3.335, rel=0.005)    # README reference
    assert rows[1][2] == rows[1][3]                                # one track: both sides
    code, rows, _ = run([str(shared_data / 'profile_1.txt')], capsys)
    assert code == 0 and len(rows) == 1 + 5                        # 544 m in 100 m segments
    starts = [float(r[0]) for r in rows[1:]]
    assert starts == [478.0, 578.0, 678.0, 778.0, 878.0] and rows[-1][1] == '1022.0'
    values = np.array([float(r[2]) for r in rows[1:]])
    lengths = np.diff(starts + [1022.0])
    assert np.sum(values * lengths) / lengths.sum() == pytest.approx(3.335, rel=0.005)


def test_lpa_bag_gives_the_same_table_as_its_source(shared_data, tmp_path, capsys):
    profile = read_text_profile(shared_data / 'profile_1.txt')
    bagio.write_lpa_bag(tmp_path / 'lpa', profile)
    _, from_file, _ = run([str(shared_data / 'profile_1.txt'), '--segment-length', '50'],
                          capsys)
    _, from_bag, _ = run([str(tmp_path / 'lpa'), '--segment-length', '50'], capsys)
    assert from_bag == from_file and len(from_bag) == 1 + 11     # 544 m: 10 x 50 m + 44 m


def test_bad_input(tmp_path, capsys):
    for argv, expected in (([str(tmp_path / 'none.csv')], 1),
                           ([], 2),
                           (['x.csv', '--segment-length', '0'], 2),
                           (['x.csv', '--segment-length', 'abc'], 2)):
        code, rows, err = run(argv, capsys)
        assert code == expected and rows == [] and err.count('\n') == 1, (argv, err)
    (tmp_path / 'short.csv').write_text('distance_m,elevation_m\n0,0\n5,0.01\n')
    code, rows, err = run([str(tmp_path / 'short.csv')], capsys)
    assert code == 1 and '11 m' in err and rows == []
    assert build_parser().parse_args(['p.csv']).segment_length == 100.0


def test_installed_executable(shared_data):
    exe = shutil.which('road_profile_iri', path=str(Path(sys.executable).parent))
    assert exe is not None, 'road_profile_iri is not installed beside the interpreter'
    done = subprocess.run([exe, str(shared_data / 'profile_1.txt'), '--segment-length', '600'],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    rows = list(csv.reader(io.StringIO(done.stdout)))
    assert rows[0] == HEADER and float(rows[1][3]) == pytest.approx(3.335, rel=0.005)
