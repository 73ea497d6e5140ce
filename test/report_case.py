"""A synthetic estimated drive with a known truth, for the report tests (test/report/).

The truth is an ISO class C road and sinusoidal loads; the estimate = truth + known errors (a
constant load offset, a sine on the profile, an LTR offset); optional GNSS fixes along a
meridian and a drive starting some distance into the road.
"""
from types import SimpleNamespace

import numpy as np

from road_force_estimator.bagio import Fixes, GroundTruth
from road_force_estimator.estimation import EstimateArrays, EstimatorStatus
from road_force_estimator.core.parameters import VehicleParameters
from road_force_estimator.core.road import iso8608_profile

VEHICLE = VehicleParameters()
RATE = 500.0
SPEED = 20.0


def make_case(n=15000, load_offset=(100.0, -200.0), with_truth=True, fixes=False,
              road_start_m=0.0):
    """A drive of n samples at 500 Hz and 20 m/s (600 m for n = 15000): the truth is an ISO
    class C road and sinusoidal loads; the estimate = truth + known errors."""
    t = np.arange(n) / RATE
    x = SPEED * t
    road = iso8608_profile('C', x[-1] + road_start_m + 1.0, seed=4, dx_m=0.04)
    true_road = road.elevation_at(road_start_m + x)
    fc = np.asarray(VEHICLE.static_load_n)
    dyn = np.column_stack([3000.0 * np.sin(2 * np.pi * 2.0 * t),
                           4000.0 * np.cos(2 * np.pi * 3.0 * t)])
    true_load = fc + dyn
    est_load = true_load + np.asarray(load_offset)
    # Profile error: a 5 m sine of 0.2 mm on the left only (inside the 0.5-30 m band).
    est_road = true_road + np.column_stack([2e-4 * np.sin(2 * np.pi * x / 5.0), np.zeros(n)])
    ltr = (est_load[:, 1] - est_load[:, 0]) / est_load.sum(axis=1)
    zeros, pair = np.zeros(n), np.zeros((n, 2))
    lift = np.zeros((n, 2), bool)
    lift[1000:1010, 0] = True          # one lift-off event of 10 samples in the first segment
    lift[8000:8003, 1] = True          # and one in the fifth
    stamps = 10**18 + np.round(t * 1e9).astype(np.int64)
    conv = t >= 0.2
    est = EstimateArrays(
        stamp_ns=stamps, valid=np.ones(n, bool), distance_m=x, q_m=pair, dq=pair, ddq=pair,
        roll_rad=zeros, droll=zeros, ddroll=zeros, body_heave_m=zeros, body_heave_rate=zeros,
        body_accel_mps2=zeros, wheel_heave_m=pair, wheel_heave_rate=pair,
        wheel_accel_mps2=pair, road_m=est_road, tire_force_dynamic_n=est_load - fc,
        wheel_load_n=est_load, ltr=ltr, residual_nm=zeros, lift_off=lift, converged=conv,
        ltr_quasi_static=ltr,
        status=EstimatorStatus(accepted=n, settling_time_s=0.2))
    truth = GroundTruth(stamps, true_load, true_road, x) if with_truth else None
    fx = None
    if fixes:
        k = np.arange(0, n, 50)
        fx = Fixes(stamps[k], 48.0 + 1e-5 * x[k], np.full(k.size, 17.0), np.zeros(k.size))
    drive = SimpleNamespace(
        truth=truth, fixes=fx, q_m=pair, roll_rad=zeros,
        messages={'/suspension/deflections': n + 3},
        rejected={'/suspension/deflections': {'nonfinite': 2, 'duplicate_stamp': 1}},
        issues=('bag_0.mcap: the file ends inside a chunk',))
    return est, drive, road
