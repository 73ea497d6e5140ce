"""The calibration's drive grid and survey check."""
import numpy as np
import pytest

from road_force_estimator.core.road import RoadProfile
from road_force_estimator.estimation.calibration_fit import (
    CalibrationError, check_survey, drive_grid)


def test_grid_keeps_missing_rows_and_integrates_the_speed():
    stamps = np.arange(100, dtype=np.int64) * 5_000_000
    keep = np.ones(100, bool)
    keep[40:45] = False
    q = np.zeros((100, 2))
    q[10] = np.nan                                      # skipped as well
    grid = drive_grid(stamps[keep], q[keep], np.zeros(100)[keep], np.full(100, 10.0)[keep])
    assert grid.good.size == 100 and grid.good.sum() == 94 and grid.rejected == 6
    assert grid.distance_m[-1] == pytest.approx(99 * 0.005 * 10.0)


def test_jittered_stamps_are_refused():
    stamps = np.arange(50, dtype=np.int64) * 1_000_000
    stamps[20] += 300_000
    with pytest.raises(CalibrationError, match='uniform grid'):
        drive_grid(stamps, np.zeros((50, 2)), np.zeros(50), np.ones(50))


def test_survey_gap_is_named():
    x = np.concatenate([np.arange(0.0, 50.0, 0.1), np.arange(55.0, 100.0, 0.1)])
    with pytest.raises(CalibrationError, match=r'gap of 5\.\d+ m at 49\.90 m'):
        check_survey(RoadProfile(x, np.zeros(x.size)))
    check_survey(RoadProfile(np.arange(0.0, 10.0, 0.1), np.zeros(100)))
