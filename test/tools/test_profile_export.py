"""``estimate_bag --export-profile`` and the commands that read a bag of estimates (issue 29).

The exported file read back by the package's own readers (the ERD reader, the CSV reader, the
text-column reader of ``../shared/data/profile_1.txt``) gives the report's IRI per segment to
0.001 m/km; the ERD header carries the keywords ProVAL reads; ``road_profile_iri`` and
``profile_to_bag`` read the estimate bag's ``/road_profile/*``.
"""
from __future__ import annotations

import csv
import pathlib

import numpy as np
import pytest

from road_force_estimator.bagio import read_profile_bag, road_from_source
from road_force_estimator.core.iri import iri_segments
from road_force_estimator.core.road_files import (
    read_erd_profile, read_text_profile, write_text_profile)
from road_force_estimator.tools import estimate_bag, profile_to_bag, road_profile_iri
from road_force_estimator.tools import simulate_bag

ERD_KEYS = ('TITLE', 'SHORTNAM', 'LONGNAME', 'GENNAME', 'UNITSNAM', 'XLABEL', 'XUNITS')


def segments(report) -> tuple[np.ndarray, np.ndarray]:
    """(edges (k + 1,), estimated IRI (k, 2)) of a report's segments.csv."""
    with (report / 'segments.csv').open() as f:
        rows = list(csv.DictReader(f))
    edges = np.array([float(rows[0]['start_m'])] + [float(r['end_m']) for r in rows])
    iri = np.array([[float(r['iri_left_m_per_km']), float(r['iri_right_m_per_km'])]
                    for r in rows])
    return edges, iri


@pytest.fixture(scope='module')
def drives(tmp_path_factory, shared_data_module):
    """Two drives: over profile_1.txt at constant speed (offline), and over ISO C with a
    slowdown (online: the estimate's samples are unevenly spaced)."""
    root = tmp_path_factory.mktemp('export')
    speed = root / 'speed.csv'
    speed.write_text('time_s,speed_mps\n0,20\n3,8\n5,8\n7,20\n')
    out = {}
    for name, road, extra, mode in (
            ('profile_1', str(shared_data_module / 'profile_1.txt'), [], 'offline'),
            ('slowdown', 'iso8608:C:seed=4', ['-p', f'simulator.speed_profile:={speed}'],
             'online')):
        assert simulate_bag.main(['--road', road, '--speed', '20', '--rate', '500',
                                  '--duration', '12', *extra, '--output',
                                  str(root / name), '--no-progress']) == 0
        out[name] = (root / name, mode)
    return root, out


@pytest.fixture(scope='module')
def shared_data_module():
    shared = pathlib.Path(__file__).resolve().parents[3] / 'shared' / 'data'
    if not shared.is_dir():
        pytest.fail(f'{shared} is missing: clone the project with shared/ beside it')
    return shared


@pytest.mark.parametrize('name', ['profile_1', 'slowdown'])
@pytest.mark.parametrize('suffix', ['.erd', '.csv', '.txt'])
def test_the_exported_profile_reads_back_with_the_reports_iri_per_segment(drives, name,
                                                                          suffix, capsys):
    root, table = drives
    drive, mode = table[name]
    out, file = root / f'{name}{suffix}-est', root / f'{name}{suffix}'
    assert estimate_bag.main([str(drive), '--mode', mode, '--output', str(out),
                              '--no-figures', '--no-progress', '--export-profile',
                              str(file)]) == 0
    assert f'profile: {file}' in capsys.readouterr().out
    edges, reported = segments(out / 'report')
    back = {'.erd': read_erd_profile, '.csv': road_from_source,
            '.txt': read_text_profile}[suffix](file)
    got = iri_segments(back.distance_m, back.elevation_m, edges)
    assert np.max(np.abs(got - reported)) <= 0.001, (got, reported)
    # and the bag it came from, as road_profile_iri reads it: the same
    bag = read_profile_bag(out / 'bag')
    np.testing.assert_allclose(iri_segments(bag.distance_m, bag.elevation_m, edges), got,
                               atol=1e-9)
    if name == 'slowdown':   # uneven samples: laid on the IRI's grid
        assert np.ptp(np.diff(back.distance_m)) < 1e-9 < np.ptp(np.diff(bag.distance_m))


def test_the_erd_header_has_the_keys_proval_reads(drives):
    root, table = drives
    drive, mode = table['profile_1']
    out, file = root / 'erd-est', root / 'header.erd'
    assert estimate_bag.main([str(drive), '--mode', mode, '--output', str(out),
                              '--no-figures', '--no-progress', '--export-profile',
                              str(file)]) == 0
    lines = file.read_text().splitlines()
    assert lines[0] == 'ERDFILEV2.00'
    fields = [f.strip() for f in lines[1].split(',') if f.strip()]
    end = lines.index('END')
    keys = {line[:8].strip(): line[8:] for line in lines[2:end]}
    assert set(ERD_KEYS) <= set(keys), keys
    assert keys['SHORTNAM'].split() == ['Left', 'Right']
    assert keys['UNITSNAM'].split() == ['m', 'm'] and keys['XUNITS'].strip() == 'm'
    assert 'tire-enveloped' in keys['FILTER'] and '/road_profile/left' in keys['SOURCE']
    rows = lines[end + 1:]
    assert int(fields[0]) == 2 and int(fields[1]) == len(rows) and int(fields[4]) == 5
    assert all(len(r.split()) == 2 for r in rows)
    profile = read_erd_profile(file)
    assert profile.distance_m.size == len(rows)
    assert np.isclose(np.diff(profile.distance_m).mean(), float(fields[5]))


def test_road_profile_iri_and_profile_to_bag_read_a_bag_of_estimates(drives, tmp_path,
                                                                     capsys):
    root, table = drives
    drive, mode = table['profile_1']
    out = tmp_path / 'est'
    assert estimate_bag.main([str(drive), '--mode', mode, '--output', str(out),
                              '--no-figures', '--no-progress']) == 0
    capsys.readouterr()
    assert road_profile_iri.main([str(out / 'bag')]) == 0
    printed = capsys.readouterr()
    rows = [line.split(',') for line in printed.out.splitlines()[1:]]
    edges, reported = segments(out / 'report')
    np.testing.assert_allclose([[float(r[2]), float(r[3])] for r in rows], reported,
                               atol=0.001)
    assert '/road_profile/left' in printed.err or 'whole profile' in printed.err
    assert profile_to_bag.main([str(out / 'bag'), '--output', str(tmp_path / 'p.csv'),
                                '--exact']) == 0
    assert 'estimated profile of /road_profile/left' in capsys.readouterr().err
    again = road_from_source(str(tmp_path / 'p.csv'))
    bag = read_profile_bag(out / 'bag')
    np.testing.assert_array_equal(again.distance_m, bag.distance_m)
    np.testing.assert_array_equal(again.elevation_m, bag.elevation_m)


def test_the_text_export_is_in_the_layout_of_shared_data(shared_data, tmp_path):
    """profile_1.txt (2 columns) and our 3-column text files go through one reader: a
    profile written in that layout reads back to the same IRI as the file it came from."""
    reference = read_text_profile(shared_data / 'profile_1.txt')
    path = tmp_path / 'p.txt'
    write_text_profile(path, reference, comments=['from profile_1.txt'], exact=True)
    back = read_text_profile(path)
    np.testing.assert_array_equal(back.distance_m, reference.distance_m)
    edges = np.array([478.0, 578.0, 678.0, 778.0, 878.0, 1022.0])
    np.testing.assert_array_equal(iri_segments(back.distance_m, back.elevation_m, edges),
                                  iri_segments(reference.distance_m, reference.elevation_m,
                                               edges))


def test_a_bad_export_path_is_refused_before_the_drive_is_estimated(drives, tmp_path,
                                                                   capsys):
    root, table = drives
    drive, _ = table['profile_1']
    assert estimate_bag.main([str(drive), '--output', str(tmp_path / 'a'),
                              '--export-profile', str(tmp_path / 'p.xlsx')]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and '.erd, .csv, .txt' in err[0]
    theirs = tmp_path / 'theirs.erd'
    theirs.write_text('a file of somebody else\n')
    for extra in ([], ['--force']):
        assert estimate_bag.main([str(drive), '--output', str(tmp_path / 'b'),
                                  '--export-profile', str(theirs), *extra]) == 1
        assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert theirs.read_text() == 'a file of somebody else\n'
    assert not (tmp_path / 'a').exists() and not (tmp_path / 'b').exists()


def test_a_bag_without_a_profile_is_refused_in_one_line(drives, capsys):
    from road_force_estimator.bagio import BagReadError
    root, table = drives
    drive, _ = table['profile_1']            # a drive bag: measurements and truth only
    with pytest.raises(BagReadError, match='neither an LPA bag nor a bag of estimates'):
        read_profile_bag(drive)
    assert road_profile_iri.main([str(drive)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and '/road_profile/fused/left' in err[0]
