"""Calibration: the vehicle's parameters from a drive over a surveyed road (MODEL.md,
"Calibration from a drive over a known road"), a product of its own beside the estimation.

:func:`calibrate` (:mod:`.calibrate`) aligns the drive with the survey (:mod:`.alignment`),
fits the plant's model to the measured deflections and roll (:mod:`.fit`, the model's free
slots: :mod:`.models.front_axle`) and gives each value a confidence interval (:mod:`.covariance`).
``calibrate_vehicle`` is its command; :mod:`road_force_estimator.report.calibration` its
report.
"""
from road_force_estimator.calibration.calibrate import (
    AlignmentError, CalibrationError, CalibrationOptions, CalibrationResult, ParameterEstimate,
    calibrate)

__all__ = ['calibrate', 'CalibrationOptions', 'CalibrationResult', 'ParameterEstimate',
           'CalibrationError', 'AlignmentError']
