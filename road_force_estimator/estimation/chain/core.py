"""The differentiator chain (``observer.discretization`` = ``'euler'``, ``'taylor'``,
``'implicit'``, ``'filtering'``): MODEL.md "Reconstruction" from three Levant differentiators
(``'filtering'``: Levant and Livne's filtering differentiators, :func:`.differentiator.
filtering_step`).

0. Three Levant differentiators (:mod:`.differentiator`, the scheme of
   ``observer.discretization``) give ``q_i, dq_i, ddq_i`` and ``phi, dphi, ddphi``;
   suspension forces ``F_bi = -(k_i q_i + c_i dq_i)``.
1. ``dd z_s = (F_b1 + F_b2) / M``.
2. ``dd z_u1 = dd z_s + s (cos(phi) ddphi - sin(phi) dphi^2) - ddq_1`` (``-s (...)`` right).
3. ``dF_i = m_i dd z_ui + F_bi``: no integration, drift-free.
4. Body heave: the band-limited double integral of ``dd z_s`` (:mod:`.body_heave`).
6. Road: ``kt_i (u_i - z_ui) + ct_i (du_i - dz_ui) = dF_i`` solved causally: the tire
   deflection ``w_i = u_i - z_ui`` is ``dF_i / kt_i`` through the first-order lag
   ``ct_i / kt_i`` (exact exponential step, ``dF`` held over the step); ``ct_i = 0`` gives
   ``w_i = dF_i / kt_i`` exactly.

Steps 5 and 7-9 (wheel heaves, road, loads, LTR, residual, lift-off) are
:mod:`.reconstruction`'s. With a latency the chain only delays its estimates.
"""
from __future__ import annotations

from collections import deque
import math

from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
import road_force_estimator.estimation.body_heave as body_heave
from road_force_estimator.estimation.chain.differentiator import (
    FilteringConstants, filtering_step, step_function)
from road_force_estimator.estimation.outputs import Column
from road_force_estimator.estimation.reconstruction import Reconstruction, tire_decay

__all__ = ['ChainCore', 'settling_time_s']

_ACCEL_SCALE = (100.0, 10.0)
# The slots of the finiteness check (plain ints: the per-sample path indexes them).
_X, _FN1, _FN2, _LTR, _RES, _ZS, _DZS, _DZU1 = (int(c) for c in (
    Column.DISTANCE, Column.FN1, Column.FN2, Column.LTR, Column.RESIDUAL, Column.ZS,
    Column.DZS, Column.DZU1))


def settling_time_s(lipschitz_deflection: float, lipschitz_roll: float, dt_s: float) -> float:
    """Time after a (re)start after which the chain reports ``converged`` (s).

    From the homogeneity of the differentiator, it absorbs an initial error ``e_2`` of the
    second derivative in a time proportional to ``e_2 / L`` (and ``e_1`` in ``(e_1/L)^(1/2)``).
    After a start at ``(f, 0, 0)`` the initial error is the signal's own ``f''``; we take the
    largest accelerations a rough road gives the front axle (100 m/s^2 of deflection,
    10 rad/s^2 of roll) and a factor 3, with a floor of 20 sample periods and of 50 ms. With
    the defaults (3000 m/s^3, 200 rad/s^3) that is 0.15 s, well above what starts in mid-drive
    on ISO class C at 20 m/s take (``python -m bench.studies.observer_schemes``).
    """
    t_q = 3.0 * _ACCEL_SCALE[0] / lipschitz_deflection
    t_phi = 3.0 * _ACCEL_SCALE[1] / lipschitz_roll
    return max(t_q, t_phi, 20.0 * dt_s, 0.05)


class ChainCore:
    """The chain, one accepted sample at a time (a core of :class:`.Estimator`).

    Parameters
    ----------
    model : FrontAxleModel
        The front axle (:class:`..models.front_axle.FrontAxleModel`): the chain is MODEL.md's
        reconstruction of its three channels.
    observer : ObserverParameters
        ``discretization`` (the scheme), ``lipschitz_deflection`` / ``lipschitz_roll`` (L per
        channel), ``latency`` (the estimates are only delayed), ``profile_cutoff_wavelength``.

    Notes
    -----
    Final rows ``(stamp_ns, row)`` (slots :class:`.Column`) go to :attr:`ready` in sample
    order; :meth:`finish` releases the ones a latency holds back.
    """

    method = 'chain'

    def __init__(self, model, observer: ObserverParameters) -> None:
        self.vehicle = vehicle = model.vehicle
        self.observer = observer
        lq, lr = observer.lipschitz_deflection_mps3, observer.lipschitz_roll_radps3
        # the filtering differentiators' constants (q_1, q_2, phi), or None: the step function
        self._fc = ((FilteringConstants(lq), FilteringConstants(lq), FilteringConstants(lr))
                    if observer.discretization == 'filtering' else None)
        self._step = None if self._fc else step_function(observer.discretization)
        self._lip = (lq, lq ** (1.0 / 3.0), math.sqrt(lq), lr, lr ** (1.0 / 3.0), math.sqrt(lr))
        v = vehicle
        # Constants of the chain, unpacked once per step.
        self._p = (v.suspension_stiffness_npm + v.suspension_damping_nspm
                   + v.unsprung_mass_kg + (1.0 / v.sprung_mass_kg,)
                   + v.tire_stiffness_npm + v.tire_damping_nspm
                   + (body_heave.cutoff_per_speed(observer.profile_cutoff_wavelength_m),))
        self._rows = Reconstruction(vehicle, observer.rollover_cutoff_frequency_hz)
        self._settle = settling_time_s(lq, lr, 0.0)
        self.ready: deque = deque()
        self.reset()

    def set_vehicle(self, vehicle: VehicleParameters) -> None:
        """Take ``vehicle`` (an estimated sprung mass and static loads, :mod:`.static_load`)
        from the next sample on; the differentiators' state goes on."""
        self.vehicle = v = vehicle
        self._p = self._p[:6] + (1.0 / v.sprung_mass_kg,) + self._p[7:]
        self._rows.set_vehicle(vehicle)

    def set_static_loads(self, fc1: float, fc2: float) -> None:
        """The static wheel loads F_c,i (N) of the rows made from now on."""
        self._rows.set_static(fc1, fc2)

    def reset(self) -> None:
        """Forget everything; the next step must be a restart."""
        # Differentiators: (z0, z1, z2, last sample) for q_1, q_2, phi; the filtering
        # differentiators' filter states.
        self._d = (0.0,) * 12
        self._wf = tuple((0.0,) * c.n_f for c in self._fc or ())
        # Body-heave filter state (body_heave.py); tire deflections w_i.
        self._h = body_heave.start(0.0)
        self._w = (0.0, 0.0)
        self._decay = (-1.0, 0.0, 0.0)   # cached (dt, e_1, e_2) of the tire lag
        self.last_row: tuple | None = None   # the newest row computed
        self.last_converged = False          # its converged flag
        self.ready.clear()
        self._pending: deque = deque()   # with latency: estimates held back
        self._lag = 0
        self._lag_known = self.observer.latency_s == 0.0

    @property
    def latency_samples(self) -> int:
        """The lag N of the published estimates (samples)."""
        return self._lag

    @property
    def pending(self) -> int:
        """Accepted samples whose estimate has not been taken yet."""
        return len(self._pending) + len(self.ready)

    def settling_time_s(self, dt_typ: float) -> float:
        """Settling time (s) at the typical step dt_typ (s), see :func:`settling_time_s`."""
        return max(self._settle, 20.0 * dt_typ)

    def fill_status(self, status) -> None:
        """The chain's fields of an :class:`.EstimatorStatus`."""
        status.method = self.method
        status.latency_samples = self._lag
        status.pending = self.pending

    def finish(self) -> bool:
        """Release the held-back estimates (end of data); False: the run goes on."""
        self.ready.extend(self._pending)
        self._pending.clear()
        return False

    def step(self, stamp: int, y: tuple, v: float, dt: float, restart: bool, x: float,
             t_run: float, dt_typ: float) -> bool:
        """One sample ``y = (q_1, q_2, phi)`` (a restart: the first of a run); False, state
        untouched, if non-finite.

        ``x`` distance (m), ``t_run`` time since the (re)start (s), ``dt_typ`` typical step.
        """
        q1, q2, phi = y
        row = self._advance(q1, q2, phi, v, dt, restart, x, t_run, dt_typ)
        if row is None:
            return False
        pending = self._pending
        if restart:
            self.ready.extend(pending)
            pending.clear()
            self._lag_known = self.observer.latency_s == 0.0
            self._lag = 0
        elif not self._lag_known:
            self._lag = int(round(self.observer.latency_s / dt))
            self._lag_known = True
        pending.append((stamp, row))
        if self._lag_known:
            lag = self._lag
            while len(pending) > lag:
                self.ready.append(pending.popleft())
        return True

    def _advance(self, q1: float, q2: float, phi: float, v: float, dt: float, restart: bool,
                 x: float, t_run: float, dt_typ: float) -> tuple | None:
        """Steps 0-4 and 6 of the chain (or a (re)start), then the output row.

        A restart sets the differentiators to ``(f, 0, 0)``, the body heave to rest at 0 and
        the tire deflections to their steady state. None, state untouched, if non-finite.
        """
        k1, k2, c1, c2, m1, m2, inv_mass, kt1, kt2, ct1, ct2, wc_per_speed = self._p
        wf = self._wf
        if restart:
            a0, a1, a2, b0, b1, b2, c0, c1_, c2_ = q1, 0.0, 0.0, q2, 0.0, 0.0, phi, 0.0, 0.0
            wf = tuple((0.0,) * len(w) for w in wf)
            conv = False
        elif self._fc is not None:
            d, fc = self._d, self._fc
            a0, a1, a2, w1 = filtering_step(d[0], d[1], d[2], wf[0], d[3], dt, fc[0])
            b0, b1, b2, w2 = filtering_step(d[4], d[5], d[6], wf[1], d[7], dt, fc[1])
            c0, c1_, c2_, w3 = filtering_step(d[8], d[9], d[10], wf[2], d[11], dt, fc[2])
            wf = (w1, w2, w3)
            conv = t_run >= self._settle and t_run >= 20.0 * dt_typ
        else:
            step = self._step
            lq, lq13, lq12, lr, lr13, lr12 = self._lip
            d = self._d
            a0, a1, a2 = step(d[0], d[1], d[2], d[3], q1, dt, lq, lq13, lq12)
            b0, b1, b2 = step(d[4], d[5], d[6], d[7], q2, dt, lq, lq13, lq12)
            c0, c1_, c2_ = step(d[8], d[9], d[10], d[11], phi, dt, lr, lr13, lr12)
            conv = t_run >= self._settle and t_run >= 20.0 * dt_typ
        # Steps 1-3: suspension forces, accelerations, tire forces.
        fb1 = -(k1 * a0 + c1 * a1)
        fb2 = -(k2 * b0 + c2 * b1)
        ddzs = (fb1 + fb2) * inv_mass
        rot = self._rows.s * (math.cos(c0) * c2_ - math.sin(c0) * c1_ * c1_)
        ddzu1 = ddzs + rot - a2
        ddzu2 = ddzs - rot - b2
        df1 = m1 * ddzu1 + fb1
        df2 = m2 * ddzu2 + fb2
        # Step 4: body heave, band-limited double integration (body_heave.py).
        h = body_heave.start(ddzs) if restart else body_heave.step(self._h, ddzs, dt, v,
                                                                    wc_per_speed)
        # Step 6: tire deflection w_i = u_i - z_ui from ct dw + kt w = dF (exact, dF held).
        if restart or (ct1 == 0.0 and ct2 == 0.0):
            w1 = df1 / kt1
            w2 = df2 / kt2
        else:
            cache = self._decay
            if cache[0] != dt:
                cache = (dt, tire_decay(dt, kt1, ct1), tire_decay(dt, kt2, ct2))
                self._decay = cache
            e1 = cache[1]
            e2 = cache[2]
            w1 = e1 * self._w[0] + (1.0 - e1) * df1 / kt1
            w2 = e2 * self._w[1] + (1.0 - e2) * df2 / kt2
        if restart:
            self._rows.restart()
        row = self._rows.row(x, a0, b0, a1, b1, a2, b2, c0, c1_, c2_, h[-2], h[-1], ddzs,
                             ddzu1, ddzu2, w1, w2, df1, df2, fb1, fb2, conv, dt)
        # Every output depends on one of these; nothing non-finite leaves.
        if not math.isfinite(row[_X] + row[_FN1] + row[_FN2] + row[_LTR] + row[_RES]
                             + row[_ZS] + row[_DZS] + w1 + w2 + row[_DZU1]):
            return None
        self._d = (a0, a1, a2, q1, b0, b1, b2, q2, c0, c1_, c2_, phi)
        self._wf = wf
        self._h = h
        self._w = (w1, w2)
        self.last_row = row
        self.last_converged = conv
        return row
