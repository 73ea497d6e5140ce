"""Shared data of the model-observer tests (test/estimation/test_model*.py, test_smoother.py,
...): vehicles, a textbook RTS smoother (the drives: test/estimation/conftest.py)."""
import numpy as np

from road_force_estimator.core import metrics
from road_force_estimator.core.parameters import VehicleParameters

VEHICLE = VehicleParameters()
# Asymmetric, with tire damping, so that index and sign slips show.
ASYM = VehicleParameters(
    sprung_mass_kg=5200.0, roll_inertia_kgm2=2800.0, track_width_m=2.1, cg_height_m=0.7,
    unsprung_mass_kg=(430.0, 470.0), suspension_stiffness_npm=(380e3, 420e3),
    suspension_damping_nspm=(14e3, 16e3), tire_stiffness_npm=(950e3, 1050e3),
    tire_damping_nspm=(1500.0, 2500.0))
SPEED = 20.0
# Known noise and roughness: constant gains (for the exactness checks).
FIXED = dict(noise_deflection_m=1e-5, noise_roll_rad=1e-4, road_roughness_m3=256e-6,
             sliding_mode_gain=0.0)



def to_stamps(t_s):
    return np.round(np.asarray(t_s) * 1e9).astype(np.int64)


def load_pct(est_load, truth, mask):
    err = metrics.load_errors(est_load, truth.wheel_load_n, VEHICLE.static_load_n, mask=mask)
    return float(np.sqrt(np.mean(err.rms ** 2)) / np.sqrt(np.mean(err.reference_rms ** 2))
                 * 100.0)


def rts_reference(gains, y, x0):
    """Textbook Kalman filter (constant gain, steady-state covariances as the prior) and
    Rauch-Tung-Striebel smoother: x_k|n = x_k|k + G (x_k+1|n - A x_k|k), G = P+ A^T P-^-1."""
    a, c, k = gains.a, gains.model.c, gains.k
    p_post = gains.p_post
    p_prior = a @ p_post @ a.T + gains.q
    g = p_post @ a.T @ np.linalg.inv(p_prior)
    xf = np.empty((len(y), 12))
    xf[0] = x0
    for i in range(1, len(y)):
        xp = a @ xf[i - 1]
        xf[i] = xp + k @ (y[i] - c @ xp)
    xs = xf.copy()
    for i in range(len(y) - 2, -1, -1):
        xs[i] = xf[i] + g @ (xs[i + 1] - a @ xf[i])
    return xs

