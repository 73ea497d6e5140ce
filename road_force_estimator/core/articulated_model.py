"""The tractor and semi-trailer (``vehicle.model: articulated``): MODEL.md "The whole vehicle".

Generalised coordinates (named by :meth:`ArticulatedModel.dof_names`): for each body b in
(tractor, trailer) heave z_b (m, up), pitch theta_b (rad, > 0 nose down) and roll phi_b (rad,
> 0 left side up), then for each axle j, front first, heave z_a,j and roll phi_a,j; all from
static equilibrium. The state is the coordinates then their rates. Inputs per sample: the road
under each tire u_j,i (m, [left, right] per axle), its rate, a_y (m/s^2, > 0 to the left) and
a_x (m/s^2, dv/dt). MODEL.md's equations, index i = 1 left (+), 2 right (-)::

    q_j,i   = z_b + d_j sin(theta_b) +- s_j sin(phi_b) - (z_a,j +- s_j sin(phi_a,j))
    F_j,i   = -(k_j,i q_j,i + c_j,i dq_j,i)  (+ friction, progressive springs: options)
    dF_j,i  = max(kt_j,i (u_j,i - z_w,j,i) + ct_j,i (du_j,i - dz_w,j,i), -F_c,j,i)
    z_w,j,i = z_a,j +- w_j sin(phi_a,j);   M_ar,j = -kphi_j (phi_b - phi_a,j)
    delta   = z_t + (xi_5 - xi_t) sin(theta_t) - z_r - (xi_5 - xi_r) sin(theta_r)
    F_5     = -(k_5 delta + c_5 d delta);   M_5 = -(kphi_5 (phi_t - phi_r) + cphi_5 (..)')
    M_b   dd z_b     = sum_j (F_j,1 + F_j,2) + sigma_b F_5
    I_y,b dd theta_b = cos(theta_b) [sum_j d_j (F_j,1 + F_j,2) + sigma_b (xi_5 - xi_b) F_5]
                       - M_b H_b a_x
    I_x,b dd phi_b   = cos(phi_b) sum_j s_j (F_j,1 - F_j,2) + sum_j M_ar,j
                       + M_b h_b (a_y cos(phi_b) + g sin(phi_b)) + sigma_b M_5
    m_j   dd z_a,j   = -(F_j,1 + F_j,2) + dF_j,1 + dF_j,2
    I_a,j dd phi_a,j = -s_j cos(phi_a,j) (F_j,1 - F_j,2) + w_j cos(phi_a,j) (dF_j,1 - dF_j,2)
                       - M_ar,j + (h_rc,j S_j / g + rho_j m_j) a_y

(sigma_t = +1, sigma_r = -1; sums over the axles of body b.) The statics (:meth:`statics`)
are the linear statics of the spring system under gravity on a level road; a vehicle that
cannot stand is refused in one line.

The per-sample path (:meth:`ArticulatedModel.functions`) is Python source written for this
vehicle (every parameter a literal, zero terms left out) and compiled once: plain floats and
the math module, the fastest CPython form of these equations. It is the only implementation
of them: the plant's per-sample and batch paths, the equilibrium and the tests of the plant
all run it.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Callable

import numpy as np
from scipy.optimize import linear_sum_assignment

from road_force_estimator.core.articulated_parameters import ArticulatedParameters
from road_force_estimator.core.friction import FrictionLaw, stick_force, tanh_force
from road_force_estimator.core.parameters import GRAVITY_MPS2

__all__ = ['ArticulatedModel', 'Statics', 'LinearSystem', 'AxleSprings', 'ModeInfo']

BODIES = ('tractor', 'trailer')


@dataclass(frozen=True)
class AxleSprings:
    """Plant-only spring options of one axle: progression p (1/m), bump-stop clearance (m)
    and stiffness (N/m), as :class:`.vehicle_model.SpringOptions` (per axle)."""

    progression_per_m: float = 0.0
    bump_stop_clearance_m: float = 0.05
    bump_stop_stiffness_npm: float = 0.0

    @property
    def active(self) -> bool:
        return self.progression_per_m > 0.0 or self.bump_stop_stiffness_npm > 0.0


@dataclass(frozen=True)
class Statics:
    """The vehicle at rest on a level road (N; per-wheel arrays (N_axles, 2) [left, right]).

    ``spring_load_n``: S_j,i, the static spring forces (> 0: compressed);
    ``wheel_load_n``: F_c,j,i from the statics; ``output_wheel_load_n``: the same, or the
    configured ``static_load`` where it is set (what the outputs carry); ``kingpin_load_n``:
    the load the trailer puts on the fifth wheel; ``axle_load_kg`` and ``gross_weight_kg``:
    the wheel loads in tonnes-of-mass units (load / g).
    """

    spring_load_n: np.ndarray
    wheel_load_n: np.ndarray
    output_wheel_load_n: np.ndarray
    kingpin_load_n: float
    displacement: np.ndarray          #: the static deflection under gravity (coordinates)

    @property
    def axle_load_kg(self) -> np.ndarray:
        return self.output_wheel_load_n.sum(axis=1) / GRAVITY_MPS2

    @property
    def gross_weight_kg(self) -> float:
        return float(self.output_wheel_load_n.sum() / GRAVITY_MPS2)


@dataclass(frozen=True)
class LinearSystem:
    """Small motions about equilibrium (no lift-off, linear springs):
    ``mass ddx + damping dx + stiffness x = road_stiffness u + road_damping du
    + lateral a_y + longitudinal a_x`` (coordinates of :meth:`ArticulatedModel.dof_names`,
    u per tire [axle j left, right, ...])."""

    mass: np.ndarray
    damping: np.ndarray
    stiffness: np.ndarray
    road_stiffness: np.ndarray
    road_damping: np.ndarray
    lateral: np.ndarray
    longitudinal: np.ndarray

    def state_matrix(self) -> np.ndarray:
        """A of d/dt [x, dx] = A [x, dx] + ... (2n, 2n)."""
        n = self.mass.shape[0]
        minv = np.linalg.inv(self.mass)
        a = np.zeros((2 * n, 2 * n))
        a[:n, n:] = np.eye(n)
        a[n:, :n] = -minv @ self.stiffness
        a[n:, n:] = -minv @ self.damping
        return a


@dataclass(frozen=True)
class ModeInfo:
    """One mode of the linear model: ``name`` (the coordinate with the most kinetic energy,
    e.g. 'trailer_pitch', 'drive_axle_roll'), undamped and damped frequencies (Hz), damping
    ratio, and the real part of the pole (1/s, < 0: stable)."""

    name: str
    frequency_hz: float
    damped_frequency_hz: float
    damping_ratio: float
    real_part: float


def _lit(value: float) -> str:
    """A float literal that reads back exactly."""
    return repr(float(value))


class ArticulatedModel:
    """MODEL.md's tractor and semi-trailer for one :class:`ArticulatedParameters`.

    Parameters
    ----------
    vehicle : ArticulatedParameters
    springs : sequence of AxleSprings, optional
        Per axle, plant-only progressive springs and bump stops (default: linear; the
        vehicle's ``simulator.axle.<name>.*`` values with :meth:`from_vehicle_springs`).

    Raises
    ------
    ValueError
        The vehicle cannot stand (:meth:`statics`).
    """

    def __init__(self, vehicle: ArticulatedParameters, springs=None) -> None:
        if not isinstance(vehicle, ArticulatedParameters):
            raise TypeError(f'vehicle must be ArticulatedParameters, got '
                            f'{type(vehicle).__name__}')
        self.vehicle = vehicle
        self.axles = vehicle.axles
        self.n_axles = len(self.axles)
        self.n_dof = 6 + 2 * self.n_axles
        self.springs = tuple(springs) if springs is not None else tuple(
            AxleSprings() for _ in self.axles)
        if len(self.springs) != self.n_axles:
            raise ValueError('springs: one AxleSprings per axle')
        self.friction = FrictionLaw(vehicle.leaf_spring_friction_model,
                                    vehicle.leaf_spring_friction_velocity_mps,
                                    vehicle.leaf_spring_friction_stiffness_ratio)
        self.friction_n = np.array([a.leaf_spring_friction_n for a in self.axles], float)
        self.has_friction = bool(np.any(self.friction_n > 0.0))
        self.sticks = self.has_friction and self.friction.sticks
        self._statics = self._solve_statics()

    @classmethod
    def from_vehicle_springs(cls, vehicle: ArticulatedParameters) -> ArticulatedModel:
        """The model with each axle's ``simulator.axle.<name>.*`` springs."""
        return cls(vehicle, [AxleSprings(a.spring_progression_per_m, a.bump_stop_clearance_m,
                                         a.bump_stop_stiffness_npm) for a in vehicle.axles])

    # ----------------------------------------------------------------------------------------
    # Layout
    # ----------------------------------------------------------------------------------------

    def dof_names(self) -> list[str]:
        names = [f'{b}_{c}' for b in BODIES for c in ('heave', 'pitch', 'roll')]
        for a in self.axles:
            names += [f'{a.name}_axle_heave', f'{a.name}_axle_roll']
        return names

    def body_index(self, axle) -> int:
        """0 for the tractor, 1 for the trailer."""
        return 0 if axle.body == 'tractor' else 1

    def lever_m(self, axle) -> float:
        """d_j = xi_j - xi_b(j) (m)."""
        return axle.position_m - self.vehicle.body(axle.body).cg_position_m

    @property
    def length_m(self) -> float:
        """Distance from the front axle to the last axle (m)."""
        return self.axles[-1].position_m

    # ----------------------------------------------------------------------------------------
    # Linear model and statics
    # ----------------------------------------------------------------------------------------

    def _geometry(self):
        """Row vectors of the linearised kinematics over the coordinates: per spring and per
        tire ([axle][side]), the fifth wheel's vertical and roll differences."""
        n = self.n_dof
        springs, tires = [], []
        for j, a in enumerate(self.axles):
            b = 3 * self.body_index(a)
            ia = 6 + 2 * j
            d = self.lever_m(a)
            per_s, per_t = [], []
            for sign in (1.0, -1.0):
                e = np.zeros(n)
                e[b], e[b + 1], e[b + 2] = 1.0, d, sign * a.spring_half_track_m
                e[ia], e[ia + 1] = -1.0, -sign * a.spring_half_track_m
                per_s.append(e)
                g = np.zeros(n)
                g[ia], g[ia + 1] = 1.0, sign * a.wheel_half_track_m
                per_t.append(g)
            springs.append(per_s)
            tires.append(per_t)
        fw = self.vehicle.fifth_wheel
        delta = np.zeros(n)
        delta[0], delta[1] = 1.0, fw.position_m - self.vehicle.tractor.cg_position_m
        delta[3], delta[4] = -1.0, -(fw.position_m - self.vehicle.trailer.cg_position_m)
        roll5 = np.zeros(n)
        roll5[2], roll5[5] = 1.0, -1.0
        return springs, tires, delta, roll5

    def kinematics(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The linearised kinematics, rows over the coordinates of :meth:`dof_names`:
        ``(springs (N, 2, n), wheels (N, 2, n), delta (n,), roll (n,))``: per axle and side
        [left, right] the suspension extension q_j,i and the wheel's heave z_w,j,i, the fifth
        wheel's vertical difference delta and the roll difference phi_t - phi_r (what the
        linear model's springs see: :meth:`linearised`)."""
        springs, tires, delta, roll5 = self._geometry()
        return np.array(springs), np.array(tires), delta.copy(), roll5.copy()

    def _matrices(self, spring_scale: float = 1.0, extra_damping=None):
        """(mass, damping, stiffness, road_stiffness, road_damping) of the linear model."""
        n, v = self.n_dof, self.vehicle
        springs, tires, delta, roll5 = self._geometry()
        mass = np.zeros((n, n))
        kk = np.zeros((n, n))
        cc = np.zeros((n, n))
        ku = np.zeros((n, 2 * self.n_axles))
        cu = np.zeros((n, 2 * self.n_axles))
        for i, body in enumerate((v.tractor, v.trailer)):
            mass[3 * i, 3 * i] = body.mass_kg
            mass[3 * i + 1, 3 * i + 1] = body.pitch_inertia_kgm2
            mass[3 * i + 2, 3 * i + 2] = body.roll_inertia_kgm2
            kk[3 * i + 2, 3 * i + 2] -= body.mass_kg * GRAVITY_MPS2 * \
                body.cg_height_above_roll_axis_m
        for j, a in enumerate(self.axles):
            ia = 6 + 2 * j
            mass[ia, ia], mass[ia + 1, ia + 1] = a.mass_kg, a.roll_inertia_kgm2
            for side in (0, 1):
                e, g = springs[j][side], tires[j][side]
                extra = 0.0 if extra_damping is None else extra_damping[j][side]
                kk += spring_scale * a.suspension_stiffness_npm[side] * np.outer(e, e)
                cc += (a.suspension_damping_nspm[side] + extra) * np.outer(e, e)
                kk += a.tire_stiffness_npm[side] * np.outer(g, g)
                cc += a.tire_damping_nspm[side] * np.outer(g, g)
                ku[:, 2 * j + side] = a.tire_stiffness_npm[side] * g
                cu[:, 2 * j + side] = a.tire_damping_nspm[side] * g
            r = np.zeros(n)
            r[3 * self.body_index(a) + 2], r[ia + 1] = 1.0, -1.0
            kk += a.auxiliary_roll_stiffness_nmprad * np.outer(r, r)
        fw = v.fifth_wheel
        kk += fw.vertical_stiffness_npm * np.outer(delta, delta)
        cc += fw.vertical_damping_nspm * np.outer(delta, delta)
        kk += fw.roll_stiffness_nmprad * np.outer(roll5, roll5)
        cc += fw.roll_damping_nmsprad * np.outer(roll5, roll5)
        return mass, cc, kk, ku, cu

    def _solve_statics(self) -> Statics:
        """Linear statics under gravity on a level road; refuse a vehicle that cannot stand."""
        v = self.vehicle
        mass, _, kk, _, _ = self._matrices()
        lam, vecs = np.linalg.eigh(0.5 * (kk + kk.T))
        if lam[0] <= 1e-9 * lam[-1]:
            worst = self.dof_names()[int(np.argmax(np.abs(vecs[:, 0])))]
            raise ValueError(f'the vehicle cannot stand: the static stiffness is not positive '
                             f'(mode {worst}: {lam[0]:.3g}); e.g. a roll stiffness below the '
                             f'gravity moment M g h or an axle layout that cannot carry a '
                             f'body')
        force = np.zeros(self.n_dof)
        force[0] = -v.tractor.mass_kg * GRAVITY_MPS2
        force[3] = -v.trailer.mass_kg * GRAVITY_MPS2
        for j, a in enumerate(self.axles):
            force[6 + 2 * j] = -a.mass_kg * GRAVITY_MPS2
        x = np.linalg.solve(kk, force)
        springs, tires, delta, _ = self._geometry()
        spring = np.array([[-a.suspension_stiffness_npm[i] * (springs[j][i] @ x)
                            for i in (0, 1)] for j, a in enumerate(self.axles)])
        wheel = np.array([[-a.tire_stiffness_npm[i] * (tires[j][i] @ x) for i in (0, 1)]
                          for j, a in enumerate(self.axles)])
        kingpin = float(v.fifth_wheel.vertical_stiffness_npm * (delta @ x))
        if kingpin <= 0.0:
            raise ValueError(f'the vehicle cannot stand: the kingpin would pull '
                             f"({kingpin:.4g} N); move the trailer's centre of gravity "
                             'forward or its axles back')
        for j, a in enumerate(self.axles):
            for i, side in enumerate(('left', 'right')):
                if spring[j, i] <= 0.0:
                    raise ValueError(f'the vehicle cannot stand: the {side} spring of axle '
                                     f'{a.name} would pull ({spring[j, i]:.4g} N): it carries '
                                     "no load (move the axle or the body's centre of "
                                     'gravity)')
                if wheel[j, i] <= 0.0:
                    raise ValueError(f'the vehicle cannot stand: the {side} wheel of axle '
                                     f'{a.name} lifts at rest ({wheel[j, i]:.4g} N)')
        setting = np.array([a.static_load_setting_n for a in self.axles], float)
        output = np.where(setting > 0.0, setting, wheel)
        return Statics(spring, wheel, output, kingpin, x)

    def statics(self) -> Statics:
        """The static loads (:class:`Statics`)."""
        return self._statics

    def linearised(self) -> LinearSystem:
        """The small-motion model about equilibrium (no lift-off; the tanh friction and the
        nonlinear springs left out, stick friction as stuck with ``stuck=True`` in
        :meth:`modes`)."""
        return self._linear()

    def _linear(self, stuck: bool = False) -> LinearSystem:
        scale = 1.0 + (self.friction.stiffness_ratio if stuck else 0.0)
        mass, cc, kk, ku, cu = self._matrices(scale if stuck else 1.0)
        n = self.n_dof
        lat = np.zeros(n)
        lon = np.zeros(n)
        for i, body in enumerate((self.vehicle.tractor, self.vehicle.trailer)):
            lat[3 * i + 2] = body.mass_kg * body.cg_height_above_roll_axis_m
            lon[3 * i + 1] = -body.mass_kg * body.cg_height_m
        for j, a in enumerate(self.axles):
            lat[6 + 2 * j + 1] = self._axle_lateral(j)
        return LinearSystem(mass, cc, kk, ku, cu, lat, lon)

    def _axle_lateral(self, j: int) -> float:
        """(h_rc,j S_j / g + rho_j m_j): the axle's roll moment per unit a_y (kg m)."""
        a = self.axles[j]
        s = float(self._statics.spring_load_n[j].sum())
        return a.roll_centre_height_m * s / GRAVITY_MPS2 + a.wheel_radius_m * a.mass_kg

    def modes(self, stuck: bool = False) -> list[ModeInfo]:
        """The modes of the linear model, by undamped frequency; each named after a coordinate
        holding much of its kinetic energy (the assignment of the largest shares, each name
        once), or ``fifth_wheel`` when the coupling's spring holds most of its strain energy
        (``stuck``: the stick friction's springs k_f in parallel, as while the sliders
        hold)."""
        lin = self._linear(stuck)
        names = self.dof_names()
        _, _, delta, _ = self._geometry()
        k5 = self.vehicle.fifth_wheel.vertical_stiffness_npm * np.outer(delta, delta)
        w2, vecs = np.linalg.eig(np.linalg.solve(lin.mass, lin.stiffness))
        lam, lvecs = np.linalg.eig(lin.state_matrix())
        keep = lam.imag >= 0.0
        lam, lvecs = lam[keep], lvecs[:self.n_dof, keep]
        mass = np.diag(lin.mass)
        free = list(range(lam.size))
        order = np.argsort(w2.real)
        shapes = vecs[:, order].real
        energy = mass[:, None] * shapes ** 2
        energy = energy / np.maximum(energy.sum(axis=0), 1e-300)
        # each coordinate names one mode: the assignment of most kinetic energy (the three
        # trailer axles' nearly equal modes would otherwise share a name)
        rows, cols = linear_sum_assignment(-energy)
        coordinate = dict(zip(cols.tolist(), rows.tolist()))
        out = []
        for i, k in enumerate(order):
            wn = math.sqrt(max(w2.real[k], 0.0))
            shape = shapes[:, i]
            strain = float(shape @ k5 @ shape) / max(float(shape @ lin.stiffness @ shape),
                                                     1e-300)
            name = 'fifth_wheel' if strain > 0.5 else names[coordinate[i]]
            # the damped pole whose shape is closest (mass-weighted) to this mode's
            p = 0j
            if free:
                score = [abs(np.vdot(mass * shape, lvecs[:, i])) / (
                    np.linalg.norm(np.sqrt(mass) * shape)
                    * np.linalg.norm(np.sqrt(mass) * lvecs[:, i]) + 1e-300) for i in free]
                p = lam[free.pop(int(np.argmax(score)))]
            out.append(ModeInfo(name, wn / (2 * math.pi), abs(p.imag) / (2 * math.pi),
                                float(-p.real / abs(p)) if abs(p) else 1.0, float(p.real)))
        return out

    def poles(self, stuck: bool = False) -> np.ndarray:
        """Eigenvalues of the linear state matrix (1/s)."""
        return np.linalg.eigvals(self._linear(stuck).state_matrix())

    def max_pole_magnitude(self) -> float:
        """Largest |lambda| (1/s) over the linear model, stuck friction (stiffer springs), the
        tanh friction's steepest slope (damping F_f / v_f) and the nonlinear springs at 10 cm
        of compression: it bounds the explicit step."""
        extra = None
        if self.has_friction and not self.friction.sticks:
            extra = [[self.friction.steepest_damping_nspm(f) for f in row]
                     for row in self.friction_n]
        stiff = max(1.0 + 2.0 * 0.1 * sp.progression_per_m + sp.bump_stop_stiffness_npm /
                    min(a.suspension_stiffness_npm) for sp, a in zip(self.springs, self.axles))
        if self.sticks:
            stiff += self.friction.stiffness_ratio
        mass, cc, kk, _, _ = self._matrices(stiff, extra)
        lin = LinearSystem(mass, cc, kk, *([None] * 4))
        return float(np.max(np.abs(np.linalg.eigvals(lin.state_matrix()))))

    # ----------------------------------------------------------------------------------------
    # The nonlinear equations (per sample)
    # ----------------------------------------------------------------------------------------

    def stick_stiffness_npm(self) -> list[float]:
        """k_f of each spring (N/m), [axle j left, right, ...]."""
        r = self.friction.stiffness_ratio
        return [r * k for a in self.axles for k in a.suspension_stiffness_npm]

    def functions(self) -> tuple[Callable, Callable]:
        """``(accelerations, outputs)``, both ``f(x, u, du, ay, ax, fb)``:

        x: the state (2 n floats); u, du: road and road rate per tire (2 N_axles); ay, ax
        (m/s^2); fb: the stick sliders' bases (:class:`.friction.Sliders`, ignored without
        stick friction). ``accelerations`` returns the n coordinate accelerations;
        ``outputs`` returns ``q (2N), dq (2N), F (2N, spring on the body), dF (2N, tire,
        clamped), F_n (2N, wheel loads >= 0)`` and the n accelerations, one flat tuple, with
        the same arithmetic.
        """
        namespace = {'sin': math.sin, 'cos': math.cos, 'tanh_force': tanh_force,
                     'stick_force': stick_force}
        exec(compile(self._source(), f'<articulated model, {self.n_axles} axles>', 'exec'),
             namespace)
        return namespace['accelerations'], namespace['outputs']

    def _source(self) -> str:
        body = self._equations()
        n, m = self.n_dof, self.n_axles
        acc = ', '.join(f'a{i}' for i in range(n))
        lines = ['def accelerations(x, u, du, ay, ax, fb):']
        lines += ['    ' + s for s in body]
        lines.append(f'    return ({acc},)')
        lines.append('')
        lines.append('def outputs(x, u, du, ay, ax, fb):')
        lines += ['    ' + s for s in body]
        q = ', '.join(f'q{j}_{i}' for j in range(m) for i in (1, 2))
        dq = ', '.join(f'dq{j}_{i}' for j in range(m) for i in (1, 2))
        f = ', '.join(f'f{j}_{i}' for j in range(m) for i in (1, 2))
        g = ', '.join(f'g{j}_{i}' for j in range(m) for i in (1, 2))
        loads = ', '.join(f'(fc{j}_{i} + g{j}_{i} if fc{j}_{i} + g{j}_{i} > 0.0 else 0.0)'
                          for j in range(m) for i in (1, 2))
        lines.append(f'    return ({q}, {dq}, {f}, {g}, {loads}, {acc})')
        return '\n'.join(lines) + '\n'

    def _equations(self) -> list[str]:
        """The shared body of both functions (source lines)."""
        v, L = self.vehicle, _lit
        n = self.n_dof
        pos = ['zt', 'tht', 'pht', 'zr', 'thr', 'phr']
        for j in range(self.n_axles):
            pos += [f'za{j}', f'pa{j}']
        vel = ['v' + p for p in pos]
        out = [f'({", ".join(pos + vel)},) = x']
        for b in ('t', 'r'):
            out += [f'st{b} = sin(th{b})', f'ct{b} = cos(th{b})', f'sp{b} = sin(ph{b})',
                    f'cp{b} = cos(ph{b})', f'wt{b} = ct{b} * vth{b}', f'wp{b} = cp{b} * vph{b}',
                    f'FZ{b} = 0.0', f'FT{b} = 0.0', f'FP{b} = 0.0', f'MA{b} = 0.0']
        statics = self._statics
        out += self._axle_lines(statics)
        fw = v.fifth_wheel
        lt = fw.position_m - v.tractor.cg_position_m
        lr = fw.position_m - v.trailer.cg_position_m
        out += [f'f5 = -({L(fw.vertical_stiffness_npm)} * (zt + {L(lt)} * stt - zr - {L(lr)} '
                f'* str) + {L(fw.vertical_damping_nspm)} * (vzt + {L(lt)} * wtt - vzr - '
                f'{L(lr)} * wtr))',
                f'm5 = -({L(fw.roll_stiffness_nmprad)} * (pht - phr) + '
                f'{L(fw.roll_damping_nmsprad)} * (vpht - vphr))']
        g = GRAVITY_MPS2
        for i, (b, body, sign) in enumerate((('t', v.tractor, '+'), ('r', v.trailer, '-'))):
            lev = lt if b == 't' else lr
            mh = body.mass_kg * body.cg_height_above_roll_axis_m
            out += [f'a{3 * i} = (FZ{b} {sign} f5) * {L(1.0 / body.mass_kg)}',
                    f'a{3 * i + 1} = (ct{b} * (FT{b} {sign} {L(lev)} * f5) - '
                    f'{L(body.mass_kg * body.cg_height_m)} * ax) * '
                    f'{L(1.0 / body.pitch_inertia_kgm2)}',
                    f'a{3 * i + 2} = (cp{b} * FP{b} + MA{b} + {L(mh)} * (ay * cp{b} + '
                    f'{L(g)} * sp{b}) {sign} m5) * {L(1.0 / body.roll_inertia_kgm2)}']
        assert len(pos) == n
        return out

    def _axle_lines(self, statics: Statics) -> list[str]:
        L = _lit
        out = []
        ratio = self.friction.stiffness_ratio
        inv_vf = 1.0 / self.friction.velocity_mps
        for j, a in enumerate(self.axles):
            b = 't' if a.body == 'tractor' else 'r'
            d, s, w = self.lever_m(a), a.spring_half_track_m, a.wheel_half_track_m
            out += [f'sa = sin(pa{j})', f'ca = cos(pa{j})',
                    f'hb = z{b} + {L(d)} * st{b}', f'vb = vz{b} + {L(d)} * wt{b}',
                    f'rb = {L(s)} * sp{b} - {L(s)} * sa',
                    f'wb = {L(s)} * wp{b} - {L(s)} * ca * vpa{j}',
                    f'q{j}_1 = hb + rb - za{j}', f'q{j}_2 = hb - rb - za{j}',
                    f'dq{j}_1 = vb + wb - vza{j}', f'dq{j}_2 = vb - wb - vza{j}',
                    f'tw = {L(w)} * sa', f'tv = {L(w)} * ca * vpa{j}']
            sp = self.springs[j]
            for i, side in ((1, 0), (2, 1)):
                k, c = a.suspension_stiffness_npm[side], a.suspension_damping_nspm[side]
                kt, ct = a.tire_stiffness_npm[side], a.tire_damping_nspm[side]
                q, dq, f, gg = f'q{j}_{i}', f'dq{j}_{i}', f'f{j}_{i}', f'g{j}_{i}'
                out.append(f'{f} = -{L(k)} * {q} - {L(c)} * {dq}')
                if sp.active:
                    out.append(f'if {q} < 0.0:')
                    if sp.progression_per_m > 0.0:
                        out.append(f'    {f} -= {L(k * sp.progression_per_m)} * {q} * -{q}')
                    if sp.bump_stop_stiffness_npm > 0.0:
                        out.append(f'    if {q} < -{L(sp.bump_stop_clearance_m)}:')
                        out.append(f'        {f} += {L(sp.bump_stop_stiffness_npm)} * (-{q} - '
                                   f'{L(sp.bump_stop_clearance_m)})')
                ff = float(self.friction_n[j, side])
                if ff > 0.0 and self.friction.sticks:
                    out.append(f'{f} += stick_force(fb[{2 * j + side}], {L(ratio * k)}, {q}, '
                               f'{L(ff)})')
                elif ff > 0.0:
                    out.append(f'{f} += tanh_force({L(ff)}, {dq}, {L(inv_vf)})')
                sgn = '-' if i == 1 else '+'
                expr = f'{L(kt)} * (u[{2 * j + side}] - za{j} {sgn} tw)'
                if ct > 0.0:
                    expr += f' + {L(ct)} * (du[{2 * j + side}] - vza{j} {sgn} tv)'
                floor = -float(statics.wheel_load_n[j, side])
                out += [f'{gg} = {expr}', f'if {gg} < {L(floor)}:', f'    {gg} = {L(floor)}',
                        f'fc{j}_{i} = {L(statics.output_wheel_load_n[j, side])}']
            ia = 6 + 2 * j
            kphi = a.auxiliary_roll_stiffness_nmprad
            out += [f'S = f{j}_1 + f{j}_2', f'D = f{j}_1 - f{j}_2',
                    f'mar = {L(kphi)} * (ph{b} - pa{j})',
                    f'FZ{b} += S', f'FT{b} += {L(d)} * S', f'FP{b} += {L(s)} * D',
                    f'MA{b} -= mar',
                    f'a{ia} = (g{j}_1 + g{j}_2 - S) * {L(1.0 / a.mass_kg)}',
                    f'a{ia + 1} = (ca * ({L(w)} * (g{j}_1 - g{j}_2) - {L(s)} * D) + mar + '
                    f'{L(self._axle_lateral(j))} * ay) * {L(1.0 / a.roll_inertia_kgm2)}']
        return out

    # ----------------------------------------------------------------------------------------
    # Equilibrium
    # ----------------------------------------------------------------------------------------

    def equilibrium(self, road_m, lateral_accel_mps2: float = 0.0,
                    longitudinal_accel_mps2: float = 0.0, slider_force_n=None,
                    road_rate_mps=None) -> tuple[np.ndarray, list[float]]:
        """The state at rest on the road under the tires, and the sliders' bases.

        Positions: the root of the nonlinear equations with zero rates, by Newton's method on
        the linear stiffness (the nonlinearity is small); ``slider_force_n``: the stick
        elements' forces (N, tension > 0) held at the start (default 0). Rates: every axle
        follows the road's rate (its tires' forces do not jump), the bodies the
        least-squares motion that keeps the springs still.

        Raises
        ------
        ValueError
            No equilibrium (a lateral acceleration beyond the rollover limit: a wheel would
            lift; or the iteration does not settle).
        """
        acc, _ = self.functions()
        n, m = self.n_dof, self.n_axles
        u = [float(x) for x in np.asarray(road_m, float).reshape(2 * m)]
        du = [0.0] * (2 * m)
        lin = self._linear()
        kinv = np.linalg.inv(lin.stiffness)
        springs, tires, _, _ = self._geometry()
        rows = np.array([e for per in springs for e in per])
        kf = self.stick_stiffness_npm()
        forces = [0.0] * (2 * m) if slider_force_n is None else [
            float(f) for f in np.asarray(slider_force_n, float).reshape(2 * m)]
        x = kinv @ (lin.road_stiffness @ np.array(u) + lin.lateral * lateral_accel_mps2
                    + lin.longitudinal * longitudinal_accel_mps2)
        diag = np.diag(lin.mass)
        for _ in range(60):
            q = rows @ x
            fb = [f - k * qq for f, k, qq in zip(forces, kf, q)]
            state = list(x) + [0.0] * n
            a = np.array(acc(state, u, du, lateral_accel_mps2, longitudinal_accel_mps2, fb))
            step = kinv @ (diag * a)
            x = x + step
            if np.max(np.abs(step)) < 1e-13 * max(1.0, float(np.max(np.abs(x)))):
                break
        else:
            raise ValueError('no static equilibrium on this road under this lateral '
                             'acceleration (the iteration does not settle)')
        q = rows @ x
        fb = [f - k * qq for f, k, qq in zip(forces, kf, q)]
        _, out = self.functions()
        loads = out(list(x) + [0.0] * n, u, du, lateral_accel_mps2, longitudinal_accel_mps2,
                    fb)[8 * m:10 * m]
        if min(loads) <= 0.0:
            raise ValueError(f'lateral_accel_mps2 = {lateral_accel_mps2:g} at the start: a '
                             'wheel lifts off at rest, beyond the rollover limit: no '
                             'equilibrium')
        rates = np.zeros(n)
        if road_rate_mps is not None:
            rates = self._follow(np.asarray(road_rate_mps, float).reshape(2 * m), rows)
        return np.concatenate([x, rates]), fb

    def _follow(self, du: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """Rates with every axle on its road rate and the bodies keeping the springs still
        (least squares)."""
        n = self.n_dof
        rates = np.zeros(n)
        for j, a in enumerate(self.axles):
            left, right = du[2 * j], du[2 * j + 1]
            rates[6 + 2 * j] = 0.5 * (left + right)
            rates[6 + 2 * j + 1] = (left - right) / (2.0 * a.wheel_half_track_m)
        # springs still: rows[:, :6] @ body_rates = -rows[:, 6:] @ axle_rates
        rhs = -rows[:, 6:] @ rates[6:]
        rates[:6] = np.linalg.lstsq(rows[:, :6], rhs, rcond=None)[0]
        return rates
