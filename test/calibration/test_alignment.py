"""Alignment of a drive's distance with a survey's (offset and odometer scale)."""
import numpy as np
import pytest

from road_force_estimator.bagio import road_from_source
from road_force_estimator.calibration.alignment import AlignmentError, align


@pytest.fixture(scope='module')
def survey():
    return road_from_source('iso8608:C:seed=5', length_m=500.0)


def _estimate(survey, offset, scale, noise=0.2, seed=1):
    """An 'estimated profile' on the drive's odometer: the survey at offset + scale x, noisy."""
    x = np.arange(0.0, 250.0, 0.02)
    z = survey.elevation_at(offset + scale * x)
    z = z + noise * np.std(z) * np.random.default_rng(seed).standard_normal(z.shape)
    return x, z


def test_offset_and_scale_found(survey):
    x, z = _estimate(survey, 37.3, 1.015)
    a = align(x, z, survey, start_m=0.0)
    # Well inside what the output-error fit refines (+-0.5 m, +-1e-3).
    assert a.offset_m == pytest.approx(37.3, abs=0.25)
    assert a.scale == pytest.approx(1.015, abs=5e-4)
    assert a.correlation > 0.8


def test_another_road_is_refused(survey):
    other = road_from_source('iso8608:C:seed=6', length_m=500.0)
    x, z = _estimate(other, 37.3, 1.0)
    with pytest.raises(AlignmentError, match='does not match the survey'):
        align(x, z, survey, start_m=0.0)


def test_no_overlap_is_refused(survey):
    x, z = _estimate(survey, 10.0, 1.0)
    with pytest.raises(AlignmentError, match='no overlap'):
        align(x, z, survey, start_m=2000.0)
