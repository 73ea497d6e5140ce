"""Estimation: from (q_1, q_2, phi) samples to wheel loads, road profile and LTR.

Online, one sample at a time: :class:`Estimator` (its batch twin :func:`estimate_batch`, the
same numbers). Offline, the whole recording: :func:`estimate_recording` (what
``estimate_bag --mode offline`` runs): the model observer's RTS smoother :func:`smooth`, or the
zero-phase chain :func:`estimate_offline`. Results: :class:`Estimate`, :class:`EstimateArrays`
(fields named as :class:`Estimate`), :class:`EstimatorStatus`.
"""
from road_force_estimator.estimation.acceptance import GAP_THRESHOLD_S, batch_inputs
from road_force_estimator.estimation.body_heave import SPEED_FLOOR_MPS
from road_force_estimator.estimation.methods import CORES, Core
from road_force_estimator.estimation.chain.differentiator import SCHEMES
from road_force_estimator.estimation.estimator import PROGRESS_BLOCK, Estimator, estimate_batch
from road_force_estimator.estimation.chain.zero_phase import (
    OfflineEstimateArrays, RunInfo, estimate_offline)
from road_force_estimator.estimation.offline import estimate_recording
from road_force_estimator.estimation.outputs import (
    FIELD_COLUMNS, PAIR_FIELDS, SCALAR_FIELDS, Column, Estimate, EstimateArrays,
    EstimatorStatus)
from road_force_estimator.estimation.reconstruction import LIFT_OFF_FRACTION, LTR_FLOOR_FRACTION
from road_force_estimator.estimation.offline import smooth

__all__ = [
    'Estimator', 'estimate_batch', 'estimate_recording', 'estimate_offline', 'smooth',
    'Estimate', 'EstimateArrays', 'OfflineEstimateArrays', 'RunInfo', 'EstimatorStatus',
    'Column', 'FIELD_COLUMNS', 'PAIR_FIELDS', 'SCALAR_FIELDS', 'CORES', 'Core', 'SCHEMES',
    'GAP_THRESHOLD_S', 'SPEED_FLOOR_MPS', 'LIFT_OFF_FRACTION', 'LTR_FLOOR_FRACTION',
    'PROGRESS_BLOCK', 'batch_inputs',
]
