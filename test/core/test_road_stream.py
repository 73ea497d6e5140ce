"""core.road_stream and Plant.extend_road: a profile that arrives in pieces drives the plant to
the same samples as the whole profile (simulate_bag over the bag), to round-off."""
import math

import numpy as np
import pytest

from road_force_estimator.core.parameters import VehicleParameters
from road_force_estimator.core.plant import Plant, simulate
from road_force_estimator.core.road import iso8608_profile
from road_force_estimator.core.road_stream import RoadStream


def test_paths_are_joined_on_equal_distances_in_arrival_order():
    stream = RoadStream()
    for x, z in [(0.0, 1.0), (0.1, 2.0), (0.1, 9.0), (0.05, 9.0), (0.2, math.nan), (0.3, 3.0)]:
        stream.add(0, x, z)
    assert len(stream) == 0 and stream.profile() is None
    for x, z in [(0.0, -1.0), (0.2, -2.0), (0.3, -3.0), (0.4, -4.0)]:
        stream.add(1, x, z)
    p = stream.profile()
    assert p.distance_m.tolist() == [0.0, 0.3] and p.elevation_m.tolist() == [[1.0, -1.0],
                                                                               [3.0, -3.0]]
    # 0.1 (left) and 0.2 (right) have no partner; a duplicate, a backward and a NaN point.
    assert stream.dropped == {'order': 2, 'nonfinite': 1, 'unmatched': 2}
    assert stream.received == [6, 4] and stream.end_m == 0.3


def test_one_path_only_is_used_for_both_once_closed():
    stream = RoadStream()
    for i in range(5):
        stream.add(1, 0.1 * i, 0.01 * i)
    assert stream.profile() is None
    stream.close()
    np.testing.assert_array_equal(stream.profile().elevation_m[:, 0],
                                  stream.profile().elevation_m[:, 1])
    assert len(stream) == 5


@pytest.mark.parametrize('envelope', [0.25, 0.0])
def test_a_plant_on_a_growing_road_gives_the_samples_of_the_whole_road(envelope):
    road = iso8608_profile('D', 40.0, seed=4)
    vehicle = VehicleParameters()
    full = simulate(vehicle, road, speed_mps=20.0, rate_hz=1000.0, duration_s=10.0,
                    tire_envelope_m=envelope)
    stream = RoadStream()
    cuts = iter(np.linspace(3.0, 40.0, 23))
    plant = None
    rows = []
    cut = next(cuts)
    for x, (zl, zr) in zip(road.distance_m, road.elevation_m):
        stream.add(0, x, zl)
        stream.add(1, x, zr)
        if x < cut and x < road.end_m:
            continue
        cut = next(cuts, math.inf)
        if plant is None:
            plant = Plant(vehicle, stream.profile(), speed_mps=20.0, rate_hz=1000.0,
                          tire_envelope_m=envelope)
        else:
            plant.extend_road(stream.profile())
        while plant.sample_index < plant.last_sample_index:  # as far as the road allows
            rows.append(plant.step())
    assert plant.step() is None and plant.finished
    assert len(rows) == len(full)
    for name in ('q_m', 'roll_rad', 'wheel_load_n', 'road_m', 'distance_m', 'body_heave_m'):
        got = np.array([getattr(r, name) for r in rows])
        np.testing.assert_allclose(got, getattr(full, name), rtol=1e-12, atol=1e-15,
                                   err_msg=name)


def test_extend_road_refuses_a_road_that_does_not_continue():
    road = iso8608_profile('C', 20.0, seed=1)
    plant = Plant(VehicleParameters(), road.segment(0.0, 10.0), speed_mps=20.0, rate_hz=1000.0)
    with pytest.raises(ValueError, match='does not extend'):
        plant.extend_road(road.segment(1.0, 20.0))
    with pytest.raises(ValueError, match='does not extend'):
        plant.extend_road(road.segment(0.0, 5.0))
