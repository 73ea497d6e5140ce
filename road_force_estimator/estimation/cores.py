"""The cores of the estimator, by ``observer.discretization``.

A core estimates one accepted sample at a time for :class:`.Estimator`::

    core = CORES[observer.discretization](vehicle, observer)
    core.reset()                     # forget everything
    core.step(stamp, q1, q2, phi, v, dt, restart, x, t_run, dt_typ) -> bool
                                     # False (state untouched): a non-finite result
    core.finish() -> bool            # release what a latency holds back; True: run ended
    core.fill_status(status)         # its fields of an EstimatorStatus

and has ``ready`` (a deque of final ``(stamp_ns, row)``, rows of :class:`.Column` slots, in
sample order), ``last_row``, ``settling_time_s(dt_typ)`` and ``method``. A new variant is one
module and one line here.
"""
from __future__ import annotations

from road_force_estimator.estimation.chain import ChainCore
from road_force_estimator.estimation.model_core import ModelCore

__all__ = ['CORES']

CORES = {
    'model': ModelCore,
    'euler': ChainCore,
    'taylor': ChainCore,
    'implicit': ChainCore,
}
