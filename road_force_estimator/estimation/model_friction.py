"""The leaf-spring friction as a known input of the model core (:mod:`.model_core`): the
forces over a step (held, Heun's trapezoid, one iterated update), their direct part in the
outputs, and with a latency their delayed correction.

The gains' linear model carries the friction's equivalent damping ``c_eq,i``
(:func:`.model.friction_damping`); the known input is the rest, ``-F_f,i tanh(dq_i / v_f) +
c_eq,i dq_i`` (README, "Friction").

Delayed correction (``observer.latency`` > 0)
---------------------------------------------
The forward filter can only evaluate the friction at its filtered rate, whose error the
steep law (``F_f / v_f`` = 150 kN s/m at 1.5 kN, ten times the damper) turns into a force
error. Once the fixed-lag estimate of sample e is out, the rates of samples e - 1 and e are
known N samples later; the friction of the step e - 1 -> e is evaluated again there, and the
difference ``delta`` (N, per side) corrects the forward filter's rows e .. e + N (its
state and innovations) exactly as the steady-state filter would have carried it (first at
the lag :data:`STAGE_S`, from that lag's estimate, then at the full lag):
``x+_e += (I - K C) B_d delta``, ``nu_e += -C B_d delta``, ``x+_(e+j) += ((I - K C) A)^j
(I - K C) B_d delta``, ``nu_(e+j) += -C A ((I - K C) A)^(j-1) (I - K C) B_d delta``
(:meth:`KnownFriction.correction`). Every later estimate then sees the
friction at the smoothed rates. Where it came from: with a sensor lag the filtered rate is
the one of a prediction over the lag (its error std at 10 um: 8.4 mm/s against 4.7 without
lag), so friction and lag together cost far more than either alone (``python -m
bench.friction_lag``).
"""
from __future__ import annotations

from collections import deque
import math

import numpy as np

from road_force_estimator.core.vehicle_model import FRICTION_VELOCITY_MPS
from road_force_estimator.estimation.gains import DT_QUANTUM, MAX_STEP_MATRICES, Gains
from road_force_estimator.estimation.model import State

__all__ = ['STAGE_S', 'KnownFriction', 'dq_rows']

#: With a latency, each step's friction is corrected twice: at this lag (s), where the rates
#: have taken most of what the later samples tell (the sensor lag and the wheel's sticking
#: time ``m_i v_f / F_f`` are ~3 ms), and at the full lag (``python -m bench.friction_lag``,
#: 10 ms, friction + 3 ms lag: 1.48 x the matched drive with the full lag's alone, 1.41 at
#: 1 ms, 1.37 at 3-6 ms).
STAGE_S = 0.004

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
        #: the law's friction ``-F_f tanh(dq / v_f)`` (N) held over the last :meth:`update`
        self.last_force = (0.0, 0.0)
        self._w_cache: dict = {}     # rows per newton by step (:meth:`_rows_per_newton`)
        self._w_gains = None         # ... of these gains
        self.restart()

    def restart(self) -> None:
        """A run's start: no step awaits its delayed correction."""
        # [sample index at the step's start, its friction (N) in effect] of the recent steps
        self._steps: deque = deque()
        self._rate: dict = {}   # per lag: (sample index, dq_1, dq_2) of its last estimate

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
        e1, e2 = first[State.DQ1], first[State.DQ2]
        f = 0.5 * (f0 + self.force(e1, e2))
        c1, c2 = self.ceq     # (the law's part: less the equivalent damping's share)
        self.last_force = (float(f[0]) - 0.5 * c1 * (x[State.DQ1] + e1),
                           float(f[1]) - 0.5 * c2 * (x[State.DQ2] + e2))
        return sv + _dot(fm, f)

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

    # -- the delayed correction (module notes) ---------------------------------------------
    def record(self, index: int, keep: int) -> None:
        """The step from sample ``index`` used :attr:`last_force`: keep it (and the ``keep``
        steps before it) for the delayed correction."""
        steps = self._steps
        steps.append([index, self.last_force])
        while len(steps) > keep + 1:
            steps.popleft()

    @staticmethod
    def stage_lag(dt: float, lag: int) -> int:
        """The intermediate lag (samples) of the first correction (:data:`STAGE_S` at the step
        dt, s), or 0 when it is not below the fixed lag ``lag``."""
        stage = int(round(STAGE_S / dt))
        return stage if 0 < stage < lag else 0

    def correction(self, g: Gains, dt: float, lag: int, index: int, dq1: float, dq2: float
                   ) -> np.ndarray | None:
        """The change (lag + 1, nx + 3) of the row of sample ``index`` and the ``lag`` rows
        after it (their x+ and nu) for its rates dq_i (m/s) estimated ``lag`` samples
        later, or None when the step into it is not known (a run's first sample, a
        re-filtered block). Added to those rows, the buffer is the filter driven by the
        friction at the latest rates (the module notes)."""
        rates = self._rate
        prev = rates.get(lag)
        rates[lag] = (index, dq1, dq2)
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
        f1, f2 = self.ff
        new = (-0.5 * f1 * (math.tanh(prev[1] / FRICTION_VELOCITY_MPS)
                            + math.tanh(dq1 / FRICTION_VELOCITY_MPS)),
               -0.5 * f2 * (math.tanh(prev[2] / FRICTION_VELOCITY_MPS)
                            + math.tanh(dq2 / FRICTION_VELOCITY_MPS)))
        step[1] = new
        return _dot(self._rows_per_newton(g, dt)[:lag + 1],
                    (new[0] - used[0], new[1] - used[1]))

    def _rows_per_newton(self, g: Gains, dt: float) -> np.ndarray:
        """(N + 1, nx + 3, 2): the change of the rows e .. e + N (x+ and nu) per newton of
        the friction over the step e - 1 -> e (module notes)."""
        if g is not self._w_gains:      # (a new design: the cache is of the gains in use)
            self._w_cache.clear()
            self._w_gains = g
        key = round(math.log(dt / g.dt_s) / DT_QUANTUM)     # (as the gains' step matrices)
        w = self._w_cache.get(key)
        if w is None:
            if len(self._w_cache) >= MAX_STEP_MATRICES:
                self._w_cache.clear()
            nx = g.nx
            _, x0, _, _, _ = g.layout
            step = g.step_matrix(dt)
            f_x = step[:nx, x0:x0 + nx]          # (I - K C) A
            ca = step[nx:nx + 3, x0:x0 + nx]     # -C A
            w = np.empty((g.lag + 1, nx + 3, 2))
            w[0] = g.friction_step(dt)[:nx + 3]  # (I - K C) B_d; -C B_d
            d = w[0, :nx]
            for j in range(1, g.lag + 1):
                w[j, nx:] = ca @ d
                d = f_x @ d
                w[j, :nx] = d
            self._w_cache[key] = w
        return w
