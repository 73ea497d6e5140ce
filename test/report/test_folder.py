"""report.folder: the report files (report.md, report.json, segments.csv) and figures.

References: the synthetic drive of test/report_case.py (known load errors), and the PNG
format's own header.
"""
import csv
import json
import struct

import numpy as np
import pytest

from report_case import VEHICLE, make_case
from road_force_estimator import report
from road_force_estimator.core.segments import SEGMENT_COLUMNS


def png_size(path):
    data = path.read_bytes()
    assert data[:8] == b'\x89PNG\r\n\x1a\n'
    return struct.unpack('>II', data[16:24])


class TestFiles:
    def test_report_folder(self, tmp_path):
        est, drive, _ = make_case(fixes=True)
        summary = report.write_report(tmp_path / 'r', est, drive, VEHICLE, mode='offline',
                                      input_name='drive_a')
        folder = tmp_path / 'r'
        assert summary['figures'] == list(report.FIGURES)
        for name in report.FIGURES:
            w, h = png_size(folder / name)
            assert w >= 1000 and h >= 600 and (folder / name).stat().st_size > 20_000
        with (folder / 'segments.csv').open() as f:
            rows = list(csv.reader(f))
        assert tuple(rows[0]) == SEGMENT_COLUMNS and len(rows) == 7
        assert float(rows[1][rows[0].index('start_lat')]) == pytest.approx(48.0)
        md = (folder / 'report.md').read_text()
        for text in ('# Estimate report: drive_a', 'Mode **offline**', '## Accuracy',
                     '| `/suspension/deflections` | nonfinite | 2 |',
                     'Breaks found while reading', '## Segments (100 m)', '![states](states.png)'):
            assert text in md, text
        data = json.loads((folder / 'report.json').read_text())
        assert data['accuracy']['load_rms_n'] == pytest.approx([100.0, 200.0])
        assert data['mode'] == 'offline' and data['input'] == 'drive_a'

    def test_without_figures_and_never_converged(self, tmp_path):
        est, drive, _ = make_case(n=3000)
        est.converged[:] = False        # never converged: judged from the settling time (0.2 s)
        summary = report.write_report(tmp_path / 'r', est, drive, VEHICLE, figures=False)
        assert summary['figures'] == [] and summary['judged_from'] == 'settling time'
        assert summary['accuracy']['samples_judged'] == 3000 - 100
        np.testing.assert_allclose(summary['accuracy']['load_rms_n'], [100.0, 200.0])
        assert not list((tmp_path / 'r').glob('*.png'))
        data = json.loads((tmp_path / 'r' / 'report.json').read_text())
        assert data['first_converged_s'] is None        # inf -> null in JSON
        assert 'never reported convergence' in (tmp_path / 'r' / 'report.md').read_text()

    def test_a_drive_without_distance(self, tmp_path):
        est, drive, _ = make_case(n=400)
        est.distance_m[:] = 0.0
        summary = report.write_report(tmp_path / 'r', est, drive, VEHICLE)
        assert summary['segments'] == 0
        assert 'No segment' in (tmp_path / 'r' / 'report.md').read_text()

    def test_segments_csv_is_rounded_and_us_units_in_the_markdown(self, tmp_path):
        est, drive, _ = make_case(fixes=True)
        est.wheel_load_n[2000:2039, 1] = -4592.0
        report.write_report(tmp_path / 'r', est, drive, VEHICLE, figures=False, units='us',
                            segment_length_m=160.9344,
                            run_info={'command': 'estimate_bag x --units us', 'params_file':
                                      None, 'overrides': ['observer.latency:=0.01']})
        with (tmp_path / 'r' / 'segments.csv').open() as f:
            rows = list(csv.DictReader(f))
        assert rows[1]['start_m'] == '160.934' and rows[1]['end_m'] == '321.869'   # 1 mm
        for row in rows:
            assert '.' not in row['peak_load_left_n']                              # 1 N
            assert len(row['iri_left_m_per_km'].split('.')[1]) == 3                # 0.001 m/km
            assert len(row['start_lat'].split('.')[1]) == 7
        md = (tmp_path / 'r' / 'report.md').read_text()
        for text in ('## Segments (0.1 mi (528 ft))', '| from (ft) | to (ft) | IRI L (in/mi) |',
                     '| 528.0 | 1056.0 |', '## What was run', '`estimate_bag x --units us`',
                     'none (package defaults)', '`observer.latency:=0.01`',
                     '| samples where a load estimate went below zero (plotted as 0) | 39 |',
                     '| convergence time t_0 (s) |', 'stays below its tolerance',
                     'estimator restarts (of which after a gap in the stamps)',
                     'True IRI: of the ground-truth profile, which is the road enveloped'):
            assert text in md, text
        assert 'measured convergence time' not in md and 'settling time of the' not in md
        # The whole-drive IRI in in/mi = 63.36 x the m/km of report.json.
        data = json.loads((tmp_path / 'r' / 'report.json').read_text())
        left = data['iri_m_per_km']['estimated'][0]
        assert f'{63.36 * left:.2f} / ' in md

    def test_loads_and_ltr_not_judged_is_said(self, tmp_path):
        from road_force_estimator.core.road import RoadProfile
        est, drive, road = make_case(with_truth=False)
        reference = RoadProfile(road.distance_m, road.elevation_m, name='survey')
        report.write_report(tmp_path / 'r', est, drive, VEHICLE, figures=False,
                            reference=reference, reference_offset_m=0.0)
        md = (tmp_path / 'r' / 'report.md').read_text()
        assert 'judged on 0 converged samples' not in md.lower()
        assert 'Loads and LTR are not judged: the bag has no ground truth of the loads' in md

    def test_a_5_s_gap_gives_segments_without_data_never_zero(self, tmp_path):
        """5 s without accepted samples at 20 m/s (100-200 m): that segment says "no data",
        has NaN in segments.csv, and the whole-drive IRI is the mean of the other segments
        weighted by their samples, not an average with a zero."""
        est, drive, _ = make_case()
        t = (est.stamp_ns - est.stamp_ns[0]) * 1e-9
        est.valid[(t >= 5.0) & (t < 10.0)] = False
        summary = report.write_report(tmp_path / 'r', est, drive, VEHICLE, figures=False)
        with (tmp_path / 'r' / 'segments.csv').open() as f:
            rows = list(csv.DictReader(f))
        assert [r['start_m'] for r in rows][:3] == ['0.000', '100.000', '200.000']
        gap = rows[1]
        assert gap['iri_left_m_per_km'] == 'nan' and gap['peak_load_left_n'] == 'nan'
        assert gap['dlc_left'] == 'nan' and gap['lift_offs'] == '0'
        assert all(r['iri_left_m_per_km'] != 'nan' for j, r in enumerate(rows) if j != 1)
        assert summary['segments_without_data'] == 1
        md = (tmp_path / 'r' / 'report.md').read_text()
        assert '| 100.0 | 200.0 | no data (gap) |' in md
        assert '| segments without data (gap; no IRI) | 1 |' in md
        whole = summary['iri_m_per_km']['estimated'][0]
        others = [float(r['iri_left_m_per_km']) for j, r in enumerate(rows) if j != 1]
        assert min(others) - 1e-3 <= whole <= max(others) + 1e-3
        assert whole > 0.9 * min(others)              # never pulled down by a zero
