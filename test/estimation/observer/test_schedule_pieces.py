"""GainSchedule.statistics on rows in a file (core/spill.py SpillRows), taken a piece at a
time: the numbers of the block held whole (numpy's medians and means over the arrays), bit
for bit, on the whole vehicle's 8 s drive (conftest), with and without leaf-spring friction
(the mean of the squared rates), in one piece and in many."""
import numpy as np
import pytest

from road_force_estimator.core.articulated_setup import ArticulatedDrive
from road_force_estimator.core.parameters import ObserverParameters, load_params_file
from road_force_estimator.core.spill import SpillColumn, SpillRows
from road_force_estimator.estimation.observer import schedule
from road_force_estimator.estimation.whole_vehicle import WholeVehicleEstimator

from conftest import ARTICULATED_CONFIG


def _model(friction_n: float):
    values = load_params_file(ARTICULATED_CONFIG)
    values['vehicle.leaf_spring_friction'] = [friction_n, friction_n]
    return WholeVehicleEstimator(ArticulatedDrive.from_values(values).vehicle).online.model


def _state(s: schedule.GainSchedule) -> tuple:
    return (tuple(map(list, s.history)), list(s.dq_history), s.noise_deflection_m,
            s.noise_roll_rad, s.road_gd_m3, s.dq_std_mps, dict(s.levels), s.blocks)


@pytest.mark.parametrize('friction_n', [0.0, 1500.0])
@pytest.mark.parametrize('piece', [1000, 4097, 1 << 16])
def test_statistics_in_pieces_are_the_whole_blocks(articulated_c, tmp_path, monkeypatch,
                                                    friction_n, piece):
    _, _, stamps, y = articulated_c
    dts = np.diff(stamps) * 1e-9
    model = _model(friction_n)
    file = SpillColumn(float, y.shape[1], tmp_path)
    file.append(y)
    whole, spilled = (schedule.GainSchedule(model, ObserverParameters()) for _ in range(2))
    monkeypatch.setattr(schedule, 'PIECE_ROWS', piece)
    for s in (whole, spilled):
        s.set_run(1e-3, 20.0)
    for a, b in ((0, 3001), (2000, y.shape[0])):      # two blocks: the medians of histories
        assert whole.statistics(y[a:b], dts[a:b - 1]) == spilled.statistics(
            SpillRows(file, a, b), dts[a:b - 1])
    assert _state(spilled) == _state(whole)
    assert whole.road_gd_m3 > schedule.MIN_ROAD_GD_M3      # (the roughness is estimated)
    assert whole.friction == (friction_n > 0.0) and len(whole.dq_history) == (
        2 if friction_n else 0)
    file.close()


def test_uneven_steps_in_a_file_are_read_whole(articulated_c, tmp_path):
    """Steps that are not even (divided differences): the block is read whole, the same
    numbers."""
    _, _, stamps, y = articulated_c
    dts = np.diff(stamps) * 1e-9
    dts[::3] *= 1.01
    model = _model(0.0)
    file = SpillColumn(float, y.shape[1], tmp_path)
    file.append(y)
    whole, spilled = (schedule.GainSchedule(model, ObserverParameters()) for _ in range(2))
    for s in (whole, spilled):
        s.set_run(1e-3, 20.0)
    whole.statistics(y, dts)
    spilled.statistics(SpillRows(file), dts)
    assert _state(spilled) == _state(whole)
    file.close()
