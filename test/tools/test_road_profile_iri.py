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
from road_force_estimator.tools import cli
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
    assert starts == [478.0, 578.0, 678.0, 778.0, 878.0] and rows[-1][1] == '1022.000'
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
    assert cli.segment_length(build_parser().parse_args(['p.csv'])) == 100.0
    assert cli.segment_length(build_parser().parse_args(['p.csv', '--units', 'us'])) == \
        pytest.approx(160.9344, abs=1e-12)


def test_installed_executable(shared_data):
    exe = shutil.which('road_profile_iri', path=str(Path(sys.executable).parent))
    assert exe is not None, 'road_profile_iri is not installed beside the interpreter'
    done = subprocess.run([exe, str(shared_data / 'profile_1.txt'), '--segment-length', '600'],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    rows = list(csv.reader(io.StringIO(done.stdout)))
    assert rows[0] == HEADER and float(rows[1][3]) == pytest.approx(3.335, rel=0.005)


def test_units_us_in_per_mi_and_tenth_mile_segments(shared_data, capsys):
    """--units us: feet and in/mi (1 m/km = 63.36 in/mi) on 0.1-mile (160.9344 m) segments,
    checked against the SI table of the same segments converted by hand."""
    path = str(shared_data / 'profile_1.txt')
    code, us, err = run([path, '--units', 'us'], capsys)
    assert code == 0
    assert us[0] == ['start_ft', 'end_ft', 'iri_left_in_per_mi', 'iri_right_in_per_mi']
    _, si, _ = run([path, '--segment-length', '160.9344'], capsys)
    assert len(us) == len(si) == 1 + 3           # 544 m: 160.9 + 160.9 + 222.1 m (joined)
    # By hand: 478 m = 478 / 0.3048 ft = 1568.241 ft; 478 + 160.9344 m = 2096.241 ft.
    assert us[1][:2] == ['1568.241', '2096.241']
    assert us[-1][1] == '3353.018'               # 1022 m / 0.3048
    for row_us, row_si in zip(us[1:], si[1:]):
        assert float(row_us[2]) == pytest.approx(63.36 * float(row_si[2]), abs=0.04)
        assert float(row_us[0]) == pytest.approx(float(row_si[0]) / 0.3048, abs=0.002)
    # The whole-profile IRI: README's 3.335 m/km = 211.3 in/mi.
    whole = [line for line in err.splitlines() if 'whole profile' in line]
    assert len(whole) == 1 and '1568.241 to 3353.018 ft' in whole[0]
    value = float(whole[0].split('left/right ')[1].split('/')[0])
    assert value == pytest.approx(3.335 * 63.36, rel=0.005)


def test_numbers_are_rounded(shared_data, capsys):
    """1 mm of distance, 0.001 m/km of IRI: no 482.80320000000006."""
    code, rows, err = run([str(shared_data / 'profile_1.txt'), '--segment-length', '4.8280320'],
                          capsys)
    assert code == 0
    for row in rows[1:]:
        for cell, decimals in zip(row, (3, 3, 3, 3)):
            assert len(cell.split('.')[1]) == decimals, row
    assert 'whole profile (478.000 to 1022.000 m): IRI left/right 3.3' in err


def test_erd_header_iri_is_echoed_beside_the_computed_one(tmp_path, capsys):
    """An ERD file in feet with IRILWP / IRIRWP: the conversion is said, the stored IRI (in/mi:
    the file's distances are feet) is printed beside the computed one."""
    z = 0.002 * np.sin(np.arange(400) * 0.7) / 0.3048
    body = '\n'.join(f'{v:.6f} {-v:.6f}' for v in z)
    (tmp_path / 'p.erd').write_text(
        'ERDFILEV2.00\n2, 400, 1, 1, 5, 1.0, 1\nTITLE   test\nSHORTNAMLeft    Right   \n'
        'UNITSNAMft      ft      \nXUNITS  ft\nIRILWP  126.72\nIRIRWP  63.36\nEND\n'
        + body + '\n')
    code, rows, err = run([str(tmp_path / 'p.erd')], capsys)
    assert code == 0 and len(rows) > 1
    assert 'distance converted from ft to m (x 0.3048)' in err
    assert 'elevation converted from ft/ft to m' in err
    stored = [line for line in err.splitlines() if 'IRILWP / IRIRWP' in line]
    assert len(stored) == 1
    assert 'stores (IRILWP / IRIRWP) 2.000/1.000 m/km' in stored[0]
    assert 'written 126.72/63.36 in/mi' in stored[0] and 'computed' in stored[0]
    code, _, err = run([str(tmp_path / 'p.erd'), '--units', 'us'], capsys)
    assert 'stores (IRILWP / IRIRWP) 126.72/63.36 in/mi' in err
