"""The leaf-spring friction as a known input of the model core (:mod:`.online`): the forces
over a step (held, Heun's trapezoid, one iterated update), their direct part in the outputs,
and with a latency their delayed correction.

The vehicle model says which states and outputs are the friction elements' rates
(``friction_rate_states``, ``friction_rate_outputs``) and gives the law
(:meth:`.VehicleModel.friction_forces`); the gains' linear model carries the friction's
equivalent damping ``c_eq,i`` (:meth:`.VehicleModel.friction_damping`), and the known input
is the rest, e.g. ``-F_f,i tanh(dq_i / v_f) + c_eq,i dq_i``.

Delayed correction (``observer.latency`` > 0)
---------------------------------------------
The forward filter can only evaluate the friction at its filtered rate, whose error a steep
law (``F_f / v_f`` = 150 kN s/m at 1.5 kN, ten times the damper) turns into a force error.
Once the fixed-lag estimate of sample e is out, the rates of samples e - 1 and e are known N
samples later; the friction of the step e - 1 -> e is evaluated again there, and the
difference ``delta`` (N, per element) corrects the forward filter's rows e .. e + N (their
state and innovations) exactly as the steady-state filter would have carried it (first at
the lag :data:`STAGE_S`, from that lag's estimate, then at the full lag): ``x+_e += (I - K C)
B_d delta``, ``nu_e += -C B_d delta``, ``x+_(e+j) += ((I - K C) A)^j (I - K C) B_d delta``,
``nu_(e+j) += -C A ((I - K C) A)^(j-1) (I - K C) B_d delta`` (:meth:`KnownFriction.
correction`). Every later estimate then sees the friction at the smoothed rates. Why: with a
sensor lag the filtered rate is that of a prediction over the lag, so friction and lag
together cost far more than either alone (``python -m bench.studies.friction_lag``).
"""
from __future__ import annotations

from collections import deque
import math

import numpy as np

from road_force_estimator.estimation.models.protocol import VehicleModel
from road_force_estimator.estimation.observer.gains import DT_QUANTUM, MAX_STEP_MATRICES, Gains

__all__ = ['STAGE_S', 'KnownFriction', 'dq_rows']

#: With a latency, each step's friction is corrected twice: at this lag (s), where the rates
#: have taken most of what the later samples tell (the sensor lag and the wheel's sticking
#: time ``m_i v_f / F_f`` are ~3 ms), and at the full lag (``python -m
#: bench.studies.friction_lag``).
STAGE_S = 0.004

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
        self._zero = (0.0,) * len(model.friction_n)
        #: the law's friction (N) held over the last :meth:`update`, per element
        self.last_force = self._zero
        self._w_cache: dict = {}     # rows per newton by step (:meth:`_rows_per_newton`)
        self._w_gains = None         # ... of these gains
        self.restart()

    def restart(self) -> None:
        """A run's start: no step awaits its delayed correction."""
        # [sample index at the step's start, its friction (N) in effect] of the recent steps
        self._steps: deque = deque()
        self._rate: dict = {}   # per lag: (sample index, rates) of its last estimate

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
        rates = list(self.rates)
        r0, r1 = x[rates], first[rates]
        f = 0.5 * (self.force(r0) + self.force(r1))
        # (the law's part: less the equivalent damping's share)
        self.last_force = tuple(float(fk) - 0.5 * c * (a + b)
                                for fk, c, a, b in zip(f, self.ceq, r0, r1))
        return sv + _dot(fm, f)

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

    # -- the delayed correction (module notes) ---------------------------------------------
    def record(self, index: int, keep: int) -> None:
        """The step from sample ``index`` used :attr:`last_force`: keep it (and the ``keep``
        steps before it) for the delayed correction."""
        steps = self._steps
        steps.append([index, self.last_force])
        while len(steps) > keep + 1:
            steps.popleft()

    def rerecord(self) -> None:
        """The last recorded step was made again (a gate undone): its :attr:`last_force`."""
        if self._steps:
            self._steps[-1][1] = self.last_force

    @staticmethod
    def stage_lag(dt: float, lag: int) -> int:
        """The intermediate lag (samples) of the first correction (:data:`STAGE_S` at the step
        dt, s), or 0 when it is not below the fixed lag ``lag``."""
        stage = int(round(STAGE_S / dt))
        return stage if 0 < stage < lag else 0

    def correction(self, g: Gains, dt: float, lag: int, index: int, dq: list
                   ) -> np.ndarray | None:
        """The change (lag + 1, nx + ny) of the row of sample ``index`` and the ``lag`` rows
        after it (their x+ and nu) for its rates dq (m/s, per element) estimated ``lag``
        samples later, or None when the step into it is not known (a run's first sample, a
        re-filtered block). Added to those rows, the buffer is the filter driven by the
        friction at the latest rates (the module notes)."""
        rates = self._rate
        prev = rates.get(lag)
        rates[lag] = (index, dq)
        steps = self._steps
        if prev is None or prev[0] != index - 1 or not steps:
            return None
        pos = index - 1 - steps[0][0]
        if not 0 <= pos < len(steps):
            return None
        step = steps[pos]
        used = step[1]
        # the law's friction of the step at the later rates (the equivalent damping's share
        # stays the filter's: its linear part carries it on the rows' own rates)
        new = tuple(0.5 * (a + b) for a, b in zip(self.law(prev[1], self._zero).tolist(),
                                                  self.law(dq, self._zero).tolist()))
        step[1] = new
        return _dot(self._rows_per_newton(g, dt)[:lag + 1],
                    [a - b for a, b in zip(new, used)])

    def _rows_per_newton(self, g: Gains, dt: float) -> np.ndarray:
        """(N + 1, nx + ny, nf): the change of the rows e .. e + N (x+ and nu) per newton of
        the friction over the step e - 1 -> e (module notes)."""
        if g is not self._w_gains:      # (a new design: the cache is of the gains in use)
            self._w_cache.clear()
            self._w_gains = g
        key = round(math.log(dt / g.dt_s) / DT_QUANTUM)     # (as the gains' step matrices)
        w = self._w_cache.get(key)
        if w is None:
            if len(self._w_cache) >= MAX_STEP_MATRICES:
                self._w_cache.clear()
            nx, ny = g.nx, g.model.ny
            _, x0, _, _, _ = g.layout
            step = g.step_matrix(dt)
            f_x = step[:nx, x0:x0 + nx]          # (I - K C) A
            ca = step[nx:nx + ny, x0:x0 + nx]    # -C A
            first = g.friction_step(dt)[:nx + ny]   # (I - K C) B_d; -C B_d
            w = np.empty((g.lag + 1, nx + ny, first.shape[1]))
            w[0] = first
            d = w[0, :nx]
            for j in range(1, g.lag + 1):
                w[j, nx:] = ca @ d
                d = f_x @ d
                w[j, :nx] = d
            self._w_cache[key] = w
        return w
