"""The calibration's drive grid and survey check."""
import numpy as np
import pytest

from road_force_estimator.core.road import RoadProfile
from road_force_estimator.calibration.fit import (
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


def test_optional_parameters_join_once_the_table_has_them():
    from road_force_estimator.core.parameters import SPECS, ParameterSpec
    from road_force_estimator.calibration.model import OPTIONAL, optional_slots

    names = [name for name, _, _ in OPTIONAL]
    assert optional_slots() == tuple(optional_slots(SPECS))
    fake = {'vehicle.leaf_spring_friction': ParameterSpec(
        'vehicle.leaf_spring_friction', 'double_pair', [0.0, 0.0], 'N', '')}
    slots = optional_slots(fake)
    assert [s.label for s in slots] == ['vehicle.leaf_spring_friction[left]',
                                        'vehicle.leaf_spring_friction[right]']
    assert all(s.plant_only and s.kind == 'scale' for s in slots)
    assert names == ['vehicle.leaf_spring_friction', 'vehicle.sensor_time_constant',
                     'vehicle.leaf_spring_friction_velocity']


def test_a_parameter_only_the_plant_sees_is_fitted_through_its_defect(monkeypatch):
    """The linear model made blind to the CG height (as it is to a friction or a sensor lag
    the plant has): its Jacobian column comes from the plant's defect, and the fit of a
    noise-free plant drive recovers it; without the plant, the column is zero (held)."""
    import dataclasses

    from road_force_estimator.core.parameters import VehicleParameters
    from road_force_estimator.core.plant import simulate
    from road_force_estimator.core.road_files import road_from_source
    from road_force_estimator.calibration import fit as calibration_fit, model as calibration_model
    from road_force_estimator.calibration.alignment import Alignment
    from road_force_estimator.calibration.model import SLOTS, slot_value

    truck = VehicleParameters(cg_height_m=1.1)
    nominal = VehicleParameters(cg_height_m=0.9)
    road = road_from_source('iso8608:C:seed=7', length_m=300.0)
    traj = simulate(truck, road, speed_mps=20.0, rate_hz=200.0, duration_s=8.0,
                    tire_envelope_m=0.25, start_m=30.0)
    grid = drive_grid(np.rint(traj.t_s * 1e9).astype(np.int64), traj.q_m, traj.roll_rad,
                      np.full(traj.t_s.size, 20.0))
    blind = calibration_model.linear_plant

    def linear_without_h(vehicle):
        return blind(dataclasses.replace(vehicle, cg_height_m=0.9))

    monkeypatch.setattr(calibration_model, 'linear_plant', linear_without_h)
    monkeypatch.setattr(calibration_fit, 'linear_plant', linear_without_h)
    h = next(s for s in SLOTS if s.name == 'vehicle.cg_height_above_roll_axis')
    fixed = {s: slot_value(truck, s) for s in SLOTS if s.physical and s != h}
    alignment = Alignment(30.0, 1.0, 1.0, 0.0, (0.0, 0.0), (1.0, 1.0), 1)
    road_env = road.enveloped(0.25)

    def problem(slot):
        return calibration_fit.FitProblem(grid, road_env, nominal, alignment, [slot], fixed,
                                          0, grid.good.size, 0)

    assert calibration_fit.structural(problem(h), np.zeros(1)) == {h}
    only = dataclasses.replace(h, plant_only=True)
    fit = problem(only)
    result, _ = calibration_fit.solve_with_plant(fit, np.zeros(1), None)
    assert 0.9 * np.exp(result.x[0]) == pytest.approx(1.1, rel=1e-4)
