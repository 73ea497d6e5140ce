"""The leaf-spring friction as a known input of the model core (:mod:`.model_core`): the
forces over a step (held, Heun's trapezoid, one iterated update) and their direct part in the
outputs.

The gains' linear model carries the friction's equivalent damping ``c_eq,i``
(:func:`.model.friction_damping`); the known input is the rest, ``-F_f,i tanh(dq_i / v_f) +
c_eq,i dq_i`` (README, "Friction").
"""
from __future__ import annotations

import math

import numpy as np

from road_force_estimator.core.vehicle_model import FRICTION_VELOCITY_MPS
from road_force_estimator.estimation.observer.gains import Gains
from road_force_estimator.estimation.models.front_axle import State

__all__ = ['KnownFriction', 'dq_rows']

_dot = np.dot     # (a little faster than the @ operator on small arrays)


def dq_rows(g: Gains, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """The rows of dq_1, dq_2 of the transition A(dt) (2, nx) and of the friction input
    B_d(dt) (2, 2)."""
    rows = [State.DQ1, State.DQ2]
    return g.transition(dt)[rows], g.friction_input(dt)[rows]


class KnownFriction:
    """The friction's known input of one model (:func:`.model.continuous_model`: its
    ``friction_n`` F_f,i (N), not all zero, and ``friction_d``, the outputs' direct part per
    newton).

    :meth:`select` takes the matrices of a step of the gains in use; :meth:`update` adds
    the friction over that step to the step's product; :meth:`add_direct` adds its direct
    part to the outputs of an estimate.
    """

    def __init__(self, model) -> None:
        self.ff = model.friction_n
        self.ceq = (0.0, 0.0)       # its equivalent damping in the gains in use (N s/m)
        d = model.friction_d
        # the outputs' rows with a non-zero direct part: (row, per F_1, per F_2)
        self.fd = [(j, float(d[j, 0]), float(d[j, 1])) for j in range(d.shape[0])
                   if d[j, 0] != 0.0 or d[j, 1] != 0.0]
        self.fm = self.a_dq = self.b_dq = None

    def select(self, g: Gains, dt: float) -> None:
        """The step of dt (s) with the gains ``g``: :meth:`.Gains.friction_step`, the dq rows
        (:func:`dq_rows`) and the equivalent damping of g's model."""
        self.fm = g.friction_step(dt)
        self.a_dq, self.b_dq = dq_rows(g, dt)
        self.ceq = g.model.friction_damping_nspm

    def update(self, sv: np.ndarray, x: np.ndarray) -> np.ndarray:
        """``sv`` (the step without friction) with the friction held over the step from
        x+_k = ``x``: that of :meth:`held` (end rate predicted), then once more with the end
        rate of that update's x+_(k+1) (one iterated update; README, "Friction"); a new
        array."""
        fm = self.fm
        first = sv + _dot(fm, self.held(x))
        f0 = self.force(x[State.DQ1], x[State.DQ2])
        return sv + _dot(fm, 0.5 * (f0 + self.force(first[State.DQ1], first[State.DQ2])))

    def held(self, x: np.ndarray) -> np.ndarray:
        """The friction forces (N) held over a step from the state x: the mean of those at
        its start and at its predicted end (Heun's trapezoid: the friction is stiff, a wheel
        time constant ``m_i v_f / F_f`` of ~3 ms against the 1 ms step)."""
        f0 = self.force(x[State.DQ1], x[State.DQ2])
        dq = _dot(self.a_dq, x) + _dot(self.b_dq, f0)
        return 0.5 * (f0 + self.force(dq[0], dq[1]))

    def force(self, dq1: float, dq2: float) -> np.ndarray:
        """The known friction input (N) at the rates dq_i (m/s): ``-F_f,i tanh(dq_i / v_f)``
        less the equivalent damping's share ``-c_eq,i dq_i`` that the gains' linear model
        carries (:func:`.model.friction_damping`)."""
        f1, f2 = self.ff
        d1, d2 = self.ceq
        return np.array([-f1 * math.tanh(dq1 / FRICTION_VELOCITY_MPS) + d1 * dq1,
                         -f2 * math.tanh(dq2 / FRICTION_VELOCITY_MPS) + d2 * dq2])

    def add_direct(self, o: list) -> None:
        """Add the friction's direct part to the outputs ``o`` (:data:`.OUTPUTS`, in place),
        the forces at its rates ``o[3]``, ``o[4]`` (dq_1, dq_2)."""
        f1, f2 = self.force(o[3], o[4]).tolist()
        for j, d1, d2 in self.fd:
            o[j] += d1 * f1 + d2 * f2
