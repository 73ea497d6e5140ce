"""The whole vehicle's status in estimate_bag's ``/diagnostics`` (pipeline/whole_vehicle.py)
carries the model fit per axle known at each status: offline the drive's verdict at every
status; online (``observer.latency``, :class:`.estimation.axle_fit.OnlineAxleFit`) nothing
before the first verdict and then the last verdict completed at or before the status's
stamp, as the node's ``/diagnostics`` does. The verdicts here come from analytic roads (one
wheel reading the road 10 % larger: that sensor named)."""
from dataclasses import replace
from pathlib import Path

import numpy as np

from road_force_estimator.core.articulated_setup import ArticulatedDrive
from road_force_estimator.core.parameters import load_params_file
from road_force_estimator.estimation.axle_fit import assess_axles
from road_force_estimator.estimation.whole_vehicle import estimate_whole_vehicle
from road_force_estimator.pipeline.whole_vehicle import add_diagnostics

CONFIG = Path(__file__).resolve().parents[2] / 'config' / 'tractor_semitrailer.yaml'


def verdict(scale: float):
    """The verdict over analytic roads (400 m), trailer_2's left wheel ``scale`` times the
    road."""
    rng = np.random.default_rng(5)
    t = np.arange(20001) * 1e-3
    x = 20.0 * t
    xi = np.array([0.0, 3.7, 9.6, 10.91, 12.22])
    waves = rng.uniform(0.7, 20.0, size=(2, 40))
    phase = rng.uniform(0.0, 2.0 * np.pi, size=(2, 40))
    road = np.array([1e-3 * np.sin(2.0 * np.pi * (x - xi[j])[:, None] / waves[s]
                                   + phase[s]).sum(axis=1) for j in range(5) for s in (0, 1)])
    road[6] *= scale
    load = np.full_like(road, 4e4)
    return assess_axles(np.round(t * 1e9).astype(np.int64), x, road, load, load, xi,
                        ('front', 'drive', 'trailer_1', 'trailer_2', 'trailer_3'))


def test_online_statuses_carry_the_last_verdict_known_at_their_stamp():
    vehicle = ArticulatedDrive.from_values(load_params_file(CONFIG)).vehicle
    stamps = np.arange(3001, dtype=np.int64) * 1_000_000
    wv = estimate_whole_vehicle(vehicle, stamps, np.zeros((stamps.size, 12)), 20.0)
    good, bad = verdict(1.0), verdict(1.1)
    assert good.culprits == () and bad.culprits == ('trailer_2_left_suspension',)
    online = replace(wv, axle_fits=((1_000_000_000, good), (2_000_000_000, bad)),
                     axle_fit=bad)
    diagnostics = [(s, []) for s in (500_000_000, 1_500_000_000, 2_500_000_000)]
    got = [statuses[-1] for _, statuses in add_diagnostics(diagnostics, online)]
    assert 'model_fit' not in got[0]['values'] and got[0]['level'] == 0
    assert got[1]['values']['model_fit'] == 'ok' and got[1]['level'] == 0
    assert got[2]['values']['model_fit'] == 'mismatch' and got[2]['level'] == 1
    assert got[2]['values']['model_fit_culprits'] == 'trailer_2_left_suspension'
    assert 'trailer_2_left_suspension' in got[2]['message']
    offline = replace(wv, axle_fit=bad)          # no history: the drive's verdict throughout
    for _, statuses in add_diagnostics(diagnostics, offline):
        assert statuses[-1]['values']['model_fit'] == 'mismatch'


def test_a_predicted_ltr_past_the_threshold_warns_in_its_period():
    """The trailer's quasi-static LTR a ramp 0.3 /s from 0.3 at 0 s (0.6 at 1.0 s): its
    predicted LTR (5 ms ahead: 0.0015 more) reaches 0.6 at 0.995 s, so the status at 1.0 s
    warns naming the trailer and the one at 0.5 s does not; the period's peak is the
    prediction's (analytic)."""
    from road_force_estimator.estimation.rollover_warning import (
        LEAD_S, WARNING_THRESHOLD, LtrPredictor)

    vehicle = ArticulatedDrive.from_values(load_params_file(CONFIG)).vehicle
    stamps = np.arange(1101, dtype=np.int64) * 1_000_000
    wv = estimate_whole_vehicle(vehicle, stamps, np.zeros((stamps.size, 12)), 20.0)
    t = stamps * 1e-9
    qs = np.zeros((3, t.size))
    qs[1] = 0.3 + 0.3 * t
    ramp = replace(wv, ltr_quasi_static=qs)
    got = [s[-1] for _, s in add_diagnostics([(500_000_000, []), (1_000_000_000, [])], ramp)]
    assert got[0]['level'] == 0 and 'rollover' not in got[0]['message']
    assert got[1]['level'] == 1 and 'rollover warning: trailer' in got[1]['message']
    peak = float(got[1]['values']['max_abs_ltr_trailer_predicted'])
    np.testing.assert_allclose(peak, 0.6 + 0.3 * LEAD_S, atol=1e-4)
    assert peak >= WARNING_THRESHOLD > float(got[1]['values']['ltr_trailer_quasi_static']) - 1e-9
    # the per-sample predictor (the node's) gives the same numbers
    p = LtrPredictor()
    np.testing.assert_array_equal(
        np.array([p.update(int(s), qs[:, k]) for k, s in enumerate(stamps)]).T,
        ramp.ltr_predicted)
