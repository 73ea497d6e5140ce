"""The leaf-spring friction of a vehicle model as the observer's known input: the law, its
equivalent damping and the tuning of both, shared by every model whose springs carry
``vehicle.leaf_spring_friction`` (:class:`LeafSpringFriction`: the front axle's two springs,
:mod:`.front_axle`; every spring of the whole vehicle, :mod:`.articulated`).

The plants' laws are :mod:`..core.friction`'s. ``tanh``: the observer's known input is the
law ``-F_f tanh(dq / v_f)`` (N on the body, dq the spring's extension rate, m/s, v_f =
``vehicle.leaf_spring_friction_velocity``) at the estimated rates; the gains' linear model
carries the friction's equivalent damping ``c_eq`` (:func:`friction_damping`), and the known
input is the rest, ``-F_f tanh(dq / v_f) + c_eq dq`` (:mod:`..observer.friction`).

``stick`` (:attr:`LeafSpringFriction.friction_sticks`): the element's force depends only on
its spring's extension history, which the deflection sensors measure, so the force is a known
input computed from the readings by the stop operator (:class:`..core.friction.Sliders`, the
plants' own) on each element's deflection channel (:attr:`LeafSpringFriction.
friction_channels`), its slider force 0 at a run's first sample; no equivalent damping (c_eq
0). A vehicle with a stick element on a spring no channel measures keeps the tanh law.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ['FRICTION_DAMPING_FACTOR', 'FRICTION_DAMPING_FACTOR_LATENCY', 'friction_damping',
           'LeafSpringFriction']

#: Equivalent damping of the friction (:func:`friction_damping`): the factor on the
#: statistical linearisation, tuned on bench/studies/truck_effects.py (classes A and C, 20 m/s,
#: 10 um, 1.5 kN; of 1, 1.5, 2 and 3, 1.5 the best 10 ms load error over both classes:
#: ``python -m bench.studies.truck_effects``).
FRICTION_DAMPING_FACTOR = 1.5
#: The same factor with a latency (``observer.latency`` > 0), where the friction of every
#: step is evaluated again at the smoothed rates (:mod:`..observer.friction`, "Delayed
#: correction"): the forward filter's friction errors are then corrected, and the error
#: dynamics want less of the damping they would add (10 ms, friction + 3 ms lag, against the
#: matched drive: 0.5 the best of 1.5, 1.0 and 0.5; ``python -m bench.studies.friction_lag``).
FRICTION_DAMPING_FACTOR_LATENCY = 0.5


def friction_damping(friction_n, dq_std_mps: float, factor: float | None = None,
                     velocity_mps: float = 0.01) -> tuple[float, ...]:
    """The friction's equivalent damping c_eq,i (N s/m) per element at an RMS suspension rate
    (m/s).

    Statistical linearisation of ``-F_f tanh(dq / v_f)`` over a Gaussian dq of std sigma:
    ``E[d f / d dq] ~ F_f sqrt(2 / pi) / sqrt(sigma^2 + 2 v_f^2 / pi)`` (``F_f / v_f`` at
    sigma = 0, ``F_f sqrt(2 / pi) / sigma`` for sigma >> v_f), times
    ``factor`` (default :data:`FRICTION_DAMPING_FACTOR`). The gains are designed with it; the
    friction itself stays the known input, so it changes the gains, not the model.
    """
    v_f = velocity_mps
    if factor is None:
        factor = FRICTION_DAMPING_FACTOR
    scale = factor * math.sqrt(2.0 / math.pi) / math.sqrt(
        dq_std_mps ** 2 + 2.0 * v_f ** 2 / math.pi)
    return tuple(float(f) * scale for f in friction_n)


class LeafSpringFriction:
    """The friction part of :class:`.protocol.VehicleModel` for a model that sets
    ``friction_n`` (F_f per element, N, the springs in the order of its
    ``friction_rate_states``) and ``friction_velocity_mps`` (v_f, m/s), and may set its own
    ``friction_damping_factors`` (zero latency, with a latency; None: this module's
    :data:`FRICTION_DAMPING_FACTOR` and :data:`FRICTION_DAMPING_FACTOR_LATENCY`)."""

    friction_n: tuple = ()
    friction_velocity_mps: float = 0.01
    friction_damping_factors: tuple[float, float] | None = None
    #: per element, its deflection channel (index into y) and the sign of the reading per
    #: metre of the spring's extension (+1.0), or None: no channel measures it
    friction_channels: tuple = ()
    #: the law of ``vehicle.leaf_spring_friction_model`` ('tanh' or 'stick')
    friction_model: str = 'tanh'
    #: k_f of each element's stick spring (N/m: ``vehicle.leaf_spring_friction_stiffness``
    #: times its suspension stiffness)
    stick_stiffness_npm: tuple = ()

    @property
    def friction_sticks(self) -> bool:
        """The friction is the stick element, carried from the measured deflections: the law
        says stick and every element with friction has a deflection channel."""
        return (self.friction_model == 'stick' and any(self.friction_n)
                and all(ch is not None for ch, f in zip(self.friction_channels,
                                                         self.friction_n) if f > 0.0))

    def friction_forces(self, dq, ceq) -> np.ndarray:
        """The friction's known input (N) per spring at its rates dq (m/s): ``-F_f,i
        tanh(dq_i / v_f)`` less the share ``-c_eq,i dq_i`` of the equivalent damping that the
        gains' linear model carries (:func:`friction_damping`)."""
        v_f = self.friction_velocity_mps
        if isinstance(dq, np.ndarray):   # (floats: the same numbers, without numpy's scalars)
            dq = dq.tolist()
        return np.array([-f * math.tanh(d / v_f) + c * d
                         for f, c, d in zip(self.friction_n, ceq, dq)])

    def friction_forces_array(self, dq: np.ndarray, ceq: np.ndarray) -> np.ndarray:
        """:meth:`friction_forces` over arrays: dq (nf, ...) (m/s), ceq (nf,) (N s/m)."""
        v_f = self.friction_velocity_mps
        shape = (len(self.friction_n),) + (1,) * (np.ndim(dq) - 1)
        ff = np.asarray(self.friction_n).reshape(shape)
        return -ff * np.tanh(dq / v_f) + np.asarray(ceq).reshape(ff.shape) * dq

    def friction_damping(self, dq_std_mps: float, delayed: bool = False) -> tuple:
        """:func:`friction_damping` of this vehicle's friction at an RMS rate (m/s);
        ``delayed``: with a latency, whose friction is corrected at the smoothed rates
        (:data:`FRICTION_DAMPING_FACTOR_LATENCY`, or the model's factors)."""
        if self.friction_sticks:        # the stick element's force is known: none
            return (0.0,) * len(self.friction_n)
        own = self.friction_damping_factors
        if own is not None:
            factor = own[1] if delayed else own[0]
        else:
            factor = FRICTION_DAMPING_FACTOR_LATENCY if delayed else None
        return friction_damping(self.friction_n, dq_std_mps, factor,
                                self.friction_velocity_mps)
