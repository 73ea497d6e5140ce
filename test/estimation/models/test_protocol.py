"""The model protocol: a vehicle the observer's code has never seen (the test-only quarter car
of quarter_car.py) goes through the same online observer, fixed-lag smoother and offline
smoother as the front axle, against a truth simulated here with scipy's solve_ivp from the
quarter car's equations written out again (not the model's matrices)."""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from quarter_car import DIST, RDF, RU, QuarterCar, QuarterCarModel
from road_force_estimator.core.parameters import ObserverParameters
from road_force_estimator.estimation.observer.online import ModelCore
from road_force_estimator.estimation.smoothing.smoother import Smoother

RATE = 1000.0
SPEED = 20.0
DURATION = 12.0
NOISE_M = 1e-5
SETTLE_S = 3.0


def _road(seed: int = 5):
    """A random road of cosines, 0.3-60 m waves, amplitudes of ISO 8608 class C (Gd(n0) =
    256e-6 m^3 at n0 = 0.1 / m): u(x) and du/dx, analytic (solve_ivp needs no interpolation)."""
    rng = np.random.default_rng(seed)
    n = np.geomspace(1.0 / 60.0, 1.0 / 0.3, 400)
    dn = np.gradient(n)
    amp = np.sqrt(2.0 * 256e-6 * (n / 0.1) ** -2.0 * dn)
    phase = rng.uniform(0.0, 2.0 * math.pi, n.size)
    k = 2.0 * math.pi * n

    def u(x):
        return np.cos(np.multiply.outer(x, k) + phase) @ amp

    return u


@pytest.fixture(scope='module')
def drive():
    """The quarter car over the road at 20 m/s: ``(t, q measured, true dF)``."""
    p = QuarterCar()
    road = _road()
    big_m, m = p.sprung_mass_kg, p.unsprung_mass_kg
    k, c, kt = p.suspension_stiffness_npm, p.suspension_damping_nspm, p.tire_stiffness_npm

    def rhs(t, s):
        zs, dzs, zu, dzu = s
        fb = -(k * (zs - zu) + c * (dzs - dzu))        # the spring and damper on the body
        ft = kt * (road(SPEED * t) - zu)               # the dynamic tire force
        return [dzs, fb / big_m, dzu, (-fb + ft) / m]

    u0 = float(road(0.0))
    t = np.arange(int(DURATION * RATE) + 1) / RATE
    sol = solve_ivp(rhs, (0.0, DURATION), [u0, 0.0, u0, 0.0], t_eval=t, rtol=1e-9,
                    atol=1e-12, max_step=2e-3)
    zs, _, zu, _ = sol.y
    q = zs - zu
    df = kt * (road(SPEED * t) - zu)
    rng = np.random.default_rng(6)
    return t, q + rng.normal(0.0, NOISE_M, t.size), df, road(SPEED * t)


def _online(t, q, latency_s: float) -> np.ndarray:
    """The rows of the online observer (the front axle's ModelCore) over the drive."""
    core = ModelCore(QuarterCarModel(), ObserverParameters(latency_s=latency_s))
    rows = []
    x = 0.0
    for i, (ti, qi) in enumerate(zip(t.tolist(), q.tolist())):
        dt = ti - t[i - 1] if i else 0.0
        x += SPEED * dt
        assert core.step(int(round(ti * 1e9)), (qi,), SPEED, dt, i == 0, x, ti, dt)
        rows += [r for _, r in core.ready]
        core.ready.clear()
    core.finish()
    rows += [r for _, r in core.ready]
    return np.array(rows)


def _offline(t, q) -> list:
    """The columns of the offline smoother (the front axle's Smoother) over the drive."""
    smoother = Smoother(QuarterCarModel(), ObserverParameters())
    pieces = list(smoother.pieces(t, q[:, None], np.full(t.size, SPEED)))
    assert len(pieces) == 1 and pieces[0][:2] == (0, t.size)
    return pieces[0][2]


def _load_error_pct(t, est_df, true_df) -> float:
    judged = t >= SETTLE_S
    err = est_df[judged] - true_df[judged]
    return 100.0 * math.sqrt(np.mean(err ** 2)) / math.sqrt(np.mean(true_df[judged] ** 2))


def test_the_quarter_car_runs_through_the_observer_the_fixed_lag_and_the_smoother(drive):
    t, q, true_df, _ = drive
    online = _online(t, q, 0.0)
    lagged = _online(t, q, 0.01)
    offline = _offline(t, q)
    assert online.shape[0] == lagged.shape[0] == t.size       # one row per sample
    np.testing.assert_allclose(online[:, DIST], SPEED * t, rtol=0.0, atol=1e-9)
    errors = [_load_error_pct(t, online[:, RDF], true_df),
              _load_error_pct(t, lagged[:, RDF], true_df),
              _load_error_pct(t, offline[RDF], true_df)]
    # a Kalman filter of an unknown input: the fixed lag and the smoother see the road's
    # effect after the sample, so each does better than the causal estimate before it
    # (measured: 28.5 %, 5.1 %, 4.4 %)
    assert errors[0] < 35.0
    assert errors[1] < 0.3 * errors[0]
    assert errors[2] < errors[1]
    assert errors[2] < 6.0


def test_the_smoothers_road_is_the_true_road_in_the_band(drive):
    """The model's own reconstruction (the road of the profile pass) through the smoother:
    its 0.5-30 m band against the truth's (the same zero-phase band-pass on both)."""
    from road_force_estimator.core import metrics

    t, q, _, true_u = drive
    offline = _offline(t, q)
    x = SPEED * t
    mask = (x > 60.0) & (x < x[-1] - 60.0)
    pe = metrics.profile_errors(x, offline[RU][:, None], true_u[:, None], mask=mask)
    assert float(pe.rms_pct[0]) < 2.0        # (measured: 0.68 %)
