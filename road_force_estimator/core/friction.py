"""Leaf-spring friction laws (MODEL.md "What the model leaves out", "Friction that sticks"):
the one place both plants (front axle and articulated) take them from.

Two laws, chosen by ``vehicle.leaf_spring_friction_model``, each per spring of friction force
F_f (N, ``leaf_spring_friction``) and acting on the body (N, > 0 upward) beside the spring and
the damper:

``tanh``
    ``-F_f tanh(dq / v_f)``: a smooth Coulomb force against the extension rate dq (m/s), with
    the smoothing velocity v_f (``vehicle.leaf_spring_friction_velocity``, m/s). It is zero
    at rest: no stick, no static hysteresis band.
``stick``
    The elastic-plastic (Jenkins) element: a spring k_f (``vehicle.
    leaf_spring_friction_stiffness`` times the suspension stiffness k) in series with a
    Coulomb slider F_f. Its force f follows ``df/dt = k_f dq`` while ``|f| < F_f`` and stays at
    ``+-F_f`` while sliding; the body feels ``-f``. Over a time step in which the extension q
    moves monotonically this is exactly the stop (play) operator
    ``f = clip(f_0 + k_f (q - q_0), -F_f, F_f)``: the plants hold ``base = f_0 - k_f q_0`` per
    spring (:class:`Sliders`), evaluate every Runge-Kutta stage with :func:`stick_force` and
    advance the base once per step (:meth:`Sliders.advance`). Parked or on a smooth road the
    element carries up to ``+-F_f`` that the deflection does not show; a rough road makes it
    slip.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Sequence

import numpy as np

__all__ = ['MODELS', 'FrictionLaw', 'tanh_force', 'tanh_forces', 'stick_force', 'Sliders']

#: The values of ``vehicle.leaf_spring_friction_model``.
MODELS = ('tanh', 'stick')


@dataclass(frozen=True)
class FrictionLaw:
    """The friction law of a vehicle: ``model`` ('tanh' or 'stick'), ``velocity_mps`` (v_f
    of tanh, m/s, > 0) and ``stiffness_ratio`` (k_f / k of stick, > 0)."""

    model: str = 'tanh'
    velocity_mps: float = 0.01
    stiffness_ratio: float = 8.0

    def __post_init__(self) -> None:
        if self.model not in MODELS:
            raise ValueError(f'vehicle.leaf_spring_friction_model = {self.model!r}: must be '
                             f'one of {", ".join(MODELS)}')
        for name, value, unit in (('vehicle.leaf_spring_friction_velocity', self.velocity_mps,
                                   'm/s'),
                                  ('vehicle.leaf_spring_friction_stiffness',
                                   self.stiffness_ratio, '')):
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f'{name} = {value!r} {unit}: must be > 0'.replace('  ', ' '))

    @property
    def sticks(self) -> bool:
        return self.model == 'stick'

    def steepest_damping_nspm(self, friction_n: float) -> float:
        """The largest rate slope of the tanh law, ``F_f / v_f`` (N s/m): an added damping
        that bounds an explicit integrator's step (0 for stick, whose stiffness counts)."""
        return 0.0 if self.sticks else friction_n / self.velocity_mps


def tanh_force(friction_n: float, dq_mps: float, inv_velocity: float) -> float:
    """``-F_f tanh(dq / v_f)`` (N, on the body), ``inv_velocity = 1 / v_f`` (s/m)."""
    return -friction_n * math.tanh(dq_mps * inv_velocity)


def tanh_forces(friction_n, dq_mps, velocity_mps: float) -> np.ndarray:
    """:func:`tanh_force` over arrays, ``-F_f tanh(dq / v_f)`` (the form the front-axle
    model's array path has always used: ``dq / v_f``)."""
    return -np.asarray(friction_n, dtype=float) * np.tanh(np.asarray(dq_mps) / velocity_mps)


def stick_force(base_n: float, stiffness_npm: float, q_m: float, friction_n: float) -> float:
    """The stick element's force on the body, ``-clip(base + k_f q, -F_f, F_f)`` (N)."""
    f = base_n + stiffness_npm * q_m
    if f > friction_n:
        return -friction_n
    if f < -friction_n:
        return friction_n
    return -f


class Sliders:
    """The slider states of a set of springs (the stop operator, see the module notes).

    Parameters
    ----------
    stiffness_npm : sequence of float
        k_f of each spring (N/m).
    friction_n : sequence of float
        F_f of each spring (N); a spring with 0 has no element (its force is 0).
    """

    def __init__(self, stiffness_npm: Sequence[float], friction_n: Sequence[float]) -> None:
        self.stiffness = [float(k) for k in stiffness_npm]
        self.friction = [float(f) for f in friction_n]
        #: ``f_0 - k_f q_0`` per spring (N): the element's force is clip(base + k_f q)
        self.base = [0.0] * len(self.stiffness)

    def start(self, q_m: Sequence[float], force_n: Sequence[float]) -> None:
        """Set the elements' forces (N, tension > 0: ``-force`` on the body) at extensions q."""
        self.base = [min(max(f, -ff), ff) - k * q for f, ff, k, q in zip(
            force_n, self.friction, self.stiffness, q_m)]

    def advance(self, q_m: Sequence[float]) -> None:
        """The step ended at extensions q (m): forces clipped there, bases moved."""
        out = []
        for b, k, ff, q in zip(self.base, self.stiffness, self.friction, q_m):
            f = b + k * q
            f = ff if f > ff else (-ff if f < -ff else f)
            out.append(f - k * q)
        self.base = out

    def forces(self, q_m: Sequence[float]) -> list[float]:
        """The elements' forces on the body at extensions q (N): ``-clip(base + k_f q)``."""
        return [stick_force(b, k, q, ff) for b, k, q, ff in zip(
            self.base, self.stiffness, q_m, self.friction)]
