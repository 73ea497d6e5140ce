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
