"""The cores of the estimator, by ``observer.discretization`` (:data:`CORES`).

A core estimates one accepted sample at a time for :class:`.Estimator` (which validates the
samples, keeps the distance and the clock, and makes the estimates); it keeps the
:class:`Core` protocol. A new variant is one module and one line in :data:`CORES`.
"""
from __future__ import annotations

from collections import deque
from typing import Protocol

from road_force_estimator.estimation.chain.core import ChainCore
from road_force_estimator.estimation.observer.online import ModelCore

__all__ = ['Core', 'CORES']


class Core(Protocol):
    """What :class:`.Estimator` needs of a core (``core = CORES[name](model, observer)``, the
    model a :class:`.models.protocol.VehicleModel`).

    ``ready`` holds the final ``(stamp_ns, row)`` (rows of :class:`.Column` slots) in sample
    order; ``last_row`` is the newest row made, ``last_converged`` the converged flag of the
    newest sample; ``method`` names it in :class:`.EstimatorStatus`.
    """

    method: str
    ready: deque
    last_row: tuple | None
    last_converged: bool

    def reset(self) -> None:
        """Forget everything; the next step is a restart."""

    def step(self, stamp: int, y: tuple, v: float, dt: float, restart: bool, x: float,
             t_run: float, dt_typ: float) -> bool:
        """One accepted sample ``y`` (the model's channels) at the speed v (m/s) after a step
        dt (s); ``restart``: the first
        of a run; ``x`` distance (m), ``t_run`` time since the (re)start (s), ``dt_typ`` the
        typical step (s). False, state untouched, on a non-finite result."""

    def finish(self) -> bool:
        """Release what a latency holds back (end of data); True if the run ended."""

    def fill_status(self, status) -> None:
        """The core's fields of an :class:`.EstimatorStatus`."""

    def settling_time_s(self, dt_typ: float) -> float:
        """Time after a (re)start after which the estimate counts as converged (s)."""

    def set_vehicle(self, vehicle) -> None:
        """Take ``vehicle`` (a new sprung mass and static loads: :mod:`.static_load`) from the
        next sample on; the model designs its gains again."""

    def set_static_loads(self, *static_n: float) -> None:
        """The static wheel loads F_c,i (N) of the rows made from now on."""


#: The core of each ``observer.discretization``.
CORES: dict[str, type] = {
    'model': ModelCore,
    'euler': ChainCore,
    'taylor': ChainCore,
    'implicit': ChainCore,
    'filtering': ChainCore,
}
