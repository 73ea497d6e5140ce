"""profile_to_bag: CSV / ERD / text / synthetic profiles to LPA bags and back, exactly."""
from pathlib import Path
import shutil
import subprocess
import sys

import numpy as np
import pytest

from road_force_estimator import bagio
from road_force_estimator.tools.profile_to_bag import build_parser, main, write_exact_csv
from road_force_estimator.core.road import RoadProfile
from road_force_estimator.core.road_files import (
    read_csv_profile,
    read_erd_profile,
    read_text_profile,
    write_erd_profile,
)


def random_profile(seed=4, n=2001, dx=0.1):
    rng = np.random.default_rng(seed)
    x = 100.0 + dx * np.arange(n)
    return RoadProfile(x, np.cumsum(rng.normal(0.0, 5e-4, (n, 2)), axis=0), name='r')


def assert_same(a, b):
    np.testing.assert_array_equal(a.distance_m, b.distance_m)
    np.testing.assert_array_equal(a.elevation_m, b.elevation_m)


def test_csv_to_bag_to_csv_is_exact(tmp_path):
    csv = tmp_path / 'road.csv'
    write_exact_csv(csv, random_profile())
    source = read_csv_profile(csv)
    assert main([str(csv), '--output', str(tmp_path / 'bag')]) == 0
    assert_same(bagio.read_lpa_bag(tmp_path / 'bag'), source)
    assert main([str(tmp_path / 'bag'), '--output', str(tmp_path / 'back.csv'), '--exact']) == 0
    assert_same(read_csv_profile(tmp_path / 'back.csv'), source)
    assert (tmp_path / 'back.csv').read_text() == csv.read_text()


def test_erd_to_bag_is_exact(tmp_path):
    erd = tmp_path / 'road.erd'
    write_erd_profile(erd, random_profile(seed=9), units='mm')
    source = read_erd_profile(erd)
    assert main([str(erd), '-o', str(tmp_path / 'bag'), '--survey-speed', '5',
                 '--track-width', '1.9']) == 0
    assert_same(bagio.read_lpa_bag(tmp_path / 'bag'), source)
    msgs = list(bagio.iter_messages(tmp_path / 'bag', ['/lpa/left']))
    assert {m.point.y for _, _, m in msgs} == {0.95}
    assert msgs[10][1] - msgs[0][1] == round(10 * 0.1 / 5.0 * 1e9)   # stamps at 5 m/s


def test_text_profile_one_track_and_synthetic(tmp_path, shared_data):
    assert main([str(shared_data / 'profile_1.txt'), '-o', str(tmp_path / 'p1')]) == 0
    p1 = bagio.read_lpa_bag(tmp_path / 'p1')
    assert_same(p1, read_text_profile(shared_data / 'profile_1.txt'))
    np.testing.assert_array_equal(p1.elevation_m[:, 0], p1.elevation_m[:, 1])
    assert main(['iso8608:C:seed=2', '--length', '200', '-o', str(tmp_path / 'c')]) == 0
    c = bagio.read_lpa_bag(tmp_path / 'c')
    assert c.length_m == pytest.approx(200.0)
    assert not np.array_equal(c.elevation_m[:, 0], c.elevation_m[:, 1])


def test_bad_input_is_one_line_and_nonzero(tmp_path, capsys):
    write_exact_csv(tmp_path / 'ok.csv', random_profile(n=50))
    cases = [
        ([str(tmp_path / 'missing.csv'), '-o', str(tmp_path / 'x')], 1),
        ([str(tmp_path / 'ok.csv'), '-o', str(tmp_path / 'x'), '--survey-speed', '0'], 1),
        ([str(tmp_path / 'ok.csv')], 2),                                # no --output
        ([str(tmp_path / 'ok.csv'), '-o', str(tmp_path / 'x'), '--length', '-1'], 2),
        ([str(tmp_path / 'ok.csv'), '-o', str(tmp_path / 'x'), '--survey-speed', 'fast'], 2),
    ]
    for argv, code in cases:
        assert main(argv) == code, argv
        err = capsys.readouterr().err
        assert err.count('\n') == 1 and 'Traceback' not in err, err
    (tmp_path / 'bad.csv').write_text('distance_m,left_m,right_m\n0,1,2\n1,x,3\n')
    assert main([str(tmp_path / 'bad.csv'), '-o', str(tmp_path / 'y')]) == 1
    assert 'line 3' in capsys.readouterr().err
    assert main([str(tmp_path / 'ok.csv'), '-o', str(tmp_path / 'z')]) == 0
    assert main([str(tmp_path / 'ok.csv'), '-o', str(tmp_path / 'z')]) == 1   # exists
    assert '--force' in capsys.readouterr().err
    assert main([str(tmp_path / 'ok.csv'), '-o', str(tmp_path / 'z'), '--force']) == 0
    assert main(['--help']) == 0
    args = build_parser().parse_args(['in.csv', '--output', 'out'])
    assert (args.input, args.output, args.survey_speed, args.track_width) == (
        'in.csv', 'out', bagio.DEFAULT_SURVEY_SPEED_MPS, bagio.DEFAULT_TRACK_WIDTH_M)


def test_installed_executable(tmp_path, shared_data):
    exe = shutil.which('profile_to_bag', path=str(Path(sys.executable).parent))
    assert exe is not None, 'profile_to_bag is not installed beside the interpreter'
    run = subprocess.run([exe, str(shared_data / 'profile_1.txt'), '--output',
                          str(tmp_path / 'bag')], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert (tmp_path / 'bag' / 'metadata.yaml').is_file()
    run = subprocess.run([exe, str(tmp_path / 'nothing.csv'), '--output', str(tmp_path / 'b')],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 1 and run.stderr.count('\n') == 1, run.stderr


def test_bag_to_csv_is_rounded_unless_exact(tmp_path):
    from road_force_estimator.core.road import RoadProfile
    x = np.array([0.0, 0.1 * 3, 0.6000000000000001])
    z = np.column_stack([[1.5240000000000001e-05, 2e-6, -1e-9], [0.0, 0.001, 0.0123456789]])
    bagio.write_lpa_bag(tmp_path / 'bag', RoadProfile(x, z))
    assert main([str(tmp_path / 'bag'), '--output', str(tmp_path / 'r.csv')]) == 0
    assert (tmp_path / 'r.csv').read_text().splitlines() == [
        'distance_m,left_m,right_m', '0.000,0.0000152,0.0000000', '0.300,0.0000020,0.0010000',
        '0.600,0.0000000,0.0123457']                 # 1 mm, 0.1 um
    assert main([str(tmp_path / 'bag'), '--output', str(tmp_path / 'e.csv'), '--exact']) == 0
    assert (tmp_path / 'e.csv').read_text().splitlines()[1] == '0.0,1.5240000000000001e-05,0.0'


def test_impossible_values_are_not_written(tmp_path, capsys):
    """Issue 16: CSV elevations of 1e30 were written into the bag."""
    csv = tmp_path / 'p.csv'
    csv.write_text('distance_m,left_m,right_m\n0,0,0\n0.25,1e30,0\n0.5,0,0\n')
    assert main([str(csv), '--output', str(tmp_path / 'bag')]) == 1
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'line 3: elevation 1e+30 m' in err
    assert not (tmp_path / 'bag').exists()
