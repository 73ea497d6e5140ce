"""MODEL.md "Reconstruction", steps 5-9: from the estimated motions to the output row.

Every estimator estimates the motions (``q_i, phi`` and their rates and accelerations, the
body heave ``z_s``, the wheel accelerations, the tire deflections ``w_i = u_i - z_ui``, the
dynamic tire forces ``dF_i`` and the suspension forces ``F_bi``) its own way; the rest is this
module's, per sample (:meth:`Reconstruction.row`) and over arrays
(:meth:`Reconstruction.columns`):

5. ``z_u1 = z_s + s sin(phi) - q_1``, ``z_u2 = z_s - s sin(phi) - q_2``, their rates
   ``dz_s +- s cos(phi) dphi - dq_i``.
6. The road ``u_i = z_ui + w_i``; the chains' tire deflection from ``kt_i w_i + ct_i dw_i =
   dF_i``: ``dF_i / kt_i`` through the first-order lag ``ct_i / kt_i`` (:func:`tire_decay`,
   :func:`tire_deflections`; the model observer has ``w_i`` as a state).
7. Distance ``x = integral of v dt`` (trapezoidal, :func:`distance_m`), continued across gaps.
8. ``F_n,i = max(0, F_c,i + dF_i)``: a tire cannot pull, so an estimate below zero (a
   lift-off; ``dF_i`` keeps the unclipped value, and :attr:`.EstimateArrays.load_clipped`
   / ``negative_load_samples`` count them) is published as 0; ``LTR = (F_n2 - F_n1) /
   (F_n1 + F_n2)`` (right minus left) of those loads, so ``|LTR| <= 1``; the denominator
   floored at :data:`LTR_FLOOR_FRACTION` of the static sum (:func:`load_transfer_ratio`). The
   quasi-static LTR for rollover warnings: the same ratio of the loads low-passed below the
   wheel-hop band, causal: two first-order lags in cascade (critically damped, -3 dB at
   ``observer.rollover_cutoff_frequency``, exact for loads held over each step), restarted
   with each run at the loads of its first sample (:meth:`Reconstruction.row` with the step,
   :meth:`Reconstruction.add_quasi_static` over a run's arrays: the same numbers).
9. Residual ``r = I_x ddphi - s cos(phi) (F_b1 - F_b2) - M g h sin(phi)`` (N m); it equals
   ``M h a_y cos(phi)`` under a lateral acceleration a_y; ``lift_off_i`` when
   ``F_n,i <=`` :data:`LIFT_OFF_FRACTION` ``F_c,i``.

The static loads F_c,i are the vehicle's (``vehicle.static_load``), or, with the deflections
read from a mechanical zero, the estimates of :mod:`.static_load`, set per sample
(:meth:`Reconstruction.set_static`) or per run (:meth:`Reconstruction.restatic`); each row
carries the F_c,i it used (:attr:`.Column.STATIC_LOAD1`, ``STATIC_LOAD2``).
"""
from __future__ import annotations

import math

import numpy as np

from road_force_estimator.core.parameters import GRAVITY_MPS2, VehicleParameters
from road_force_estimator.estimation.outputs import Column

__all__ = ['LIFT_OFF_FRACTION', 'LTR_FLOOR_FRACTION', 'Reconstruction', 'distance_m',
           'tire_decay', 'tire_deflections', 'load_transfer_ratio', 'load_transfer_ratios']

#: Lift-off flag when the estimated load is at most this fraction of the static load.
LIFT_OFF_FRACTION = 0.05
#: Floor of the LTR denominator, as a fraction of the static axle load.
LTR_FLOOR_FRACTION = 0.01
#: Samples per chunk of the batch quasi-static LTR (:meth:`Reconstruction.add_quasi_static`).
QUASI_STATIC_CHUNK = 65536
#: -3 dB frequency of a cascade of two equal first-order lags, per unit pole frequency.
_CASCADE_3DB = math.sqrt(math.sqrt(2.0) - 1.0)


def load_transfer_ratio(fn1_n: float, fn2_n: float, floor_n: float) -> float:
    """LTR = (F_n2 - F_n1) / (F_n1 + F_n2) of one sample (MODEL.md step 8; right minus left)
    from the left and right vertical loads (N); scalar fast path.

    A tire cannot pull, so each load enters as ``max(F_n,i, 0)``: then ``|LTR| <= 1``, +1 when
    the left wheel has lifted off, -1 when the right one has (the rollover limit). The
    denominator is floored at ``floor_n`` (the estimators: :data:`LTR_FLOOR_FRACTION` of the
    static axle load), so the ratio stays finite, and is 0, with both wheels off the ground.
    """
    a = fn1_n if fn1_n > 0.0 else 0.0
    b = fn2_n if fn2_n > 0.0 else 0.0
    den = a + b
    return (b - a) / (den if den > floor_n else floor_n)


def load_transfer_ratios(fn1_n: np.ndarray, fn2_n: np.ndarray, floor_n) -> np.ndarray:
    """:func:`load_transfer_ratio` over arrays (the same numbers)."""
    a = np.maximum(np.asarray(fn1_n, dtype=float), 0.0)
    b = np.maximum(np.asarray(fn2_n, dtype=float), 0.0)
    return (b - a) / np.maximum(a + b, floor_n)


def distance_m(steps_s: np.ndarray, speed_mps: np.ndarray) -> np.ndarray:
    """Step 7 over arrays: the distance (m) at each sample from the steps (s) between them
    and the speeds (m/s); 0 at the first (the per-sample path's sum, term by term)."""
    out = np.zeros(speed_mps.size)
    if speed_mps.size > 1:
        out[1:] = np.cumsum(0.5 * (speed_mps[1:] + speed_mps[:-1]) * steps_s)
    return out


def tire_decay(dt: float, kt: float, ct: float) -> float:
    """Step 6 per sample: the factor ``exp(-dt kt / ct)`` of the tire lag over a step dt (s)
    (0 without tire damping): ``w_k = e w_(k-1) + (1 - e) dF_k / kt``."""
    return math.exp(-dt * kt / ct) if ct > 0.0 else 0.0


def tire_deflections(df: np.ndarray, t: np.ndarray, kt, ct) -> np.ndarray:
    """Step 6 over arrays: ``w = u - z_u`` (m, (m, 2)) from ``ct dw + kt w = dF`` (exact, dF
    held), from the dynamic tire forces df (N, (m, 2)) at the times t (s); the first sample
    at its steady state ``dF / kt``."""
    from road_force_estimator.core.scipy_signal import signal
    lfilter = signal().lfilter

    w = df / kt
    m = t.size
    for i in (0, 1):
        if ct[i] > 0.0 and m > 1:
            steps = np.diff(t)
            e = np.exp(-steps * kt[i] / ct[i])
            wi = np.empty(m)
            wi[0] = df[0, i] / kt[i]
            target = df[1:, i] / kt[i]
            if np.allclose(e, e[0]):
                wi[1:], _ = lfilter([1.0 - e[0]], [1.0, -e[0]], target, zi=[e[0] * wi[0]])
            else:
                for j in range(1, m):
                    wi[j] = e[j - 1] * wi[j - 1] + (1.0 - e[j - 1]) * target[j - 1]
            w[:, i] = wi
    return w


class Reconstruction:
    """Steps 5, 8 and 9 of MODEL.md for one vehicle (see the module notes)."""

    def __init__(self, vehicle: VehicleParameters, rollover_cutoff_hz: float = 2.0) -> None:
        self.set_vehicle(vehicle)
        #: pole rate (1/s) of each lag of the quasi-static LTR's low-pass
        self.rollover_rate = 2.0 * math.pi * float(rollover_cutoff_hz) / _CASCADE_3DB
        self._qs: tuple | None = None       # the low-pass's (left 1, left 2, right 1, right 2)
        self._qs_e = (-1.0, 0.0)            # (dt, exp(-dt rate)) of the last step

    def set_vehicle(self, vehicle: VehicleParameters) -> None:
        """Take the track, roll inertia, gravity moment and static loads of ``vehicle`` (the
        sprung mass estimated under ``zero_load``)."""
        self.s = vehicle.half_track_m
        self.ix = vehicle.roll_inertia_kgm2
        #: M g h (N m): the gravity moment per unit sin(phi) in the residual of step 9
        self.mgh = vehicle.sprung_mass_kg * GRAVITY_MPS2 * vehicle.cg_height_m
        self.set_static(*vehicle.static_load_n)

    def set_static(self, fc1: float, fc2: float) -> None:
        """The static wheel loads F_c,i (N) of the next rows (and the lift-off thresholds and
        the LTR floor that follow from them)."""
        self.static_n = (fc1, fc2)
        self.lift_off_n = (LIFT_OFF_FRACTION * fc1, LIFT_OFF_FRACTION * fc2)
        self.ltr_floor_n = LTR_FLOOR_FRACTION * (fc1 + fc2)
        self._c = (self.s, self.ix, fc1, fc2) + self.lift_off_n + (self.ltr_floor_n,)

    def restatic(self, out: list, static_n: np.ndarray, t: np.ndarray,
                 t_prev: float | None = None) -> None:
        """The columns of one run ``out`` (:meth:`columns` and :meth:`add_quasi_static`
        done) again with per-sample static loads ``static_n`` (N, (m, 2)) at the times t (s):
        the loads, LTR, lift-off flags and the quasi-static LTR (restarted at the run's
        start), as :meth:`row` gives them sample by sample with :meth:`set_static`. ``t_prev``
        (s): the time of the run's previous sample when these rows continue the rows of the
        last call (the low-pass goes on from there: a run in pieces gives the numbers of one
        piece); None at a run's start."""
        fc1, fc2 = static_n[:, 0], static_n[:, 1]
        fn1 = np.maximum(fc1 + out[Column.DF1], 0.0)
        fn2 = np.maximum(fc2 + out[Column.DF2], 0.0)
        C = Column
        for j, col in ((C.FN1, fn1), (C.FN2, fn2),
                       (C.LTR, load_transfer_ratios(fn1, fn2, LTR_FLOOR_FRACTION * (fc1 + fc2))),
                       (C.LIFT_OFF1, fn1 <= LIFT_OFF_FRACTION * fc1),
                       (C.LIFT_OFF2, fn2 <= LIFT_OFF_FRACTION * fc2),
                       (C.STATIC_LOAD1, fc1), (C.STATIC_LOAD2, fc2)):
            out[j][:] = col
        t = np.asarray(t, dtype=float)
        if t_prev is None:
            self.restart()
        floor = self.ltr_floor_n
        steps = [0.0 if t_prev is None else float(t[0] - t_prev)] + np.diff(t).tolist()
        qs = []
        for a, b, f1, f2, d in zip(fn1.tolist(), fn2.tolist(), fc1.tolist(), fc2.tolist(),
                                   steps):
            self.ltr_floor_n = LTR_FLOOR_FRACTION * (f1 + f2)
            qs.append(self.quasi_static_ltr(a, b, d))
        out[Column.LTR_QUASI_STATIC][:] = qs
        self.ltr_floor_n = floor

    def restart(self) -> None:
        """A new run: the quasi-static LTR's low-pass starts again at the next sample."""
        self._qs = None

    def quasi_static_ltr(self, fn1: float, fn2: float, dt: float) -> float:
        """The quasi-static LTR of the next sample from its loads (N) and the step dt (s)
        since the previous one (ignored at a restart); a non-finite load leaves the state."""
        a = fn1 if fn1 > 0.0 else 0.0
        b = fn2 if fn2 > 0.0 else 0.0
        st = self._qs
        if not math.isfinite(a + b):
            return math.nan
        if st is None:
            st = (a, a, b, b)
        else:
            if self._qs_e[0] != dt:
                self._qs_e = (dt, math.exp(-dt * self.rollover_rate))
            e = self._qs_e[1]
            g = 1.0 - e
            a1 = e * st[0] + g * a
            b1 = e * st[2] + g * b
            st = (a1, e * st[1] + g * a1, b1, e * st[3] + g * b1)
        self._qs = st
        return load_transfer_ratio(st[1], st[3], self.ltr_floor_n)

    def add_quasi_static(self, out: list, t: np.ndarray) -> None:
        """The quasi-static LTR column of one run's columns ``out`` (loads filled) at the
        times t (s): :meth:`quasi_static_ltr` sample by sample from a restart (in chunks of
        :data:`QUASI_STATIC_CHUNK` samples: the lists of floats stay small), its steps
        written out in one loop (the same operations in the same order: the same numbers,
        at less than half the time of a call per sample)."""
        self.restart()
        t = np.asarray(t, dtype=float)
        col, fn1, fn2 = out[Column.LTR_QUASI_STATIC], out[Column.FN1], out[Column.FN2]
        for k0 in range(0, t.size, QUASI_STATIC_CHUNK):
            k1 = min(t.size, k0 + QUASI_STATIC_CHUNK)
            steps = np.diff(t[k0 - 1:k1]).tolist() if k0 else [0.0] + np.diff(t[:k1]).tolist()
            col[k0:k1] = self._quasi_static_run(fn1[k0:k1].tolist(), fn2[k0:k1].tolist(),
                                                steps)
        self.restart()

    def _quasi_static_run(self, fn1: list, fn2: list, steps: list) -> list:
        """:meth:`quasi_static_ltr` over lists of loads (N) and steps (s), in order."""
        rate = self.rollover_rate
        floor = self.ltr_floor_n
        isfinite = math.isfinite
        exp = math.exp
        st = self._qs
        last_dt, e = self._qs_e
        out = []
        put = out.append
        if st is not None:
            s0, s1, s2, s3 = st
        for a, b, dt in zip(fn1, fn2, steps):
            if not a > 0.0:
                a = 0.0
            if not b > 0.0:
                b = 0.0
            if not isfinite(a + b):
                put(math.nan)
                continue
            if st is None:
                st = True
                s0 = s1 = a
                s2 = s3 = b
            else:
                if last_dt != dt:
                    last_dt = dt
                    e = exp(-dt * rate)
                g = 1.0 - e
                s0 = e * s0 + g * a
                s1 = e * s1 + g * s0
                s2 = e * s2 + g * b
                s3 = e * s3 + g * s2
            # load_transfer_ratio(s1, s3, floor), written out
            p = s1 if s1 > 0.0 else 0.0
            q = s3 if s3 > 0.0 else 0.0
            den = p + q
            put((q - p) / (den if den > floor else floor))
        self._qs = (s0, s1, s2, s3) if st is not None else None
        self._qs_e = (last_dt, e)
        return out

    def row(self, x: float, q1: float, q2: float, dq1: float, dq2: float, ddq1: float,
            ddq2: float, phi: float, dphi: float, ddphi: float, zs: float, dzs: float,
            ddzs: float, ddzu1: float, ddzu2: float, w1: float, w2: float, df1: float,
            df2: float, fb1: float, fb2: float, conv: bool, dt: float = 0.0,
            road: tuple[float, float] | None = None) -> tuple:
        """The output row (slots :class:`.Column`) of one sample (SI, see the module notes);
        ``dt`` (s): the step since the previous row of the run (see :meth:`restart`);
        ``road``: ``(u_1, u_2)`` (m) estimated otherwise (the model's profile filter), else
        ``z_ui + w_i``."""
        s, ix, fc1, fc2, lift1, lift2, ltr_floor = self._c
        cphi = math.cos(phi)
        sphi = math.sin(phi)
        ssin = s * sphi
        srate = s * cphi * dphi
        zu1 = zs + ssin - q1
        zu2 = zs - ssin - q2
        fn1 = fc1 + df1
        fn2 = fc2 + df2
        if fn1 < 0.0:
            fn1 = 0.0
        if fn2 < 0.0:
            fn2 = 0.0
        u1, u2 = (zu1 + w1, zu2 + w2) if road is None else road
        return (x, q1, q2, dq1, dq2, ddq1, ddq2, phi, dphi, ddphi, zs, dzs, ddzs, zu1, zu2,
                dzs + srate - dq1, dzs - srate - dq2, ddzu1, ddzu2, u1, u2, df1, df2,
                fn1, fn2, load_transfer_ratio(fn1, fn2, ltr_floor),
                ix * ddphi - s * cphi * (fb1 - fb2) - self.mgh * sphi, fn1 <= lift1,
                fn2 <= lift2, conv, self.quasi_static_ltr(fn1, fn2, dt), fc1, fc2)

    def columns(self, out: list, q: tuple, dq: tuple, ddq: tuple, phi, dphi, ddphi, ddzs,
                ddzu: tuple, w: tuple, df: tuple, fb: tuple, heave: tuple | None) -> None:
        """:meth:`row` over arrays: fill the columns ``out`` (slots :class:`.Column`, each
        (m,)) but the distance, ``converged`` and the quasi-static LTR
        (:meth:`add_quasi_static`, over the whole run).

        Pairs are ``(left, right)`` arrays. ``heave`` = ``(z_s, dz_s)`` arrays, or None for
        a smoother that has the body heave only after the whole run: then the wheel heaves
        and the road are written without it and :meth:`add_heave` adds it later.
        """
        s, ix, fc1, fc2, lift1, lift2, ltr_floor = self._c
        (q1, q2), (dq1, dq2), (df1, df2), (w1, w2) = q, dq, df, w
        cph = np.cos(phi)
        sph = np.sin(phi)
        ssin = s * sph
        srate = s * cph * dphi
        fn1 = np.maximum(fc1 + df1, 0.0)
        fn2 = np.maximum(fc2 + df2, 0.0)
        if heave is None:   # (the operations in the order the smoother's numbers were made)
            zu1, zu2 = ssin - q1, -ssin - q2
            dzu1, dzu2 = srate - dq1, -srate - dq2
            u1, u2 = ssin - q1 + w1, w2 - ssin - q2
        else:
            zs, dzs = heave
            out[Column.ZS][:] = zs
            out[Column.DZS][:] = dzs
            zu1, zu2 = zs + ssin - q1, zs - ssin - q2
            dzu1, dzu2 = dzs + srate - dq1, dzs - srate - dq2
            u1, u2 = zu1 + w1, zu2 + w2
        C = Column
        for j, col in ((C.Q1, q1), (C.Q2, q2), (C.DQ1, dq1), (C.DQ2, dq2), (C.DDQ1, ddq[0]),
                       (C.DDQ2, ddq[1]), (C.PHI, phi), (C.DPHI, dphi), (C.DDPHI, ddphi),
                       (C.DDZS, ddzs), (C.ZU1, zu1), (C.ZU2, zu2), (C.DZU1, dzu1),
                       (C.DZU2, dzu2), (C.DDZU1, ddzu[0]), (C.DDZU2, ddzu[1]), (C.U1, u1),
                       (C.U2, u2), (C.DF1, df1), (C.DF2, df2), (C.FN1, fn1), (C.FN2, fn2),
                       (C.LTR, load_transfer_ratios(fn1, fn2, ltr_floor)),
                       (C.RESIDUAL, ix * ddphi - s * cph * (fb[0] - fb[1]) - self.mgh * sph),
                       (C.LIFT_OFF1, fn1 <= lift1), (C.LIFT_OFF2, fn2 <= lift2),
                       (C.STATIC_LOAD1, fc1), (C.STATIC_LOAD2, fc2)):
            out[j][:] = col

    @staticmethod
    def add_heave(out: list, zs: np.ndarray, dzs: np.ndarray) -> None:
        """Add the body heave to columns :meth:`columns` wrote without it."""
        C = Column
        out[C.ZS][:] = zs
        out[C.DZS][:] = dzs
        for j, add in ((C.ZU1, zs), (C.ZU2, zs), (C.DZU1, dzs), (C.DZU2, dzs), (C.U1, zs),
                       (C.U2, zs)):
            out[j] += add
