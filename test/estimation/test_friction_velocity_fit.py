"""The friction's v_f fitted from the drive (estimation.offline.fit_friction_velocity,
observer.friction_velocity_fit; issue 30): the likelihood of the online observer's innovations
picks the plant's v_f from the grid around the file's.

Truth: the plant's tanh friction velocity (core/plant.py, its friction checked against solve_ivp
in test/core/test_friction.py); the file always states 0.01 m/s.
"""
from dataclasses import replace

import numpy as np
import pytest

from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
from road_force_estimator.core.plant import simulate
from road_force_estimator.core.road import iso8608_profile
from road_force_estimator.core.sensors import SensorModel
from road_force_estimator.estimation.offline import fit_friction_velocity

FILE = replace(VehicleParameters(), leaf_spring_friction_n=(1500.0, 1500.0),
               sensor_time_constant_s=(0.003, 0.003))


def _drive(truth_vf: float, road_m: float, duration_s: float, road_seed: int = 4,
           plant_out: list | None = None):
    """The plant's drive at 20 m/s, 1 kHz over class C (``road_seed``) with v_f ``truth_vf``
    (the file's friction and lag otherwise), read by lagging noisy sensors: (stamps ns, q,
    phi); ``plant_out``: the plant's trace appended."""
    plant = replace(FILE, leaf_spring_friction_velocity_mps=truth_vf)
    tr = simulate(plant, iso8608_profile('C', road_m, seed=road_seed), speed_mps=20.0,
                  rate_hz=1000.0, duration_s=duration_s, tire_envelope_m=0.25)
    if plant_out is not None:
        plant_out.append(tr)
    q, phi = SensorModel(deflection_std_m=1e-5, roll_std_rad=1e-4, seed=5,
                         time_constant_s=plant.sensor_time_constant_s,
                         rate_hz=1000.0).measure(tr.q_m, tr.roll_rad)
    return np.round(tr.t_s * 1e9).astype(np.int64), q, phi


@pytest.mark.parametrize('truth_vf', [0.005, 0.01, 0.02])
def test_the_fit_finds_the_plants_friction_velocity(truth_vf):
    stamps, q, phi = _drive(truth_vf, 300.0, 12.0)
    restart = np.zeros(stamps.size, bool)
    restart[0] = True
    fitted = fit_friction_velocity(FILE, ObserverParameters(), stamps, q, phi,
                                   np.full(stamps.size, 20.0), restart)
    assert fitted.leaf_spring_friction_velocity_mps == pytest.approx(truth_vf)
    off = fit_friction_velocity(FILE, ObserverParameters(friction_velocity_fit=0), stamps,
                                q, phi, np.full(stamps.size, 20.0), restart)
    assert off is FILE


def test_a_file_told_the_truth_stands_where_a_sharper_v_f_leads_by_little():
    """With a 3 ms lag the zero-latency likelihood leans sharper than the truth: on this drive
    (road seed 5, 12 s, the plant's and the file's v_f 0.005) 0.0035 is likeliest, by less
    than FIT_LEAD_NATS, and the file's v_f stands. Against the plant's wheel loads the file's
    v_f gives the smaller offline load error, so standing is the better estimate."""
    from road_force_estimator.estimation import estimate_recording
    from road_force_estimator.estimation.friction_fit import FIT_LEAD_NATS

    told = replace(FILE, leaf_spring_friction_velocity_mps=0.005)
    plant: list = []
    stamps, q, phi = _drive(0.005, 300.0, 12.0, road_seed=5, plant_out=plant)
    speed = np.full(stamps.size, 20.0)
    restart = np.zeros(stamps.size, bool)
    restart[0] = True
    table: list = []
    taken = fit_friction_velocity(told, ObserverParameters(), stamps, q, phi, speed, restart,
                                  table)
    nll = {row[0]: row[3] for row in table}
    likeliest = min(nll, key=nll.get)
    assert likeliest == pytest.approx(0.0035)           # the lean this test is about
    assert 0.0 < nll[0.005] - nll[likeliest] < FIT_LEAD_NATS
    assert taken.leaf_spring_friction_velocity_mps == 0.005
    truth = np.asarray(plant[0].wheel_load_n)
    skip = 2000                                          # the first 2 s: settling

    def error(v_f: float) -> float:
        est = estimate_recording(stamps, q, phi, speed,
                                 replace(FILE, leaf_spring_friction_velocity_mps=v_f),
                                 ObserverParameters(friction_velocity_fit=0))
        return float(np.sqrt(np.mean((np.asarray(est.wheel_load_n)[skip:]
                                      - truth[skip:]) ** 2)))

    assert error(0.005) < error(likeliest)


def test_the_fits_runs_make_no_rows_and_the_same_innovations():
    """The fit's runs (BatchRun(rows=False): no output row made) give each v_f's innovation
    terms bit for bit as runs that make every row (the reference: BatchRun as it was), so the
    same v_f; on a plant drive with tanh friction and a sensor lag (v_f 0.005, the file's
    0.01), 6 s."""
    from road_force_estimator.estimation.estimator import BatchRun
    from road_force_estimator.estimation.friction_fit import FIT_GRID, likeliest_velocity

    stamps, q, phi = _drive(0.005, 200.0, 6.0)
    speed = np.full(stamps.size, 20.0)
    obs = ObserverParameters()

    def terms(v_f: float, rows: bool) -> list:
        run = BatchRun(replace(FILE, leaf_spring_friction_velocity_mps=v_f), obs, rows=rows)
        out = run.estimator.core.nll_terms = []
        valid, _, made = run.feed(stamps, q, phi, speed)
        assert valid.all()
        assert made.shape[0] == (stamps.size if rows else 0)
        return out

    for factor in (FIT_GRID[0], FIT_GRID[-1]):
        with_rows, without = terms(0.01 * factor, True), terms(0.01 * factor, False)
        assert len(with_rows) > 1000
        assert without == with_rows              # (index, nats): the same floats
    reference = likeliest_velocity(0.01, lambda v_f: terms(v_f, True))
    restart = np.zeros(stamps.size, bool)
    restart[0] = True
    fitted = fit_friction_velocity(FILE, obs, stamps, q, phi, speed, restart)
    assert fitted.leaf_spring_friction_velocity_mps == reference


def test_no_rows_is_the_model_cores_only():
    """rows=False on a core that always makes its rows (the differentiator chain) refuses."""
    from road_force_estimator.estimation.estimator import BatchRun

    with pytest.raises(ValueError, match='model core'):
        BatchRun(FILE, ObserverParameters(discretization='euler'), rows=False)
