"""core.units: the unit systems of --units, FHWA's condition bands and the rounding."""
import math

import pytest

from road_force_estimator.core.units import (
    CONDITION_BANDS_IN_PER_MI, IN_PER_MI_PER_M_PER_KM, rounded, units)


def test_si_and_us_by_hand():
    si, us = units('si'), units('us')
    assert IN_PER_MI_PER_M_PER_KM == 63.36            # 63 360 in per mile / 1000
    assert us.iri(1.0) == 63.36 and si.iri(3.335) == 3.335
    assert us.iri_text(3.335) == '211.31' and si.iri_text(3.335) == '3.335'
    assert us.length_text(160.9344) == '528.000' and si.length_text(482.80320000000006) == \
        '482.803'
    assert si.segment_length_m == 100.0 and us.segment_length_m == pytest.approx(160.9344)
    assert us.segment_text(160.9344) == '0.1 mi (528 ft)' and si.segment_text(100.0) == '100 m'
    assert si.iri_text(None) == 'n/a' and us.iri_text(math.nan) == 'n/a'
    with pytest.raises(ValueError, match='units'):
        units('imperial')


def test_condition_bands_in_either_unit():
    assert CONDITION_BANDS_IN_PER_MI == (95.0, 170.0)
    assert units('us').iri(1.0) * 95.0 / 63.36 == pytest.approx(95.0)
    from road_force_estimator.core.units import condition_bands
    assert condition_bands(units('us')) == pytest.approx((95.0, 170.0))
    assert condition_bands(units('si')) == pytest.approx((95.0 / 63.36, 170.0 / 63.36))


def test_rounding_to_what_the_measurement_supports():
    assert rounded(42966.87990743888, 'load_n') == '42967'
    assert rounded(899.9999999994715, 'distance_m') == '900.000'
    assert rounded(1.5240000000000001e-05, 'elevation_m') == '0.0000152'
    assert rounded(-1e-9, 'elevation_m') == '0.0000000'           # no -0
    assert rounded(math.nan, 'iri_m_per_km') == 'nan'
