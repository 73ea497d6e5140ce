"""The synthetic jointed concrete road: its geometry against the definition (steps at the
joints, the saw-tooth between them, the curl parabola), the seed, the source string, and a
drive over it through simulate_bag against the plant run directly."""
import numpy as np
import pytest

from road_force_estimator import bagio
from road_force_estimator.core import road_files
from road_force_estimator.core.parameters import VehicleParameters
from road_force_estimator.core.plant import simulate
from road_force_estimator.core.road import iso8608_profile
from road_force_estimator.core.road_jpcp import jpcp_from_source, jpcp_profile

L, W = 4.6, 0.005


def joints(length):
    return L * np.arange(1, int(length / L) + 1)


def test_steps_at_the_joints_are_1_to_3_mm_down():
    road = jpcp_profile(200.0, roughness=None, curl_m=0.0, faulting_m=2e-3, seed=3)
    xj = joints(200.0)
    before = road.elevation_at(xj)
    after = road.elevation_at(xj + W)
    step = before - after                          # the slab after the joint is lower
    assert step.shape == (xj.size, 2)
    assert np.all(step >= 1e-3 - 1e-12) and np.all(step <= 3e-3 + 1e-12)
    assert np.mean(step) == pytest.approx(2e-3, rel=0.15)
    assert not np.allclose(step[:, 0], step[:, 1])     # uneven across the lane
    # between the joints the road rises linearly (a saw-tooth): level on average
    mid = road.elevation_at(0.5 * (xj[:-1] + W + xj[1:]))
    ends = 0.5 * (after[:-1] + before[1:])
    np.testing.assert_allclose(mid, ends, atol=1e-12)
    np.testing.assert_allclose(after[1:], -0.5 * step[1:], atol=1e-12)
    np.testing.assert_allclose(before, 0.5 * step, atol=1e-12)
    assert abs(np.mean(road.elevation_m)) < 0.1e-3


def test_nothing_but_joints_moves_the_road_fast():
    """The largest slopes are the joints' ramps (a step over 5 mm), nowhere else."""
    road = jpcp_profile(100.0, roughness=None, curl_m=0.0, seed=1)
    slopes = np.abs(road.segment_slopes()[:, 0])
    fast = road.distance_m[:-1][slopes > 0.05]
    np.testing.assert_allclose(fast, joints(100.0), atol=1e-9)


@pytest.mark.parametrize('curl', [1.5e-3, -1e-3])
def test_curl_lifts_each_slab_end_above_its_middle(curl):
    road = jpcp_profile(60.0, roughness=None, faulting_m=0.0, curl_m=curl, seed=2)
    xj = np.concatenate([[0.0], joints(60.0)])
    begin, end = xj[:-1] + np.where(xj[:-1] > 0, W, 0.0), xj[1:]
    for a, b in zip(begin, end):
        inner = road.distance_m[(road.distance_m >= a) & (road.distance_m <= b)]
        s = (inner - a) / (b - a)
        np.testing.assert_allclose(road.elevation_at(inner)[:, 0], curl * (2 * s - 1) ** 2,
                                   atol=1e-12)
        np.testing.assert_allclose(road.elevation_at(inner)[:, 1], curl * (2 * s - 1) ** 2,
                                   atol=1e-12)


def test_the_seed_gives_one_road():
    a = jpcp_profile(150.0, seed=5)
    b = jpcp_profile(150.0, seed=5)
    c = jpcp_profile(150.0, seed=6)
    np.testing.assert_array_equal(a.distance_m, b.distance_m)
    np.testing.assert_array_equal(a.elevation_m, b.elevation_m)
    assert not np.allclose(a.elevation_m, c.elevation_m)


def test_roughness_is_an_iso_road_underneath():
    """The rough road is the smooth one plus the ISO 8608 road of the seed's first draw (the
    module notes), and the joints are the same with or without it."""
    rough = jpcp_profile(800.0, roughness='A', seed=4)
    smooth = jpcp_profile(800.0, roughness=None, seed=4)
    np.testing.assert_array_equal(rough.distance_m, smooth.distance_m)
    iso = iso8608_profile('A', 800.0, seed=int(np.random.default_rng(4).integers(2**31)),
                          dx_m=0.05)
    np.testing.assert_allclose(rough.elevation_m - smooth.elevation_m,
                               iso.elevation_at(smooth.distance_m), atol=1e-15)


def test_source_string_through_road_from_source():
    a = road_files.road_from_source('jpcp:joint_spacing=5:faulting=1e-3:curl=0:roughness=none:'
                                    'seed=2:length=50')
    b = jpcp_profile(50.0, joint_spacing_m=5.0, faulting_m=1e-3, curl_m=0.0, roughness=None,
                     seed=2)
    np.testing.assert_array_equal(a.elevation_m, b.elevation_m)
    assert a.name.startswith('jpcp:joint_spacing=5:faulting=0.001')
    c = bagio.road_from_source('jpcp:seed=3', length_m=40.0)
    assert c.length_m == pytest.approx(40.0)


@pytest.mark.parametrize('text, message', [
    ('jpcp:spacing=4', "unknown option 'spacing'"),
    ('jpcp:faulting=abc', 'is not a number'),
    ('jpcp:seed=1.5', 'is not an integer'),
    ('jpcp:faulting=0.2', 'faulting = 0.2'),
    ('jpcp:roughness=Q', 'road_class'),
    ('jpcp:curl', 'is not name=value'),
])
def test_bad_source_strings_say_what_is_wrong(text, message):
    with pytest.raises(ValueError, match=message) as info:
        jpcp_from_source(text)
    assert '\n' not in str(info.value)


def test_simulate_bag_drives_over_it(tmp_path, capsys):
    from road_force_estimator.tools.simulate_bag import main

    code = main(['--road', 'jpcp:seed=2', '--speed', '20', '--rate', '500', '--duration', '2',
                 '--output', str(tmp_path / 'd')])
    assert code == 0, capsys.readouterr().err
    d = bagio.read_drive_bag(tmp_path / 'd')
    road = jpcp_profile(20.0 * 2 + 2 * 0.25 + 1.0, seed=2)
    tr = simulate(VehicleParameters(), road, speed_mps=20.0, rate_hz=500.0, duration_s=2.0,
                  tire_envelope_m=0.25)
    np.testing.assert_array_equal(d.truth.road_m, tr.road_m)
    np.testing.assert_array_equal(d.truth.wheel_load_n, tr.wheel_load_n)
