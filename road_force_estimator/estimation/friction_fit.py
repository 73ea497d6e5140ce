"""The tanh leaf-spring friction's ``v_f`` fitted from the drive offline
(``observer.friction_velocity_fit``, issue 30): one rule for the front axle
(:func:`.offline.fit_friction_velocity`) and the whole vehicle
(:func:`.whole_vehicle.fit_friction_velocity`).

The model's online observer at zero latency runs over the first run's first :data:`FIT_S`
seconds once per ``v_f`` of :data:`FIT_GRID` x the file's; the ``v_f`` whose converged
innovations have the least negative log-likelihood (the steady-state Gaussian
``(nu^T S^-1 nu + log det S) / 2`` summed over the samples converged under every ``v_f``,
:attr:`.observer.online.ModelCore.nll_terms`) is the smoother's, where it leads the file's by
:data:`FIT_LEAD_NATS` (else the file's stands). The innovations depend on
``v_f``: the friction is a known input evaluated on the estimated rates, steep near zero
rate (docs/method.md "Offline, v_f fitted from the drive").
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any, Callable, Iterable

import numpy as np

from road_force_estimator.core.parameters import ObserverParameters

__all__ = ['FIT_S', 'FIT_GRID', 'FIT_LEAD_NATS', 'states_friction', 'fits', 'fit_end',
           'likeliest_velocity', 'FrictionVelocity']

#: The seconds of the first run the fit takes, and the v_f tried, relative to the file's.
FIT_S = 20.0
FIT_GRID = (0.5, 0.7, 1.0, 1.4, 2.0)
#: The lead (nats) over the file's ``v_f`` that the likeliest needs to be taken: the file is the
#: null hypothesis, left at a likelihood ratio of e^10. With a sensor lag the zero-latency
#: likelihood leans sharper than the truth (the front axle told the truth's 0.005 m/s on class C
#: drives of 20 s: 0.0035 or 0.0025 ahead by up to 15 nats on 6 of 9 road seeds, over 10 on one;
#: a file wrong by 2 x is behind by 23-67): ``python -m bench.studies.friction_lag --fit-bias``.
FIT_LEAD_NATS = 10.0


def states_friction(friction_model: str, friction_n: Iterable[float]) -> bool:
    """Whether the file states a tanh friction, and so a ``v_f``: the friction law ``tanh``
    and some spring's friction ``friction_n`` (N) not 0."""
    return friction_model == 'tanh' and any(float(f) for f in friction_n)


def fits(observer: ObserverParameters, friction_model: str,
         friction_n: Iterable[float]) -> bool:
    """Whether ``v_f`` is fitted: ``observer.friction_velocity_fit`` set and the file states
    a tanh friction (:func:`states_friction`)."""
    return bool(observer.friction_velocity_fit) and states_friction(friction_model, friction_n)


def fit_end(stamps_ns, run_end: int) -> int:
    """The samples the fit takes, ``[0, fit_end)``: the first run (``run_end``, its end) up to
    :data:`FIT_S` s after the first stamp (``stamps_ns``, ns increasing)."""
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    if stamps.size == 0:
        return 0
    return min(int(run_end), int(np.searchsorted(stamps, stamps[0] + round(FIT_S * 1e9))))


def likeliest_velocity(v_file_mps: float, nll_terms: Callable[[float], list],
                       table: list | None = None) -> float:
    """The ``v_f`` (m/s) of :data:`FIT_GRID` x ``v_file_mps`` whose innovations are likeliest:
    ``nll_terms(v_f)`` each converged sample's ``(index, negative log-likelihood)``
    (:attr:`.observer.online.ModelCore.nll_terms`), summed over the samples converged under
    every ``v_f`` (the settling time depends on ``v_f``, and each sample adds its nll, about
    -125 nats on the whole vehicle (``python -m bench.studies.friction_lag --fit-detail``):
    unequal sets would favour the ``v_f`` that settles first); the first of
    equals; the file's where the likeliest does not lead it by :data:`FIT_LEAD_NATS`, or
    without a sample converged under every ``v_f``. ``table``: a list,
    one ``(v_f, samples converged, samples summed, the sum (nats))`` appended per ``v_f``."""
    terms = [dict(nll_terms(factor * v_file_mps)) for factor in FIT_GRID]
    common = set(terms[0]).intersection(*terms[1:])
    best = (math.inf, v_file_mps)
    file_value = math.inf
    for factor, t in zip(FIT_GRID, terms):
        value = 0.0
        for k in sorted(common):
            value += t[k]
        if table is not None:
            table.append((factor * v_file_mps, len(t), len(common), value))
        if factor == 1.0:
            file_value = value
        if common and value < best[0]:
            best = (value, factor * v_file_mps)
    if not common or file_value - best[0] < FIT_LEAD_NATS:
        return v_file_mps   # (nothing to tell, or not told clearly enough: the file's)
    return best[1]


@dataclass(frozen=True)
class FrictionVelocity:
    """The tanh friction's ``v_f`` an offline estimate took, as its report states it
    (``report.json`` ``friction_velocity``, a line in ``report.md``): ``taken_mps`` (m/s) the
    smoother's, ``file_mps`` the file's (``vehicle.leaf_spring_friction_velocity``),
    ``fitted`` whether the fit ran (:func:`fits`, not under ``zero_load``; it may keep the
    file's), ``reason`` why not ('' when it ran). Its words in the report:
    :func:`road_force_estimator.report.summary.friction_velocity_line`."""

    taken_mps: float
    file_mps: float
    fitted: bool
    reason: str = ''

    @classmethod
    def of(cls, file_mps: float, taken_mps: float, observer: ObserverParameters,
           friction_model: str, friction_n: Iterable[float], zero_load: bool
           ) -> FrictionVelocity | None:
        """The ``v_f`` taken (``taken_mps``, the fit's result: the smoother's vehicle) against
        the file's; None where the file states no tanh friction (:func:`states_friction`)."""
        if not states_friction(friction_model, friction_n):
            return None
        reason = ('observer.friction_velocity_fit is 0' if not observer.friction_velocity_fit
                  else 'under vehicle.zero_load' if zero_load else '')
        return cls(float(taken_mps), float(file_mps), not reason, reason)

    @property
    def changed(self) -> bool:
        """The fit took another ``v_f`` than the file's."""
        return self.taken_mps != self.file_mps

    def as_dict(self) -> dict[str, Any]:
        """``report.json``'s ``friction_velocity``: ``taken_mps``, ``file_mps``, ``fitted``,
        ``changed``, ``reason``."""
        return {'taken_mps': self.taken_mps, 'file_mps': self.file_mps, 'fitted': self.fitted,
                'changed': self.changed, 'reason': self.reason}
