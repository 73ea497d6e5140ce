"""The leaf-spring friction as a known input of the model core (:mod:`.online`): the forces
over a step (held, Heun's trapezoid, one iterated update), their direct part in the outputs,
and with a latency their delayed correction.

The vehicle model says which states and outputs are the friction elements' rates
(``friction_rate_states``, ``friction_rate_outputs``) and gives the law
(:meth:`.VehicleModel.friction_forces`); the gains' linear model carries the friction's
equivalent damping ``c_eq,i`` (:meth:`.VehicleModel.friction_damping`), and the known input
is the rest, e.g. ``-F_f,i tanh(dq_i / v_f) + c_eq,i dq_i``.

The stick element (``vehicle.leaf_spring_friction_model: stick``, the model's
``friction_sticks``)
-----------------------------------------------------------------------------------
Its force depends only on the spring's extension history, which the deflection channels read:
the known input is the stop operator (:class:`..core.friction.Sliders`) on each element's
reading (:class:`MeasuredSliders`; the model's ``friction_channels``), its slider force 0 at
a run's first sample. The force over a step is the trapezoid of the operator's outputs at its
two samples, both known from the readings; no equivalent damping, no iterated update; the
outputs' direct part is the force at the emitted sample (kept by its stamp for a latency).
The operator reads what the filter is fed: a gated or left-out channel's prediction in place
of its reading (a spike would otherwise move the slider for good), the reading again when the
gate is undone. The noise and roughness statistics (:meth:`.GainSchedule.statistics`) see the
readings less the linear model's response to these forces (:func:`friction_response`): stuck
springs move less, and the roughness matched on the readings themselves came out a third of
the road's (class A).

With a latency the forward operator's forces are corrected later, as the tanh law's below
(:meth:`KnownFriction.stick_correction`): a sensor lag delays the operator's force by the
lag, which costs far more at 10 ms than at zero latency while those forces are final. Once
the samples after e are in, each element's reading at e is read again de-lagged: ``y + tau
dy/dt`` (tau its sensor's time constant, :func:`channel_lags`; 0: none) from the centred
quadratic fit over at most ``lag`` samples each side (:func:`delagged`, a light low-pass
that is causal within the fixed lag). An operator per correction (the stage's, the final)
runs on them (force 0 at the run's first sample, as the forward one). The trapezoid of its
forces at e - 1 and e replaces the forward filter's force of that step. The difference
corrects the rows e .. e + lag as below, first at :data:`STAGE_S` (the full lag alone leaves
much of the cost) and then at the full lag. At the full lag this happens before sample e is
emitted, and its direct part takes that operator's force at e. The forward operator goes on
from its own state on the fed readings (re-basing it on the delayed operator's force each
step changed nothing that mattered). A gated or left-out channel's prediction is in the fed
readings that both operators take. The correction runs with no lag stated too: the low-pass
alone helps a little on class A (``python -m bench.studies.stick_friction
[--whole-vehicle]``; the figures: docs/notes/stick_friction.md). A gap or a run's start
starts every operator again; a run filtered again (the first block's replay) keeps them and
its rows lose the corrections made so far, as the tanh law's.

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
from itertools import islice
import math

import numpy as np
from scipy import linalg

from road_force_estimator.core.friction import Sliders
from road_force_estimator.estimation.models.protocol import ContinuousModel, VehicleModel
from road_force_estimator.estimation.observer.gains import DT_QUANTUM, MAX_STEP_MATRICES, Gains

__all__ = ['STAGE_S', 'KnownFriction', 'MeasuredSliders',
           'channel_lags', 'delagged', 'delag_weights', 'dq_rows', 'friction_response',
           'friction_step']

#: With a latency, each step's friction is corrected twice: at this lag (s), where the rates
#: have taken most of what the later samples tell (the sensor lag and the wheel's sticking
#: time ``m_i v_f / F_f`` are ~3 ms), and at the full lag (``python -m
#: bench.studies.friction_lag``).
STAGE_S = 0.004

_dot = np.dot     # (a little faster than the @ operator on small arrays)
_FITS: dict = {}  # :func:`delag_weights` by h


def channel_lags(model: ContinuousModel) -> list[float]:
    """Each channel's sensor time constant (s, 0: none) from the model's lag states."""
    tau = [0.0] * model.ny
    first = model.nx - len(model.lagged)
    for n, ch in enumerate(model.lagged):
        tau[ch] = -1.0 / float(model.a[first + n, first + n])
    return tau


def dq_rows(g: Gains, dt: float, rates: tuple) -> tuple[np.ndarray, np.ndarray]:
    """The rows of the friction elements' rates (the states ``rates``) of the transition A(dt)
    (nf, nx) and of the friction input B_d(dt) (nf, nf)."""
    rows = list(rates)
    return g.transition(dt)[rows], g.friction_input(dt)[rows]


def friction_step(model: ContinuousModel, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``(A_d, B_d)``: the transition of a step of dt (s) and the state change per newton of
    friction force held over it (zero-order hold)."""
    nx, nf = model.friction_b.shape
    big = np.zeros((nx + nf, nx + nf))
    big[:nx, :nx] = model.a
    big[:nx, nx:] = model.friction_b
    step = linalg.expm(big * dt)
    return step[:nx, :nx], step[:nx, nx:]


def friction_response(model: ContinuousModel, dt: float, forces, x0=None, step=None
                      ) -> tuple[np.ndarray, np.ndarray]:
    """The linear model's readings (m, ny) driven by the friction forces alone: ``forces``
    (m, nf) (N) held over the step into each sample (row 0: the first sample, whose state is
    ``x0``, default 0), steps of dt (s, zero-order hold; ``step``: its :func:`friction_step`
    when known); and the last sample's state."""
    forces = np.asarray(forces, dtype=float)
    a, bd = friction_step(model, dt) if step is None else step
    x = np.zeros(a.shape[0]) if x0 is None else np.asarray(x0, dtype=float)
    states = np.empty((forces.shape[0], a.shape[0]))
    for k, f in enumerate(forces):
        if k or x0 is not None:
            x = a @ x + bd @ f
        states[k] = x
    return states @ model.c.T, x


def delag_weights(h: int) -> tuple[np.ndarray, np.ndarray]:
    """The centred local quadratic fit (Savitzky-Golay) over the 2 h + 1 samples k = -h..h:
    the weights of its value at k = 0 and of its slope there per step (multiply by 1 / dt,
    s); h = 0: the sample itself, slope 0."""
    w = _FITS.get(h)
    if w is None:
        if h <= 0:
            w = np.ones(1), np.zeros(1)
        else:
            k = np.arange(-h, h + 1, dtype=float)
            w = ((3.0 * (3 * h * h + 3 * h - 1) - 15.0 * k * k)
                 / ((2 * h - 1) * (2 * h + 1) * (2 * h + 3)), k / float(np.sum(k * k)))
        if len(_FITS) < 64:
            _FITS[h] = w
    return w


def delagged(window, dt: float, tau) -> np.ndarray:
    """The quantity a first-order sensor lag of time constant tau (s, per column; 0: none)
    read as ``window`` (2 h + 1, n): the centre sample's ``y + tau dy/dt`` (the lag's
    ``tau dy/dt + y = q`` undone), y and its rate from the centred quadratic fit
    (:func:`delag_weights`) over the window, samples dt (s) apart (units of the readings)."""
    w = np.asarray(window, dtype=float)
    value, slope = delag_weights(w.shape[0] // 2)
    return _dot(value, w) + np.asarray(tau, dtype=float) * (_dot(slope, w) / dt)


class MeasuredSliders:
    """The stick elements' forces on the body (N) from the deflection readings: the stop
    operator (:class:`..core.friction.Sliders`) on each element's extension as its channel
    reads it (the model's ``friction_channels``: channel and sign; a constant offset of the
    reading does not matter, the operator sees increments), its force 0 at the first sample."""

    def __init__(self, vehicle_model: VehicleModel) -> None:
        chans = vehicle_model.friction_channels
        self.channels = [c for c, _ in chans]
        self.signs = [float(sign) for _, sign in chans]
        self.sliders = Sliders(vehicle_model.stick_stiffness_npm, vehicle_model.friction_n)

    def extensions(self, y) -> list[float]:
        """The elements' extensions (m, up to a constant) in one sample y."""
        return [sign * float(y[c]) for c, sign in zip(self.channels, self.signs)]

    def start(self, y) -> tuple:
        """A run's first sample y: every slider force 0; the forces (N, zeros)."""
        q = self.extensions(y)
        self.sliders.start(q, [0.0] * len(q))
        return (0.0,) * len(q)

    def peek(self, y) -> tuple[list, tuple]:
        """``(bases, forces)`` after the next sample y, the operator left as it was."""
        sl = self.sliders
        keep = sl.base
        q = self.extensions(y)
        sl.advance(q)
        out = (sl.base, tuple(sl.forces(q)))
        sl.base = keep
        return out

    def run(self, y: np.ndarray) -> np.ndarray:
        """The forces (nf, m) (N) of a run's samples y (m, ny), from its first sample."""
        y = np.asarray(y, dtype=float)
        m = y.shape[0]
        q = y[:, self.channels] * np.asarray(self.signs)
        out = np.zeros((len(self.channels), m))
        if m == 0:
            return out
        sl = self.sliders
        sl.start(q[0].tolist(), [0.0] * q.shape[1])
        for k, qk in enumerate(q.tolist()):
            sl.advance(qk)
            out[:, k] = sl.forces(qk)
        return out


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
        #: the stick element from the readings (module notes), or None: the law on the rates
        self.stick = MeasuredSliders(vehicle_model) if vehicle_model.friction_sticks else None
        #: stick, each element's channel's sensor time constant (s, 0: none) for the forces'
        #: delayed correction at a latency (:meth:`stick_correction`; with no lag too)
        self.tau = (tuple(channel_lags(model)[c] for c in self.stick.channels)
                    if self.stick is not None else ())
        self._tau_a = np.array(self.tau)
        self._pend_q: list = []
        self._y_start = None
        self._stat_step = None       # (model, dt, its friction_step) of :meth:`response`
        # stick: the outputs' direct part per newton (no, nf) and the rows that have one
        self._fd_rows = [j for j, *_ in self.fd]
        self._fd_mat = np.array([d for _, *d in self.fd]).reshape(len(self.fd), -1)
        self.restart()

    @property
    def sticks(self) -> bool:
        """The friction is the stick element from the readings (at a latency its delayed
        correction: :meth:`stick_correction`)."""
        return self.stick is not None

    def restart(self, y=None, stamp: int | None = None) -> None:
        """A run's start: no step awaits its delayed correction. Stick: the operator starts
        at the run's first sample y (stamped ``stamp``), or again at the last run's first
        sample (y None: the run filtered again, its forces the same)."""
        # [sample index at the step's start, its friction (N) in effect] of the recent steps
        self._steps: deque = deque()
        self._rate: dict = {}   # per lag: (sample index, rates) of its last estimate
        if self.stick is not None:
            if y is not None:
                self._y_start = tuple(y)
                self._direct: deque = deque()   # (stamp, force at that sample (N))
                # the fed extensions of the run's latest samples (newest last, its index
                # _fed_last) and per correction (stage, final) its operator on their
                # de-lagged readings
                self._fed: deque = deque([self.stick.extensions(y)])
                self._fed_last = 0
                self._late: dict = {}
            if self._y_start is not None:
                self._f = self.stick.start(self._y_start)
                self._before = self._pend = (self.stick.sliders.base, self._f)
                if y is not None and stamp is not None:
                    self._direct.append((stamp, self._f))
                    # the forces into each sample since the last :meth:`response` (the run's
                    # first: none) and the response's state
                    self._stat_f: list = [self._f]
                    self._stat_x = None

    def select(self, g: Gains, dt: float) -> None:
        """The step of dt (s) with the gains ``g``: :meth:`.Gains.friction_step`, the dq rows
        (:func:`dq_rows`) and the equivalent damping of g's model."""
        self.fm = g.friction_step(dt)
        self.ceq = g.model.friction_damping_nspm
        if self.stick is None:
            self.a_dq, self.b_dq = dq_rows(g, dt, self.rates)

    def update(self, sv: np.ndarray, x: np.ndarray, y=None) -> np.ndarray:
        """``sv`` (the step without friction) with the friction held over the step from
        x+_k = ``x``: that of :meth:`held` (end rate predicted), then once more with the end
        rate of that update's x+_(k+1) (one iterated update; README, "Friction"); a new
        array. Stick: the trapezoid of the operator's forces at the step's two samples, the
        second from the reading ``y`` the step is fed (committed by :meth:`record`)."""
        fm = self.fm
        if self.stick is not None:
            self._pend_q = self.stick.extensions(y)
            self._pend = self.stick.peek(y)
            f1 = self._pend[1]
            self.last_force = tuple(0.5 * (a + b) for a, b in zip(self._f, f1))
            return sv + _dot(fm, self.last_force)
        first = sv + _dot(fm, self.held(x))
        rates = list(self.rates)
        r0, r1 = x[rates], first[rates]
        f = 0.5 * (self.force(r0) + self.force(r1))
        # (the law's part: less the equivalent damping's share)
        self.last_force = tuple(fk - 0.5 * c * (a + b) for fk, c, a, b in zip(
            f.tolist(), self.ceq, r0.tolist(), r1.tolist()))
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

    def add_direct(self, o: list, stamp: int | None = None) -> None:
        """Add the friction's direct part to the outputs ``o`` (the model's outputs, in place),
        the forces at the elements' rates among them (stick: the forces of the sample
        stamped ``stamp``, kept since :meth:`record`)."""
        if self.stick is not None:
            add = _dot(self._fd_mat, self._direct_force(stamp)).tolist()
            for j, a in zip(self._fd_rows, add):
                o[j] += a
            return
        f = self.force([o[j] for j in self.rate_outputs]).tolist()
        for j, *d in self.fd:
            o[j] += sum(dk * fk for dk, fk in zip(d, f))

    def response(self, model: ContinuousModel, dt: float) -> np.ndarray:
        """Stick: the linear model's readings (m, ny) driven by the forces of the samples
        recorded since the last call (:func:`friction_response`, steps of dt, s; its state
        carried on), for the noise and roughness statistics."""
        f, self._stat_f = self._stat_f, []
        if not f:
            return np.zeros((0, model.c.shape[0]))
        key = self._stat_step
        if key is None or key[0] is not model or key[1] != dt:
            key = self._stat_step = (model, dt, friction_step(model, dt))
        out, self._stat_x = friction_response(model, dt, f, self._stat_x, key[2])
        return out

    def _direct_force(self, stamp: int | None) -> tuple:
        """Stick: the forces (N) of the sample stamped ``stamp`` (dropped with the older
        ones: the samples are emitted in order), or the newest sample's."""
        kept = self._direct
        for n, (s, f) in enumerate(kept):
            if s == stamp:
                for _ in range(n + 1):
                    kept.popleft()
                return f
        return self._f

    def redo(self) -> None:
        """The last recorded step is made again (a gate undone): stick, the operator back to
        before it (then :meth:`update` and :meth:`rerecord`)."""
        if self.stick is not None:
            self.stick.sliders.base, self._f = self._before

    def record(self, index: int, keep: int, stamp: int | None = None) -> None:
        """The step from sample ``index`` used :attr:`last_force`: keep it (and the ``keep``
        steps before it) for the delayed correction. Stick: the operator moves to the step's
        end, its forces kept for the direct part of the sample ``stamp`` (None: a run
        filtered again, whose forces are kept already)."""
        if self.stick is not None:
            self._before = (self.stick.sliders.base, self._f)
            self.stick.sliders.base, self._f = self._pend
            # the force used, and the reading fed (a run filtered again: the same forces, the
            # readings kept)
            self._keep_step(index, keep)
            if stamp is not None:
                fed = self._fed
                fed.append(self._pend_q)
                self._fed_last += 1
                while len(fed) > 2 * keep + 1:
                    fed.popleft()
                kept = self._direct
                kept.append((stamp, self._f))
                while len(kept) > keep + 2:
                    kept.popleft()
                self._stat_f.append(self.last_force)
            return
        self._keep_step(index, keep)

    def _keep_step(self, index: int, keep: int) -> None:
        """Keep the step from sample ``index`` and its :attr:`last_force` (and the ``keep``
        steps before it) for the delayed correction."""
        steps = self._steps
        steps.append([index, self.last_force])
        while len(steps) > keep + 1:
            steps.popleft()

    def rerecord(self) -> None:
        """The last recorded step was made again (a gate undone): its :attr:`last_force`
        (stick: the operator at its end, its sample's direct forces)."""
        if self.stick is not None:
            self.stick.sliders.base, self._f = self._pend
            if self._direct:
                self._direct[-1] = (self._direct[-1][0], self._f)
            if self._stat_f:
                self._stat_f[-1] = self.last_force
            if self._fed:
                self._fed[-1] = self._pend_q
        if self._steps:
            self._steps[-1][1] = self.last_force

    # -- the delayed correction (module notes) ---------------------------------------------
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
        if self.stick is not None:      # (its own: :meth:`stick_correction`)
            return None
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

    def stick_correction(self, g: Gains, dt: float, lag: int, index: int, final: bool
                         ) -> np.ndarray | None:
        """Stick, at a latency: the change (lag + 1, nx + ny) of the row of sample ``index``
        and the ``lag`` rows after it (x+ and nu) for the forces over the step into it read
        again ``lag`` samples later from the de-lagged readings (:func:`delagged`, the
        centred fit over at most ``lag`` samples each side; one operator runs on them per
        role: the stage's correction, the final one), or None (a run's first sample, the
        step not kept, no change). ``final`` (the output's lag): the sample's direct part
        takes that operator's forces too (module notes)."""
        late = self._late.get(final)    # (by its role: the stage's lag follows the step)
        if late is None:     # [operator, next sample, forces at the one before, at the last,
            # (h, dt, weights) of its last de-lagging fit]
            late = self._late[final] = [Sliders(self.stick.sliders.stiffness,
                                              self.stick.sliders.friction), 0, None, None,
                                      (-1, 0.0, None)]
        fed = self._fed
        newest = self._fed_last
        oldest = newest - len(fed) + 1
        if late[1] < oldest:
            late[1] = oldest
        sl = late[0]
        while late[1] <= index:
            j = late[1]
            h = min(lag, j - oldest, newest - j)
            a = j - oldest
            fit = late[4]
            if fit[0] != h or fit[1] != dt:     # the fit's weights per reading (2 h + 1, nf)
                value, slope = delag_weights(h)
                fit = late[4] = (h, dt, value[:, None] + slope[:, None] * (self._tau_a / dt))
            q = (fit[2] * list(islice(fed, a - h, a + h + 1))).sum(axis=0).tolist()
            if late[3] is None:       # the operator's first sample: its forces 0
                sl.start(q, [0.0] * len(q))
                f = (0.0,) * len(q)
            else:
                sl.advance(q)
                f = tuple(sl.forces(q))
            late[2], late[3] = late[3], f
            late[1] = j + 1
        steps = self._steps
        if late[1] != index + 1 or late[2] is None or not steps:
            return None
        pos = index - 1 - steps[0][0]
        if not 0 <= pos < len(steps):
            return None
        step = steps[pos]
        new = tuple(0.5 * (a + b) for a, b in zip(late[2], late[3]))
        delta = [a - b for a, b in zip(new, step[1])]
        step[1] = new
        if final:
            back = newest - index
            kept = self._direct
            if back < len(kept):
                kept[-1 - back] = (kept[-1 - back][0], late[3])
        if not any(delta):      # (both sliding at the same +-F_f)
            return None
        return _dot(self._rows_per_newton(g, dt)[:lag + 1], delta)

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
