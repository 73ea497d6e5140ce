"""The offline estimate of a recording (``estimate_bag --mode offline``): the best non-causal
estimate for the observer's method (:func:`estimate_recording`).

The model observer (``observer.discretization: model``, the default) goes through its forward
filter and RTS smoother (:func:`.smoothing.smoother.smooth`); a differentiator scheme through
the zero-phase chain (:func:`.chain.zero_phase.estimate_offline`). With the distance fused from
GNSS (:func:`fused_speed`) the speed is scaled first.
"""
from __future__ import annotations

import numpy as np

from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
from road_force_estimator.estimation.acceptance import GAP_THRESHOLD_S
from road_force_estimator.estimation.chain.zero_phase import estimate_offline
from road_force_estimator.estimation.smoothing.smoother import smooth

__all__ = ['estimate_recording', 'fused_speed']


def estimate_recording(stamps_ns, q_m, roll_rad, speed_mps,
                       vehicle: VehicleParameters | None = None,
                       observer: ObserverParameters | None = None, *,
                       gap_threshold_s: float = GAP_THRESHOLD_S, fixes=None):
    """The offline mode of ``estimate_bag``: the best non-causal estimate for ``observer``.

    With ``observer.discretization == 'model'`` (the default) the model observer's own
    forward filter and Rauch-Tung-Striebel smoother (:func:`.smoother.smooth`): the
    same model and noise estimates as the online observer, over the whole recording. With a
    differentiator scheme (``euler``, ``taylor``, ``implicit``), the zero-phase chain of
    :func:`estimate_offline`. Row k is the estimate for sample k in both.

    With ``observer.distance_source == 'gnss'`` and ``fixes`` (``stamps_ns``,
    ``latitude_deg``, ``longitude_deg``), the odometer scale is estimated from the fixes
    (:func:`.odometer.fit_odometer`) and the speed multiplied by it (:func:`.odometer.scale_at`)
    before the estimate: the distance is the fused one. The fit (or None: too few fixes) is
    the result's ``odometer`` attribute (a fit with a ``problem`` is reported, not applied);
    without fusion there is no such attribute and the numbers are those without fixes.
    """
    observer = ObserverParameters() if observer is None else observer
    fit = None
    fused = observer.distance_source == 'gnss' and fixes is not None
    if fused:
        speed_mps, fit = fused_speed(stamps_ns, speed_mps, fixes)
    if observer.discretization == 'model':
        est = smooth(stamps_ns, q_m, roll_rad, speed_mps, vehicle, observer,
                     gap_threshold_s=gap_threshold_s)
    else:
        est = estimate_offline(stamps_ns, q_m, roll_rad, speed_mps, vehicle, observer,
                               gap_threshold_s=gap_threshold_s)
    if fused:
        est.odometer = fit
    return est


def fused_speed(stamps_ns, speed_mps, fixes):
    """``(speed times the odometer scale, the fit)``; the speed as given when the fixes do
    not make a fit (None) or one to use (its ``problem`` says why)."""
    from road_force_estimator.estimation import odometer

    fit = odometer.fit_odometer(*odometer.odometer_distance(stamps_ns, speed_mps),
                                fixes.stamps_ns, fixes.latitude_deg, fixes.longitude_deg)
    if fit is None or fit.problem:
        return speed_mps, fit
    v = np.broadcast_to(np.asarray(speed_mps, dtype=float), np.shape(stamps_ns))
    return v * odometer.scale_at(stamps_ns, fit), fit
