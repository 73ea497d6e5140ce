"""pipeline.plan: the one place that decides whether a drive goes in blocks."""
import dataclasses

import pytest

from road_force_estimator import bagio
from road_force_estimator.core.parameters import ObserverParameters
from road_force_estimator.pipeline import plan

from bag_samples import make_trajectory


def test_the_threshold_follows_the_memory_limit():
    """No limit: STREAM_MIN_SAMPLES; a limit: half of it at ONE_BLOCK_BYTES_PER_SAMPLE."""
    assert plan.stream_threshold() == plan.STREAM_MIN_SAMPLES
    assert plan.stream_threshold(400e6) == int(0.5 * 400e6 / plan.ONE_BLOCK_BYTES_PER_SAMPLE)
    assert plan.stream_threshold(1e15) == plan.STREAM_MIN_SAMPLES
    assert plan.stream_threshold(1.0) == 1
    with pytest.raises(ValueError):
        plan.stream_threshold(0.0)


def test_a_drive_with_truth_goes_in_blocks_from_the_threshold(tmp_path):
    """Ground truth no longer keeps a drive in one block; a memory limit lowers the
    threshold; a reference profile and the offline differentiator chain stay one block."""
    traj, q, roll = make_trajectory(300)
    bagio.write_drive_bag(tmp_path / 'd', traj, q, roll)
    obs = ObserverParameters()
    assert plan.plan_drive(tmp_path / 'd', 'online', obs) == plan.BlockPlan(False, 300)
    assert plan.plan_drive(tmp_path / 'd', 'offline', obs, min_samples=300).blocks
    assert plan.plan_drive(tmp_path / 'd', 'online', obs, memory_limit_bytes=0.5e6).blocks
    assert not plan.plan_drive(tmp_path / 'd', 'online', obs, object(), min_samples=1).blocks
    chain = dataclasses.replace(obs, discretization='implicit')
    assert not plan.plan_drive(tmp_path / 'd', 'offline', chain, min_samples=1).blocks
    assert plan.plan_drive(tmp_path / 'd', 'online', chain, min_samples=1).blocks
    assert not plan.plan_drive(tmp_path / 'missing', 'online', obs, min_samples=1).blocks


def test_the_whole_vehicle_goes_in_pieces_from_the_threshold(tmp_path):
    """With an articulated vehicle (the whole vehicle's stage) a drive below the threshold is
    one block offline (its smoother in windows), from it on in pieces (not with the
    differentiators' chain); online its input is read in blocks and, from the threshold on
    (not below it), the front axle's stage goes in blocks beside it; the same drive with a
    front-axle vehicle goes in blocks."""
    from pathlib import Path

    from road_force_estimator.core.articulated_parameters import ArticulatedParameters
    from road_force_estimator.core.parameters import VehicleParameters, load_params_file

    traj, q, roll = make_trajectory(300)
    bagio.write_drive_bag(tmp_path / 'd', traj, q, roll)
    obs = ObserverParameters()
    config = Path(__file__).resolve().parents[2] / 'config' / 'tractor_semitrailer.yaml'
    whole = ArticulatedParameters.from_parameters(load_params_file(config))
    assert plan.plan_drive(tmp_path / 'd', 'offline', obs, min_samples=301,
                           vehicle=whole) == plan.BlockPlan(False, 300, True, False)
    assert plan.plan_drive(tmp_path / 'd', 'offline', obs, min_samples=300,
                           vehicle=whole) == plan.BlockPlan(True, 300, True, False)
    chain = dataclasses.replace(obs, discretization='implicit')
    assert not plan.plan_drive(tmp_path / 'd', 'offline', chain, min_samples=1,
                               vehicle=whole).blocks
    assert not plan.plan_drive(tmp_path / 'd', 'offline', obs, vehicle=whole,
                               memory_limit_bytes=0.7e6).blocks       # 350 samples
    assert plan.plan_drive(tmp_path / 'd', 'offline', obs, vehicle=whole,
                           memory_limit_bytes=0.6e6).blocks
    assert plan.plan_drive(tmp_path / 'd', 'online', obs, min_samples=300,
                           vehicle=whole) == plan.BlockPlan(True, 300, False, True)
    assert plan.plan_drive(tmp_path / 'd', 'online', obs, min_samples=301,
                           vehicle=whole) == plan.BlockPlan(False, 300, False, True)
    # without a threshold given: the whole vehicle's (lower than the front axle's)
    assert plan.WHOLE_VEHICLE_STREAM_MIN_SAMPLES < plan.STREAM_MIN_SAMPLES
    assert not plan.plan_drive(tmp_path / 'd', 'online', obs, vehicle=whole).blocks
    assert not plan.plan_drive(tmp_path / 'd', 'online', obs, vehicle=whole,
                               memory_limit_bytes=0.7e6).blocks       # 350 samples
    assert plan.plan_drive(tmp_path / 'd', 'online', obs, vehicle=whole,
                           memory_limit_bytes=0.6e6).blocks
    for mode in ('online', 'offline'):
        assert plan.plan_drive(tmp_path / 'd', mode, obs, min_samples=1,
                               vehicle=VehicleParameters()).blocks
