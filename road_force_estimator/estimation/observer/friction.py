"""The leaf-spring friction as a known input of the model core (:mod:`.online`): the forces
over a step (held, Heun's trapezoid, one iterated update) and their direct part in the
outputs.

The vehicle model says which states and outputs are the friction elements' rates
(``friction_rate_states``, ``friction_rate_outputs``) and gives the law
(:meth:`.VehicleModel.friction_forces`); the gains' linear model carries the friction's
equivalent damping ``c_eq,i`` (:meth:`.VehicleModel.friction_damping`), and the known input
is the rest, e.g. ``-F_f,i tanh(dq_i / v_f) + c_eq,i dq_i``.
"""
from __future__ import annotations

import numpy as np

from road_force_estimator.estimation.models.protocol import VehicleModel
from road_force_estimator.estimation.observer.gains import Gains

__all__ = ['KnownFriction', 'dq_rows']

_dot = np.dot     # (a little faster than the @ operator on small arrays)


def dq_rows(g: Gains, dt: float, rates: tuple) -> tuple[np.ndarray, np.ndarray]:
    """The rows of the friction elements' rates (the states ``rates``) of the transition A(dt)
    (nf, nx) and of the friction input B_d(dt) (nf, nf)."""
    rows = list(rates)
    return g.transition(dt)[rows], g.friction_input(dt)[rows]


class KnownFriction:
    """The friction's known input of one vehicle model (its continuous model's
    ``friction_n`` F_f,i (N), not all zero, and ``friction_d``, the outputs' direct part per
    newton).

    :meth:`select` takes the matrices of a step of the gains in use; :meth:`update` adds
    the friction over that step to the step's product; :meth:`add_direct` adds its direct
    part to the outputs of an estimate.
    """

    def __init__(self, vehicle_model: VehicleModel, model) -> None:
        self.law = vehicle_model.friction_forces
        self.rates = vehicle_model.friction_rate_states
        self.rate_outputs = vehicle_model.friction_rate_outputs
        self.ceq = (0.0,) * len(model.friction_n)   # its equivalent damping in the gains in use
        d = model.friction_d
        # the outputs' rows with a non-zero direct part: (row, per newton of each element)
        self.fd = [(j, *(float(e) for e in d[j])) for j in range(d.shape[0]) if d[j].any()]
        self.fm = self.a_dq = self.b_dq = None

    def select(self, g: Gains, dt: float) -> None:
        """The step of dt (s) with the gains ``g``: :meth:`.Gains.friction_step`, the dq rows
        (:func:`dq_rows`) and the equivalent damping of g's model."""
        self.fm = g.friction_step(dt)
        self.a_dq, self.b_dq = dq_rows(g, dt, self.rates)
        self.ceq = g.model.friction_damping_nspm

    def update(self, sv: np.ndarray, x: np.ndarray) -> np.ndarray:
        """``sv`` (the step without friction) with the friction held over the step from
        x+_k = ``x``: that of :meth:`held` (end rate predicted), then once more with the end
        rate of that update's x+_(k+1) (one iterated update; README, "Friction"); a new
        array."""
        fm = self.fm
        first = sv + _dot(fm, self.held(x))
        f0 = self.force(x[list(self.rates)])
        return sv + _dot(fm, 0.5 * (f0 + self.force(first[list(self.rates)])))

    def held(self, x: np.ndarray) -> np.ndarray:
        """The friction forces (N) held over a step from the state x: the mean of those at
        its start and at its predicted end (Heun's trapezoid: the friction is stiff, a wheel
        time constant ``m_i v_f / F_f`` of ~3 ms against the 1 ms step)."""
        f0 = self.force(x[list(self.rates)])
        dq = _dot(self.a_dq, x) + _dot(self.b_dq, f0)
        return 0.5 * (f0 + self.force(dq))

    def force(self, dq) -> np.ndarray:
        """The known friction input (N) at the elements' rates dq (m/s): the model's law
        less the equivalent damping's share that the gains' linear model carries."""
        return self.law(dq, self.ceq)

    def add_direct(self, o: list) -> None:
        """Add the friction's direct part to the outputs ``o`` (the model's outputs, in place),
        the forces at the elements' rates among them."""
        f = self.force([o[j] for j in self.rate_outputs]).tolist()
        for j, *d in self.fd:
            o[j] += sum(dk * fk for dk, fk in zip(d, f))
