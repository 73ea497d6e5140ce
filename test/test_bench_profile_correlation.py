"""bench/studies/profile_correlation.py: its rating of a perfect estimate (1, the offset 0) and of
one placed by a speed read 1.5 % high (the rating collapses), on a short drive. No timing."""
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from bench.studies import profile_correlation as bpc
from bench.accuracy.scenarios import build_drive, scenario_by_name


@pytest.fixture(scope='module')
def drive():
    return build_drive(replace(scenario_by_name('jpcp'), duration_s=12.0, skip_s=1.0))


def _as_estimate(drive, scale):
    n = len(drive.t_s)
    return SimpleNamespace(stamp_ns=drive.stamps_ns, valid=np.ones(n, bool),
                           distance_m=scale * (drive.truth['distance_m']
                                               - drive.truth['distance_m'][0]),
                           road_m=drive.truth['road_m'])


def test_the_truth_at_the_true_distance_rates_one(drive):
    r = bpc.rate(drive, _as_estimate(drive, 1.0))
    assert r['xcorr'] == pytest.approx(1.0, abs=1e-9)
    assert r['seg_min'] == pytest.approx(1.0, abs=1e-9)
    assert r['last_lag_m'] == pytest.approx(0.0, abs=1e-9)


def test_the_truth_at_a_distance_1_5_percent_long_does_not(drive):
    r = bpc.rate(drive, _as_estimate(drive, 1.015))
    assert r['xcorr'] < 0.5
    assert 'x 1.015' in bpc.markdown([{'scenario': 'jpcp', 'scale': 1.015,
                                       'mode': 'offline', **r}], 'cmd')
