"""The 4-DOF roll-plane model of a truck's front axle (``../shared/design/MODEL.md``).

States (named slots of :class:`State`): body heave z_s (m), roll phi (rad, > 0 when the LEFT
side goes up), wheel heaves z_u1 (left), z_u2 (right) (m), and their rates. All displacements
are measured from static equilibrium (gravity and spring preloads cancel). Inputs: the road
elevation u_i under each tire (m) and its rate du_i (m/s), and an optional lateral acceleration
a_y (m/s^2, > 0 to the left, REP-103).

Kinematics and forces (index 1 = left, 2 = right, s = T/2)::

    q_1 = z_s + s sin(phi) - z_u1          q_2 = z_s - s sin(phi) - z_u2      (extensions)
    F_bi = -(k_i q_i + c_i dq_i)                                (suspension force on the body)
    dF_i = max(kt_i (u_i - z_ui) + ct_i (du_i - dz_ui), -F_c,i)   (dynamic tire force; the
                                                                    tire never pulls)
    M   dd z_s = F_b1 + F_b2
    I_x dd phi = s cos(phi) (F_b1 - F_b2) + M h (a_y cos(phi) + g sin(phi))
    m_i dd z_ui = -F_bi + dF_i
    F_n,i = F_c,i + dF_i >= 0                                        (vertical wheel load)

The gravity moment M g h sin(phi) (MODEL.md, issue 19) lowers the roll stiffness from
2 k s^2 to 2 k s^2 - M g h; the heave equation has no cos(phi) on the suspension forces, as
in MODEL.md. This is the model the observers invert, and the plant is exactly that model.

The per-sample path (:meth:`VehicleModel.make_accelerations`) works on plain floats with the
math module; the array methods broadcast over leading dimensions.
"""
from __future__ import annotations

from dataclasses import dataclass
import enum
import math
from typing import Callable

import numpy as np

from road_force_estimator.core.friction import FrictionLaw, stick_force, tanh_force, tanh_forces
from road_force_estimator.core.parameters import GRAVITY_MPS2, VehicleParameters

__all__ = ['State', 'VehicleModel', 'ModelOutputs', 'LinearModel', 'Mode', 'SpringOptions']

@dataclass(frozen=True)
class SpringOptions:
    """Plant-only nonlinear springs (``simulator.spring_progression``, ``simulator.bump_stop_*``).

    The spring force on the body becomes ``-k q (1 + p max(-q, 0))`` (progressive: the
    stiffness rises by ``k p`` per metre of compression) plus, beyond the clearance d,
    ``k_b (-q - d)`` (the bump stop, pushing the body up). q from static equilibrium (m).
    """

    progression_per_m: float = 0.0
    bump_stop_clearance_m: float = 0.05
    bump_stop_stiffness_npm: float = 0.0

    @property
    def active(self) -> bool:
        """True when the springs differ from the linear ones."""
        return self.progression_per_m > 0.0 or self.bump_stop_stiffness_npm > 0.0

    @classmethod
    def from_simulator(cls, sim) -> SpringOptions:
        """From :class:`.SimulatorParameters`."""
        return cls(sim.spring_progression_per_m, sim.bump_stop_clearance_m,
                   sim.bump_stop_stiffness_npm)


class State(enum.IntEnum):
    """Named slots of the state vector (m, rad, m/s, rad/s)."""

    Z_S = 0
    PHI = 1
    Z_U1 = 2
    Z_U2 = 3
    DZ_S = 4
    DPHI = 5
    DZ_U1 = 6
    DZ_U2 = 7


@dataclass(frozen=True)
class ModelOutputs:
    """Everything the model says about a state (arrays broadcast over leading dimensions).

    Per-side arrays have a last axis of 2 ([left, right]).
    """

    q_m: np.ndarray                     #: suspension extension q_i (m), (..., 2)
    dq_mps: np.ndarray                  #: its rate (m/s), (..., 2)
    suspension_force_n: np.ndarray      #: F_bi, upward on the body (N), (..., 2)
    tire_force_dynamic_n: np.ndarray    #: dF_i, clamped at -F_c,i (N), (..., 2)
    wheel_load_n: np.ndarray            #: F_n,i = F_c,i + dF_i >= 0 (N), (..., 2)
    lift_off: np.ndarray                #: True where the tire force is clamped, (..., 2)
    body_accel_mps2: np.ndarray         #: dd z_s (m/s^2), (...)
    roll_accel_radps2: np.ndarray       #: dd phi (rad/s^2), (...)
    wheel_accel_mps2: np.ndarray        #: dd z_ui (m/s^2), (..., 2)


@dataclass(frozen=True)
class LinearModel:
    """Small-motion model about phi = 0 in coordinates x = (z_s, phi, z_u1, z_u2)::

        mass @ ddx + damping @ dx + stiffness @ x = road_stiffness @ u + road_damping @ du
                                                    + lateral * a_y

    Tire lift-off is ignored (linear). Units: kg, kg m^2, N s/m, N/m, N m/rad.
    """

    mass: np.ndarray            #: (4, 4)
    damping: np.ndarray         #: (4, 4)
    stiffness: np.ndarray       #: (4, 4)
    road_stiffness: np.ndarray  #: (4, 2)
    road_damping: np.ndarray    #: (4, 2)
    lateral: np.ndarray         #: (4,): generalized force per unit a_y

    def state_matrices(self) -> tuple[np.ndarray, np.ndarray]:
        """First-order form d/dt [x, dx] = A [x, dx] + B [u_1, u_2, du_1, du_2, a_y].

        Returns
        -------
        A : ndarray, shape (8, 8)
        B : ndarray, shape (8, 5)
        """
        minv = np.linalg.inv(self.mass)
        a = np.zeros((8, 8))
        a[:4, 4:] = np.eye(4)
        a[4:, :4] = -minv @ self.stiffness
        a[4:, 4:] = -minv @ self.damping
        b = np.zeros((8, 5))
        b[4:, 0:2] = minv @ self.road_stiffness
        b[4:, 2:4] = minv @ self.road_damping
        b[4:, 4] = minv @ self.lateral
        return a, b


@dataclass(frozen=True)
class Mode:
    """One vibration mode of the linear model."""

    name: str                   #: 'bounce', 'roll', 'wheel_hop' or 'wheel_tramp'
    frequency_hz: float         #: undamped natural frequency (Hz)
    damped_frequency_hz: float  #: |Im(lambda)| / 2 pi of the damped pole (Hz)
    damping_ratio: float        #: -Re(lambda) / |lambda|
    shape: np.ndarray           #: undamped mode shape over (z_s, phi, z_u1, z_u2)


class VehicleModel:
    """The roll-plane model of MODEL.md for one set of :class:`VehicleParameters`.

    Parameters
    ----------
    vehicle : VehicleParameters
        Validated parameters (SI); index 0 = left.

    Attributes
    ----------
    vehicle : VehicleParameters
    static_load_n : tuple of float
        F_c,i (N).
    """

    def __init__(self, vehicle: VehicleParameters, springs: SpringOptions | None = None) -> None:
        if not isinstance(vehicle, VehicleParameters):
            raise TypeError(f'vehicle must be VehicleParameters, got {type(vehicle).__name__}')
        self.vehicle = vehicle
        self.static_load_n = tuple(float(f) for f in vehicle.static_load_n)
        v = vehicle
        self._m = float(v.sprung_mass_kg)
        self._ix = float(v.roll_inertia_kgm2)
        self._s = float(v.half_track_m)
        self._h = float(v.cg_height_m)
        self._mu = np.array(v.unsprung_mass_kg, dtype=np.float64)
        self._k = np.array(v.suspension_stiffness_npm, dtype=np.float64)
        self._c = np.array(v.suspension_damping_nspm, dtype=np.float64)
        self._kt = np.array(v.tire_stiffness_npm, dtype=np.float64)
        self._ct = np.array(v.tire_damping_nspm, dtype=np.float64)
        self._fc = np.array(self.static_load_n, dtype=np.float64)
        self._ff = tuple(float(f) for f in v.leaf_spring_friction_n)
        #: the friction law (:mod:`.friction`): tanh with v_f, or the stick element
        self.friction = FrictionLaw(v.leaf_spring_friction_model,
                                    v.leaf_spring_friction_velocity_mps,
                                    v.leaf_spring_friction_stiffness_ratio)
        self._vf = self.friction.velocity_mps
        #: True with stick friction on a spring: the per-sample closures read the sliders'
        #: bases from :attr:`slider_base` ([left, right], N), which the plant advances
        self.sticks = self.friction.sticks and any(f > 0.0 for f in self._ff)
        self.slider_base = [0.0, 0.0]
        #: k_f of each side's stick element (N/m)
        self.stick_stiffness_npm = tuple(self.friction.stiffness_ratio * float(k)
                                         for k in self._k)
        self.springs = springs if springs is not None else SpringOptions()
        #: True when friction or nonlinear springs act (the general per-sample closures).
        self.nonlinear_suspension = self.springs.active or any(f > 0.0 for f in self._ff)

    # ----------------------------------------------------------------------------------------
    # Nonlinear model
    # ----------------------------------------------------------------------------------------

    def _scalars(self) -> tuple[float, ...]:
        """The parameters as plain floats for the per-sample closures: ``(s, 1/M, 1/I_x, M h,
        M g h, k_1, k_2, c_1, c_2, kt_1, kt_2, ct_1, ct_2, 1/m_1, 1/m_2, F_c1, F_c2)``."""
        k1, k2 = (float(x) for x in self._k)
        c1, c2 = (float(x) for x in self._c)
        kt1, kt2 = (float(x) for x in self._kt)
        ct1, ct2 = (float(x) for x in self._ct)
        inv_m1, inv_m2 = (1.0 / float(x) for x in self._mu)
        fc1, fc2 = (float(x) for x in self._fc)
        mh = self._m * self._h
        return (self._s, 1.0 / self._m, 1.0 / self._ix, mh, mh * GRAVITY_MPS2, k1, k2, c1, c2,
                kt1, kt2, ct1, ct2, inv_m1, inv_m2, fc1, fc2)

    def make_accelerations(self) -> Callable[..., tuple[float, float, float, float]]:
        """A fast float-only function for integrators (the per-sample path).

        Returns
        -------
        callable
            ``f(z_s, phi, z_u1, z_u2, dz_s, dphi, dz_u1, dz_u2, u_1, u_2, du_1, du_2, a_y)``
            returning ``(dd z_s, dd phi, dd z_u1, dd z_u2)``; all plain floats, SI units.
        """
        if self.nonlinear_suspension:
            return self._general_accelerations()
        (s, inv_m, inv_ix, mh, mgh, k1, k2, c1, c2, kt1, kt2, ct1, ct2, inv_m1, inv_m2, fc1,
         fc2) = self._scalars()
        floor1, floor2 = -fc1, -fc2
        sin, cos = math.sin, math.cos

        def accelerations(zs, ph, z1, z2, vs, vp, v1, v2, u1, u2, du1, du2, ay):
            sn = sin(ph)
            sp = s * sn
            cp = cos(ph)
            w = s * cp * vp
            fb1 = -(k1 * (zs + sp - z1) + c1 * (vs + w - v1))
            fb2 = -(k2 * (zs - sp - z2) + c2 * (vs - w - v2))
            f1 = kt1 * (u1 - z1) + ct1 * (du1 - v1)
            if f1 < floor1:
                f1 = floor1
            f2 = kt2 * (u2 - z2) + ct2 * (du2 - v2)
            if f2 < floor2:
                f2 = floor2
            return ((fb1 + fb2) * inv_m,
                    (s * cp * (fb1 - fb2) + mh * ay * cp + mgh * sn) * inv_ix,
                    (f1 - fb1) * inv_m1,
                    (f2 - fb2) * inv_m2)

        return accelerations

    def make_outputs(self) -> Callable[..., tuple[float, ...]]:
        """A float-only function giving every per-sample output of a state.

        Returns
        -------
        callable
            ``g(z_s, phi, z_u1, z_u2, dz_s, dphi, dz_u1, dz_u2, u_1, u_2, du_1, du_2, a_y)``
            returning ``(q_1, q_2, dq_1, dq_2, F_b1, F_b2, dF_1, dF_2, F_n1, F_n2,
            dd z_s, dd phi, dd z_u1, dd z_u2)`` with the same arithmetic as
            :meth:`make_accelerations`.
        """
        if self.nonlinear_suspension:
            return self._general_outputs()
        (s, inv_m, inv_ix, mh, mgh, k1, k2, c1, c2, kt1, kt2, ct1, ct2, inv_m1, inv_m2, fc1,
         fc2) = self._scalars()
        sin, cos = math.sin, math.cos

        def outputs(zs, ph, z1, z2, vs, vp, v1, v2, u1, u2, du1, du2, ay):
            sn = sin(ph)
            sp = s * sn
            cp = cos(ph)
            w = s * cp * vp
            q1, q2 = zs + sp - z1, zs - sp - z2
            dq1, dq2 = vs + w - v1, vs - w - v2
            fb1 = -(k1 * q1 + c1 * dq1)
            fb2 = -(k2 * q2 + c2 * dq2)
            f1 = kt1 * (u1 - z1) + ct1 * (du1 - v1)
            if f1 < -fc1:
                f1 = -fc1
            f2 = kt2 * (u2 - z2) + ct2 * (du2 - v2)
            if f2 < -fc2:
                f2 = -fc2
            return (q1, q2, dq1, dq2, fb1, fb2, f1, f2, max(fc1 + f1, 0.0), max(fc2 + f2, 0.0),
                    (fb1 + fb2) * inv_m,
                    (s * cp * (fb1 - fb2) + mh * ay * cp + mgh * sn) * inv_ix,
                    (f1 - fb1) * inv_m1,
                    (f2 - fb2) * inv_m2)

        return outputs

    def _general_accelerations(self) -> Callable[..., tuple[float, float, float, float]]:
        """:meth:`make_accelerations` with friction and nonlinear springs (the arithmetic of
        :meth:`_general_outputs`; with linear springs the spring force stays inline)."""
        if self.springs.active or self.sticks:
            outputs = self._general_outputs()

            def general(zs, ph, z1, z2, vs, vp, v1, v2, u1, u2, du1, du2, ay):
                return outputs(zs, ph, z1, z2, vs, vp, v1, v2, u1, u2, du1, du2, ay)[10:]

            return general
        (s, inv_m, inv_ix, mh, mgh, k1, k2, c1, c2, kt1, kt2, ct1, ct2, inv_m1, inv_m2, fc1,
         fc2) = self._scalars()
        ff1, ff2 = self._ff
        floor1, floor2 = -fc1, -fc2
        sin, cos = math.sin, math.cos
        inv_vf = 1.0 / self._vf

        def friction(zs, ph, z1, z2, vs, vp, v1, v2, u1, u2, du1, du2, ay):
            sn = sin(ph)
            sp = s * sn
            cp = cos(ph)
            w = s * cp * vp
            dq1 = vs + w - v1
            dq2 = vs - w - v2
            # the tanh law of .friction (a + tanh_force(..) == a - F_f tanh(..), bit for bit)
            fb1 = -k1 * (zs + sp - z1) - c1 * dq1 + tanh_force(ff1, dq1, inv_vf)
            fb2 = -k2 * (zs - sp - z2) - c2 * dq2 + tanh_force(ff2, dq2, inv_vf)
            f1 = kt1 * (u1 - z1) + ct1 * (du1 - v1)
            if f1 < floor1:
                f1 = floor1
            f2 = kt2 * (u2 - z2) + ct2 * (du2 - v2)
            if f2 < floor2:
                f2 = floor2
            return ((fb1 + fb2) * inv_m,
                    (s * cp * (fb1 - fb2) + mh * ay * cp + mgh * sn) * inv_ix,
                    (f1 - fb1) * inv_m1,
                    (f2 - fb2) * inv_m2)

        return friction

    def _general_outputs(self) -> Callable[..., tuple[float, ...]]:
        """:meth:`make_outputs` with the leaf-spring friction (``-F_f tanh(dq / v_f)``, or the
        stick element of :mod:`.friction` with the bases of :attr:`slider_base`) and the
        nonlinear springs of :class:`SpringOptions` in the suspension forces."""
        (s, inv_m, inv_ix, mh, mgh, k1, k2, c1, c2, kt1, kt2, ct1, ct2, inv_m1, inv_m2, fc1,
         fc2) = self._scalars()
        ff1, ff2 = self._ff
        sp_ = self.springs
        prog, clear, kb = (sp_.progression_per_m, sp_.bump_stop_clearance_m,
                           sp_.bump_stop_stiffness_npm)
        sin, cos = math.sin, math.cos
        inv_vf = 1.0 / self._vf
        base = self.slider_base
        kf1, kf2 = self.stick_stiffness_npm
        if self.sticks:
            def leaf(ff, dq, q, side):
                return stick_force(base[side], kf1 if side == 0 else kf2, q, ff)
        else:
            def leaf(ff, dq, q, side):
                return tanh_force(ff, dq, inv_vf)

        def spring(k, q):
            f = -k * q
            if q < 0.0:
                f -= k * prog * q * -q
                if q < -clear:
                    f += kb * (-q - clear)
            return f

        def outputs(zs, ph, z1, z2, vs, vp, v1, v2, u1, u2, du1, du2, ay):
            sn = sin(ph)
            sp = s * sn
            cp = cos(ph)
            w = s * cp * vp
            q1, q2 = zs + sp - z1, zs - sp - z2
            dq1, dq2 = vs + w - v1, vs - w - v2
            fb1 = spring(k1, q1) - c1 * dq1 + leaf(ff1, dq1, q1, 0)
            fb2 = spring(k2, q2) - c2 * dq2 + leaf(ff2, dq2, q2, 1)
            f1 = kt1 * (u1 - z1) + ct1 * (du1 - v1)
            if f1 < -fc1:
                f1 = -fc1
            f2 = kt2 * (u2 - z2) + ct2 * (du2 - v2)
            if f2 < -fc2:
                f2 = -fc2
            return (q1, q2, dq1, dq2, fb1, fb2, f1, f2, max(fc1 + f1, 0.0), max(fc2 + f2, 0.0),
                    (fb1 + fb2) * inv_m,
                    (s * cp * (fb1 - fb2) + mh * ay * cp + mgh * sn) * inv_ix,
                    (f1 - fb1) * inv_m1,
                    (f2 - fb2) * inv_m2)

        return outputs

    def evaluate(self, state, road_m, road_rate_mps=(0.0, 0.0),
                 lateral_accel_mps2=0.0, slider_force_n=(0.0, 0.0)) -> ModelOutputs:
        """Kinematics, forces and accelerations for state(s) and input(s).

        Parameters
        ----------
        state : array_like, shape (..., 8)
            See :class:`State`.
        road_m : array_like, shape (..., 2)
            Road elevation u_i under each tire (m).
        road_rate_mps : array_like, shape (..., 2)
            du_i/dt (m/s); only matters with tire damping.
        lateral_accel_mps2 : float or array_like, shape (...)
            a_y (m/s^2, > 0 to the left).
        slider_force_n : array_like, shape (..., 2)
            Stick friction only: the elements' forces on the body (N, > 0 upward).
        """
        x = np.asarray(state, dtype=np.float64)
        u = np.asarray(road_m, dtype=np.float64)
        du = np.asarray(road_rate_mps, dtype=np.float64)
        ay = np.asarray(lateral_accel_mps2, dtype=np.float64)
        zs, ph, vs, vp = x[..., 0], x[..., 1], x[..., 4], x[..., 5]
        zu, vu = x[..., 2:4], x[..., 6:8]
        s = self._s
        sign = np.array([1.0, -1.0])
        arm = (s * np.sin(ph))[..., None] * sign
        w = (s * np.cos(ph) * vp)[..., None] * sign
        q = zs[..., None] + arm - zu
        dq = vs[..., None] + w - vu
        fb = -(self._k * q + self._c * dq)
        if self.nonlinear_suspension:
            sp = self.springs
            comp = np.maximum(-q, 0.0)
            fb = (fb + self._k * sp.progression_per_m * q * q * (q < 0.0)
                  + sp.bump_stop_stiffness_npm * np.maximum(comp - sp.bump_stop_clearance_m, 0.0))
            if self.sticks:
                fb = fb + np.asarray(slider_force_n, dtype=np.float64)
            else:       # a - F_f tanh(dq / v_f): the array form of .friction, bit for bit
                fb = fb + tanh_forces(self._ff, dq, self._vf)
        df_free = self._kt * (u - zu) + self._ct * (du - vu)
        lift = df_free < -self._fc
        df = np.maximum(df_free, -self._fc)
        load = np.maximum(self._fc + df, 0.0)
        cp = np.cos(ph)
        acc_s = (fb[..., 0] + fb[..., 1]) / self._m
        mh = self._m * self._h
        acc_p = (s * cp * (fb[..., 0] - fb[..., 1]) + mh * ay * cp
                 + mh * GRAVITY_MPS2 * np.sin(ph)) / self._ix
        acc_u = (df - fb) / self._mu
        return ModelOutputs(q, dq, fb, df, load, lift, acc_s, acc_p, acc_u)

    def derivatives(self, state, road_m, road_rate_mps=(0.0, 0.0),
                    lateral_accel_mps2=0.0) -> np.ndarray:
        """d(state)/dt, shape (..., 8) (see :meth:`evaluate` for the arguments)."""
        x = np.asarray(state, dtype=np.float64)
        out = self.evaluate(x, road_m, road_rate_mps, lateral_accel_mps2)
        return np.concatenate((x[..., 4:8], out.body_accel_mps2[..., None],
                               out.roll_accel_radps2[..., None], out.wheel_accel_mps2),
                              axis=-1)

    def equilibrium(self, road_m, road_rate_mps=(0.0, 0.0),
                    lateral_accel_mps2: float = 0.0,
                    slider_force_n: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
        """The state at rest on the road (quasi-static), shape (8,).

        Positions: the static equilibrium under a constant ``a_y`` on a road held at
        ``road_m``: F_b1 = -F_b2 = F, dF_i = F_bi, and the roll equation
        ``2 s cos(phi) F + M h (a_y cos(phi) + g sin(phi)) = 0`` with the kinematics
        ``2 s sin(phi) = u_1 - u_2 - F (1/k_1 + 1/k_2 + 1/kt_1 + 1/kt_2)``, solved for phi by
        Newton's method (the gravity moment couples them; equal sides, small angles:
        ``phi = M h a_y / (2 k_e s^2 - M g h)`` on a level road, k_e the suspension and the
        tire in series). Rates: the whole axle follows the road's rate (dz_ui = du_i,
        dq_i = 0), so that no spring or damper force acts at the start. ``slider_force_n``:
        stick friction holding forces f_0,i on the body (N, > 0 upward) at the start: the
        springs carry that much less, ``q_i = -(F_bi - f_0,i) / k_i``.

        Raises
        ------
        ValueError
            ``a_y`` beyond the rollover limit (a wheel would lift off: no equilibrium), or a
            roll the gravity moment tips over.
        """
        u1, u2 = (float(v) for v in road_m)
        du1, du2 = (float(v) for v in road_rate_mps)
        ay = float(lateral_accel_mps2)
        s = self._s
        held = tuple(float(f) for f in slider_force_n)
        du = u1 - u2
        if held != (0.0, 0.0):  # the springs' share of F_bi: the roll sees their offsets
            du = du + held[0] / float(self._k[0]) - held[1] / float(self._k[1])
        phi = _roll_equilibrium(s, self._m * self._h, ay, du,
                                float(np.sum(1.0 / self._k) + np.sum(1.0 / self._kt)))
        fb1 = -self._m * self._h * (ay + GRAVITY_MPS2 * math.tan(phi)) / (2.0 * s)
        fb = np.array([fb1, -fb1])
        if np.any(fb < -self._fc):
            fc = float(np.min(self._fc))
            tilt = math.asin(min(fc * float(np.sum(1.0 / self._k) + np.sum(1.0 / self._kt))
                                 / (2.0 * s), 1.0))
            limit = 2.0 * s * fc / (self._m * self._h) - GRAVITY_MPS2 * math.tan(tilt)
            raise ValueError(f'lateral_accel_mps2 = {ay:g} at the start exceeds the rollover '
                             f'limit {limit:.3g} m/s^2 of this vehicle: no equilibrium')
        q = -fb / self._k if held == (0.0, 0.0) else -(fb - np.array(held)) / self._k
        zu = np.array([u1, u2]) - fb / self._kt
        a1, a2 = q + zu                     # z_s +- s sin(phi)
        zs = 0.5 * (a1 + a2)
        dphi = (du1 - du2) / (2.0 * s * math.cos(phi))
        return np.array([zs, phi, zu[0], zu[1], 0.5 * (du1 + du2), dphi, du1, du2])

    # ----------------------------------------------------------------------------------------
    # Linear model
    # ----------------------------------------------------------------------------------------

    def linearised(self) -> LinearModel:
        """The small-motion model about phi = 0 (no lift-off), see :class:`LinearModel`."""
        s = self._s
        k1, k2 = self._k
        c1, c2 = self._c
        kt1, kt2 = self._kt
        ct1, ct2 = self._ct

        def matrix(a1, a2, b1, b2):
            # Rows: heave, roll, left wheel, right wheel; q_1 = z_s + s phi - z_u1 etc.
            return np.array([
                [a1 + a2, s * (a1 - a2), -a1, -a2],
                [s * (a1 - a2), s * s * (a1 + a2), -s * a1, s * a2],
                [-a1, -s * a1, a1 + b1, 0.0],
                [-a2, s * a2, 0.0, a2 + b2],
            ])

        mass = np.diag([self._m, self._ix, self._mu[0], self._mu[1]])
        road_k = np.array([[0.0, 0.0], [0.0, 0.0], [kt1, 0.0], [0.0, kt2]])
        road_c = np.array([[0.0, 0.0], [0.0, 0.0], [ct1, 0.0], [0.0, ct2]])
        lateral = np.array([0.0, self._m * self._h, 0.0, 0.0])
        stiffness = matrix(k1, k2, kt1, kt2)
        stiffness[1, 1] -= self._m * GRAVITY_MPS2 * self._h     # the gravity moment M g h phi
        return LinearModel(mass, matrix(c1, c2, ct1, ct2), stiffness, road_k, road_c, lateral)

    def modes(self) -> list[Mode]:
        """The four vibration modes, sorted by undamped frequency.

        The two lowest modes are the body's: 'bounce' is the one whose kinetic energy is more
        in heave than in roll (relative to the other), 'roll' the other; the two highest are
        the wheels': 'wheel_hop' the one whose wheels move more in phase, 'wheel_tramp' the
        other. The same naming is applied to the undamped modes (frequency, shape) and to the
        damped poles of the first-order state matrix (damped frequency, damping ratio).
        """
        lin = self.linearised()
        w2, vecs = np.linalg.eig(np.linalg.solve(lin.mass, lin.stiffness))
        order = np.argsort(w2.real)
        undamped = _name_modes(np.sqrt(np.maximum(w2.real[order], 0.0)), vecs[:, order].real,
                               np.diag(lin.mass))
        a, _ = lin.state_matrices()
        lam, vecs_a = np.linalg.eig(a)
        upper = lam.imag >= 0.0
        lam, vecs_a = lam[upper], vecs_a[:, upper]
        if lam.size == 4:
            order = np.argsort(np.abs(lam))
            damped = _name_modes(lam[order], vecs_a[:4, order], np.diag(lin.mass))
        else:       # over-damped modes: poles on the real axis, no pairing to name
            damped = {}
        out = []
        for name, (wn, shape) in undamped.items():
            p = damped.get(name, (complex('nan'), None))[0]
            out.append(Mode(name, float(wn) / (2.0 * math.pi),
                            float(abs(p.imag)) / (2.0 * math.pi), float(-p.real / abs(p)),
                            shape / np.max(np.abs(shape))))
        return sorted(out, key=lambda m: m.frequency_hz)

    def natural_frequencies_hz(self) -> dict[str, float]:
        """Undamped natural frequency of each mode by name (Hz)."""
        return {mode.name: mode.frequency_hz for mode in self.modes()}

    def max_pole_magnitude(self) -> float:
        """Largest |lambda| of the linear state matrix (1/s): it bounds the RK4 step (with
        friction: at its steepest, a damping of ``F_f / v_f`` more; with nonlinear springs: the
        stiffness at 10 cm of compression)."""
        if self.nonlinear_suspension:
            return _stiffest(self).max_pole_magnitude()
        a, _ = self.linearised().state_matrices()
        return float(np.max(np.abs(np.linalg.eigvals(a))))


def _stiffest(model: VehicleModel) -> VehicleModel:
    """The linear model at the steepest friction slope (a damping of ``F_f / v_f`` more; stick
    friction: its stiffness k_f more) and the spring stiffness at 10 cm of compression (with
    the bump stop's)."""
    v, sp = model.vehicle, model.springs
    out = VehicleModel(v)
    bump = sp.bump_stop_stiffness_npm
    out._k = model._k * (1.0 + 2.0 * 0.1 * sp.progression_per_m) + bump
    if model.sticks:        # the stick elements' springs k_f in parallel while they hold
        out._k = out._k + np.array(model.stick_stiffness_npm)
    else:
        out._c = model._c + np.array(model._ff) / model._vf
    out.nonlinear_suspension = False
    return out


def _roll_equilibrium(s: float, mh: float, ay: float, du: float, compliance: float) -> float:
    """The roll angle (rad) at rest: the root of ``2 s sin(phi) - du + F(phi) compliance``,
    ``F(phi) = -M h (a_y + g tan(phi)) / (2 s)`` (see :meth:`VehicleModel.equilibrium`)."""
    ratio = du / (2.0 * s)
    if abs(ratio) >= 1.0:
        raise ValueError(f'road difference {du:g} m exceeds the track width, no equilibrium')
    phi = math.asin(ratio)
    g = GRAVITY_MPS2
    for _ in range(100):
        cp = math.cos(phi)
        res = 2.0 * s * math.sin(phi) - du - mh * (ay + g * math.tan(phi)) * compliance / (2 * s)
        slope = 2.0 * s * cp - mh * g * compliance / (2.0 * s * cp * cp)
        if slope <= 0.0:
            raise ValueError('the gravity moment exceeds the roll stiffness: no equilibrium')
        step = res / slope
        phi -= step
        if abs(step) <= 1e-15 * max(1.0, abs(phi)):
            break
    if abs(phi) >= 0.5 * math.pi:
        raise ValueError('no roll equilibrium within +-90 degrees')
    return phi


def _name_modes(values: np.ndarray, shapes: np.ndarray, mass_diag: np.ndarray) -> dict:
    """Name four modes sorted by frequency: {name: (value, shape)} (see VehicleModel.modes)."""
    energy = mass_diag[:, None] * np.abs(shapes) ** 2
    heave_share = energy[0] / np.maximum(energy[0] + energy[1], 1e-300)
    in_phase = np.real(shapes[2] * np.conj(shapes[3])) / np.maximum(
        np.abs(shapes[2]) * np.abs(shapes[3]), 1e-300)
    bounce = 0 if heave_share[0] >= heave_share[1] else 1
    hop = 2 if in_phase[2] >= in_phase[3] else 3
    names = {bounce: 'bounce', 1 - bounce: 'roll', hop: 'wheel_hop', 5 - hop: 'wheel_tramp'}
    return {names[i]: (values[i], shapes[:, i]) for i in range(4)}
