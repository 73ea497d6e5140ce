"""Road profile files (INTERFACES.md CSV, MODEL.md ERD, the shared text profile) written by
hand here, and profiles from source strings."""
import numpy as np
import pytest

from road_force_estimator.core.road import RoadProfile, flat_profile, iso8608_profile
from road_force_estimator.core.road_files import (
    read_csv_profile, read_erd_profile, read_text_profile, road_from_source, write_csv_profile,
    write_erd_profile)

INCH, FOOT = 0.0254, 0.3048


# ------------------------------------------------------------------------------------------
# Files
# ------------------------------------------------------------------------------------------

def test_read_hand_written_csv(tmp_path):
    path = tmp_path / 'two.csv'
    path.write_text('distance_m,left_m,right_m\n'
                    '0.0,0.001,-0.001\n'
                    '0.5,0.002,nan\n'          # non-finite: dropped, counted
                    '1.0,0.003,-0.003\n'
                    '1.0,0.004,-0.004\n'       # duplicate distance: dropped, counted
                    '0.9,0.004,-0.004\n'       # going back: dropped, counted
                    '1.5,0.005,-0.005\n')
    p = read_csv_profile(path)
    np.testing.assert_allclose(p.distance_m, [0.0, 1.0, 1.5])
    np.testing.assert_allclose(p.elevation_m, [[0.001, -0.001], [0.003, -0.003],
                                               [0.005, -0.005]])
    assert any('1 rows with a non-finite' in n for n in p.notes)
    assert any('2 rows with a duplicate or decreasing' in n for n in p.notes)
    one = tmp_path / 'one.csv'
    one.write_text('elevation_m,distance_m\n0.01,10\n0.02,10.25\n')
    p = read_csv_profile(one)
    np.testing.assert_allclose(p.elevation_m, [[0.01, 0.01], [0.02, 0.02]])
    np.testing.assert_allclose(p.distance_m, [10.0, 10.25])


def test_csv_errors(tmp_path):
    bad = tmp_path / 'bad.csv'
    bad.write_text('x,z\n0,0\n1,0\n')
    with pytest.raises(ValueError, match='distance_m,left_m,right_m'):
        read_csv_profile(bad)
    bad.write_text('distance_m,elevation_m\n0,0\n1,abc\n')
    with pytest.raises(ValueError, match='line 3'):
        read_csv_profile(bad)
    with pytest.raises(ValueError, match='cannot read'):
        read_csv_profile(tmp_path / 'missing.csv')


def test_csv_round_trip(tmp_path):
    road = iso8608_profile('C', 50.0, seed=3, start_m=100.0)
    write_csv_profile(tmp_path / 'r.csv', road)
    assert (tmp_path / 'r.csv').read_text().startswith('distance_m,left_m,right_m\n')
    back = read_csv_profile(tmp_path / 'r.csv')
    np.testing.assert_allclose(back.distance_m, road.distance_m, rtol=1e-12)
    np.testing.assert_allclose(back.elevation_m, road.elevation_m, rtol=1e-10, atol=1e-15)


def test_shared_profile_1_reads(shared_data):
    p = read_text_profile(shared_data / 'profile_1.txt')
    # README: 2177 points, regular 0.25 m spacing, 478.0 m to 1022.0 m, one track.
    assert len(p) == 2177
    assert (p.start_m, p.end_m) == (478.0, 1022.0)
    np.testing.assert_allclose(np.diff(p.distance_m), 0.25)
    assert np.array_equal(p.left_m, p.right_m)
    assert p.left_m[0] == 583.1370 and p.left_m[1] == 583.1337
    assert 570.0 < p.left_m.min() and p.left_m.max() < 600.0
    assert p.notes == ()
    assert len(road_from_source(str(shared_data / 'profile_1.txt'))) == 2177


# Hand-written ERD files, as ProVAL / RoadRuf / LTPP write them.
ERD_METRES = """ERDFILEV2.00
      2,      5,      1,      1,      5,  2.500000e-01,      1,
TITLE   Test section 1, metres
SHORTNAMLeft    Right
UNITSNAMm       m
XLABEL  Distance
XUNITS  m
IRILWP  1.23
IRIRWP  1.45
END
 0.0010 -0.0020
 0.0020 -0.0010
 0.0030  0.0000
 0.0025  0.0010
 0.0015  0.0020
"""

ERD_MM_LTPP = """ERDFILEV2.00
      3,      4,     -1,      1,      5,       0.0250,     -1,
TITLE   LTPP-like section: Run 1
UNITSNAMmm      mm      mm
XUNITS  m
DATE    11/Apr/1997

END
 0.0 0.5 -1.0
 1.5 2.0 -2.0
 3.0 4.5 -3.5
 2.0 1.0 -4.0
"""

ERD_INCHES_FEET = """ERDFILEV2.00
2, 3, 1, 1, 5, 0.5, 0,
TITLE   US survey
SHORTNAMRWP     LWP
UNITSNAMin      in
XLABEL  Distance
XUNITS  ft
SURVDATE03/02/2001
END
0.10 0.20
-0.30 0.40
0.50 -0.60
"""

ERD_FEET_ONE_TRACK = """ERDFILEV2.00
      1,     10,      1,      1,      5,  1.0,      1,
TITLE   one track in feet
UNITSNAMft
XUNITS  ft
END
0.01
0.02
-0.03
"""


def test_erd_in_metres(tmp_path):
    path = tmp_path / 'm.erd'
    path.write_text(ERD_METRES)
    p = read_erd_profile(path)
    np.testing.assert_allclose(p.distance_m, [0.0, 0.25, 0.5, 0.75, 1.0])
    np.testing.assert_allclose(p.left_m, [0.001, 0.002, 0.003, 0.0025, 0.0015])
    np.testing.assert_allclose(p.right_m, [-0.002, -0.001, 0.0, 0.001, 0.002])
    assert 'Test section 1' in p.name and p.notes == ()


def test_erd_in_millimetres_with_three_unnamed_channels(tmp_path):
    path = tmp_path / 'ltpp.erd'
    path.write_text(ERD_MM_LTPP)
    p = read_erd_profile(path)
    np.testing.assert_allclose(p.distance_m, [0.0, 0.025, 0.05, 0.075])
    np.testing.assert_allclose(p.left_m, [0.0, 0.0015, 0.003, 0.002])
    np.testing.assert_allclose(p.right_m, [0.0005, 0.002, 0.0045, 0.001])
    assert any('channels 1 and 2' in n for n in p.notes)


def test_erd_in_inches_over_feet_with_named_channels(tmp_path):
    path = tmp_path / 'us.erd'
    path.write_text(ERD_INCHES_FEET)
    p = read_erd_profile(path)
    np.testing.assert_allclose(p.distance_m, [0.0, 0.5 * FOOT, 1.0 * FOOT])
    # SHORTNAM says the right wheel path comes first.
    np.testing.assert_allclose(p.left_m, np.array([0.20, 0.40, -0.60]) * INCH)
    np.testing.assert_allclose(p.right_m, np.array([0.10, -0.30, 0.50]) * INCH)


def test_erd_in_feet_one_track_truncated(tmp_path):
    path = tmp_path / 'ft.erd'
    path.write_text(ERD_FEET_ONE_TRACK)
    p = read_erd_profile(path)
    np.testing.assert_allclose(p.distance_m, np.array([0.0, 1.0, 2.0]) * FOOT)
    np.testing.assert_allclose(p.left_m, np.array([0.01, 0.02, -0.03]) * FOOT)
    assert np.array_equal(p.left_m, p.right_m)
    assert any('truncated: 3 of 10' in n for n in p.notes)


def test_erd_errors(tmp_path):
    path = tmp_path / 'bad.erd'
    path.write_text(ERD_METRES.replace(' 5,  2.5', ' -5,  2.5'))
    with pytest.raises(ValueError, match='KEY = -5'):
        read_erd_profile(path)
    path.write_text(ERD_METRES.replace('END\n', ''))
    with pytest.raises(ValueError, match='END'):
        read_erd_profile(path)
    path.write_text(ERD_METRES.replace(' 0.0030  0.0000', ' 0.0030'))
    with pytest.raises(ValueError, match='expected 2 values'):
        read_erd_profile(path)
    path.write_text(ERD_METRES.replace('UNITSNAMm       m', 'UNITSNAMN       N'))
    with pytest.raises(ValueError, match='not a length unit'):
        read_erd_profile(path)
    path.write_text('distance,elevation\n0,0\n')
    with pytest.raises(ValueError, match='not an ERD file'):
        read_erd_profile(path)



@pytest.mark.parametrize('step', ['1.000000e+05', '1.000000e+06', '1.000000e+30'])
def test_erd_with_an_impossible_step_is_refused(tmp_path, step):
    """Issue 16. Before: STEP 1e5 / 1e6 took 672 MB / 5.6 GB downstream, 1e30 a raw numpy
    "Maximum allowed size exceeded"."""
    path = tmp_path / 'step.erd'
    path.write_text(ERD_METRES.replace('2.500000e-01', step))
    with pytest.raises(ValueError,
                       match=r'line 2: STEP = (100000|1e\+06|1e\+30) m is more than 100 m'):
        read_erd_profile(path)
    path.write_text(ERD_METRES.replace('2.500000e-01', '1.000000e+02'))   # 100 m: accepted
    assert read_erd_profile(path).distance_m[-1] == 400.0


def test_impossible_elevations_and_distances_are_refused_with_the_line(tmp_path):
    """Issue 16. Before: CSV elevations of 1e30 gave an IRI of 7e30 m/km with exit 0."""
    csv = tmp_path / 'p.csv'
    csv.write_text('distance_m,left_m,right_m\n0,0,0\n0.25,0.001,0\n0.5,1e30,0\n'
                   '0.75,0,-2e4\n')
    with pytest.raises(ValueError, match=r'p.csv, line 4: elevation 1e\+30 m is beyond '
                       r'\+-10000 m.*2 such row'):
        read_csv_profile(csv)
    csv.write_text('distance_m,elevation_m\n0,0\n0.25,0.001\n1e30,0\n')
    with pytest.raises(ValueError, match=r'line 4: distance 1e\+30 m is beyond'):
        read_csv_profile(csv)
    txt = tmp_path / 'p.txt'
    txt.write_text('# x z\n0 0\n\n0.25 5e4\n')
    with pytest.raises(ValueError, match=r'p.txt, line 4: elevation 50000 m'):
        read_text_profile(txt)
    erd = tmp_path / 'p.erd'
    erd.write_text(ERD_METRES.replace(' 0.0030  0.0000', ' 0.0030  1e30'))
    with pytest.raises(ValueError, match=r'p.erd, line 13: elevation 1e\+30 m'):
        read_erd_profile(erd)
    erd.write_text(ERD_METRES.replace(' 0.0030  0.0000', ' 0.0030  nan'))   # dropped, noted
    assert read_erd_profile(erd).distance_m.size == 4


@pytest.mark.parametrize('units, factor', [('m', 1.0), ('mm', 1e-3), ('in', INCH),
                                           ('ft', FOOT)])
def test_erd_round_trip(tmp_path, units, factor):
    road = iso8608_profile('C', 20.0, seed=4, dx_m=0.25, start_m=478.0)
    path = tmp_path / f'r_{units}.erd'
    write_erd_profile(path, road, units=units)
    text = path.read_text()
    assert text.startswith('ERDFILEV2.00\n') and f'UNITSNAM{units:<8}{units:<8}' in text
    first_row = text.split('END\n')[1].split('\n')[0].split()
    assert float(first_row[0]) == pytest.approx(road.left_m[0] / factor, rel=1e-9)
    back = read_erd_profile(path)
    np.testing.assert_allclose(back.distance_m, road.distance_m, rtol=1e-12)
    np.testing.assert_allclose(back.elevation_m, road.elevation_m, rtol=1e-9, atol=1e-15)
    uneven = RoadProfile([0.0, 0.1, 0.3], [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match='evenly spaced'):
        write_erd_profile(tmp_path / 'u.erd', uneven)


# ------------------------------------------------------------------------------------------
# Sources
# ------------------------------------------------------------------------------------------

def test_sources_synthetic():
    a = road_from_source('iso8608:C:seed=1')
    assert np.array_equal(a.elevation_m, iso8608_profile('C', 1000.0, seed=1).elevation_m)
    b = road_from_source('ISO8608:c:seed=2:length=300:dx=0.1:coherence=identical')
    assert b.end_m == pytest.approx(300.0) and len(b) == 3001
    assert np.array_equal(b.left_m, b.right_m)
    assert road_from_source('iso8608:E', length_m=250.0).end_m == pytest.approx(250.0)
    assert road_from_source('iso8608:E:length=100', length_m=250.0).end_m == pytest.approx(100)
    flat = road_from_source('flat:length=50')
    assert flat.end_m == pytest.approx(50.0) and np.all(flat.elevation_m == 0.0)
    for bad, match in (('iso8608:Z', 'road_class'), ('iso8608:C:seed=x', 'seed'),
                       ('iso8608:C:depth=3', 'unknown option'), ('iso8608', 'expected'),
                       ('iso8608:C:length=abc', 'not a number'), ('nowhere.csv', 'no such'),
                       ('iso8608:C:seed', 'name=value')):
        with pytest.raises(ValueError, match=match):
            road_from_source(bad)


def test_sources_files(tmp_path):
    road = iso8608_profile('B', 10.0, seed=5, dx_m=0.25)
    write_csv_profile(tmp_path / 'a.csv', road)
    write_erd_profile(tmp_path / 'a.erd', road)
    write_erd_profile(tmp_path / 'erd.txt', road)           # an ERD file named .txt
    (tmp_path / 'a.dat').write_text('0 0.001\n1 0.002\n2 0.0\n')
    for name in ('a.csv', 'a.erd', 'erd.txt'):
        np.testing.assert_allclose(road_from_source(str(tmp_path / name)).elevation_m,
                                   road.elevation_m, rtol=1e-9, atol=1e-15)
    assert len(road_from_source(str(tmp_path / 'a.dat'))) == 3
    (tmp_path / 'a.xlsx').write_text('')
    with pytest.raises(ValueError, match='unknown file type'):
        road_from_source(str(tmp_path / 'a.xlsx'))
    with pytest.raises(ValueError, match='metadata.yaml'):
        road_from_source(str(tmp_path))


def test_bag_folders_are_left_to_bagio(tmp_path):
    # core never reads bags: road_force_estimator.bagio.road_from_source does.
    bag = tmp_path / 'lpa_bag'
    bag.mkdir()
    (bag / 'metadata.yaml').write_text('rosbag2_bagfile_information: {}\n')
    with pytest.raises(ValueError, match='bagio.road_from_source'):
        road_from_source(str(bag))
    assert flat_profile(5.0).end_m == 5.0


# ------------------------------------------------------------------------------------------
# Files as people have them (issue 28): a byte-order mark, no units, very long files
# ------------------------------------------------------------------------------------------

BOM = '\ufeff'


def test_files_with_a_utf8_byte_order_mark_are_read_as_without(tmp_path):
    csv_text = 'distance_m,elevation_m\n0.0,0.001\n0.5,0.002\n1.0,0.003\n'
    (tmp_path / 'plain.csv').write_text(csv_text, 'utf-8')
    (tmp_path / 'excel.csv').write_text(BOM + csv_text.replace('\n', '\r\n'), 'utf-8')
    (tmp_path / 'plain.erd').write_text(ERD_METRES, 'utf-8')
    (tmp_path / 'excel.erd').write_text(BOM + ERD_METRES, 'utf-8')
    (tmp_path / 'plain.txt').write_text('0 0.001\n1 0.002\n2 0.004\n', 'utf-8')
    (tmp_path / 'excel.txt').write_text(BOM + '0 0.001\n1 0.002\n2 0.004\n', 'utf-8')
    for stem in ('csv', 'erd', 'txt'):
        a = road_from_source(str(tmp_path / f'plain.{stem}'))
        b = road_from_source(str(tmp_path / f'excel.{stem}'))
        np.testing.assert_array_equal(a.distance_m, b.distance_m)
        np.testing.assert_array_equal(a.elevation_m, b.elevation_m)
        assert a.distance_m.size >= 3


@pytest.mark.parametrize('drop, named', [('UNITSNAMm       m\n', 'UNITSNAM'),
                                         ('XUNITS  m\n', 'XUNITS'),
                                         ('UNITSNAMm       m\nXUNITS  m\n',
                                          'UNITSNAM and XUNITS')])
def test_an_erd_file_without_its_units_is_refused_naming_what_is_missing(tmp_path, drop,
                                                                          named):
    text = ERD_METRES
    for line in drop.splitlines(keepends=True):
        text = text.replace(line, '')
    path = tmp_path / 'nounits.erd'
    path.write_text(text)
    with pytest.raises(ValueError, match=rf'has no {named}: the units .* unknown'):
        read_erd_profile(path)


def _long_csv(path, rows: int) -> None:
    x = np.arange(rows) * 0.05
    z = np.column_stack([x, 1e-3 * np.sin(x), 1e-3 * np.cos(x)])
    np.savetxt(path, z, delimiter=',', fmt='%.9g', header='distance_m,left_m,right_m',
               comments='')


def test_a_long_csv_profile_is_read_in_memory_of_its_numbers_not_of_its_text(tmp_path):
    # numpy's allocations are traced by tracemalloc: the peak of the read, against the size
    # of the numbers it returns (3 columns of float64). Reading the text whole (a list of
    # rows of str) took more than ten times that.
    import tracemalloc

    path = tmp_path / 'long.csv'
    rows = 600_000
    _long_csv(path, rows)
    numbers = rows * 3 * 8
    tracemalloc.start()
    try:
        p = read_csv_profile(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert p.distance_m.size == rows
    np.testing.assert_allclose(p.elevation_m[-1], [1e-3 * np.sin(p.distance_m[-1]),
                                                   1e-3 * np.cos(p.distance_m[-1])], atol=1e-11)
    assert peak < 5 * numbers, (peak, numbers, path.stat().st_size)


def test_a_bad_line_deep_in_a_long_file_is_named(tmp_path):
    from road_force_estimator.core import road_files
    path = tmp_path / 'long.csv'
    _long_csv(path, 3 * road_files.CHUNK_LINES)
    lines = path.read_text().splitlines()
    k = 2 * road_files.CHUNK_LINES + 17            # in the third chunk
    lines[k] = '12.5,abc,0.1'
    path.write_text('\n'.join(lines) + '\n')
    with pytest.raises(ValueError, match=rf'long.csv, line {k + 1}: expected 3 numbers, got '
                                         r"'12.5,abc,0.1'"):
        read_csv_profile(path)
