"""The model observer (``observer.discretization: model``, the default): a Kalman
unknown-input observer on a vehicle model (:mod:`..models`).

Its design: the discretisation and the Riccati equation (:mod:`.riccati`), the gains and the
fixed-lag smoother's (:mod:`.gains`), the operating point they are designed at and the noise
and roughness statistics (:mod:`.schedule`, :mod:`.noise`), the stamps' clock
(:mod:`.sample_clock`). Online, one sample at a time: :class:`.online.ModelCore`, with the
known friction input (:mod:`.friction`), the sliding-mode injection (:mod:`.sliding_mode`)
and the zero-latency profile filter's road (:mod:`.online_road`). Offline:
:mod:`road_force_estimator.estimation.smoothing`.
"""
from road_force_estimator.estimation.observer.online import ModelCore

__all__ = ['ModelCore']
