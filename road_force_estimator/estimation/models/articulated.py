"""The model observer of the whole vehicle (``vehicle.model: articulated``, MODEL.md "The whole
vehicle: tractor and semi-trailer"): the tractor and semi-trailer's linear model with the road
under every wheel and each unit's lateral acceleration as unknown inputs, as a
:class:`.protocol.VehicleModel` (the observer, its fixed lag and the smoother take it as they
take the front axle).

The linear model is the core's (:meth:`.core.articulated_model.ArticulatedModel.linearised`:
``M ddx + C dx + K x = K_u u + C_u du + l a_y``, x the ``6 + 2 N`` coordinates of
:meth:`~.core.articulated_model.ArticulatedModel.dof_names`) written in the states below, which
carry no absolute level: the heave, the grade and every kink of the road under the trailer's
axles move bodies, axles and road together, and no deflection sees them (the front axle's
reason for ``w = u - z_u``, :mod:`.front_axle`). State (SI; :class:`Layout`)::

    x = [q (2N) | phi_t, phi_r | delta | w (2N) | dq (2N), dx_b (6) | du (2N) | a_y,t, a_y,r
         | l (lagged channels)]

``q_j,i`` every spring's extension (axle j front first, side i left, right; the measured
ones of the instrumented axles), ``phi_t``, ``phi_r`` the bodies' roll (measured: the
tractor's, the trailer's where fitted), ``delta`` the fifth wheel's vertical deflection,
``w_j,i = u_j,i - z_w,j,i`` every tire's deflection, the rates of the ``6 + 2 N`` coordinates
as every spring's extension rate ``dq_j,i`` and the bodies' six rates ``dx_b`` (the axles'
rates follow from them: :attr:`ArticulatedObserverModel.rate_rows`; the friction's rates are
states, as the front axle's), ``du_j,i``
the road velocity under every tire (an Ornstein-Uhlenbeck process per wheel path per axle,
as the front axle's: the unknown input) and ``a_y,b`` the lateral acceleration of each unit
(a random walk: it drives the body's roll ``M_b h_b a_y`` and its axles' ``(h_rc,j S_j / g
+ rho_j m_j) a_y``, the lateral load transfer the springs do not see; a cross wind or a
crossfall shows as one). The road under axle j is the front axle's delayed by ``xi_j / v``
(MODEL.md): this model does not use it, each axle's road is an input of its own (the
fused profile is the next step). Positions enter the forces through the core's kinematics
(:meth:`~.core.articulated_model.ArticulatedModel.kinematics`): the positional states are
``P [x; u]`` and the forces ``[-K, K_u] = F P`` with ``F = [-K, K_u] P^+`` exactly (every
motion P does not see, the rigid heave, grade and kinks with their road, moves no spring,
tire or coupling: checked at construction).

Outputs (:data:`outputs` of a model): per wheel ``q``, ``dq``, ``w``, the dynamic tire force
``dF = kt w + ct dw`` and the spring force on the body, then the bodies' roll, each unit's
``a_y``, the bodies' heave and pitch accelerations and every wheel's vertical acceleration.
The wheel loads are the statics' (:meth:`~.core.articulated_model.ArticulatedModel.statics`,
``output_wheel_load_n``) plus ``dF``; offline, the road under every wheel is ``w`` plus the
wheel's heave, the band-limited double integral of its acceleration, from a second smoother
tuned for the road as the front axle's (:mod:`.articulated_rows`). The longitudinal
acceleration ``a_x = dv/dt`` (the braking pitch, ``-M_b H_b a_x`` on each body) is a known
input, the change of the speed the estimator is given: its response adds to the estimate
(:class:`BrakingResponse`; a constant speed gives none, bit for bit).

The roll sensors and the IMU (docs/sensors.md "The roll sensor in the observer"): with
``imu=True`` a last channel, the tractor IMU's lateral acceleration (``/imu/tractor``'s
``linear_acceleration.y``, m/s^2), measures ``a_y,t`` with :data:`IMU_AY_NOISE_MPS2` of noise;
with it and ``vehicle.roll_sensor: pendulum`` each unit's roll channel reads ``phi_b + a_y,b /
g`` (a row on existing states, :attr:`ArticulatedObserverModel.pendulum`). Without the IMU
that row leaves a mode no reading sees (the whole vehicle tilted by d with ``a_y = -g d``:
the tilt / lateral-acceleration ambiguity; the Riccati equation has no stabilising
solution), and a leak on the a_y states that removes it measured worse than reading the
pendulum as phi on a straight road (``python -m bench.studies.roll_sensors --parts whole``):
a pendulum without the IMU is read as phi.

Friction and sensor lag, as the front axle's (:mod:`.front_axle`, "Friction and sensor lag";
the law shared, :mod:`.leaf_friction`; the equivalent damping's factors this model's own,
:data:`FRICTION_DAMPING_FACTORS`): every spring's ``-F_f,j,i tanh(dq_j,i / v_f)``
(``vehicle.axle.<name>.leaf_spring_friction``; the ``stick`` element: its force from the
measured ``q_j,i`` where every such spring's axle is instrumented, :mod:`.leaf_friction`) is a
known input acting where its spring and damper act (generalised force ``S^T f``, S the springs'
kinematic rows), evaluated on the estimated ``dq_j,i``; the gains' linear model carries its
equivalent damping. Every lagged channel (an axle's ``sensor_time_constant``, the rolls'
``vehicle.sensor_time_constant[1]``) has a first-order state ``tau dl = y - l`` appended after
``a_y``, which the sensor measures; the braking response is read through the same lag. The
friction is evaluated on the rates the filter estimates, without the braking response's (whose
rates are slow).

Tuning: the front axle's schedule on the deflection noise (:func:`.front_axle.scheduled`),
force noise on every equation of motion (per wheel on the axles, heave, pitch and roll on the
bodies), the roll-moment density over the tractor's ``M h`` squared as the density of each
``a_y`` times :data:`AY_PSD_FACTOR`.
"""
from __future__ import annotations

import math
from typing import Iterator

import numpy as np
from scipy import linalg

from road_force_estimator.core.articulated_model import ArticulatedModel
from road_force_estimator.core.articulated_parameters import ArticulatedParameters
from road_force_estimator.core.articulated_sensors import channel_layout
from road_force_estimator.core.parameters import GRAVITY_MPS2
from road_force_estimator.estimation.body_heave import SPEED_FLOOR_MPS
from road_force_estimator.estimation.models import front_axle
from road_force_estimator.estimation.models.leaf_friction import LeafSpringFriction
from road_force_estimator.estimation.models.articulated_rows import (
    ArticulatedOfflineRows, ArticulatedOnlineRows)
from road_force_estimator.estimation.models.protocol import (
    FORCE_PSD, ROLL_MOMENT_PSD, ContinuousModel, road_diffusion)

__all__ = ['AX_TIME_CONSTANT_S', 'AX_OFFLINE_TIME_CONSTANT_S', 'AY_PSD_FACTOR',
           'FRICTION_DAMPING_FACTORS', 'IMU_AY_NOISE_MPS2', 'IMU_CHANNEL', 'Layout',
           'ArticulatedObserverModel', 'BrakingResponse', 'output_names', 'channel_names']

SIDES = ('left', 'right')
#: The a_y random walks' density: this factor times the roll-moment density over the
#: tractor's ``(M h)^2``. Tuned on separate drives (road seed 1001, 10 um, 12-16 s, judged
#: after 4 s; worst axle's dynamic-load error at 10 ms): straight class A 8.98 % with 1,
#: 6.74 % with 0.01, 6.71 % with 0.001; class C 3.52, 3.17, 3.16 %; through a curve to
#: 3 m/s^2 on class C 1.87, 1.82, 1.97 % and on class A 1.28, 1.17, 1.49 %. (Each unit's own
#: ``(M h)^2`` instead of the tractor's: the same to 0.01 point.)
AY_PSD_FACTOR = 0.01
BODIES = ('tractor', 'trailer')
#: The time constant (s) of ``a_x``'s causal low-pass online (``a_x`` the change of speed over
#: each step): the speed a node is given (a wheel-speed or GNSS twist) is noisy, and its
#: differences at 1 kHz are ``sqrt(2) sigma_v / dt``. Measured on the drive family's C20-stop
#: (25 s; worst axle, the drive axle, with 10 ms; the speed exact, then with 0.01 m/s of white
#: noise): 2.7 / 9.4 % with 0, 2.9 / 3.6 % with 0.02 s, 2.9 / 3.1 % with 0.05 s, 3.0 / 3.0 %
#: with 0.1 s (zero latency 16.8 / 23.4, 16.5 / 16.5 % with 0.05 s).
AX_TIME_CONSTANT_S = 0.05
#: Offline, the low-pass runs forward and backward (zero phase) with this time constant (s):
#: the road takes what a smoothed step of ``a_x`` leaves. Measured on C20-stop offline (worst
#: axle's load; the fused profile's 0.5-30 m band error; the speed exact / 0.01 m/s noise):
#: 0 s 2.4 / 9.5 %, 0.16 / 0.71 %; 0.005 s 2.4 / 4.9 %, 0.16 / 0.44 %; 0.02 s 2.5 / 2.7 %,
#: 0.37 / 0.34 %; 0.05 s 2.6 % and 1.84 % (exact speed).
AX_OFFLINE_TIME_CONSTANT_S = 0.02
#: The factors on the friction's equivalent damping (:func:`.leaf_friction.friction_damping`)
#: at zero latency and with a latency, the articulated model's own: the front axle's (1.5,
#: 0.5) made the 10 ms filter unstable on class A (the gains designed for springs nearly
#: locked by the damping, the trailer's axles growing without bound: worst axle 101 % over
#: 30 s with a 3 ms lag, 12 % without). Tuned on separate drives (road seed 1001, 30 s,
#: zero-load readings, payload unknown, 1.5 kN tanh per spring, with and without a 3 ms lag;
#: worst axle, classes A / C): with a latency 0 the best (no lag 8.1 / 4.0 %, lag 10.1 /
#: 5.7 %; 0.25: 8.8 / 4.1, 11.4 / 6.1 %); at zero latency 0.5 (no lag 41.1 / 32.8 %, lag
#: 53.4 / 50.4 %; 0: 44.4 / 31.8, 57.8 / 46.1 %; 1.5: 46.2 / 35.2, 87.4 / 62.3 %):
#: ``python -m bench.accuracy.articulated_wim --parts damping``.
FRICTION_DAMPING_FACTORS = (0.5, 0.0)
#: The IMU's lateral-acceleration noise the observer assumes (m/s^2, standard deviation): the
#: plant's default ``simulator.noise.imu_acceleration`` (an ESC unit's accelerometer).
IMU_AY_NOISE_MPS2 = 0.05
#: The IMU channel's name (after /suspension/deflections' channels, ``imu=True``).
IMU_CHANNEL = 'tractor_imu_accel_y'


class Layout:
    """The state's parts (slices, and the fifth wheel's index) for N axles and n = 6 + 2 N
    coordinates (module notes)."""

    def __init__(self, n_axles: int) -> None:
        nw = 2 * n_axles
        n = 6 + nw
        self.n_axles, self.nw, self.n = n_axles, nw, n
        self.q = slice(0, nw)
        self.phi = slice(nw, nw + 2)
        self.delta = nw + 2
        self.w = slice(nw + 3, 2 * nw + 3)
        self.pos = slice(0, 2 * nw + 3)            # the positional states
        self.dx = slice(2 * nw + 3, 2 * nw + 3 + n)
        self.du = slice(2 * nw + 3 + n, 3 * nw + 3 + n)
        self.ay = slice(3 * nw + 3 + n, 3 * nw + 5 + n)
        self.nx = 3 * nw + 5 + n


def output_names(axles) -> tuple[str, ...]:
    """The linear outputs' names: per wheel (``<axle>_<side>``) q, dq, w, df, fb; then the
    bodies' roll, each unit's a_y, the bodies' heave and pitch accelerations and every
    wheel's vertical acceleration (``ddzw``: with ``w`` its road, offline)."""
    wheels = [f'{a}_{s}' for a in axles for s in SIDES]
    names = [f'{kind}_{wh}' for kind in ('q', 'dq', 'w', 'df', 'fb') for wh in wheels]
    names += [f'phi_{b}' for b in BODIES] + [f'ay_{b}' for b in BODIES]
    names += [f'{acc}_{b}' for b in BODIES for acc in ('ddz', 'ddtheta')]
    names += [f'ddzw_{wh}' for wh in wheels]
    return tuple(names)


def channel_names(model: ArticulatedModel) -> tuple[str, ...]:
    """The measured channels' joint names (INTERFACES.md ``/suspension/deflections``)."""
    out = []
    for ch in channel_layout(model):
        if ch[0] == 'q':
            out.append(f'{model.axles[ch[1]].name}_{SIDES[ch[2]]}_suspension')
        else:
            out.append(f'{BODIES[ch[1]]}_roll')
    return tuple(out)


class ArticulatedObserverModel(LeafSpringFriction):
    """MODEL.md's tractor and semi-trailer as the observer's vehicle model
    (:class:`.protocol.VehicleModel`) for one :class:`.ArticulatedParameters`.

    Channels: both deflections of every instrumented axle (front first), the tractor's roll
    and, where fitted, the trailer's (``/suspension/deflections``' order); state and outputs:
    the module notes; rows: :mod:`.articulated_rows`.

    The friction of every spring (F_f per element in the order of the springs' states, front
    axle first, left then right) and the channels' lags (s) come from the parameters; what the
    roll sensors read from ``vehicle.roll_sensor`` (module notes). ``imu``: the tractor IMU's
    ``a_y`` is a last channel (:data:`IMU_CHANNEL`).
    """

    #: the equivalent damping's factors (:data:`FRICTION_DAMPING_FACTORS`)
    friction_damping_factors = FRICTION_DAMPING_FACTORS

    def __init__(self, vehicle: ArticulatedParameters, imu: bool = False) -> None:
        self.vehicle = vehicle
        self.imu = bool(imu)
        self.core = ArticulatedModel(vehicle)
        self.layout = Layout(self.core.n_axles)
        self.outputs = output_names(vehicle.axle_names)
        self.channels = channel_layout(self.core) + ([('ay', 0)] if self.imu else [])
        self.channel_names = channel_names(self.core) + ((IMU_CHANNEL,) if self.imu else ())
        #: what a roll channel reads per m/s^2 of its unit's a_y (s^2/m): 1/g with a pendulum
        #: and the IMU; without the IMU a pendulum is read as phi (module notes)
        self.pendulum = (1.0 / GRAVITY_MPS2 if vehicle.roll_sensor == 'pendulum' and self.imu
                         else 0.0)
        self.deflection_channels = tuple(k for k, ch in enumerate(self.channels)
                                         if ch[0] == 'q')
        self.roll_channels = tuple(k for k, ch in enumerate(self.channels) if ch[0] == 'roll')
        nw = self.layout.nw
        self.load_outputs = tuple(range(3 * nw, 4 * nw))
        self.static_wheel_load_n = self.core.statics().output_wheel_load_n.reshape(-1).copy()
        #: every spring's friction F_f (N), the tanh law's v_f (m/s), the springs' rate
        #: states and outputs (:class:`.leaf_friction.LeafSpringFriction`)
        self.friction_n = tuple(float(f) for a in vehicle.axles
                                for f in a.leaf_spring_friction_n)
        self.friction_velocity_mps = float(vehicle.leaf_spring_friction_velocity_mps)
        self.friction_rate_states = tuple(range(self.layout.dx.start,
                                                self.layout.dx.start + nw))
        self.friction_rate_outputs = tuple(range(nw, 2 * nw))
        #: the stick element's law and k_f (N/m) per spring, and each spring's deflection
        #: channel (sign +1: the channel reads q_j,i; None: its axle is not instrumented)
        self.friction_model = vehicle.leaf_spring_friction_model
        self.stick_stiffness_npm = tuple(self.core.stick_stiffness_npm())
        measured = {(ch[1], ch[2]): k for k, ch in enumerate(self.channels) if ch[0] == 'q'}
        self.friction_channels = tuple(
            (measured[(j, side)], 1.0) if (j, side) in measured else None
            for j in range(self.core.n_axles) for side in (0, 1))
        #: each channel's sensor time constant (s; 0: none) and the lagged channels
        self.sensor_time_constant_s = tuple(
            vehicle.axles[ch[1]].sensor_time_constant_s if ch[0] == 'q'
            else vehicle.roll_time_constant_s if ch[0] == 'roll' else 0.0
            for ch in self.channels)
        self.lagged = tuple(k for k, tau in enumerate(self.sensor_time_constant_s)
                            if tau > 0.0)
        self._build()

    def with_vehicle(self, vehicle: ArticulatedParameters) -> ArticulatedObserverModel:
        """The model of other parameters (the same channels)."""
        return ArticulatedObserverModel(vehicle, self.imu)

    # -- the linear model ------------------------------------------------------------------
    def _build(self) -> None:
        """The parts of A that do not depend on the operating point: kinematics, forces."""
        core, lay = self.core, self.layout
        n, nw = lay.n, lay.nw
        lin = core.linearised()
        springs, wheels, delta, roll = core.kinematics()
        self.spring_rows = springs.reshape(nw, n)
        self.wheel_rows = wheels.reshape(nw, n)
        # P: the positional states over [x; u]
        p = np.zeros((2 * nw + 3, n + nw))
        p[lay.q, :n] = self.spring_rows
        p[nw, 2] = p[nw + 1, 5] = 1.0
        p[lay.delta, :n] = delta
        p[lay.w, :n] = -self.wheel_rows
        p[lay.w, n:] = np.eye(nw)
        f_pos = np.hstack([-lin.stiffness, lin.road_stiffness])
        f_rel = f_pos @ np.linalg.pinv(p)
        err = float(np.max(np.abs(f_rel @ p - f_pos)))
        if err > 1e-9 * float(np.max(np.abs(f_pos))):
            raise ValueError(f'the forces are not a function of the relative positions '
                             f'({err:.3g})')
        self.minv = np.linalg.inv(lin.mass)
        self.force_pos = f_rel
        self.damping = lin.damping
        self.road_damping = lin.road_damping
        self.delta_row = delta
        #: T (n, n): the rate states over the coordinates' rates, every spring's extension
        #: rate then the bodies' six (invertible: each axle's two springs hold its heave and
        #: roll), and its inverse
        self.rate_rows = np.vstack([self.spring_rows, np.eye(n)[:6]])
        self.rate_inverse = np.linalg.inv(self.rate_rows)
        # each unit's lateral acceleration: its body's roll and its axles' roll equations
        lateral = np.zeros((n, 2))
        for b in (0, 1):
            lateral[3 * b + 2, b] = lin.lateral[3 * b + 2]
        for j, a in enumerate(core.axles):
            ia = 6 + 2 * j + 1
            lateral[ia, core.body_index(a)] = lin.lateral[ia]
        self.lateral = lateral

    def continuous(self, speed_mps: float, road_gd_m3: float, *,
                   correlation_length_m: float = 0.8, force_psd: float = FORCE_PSD,
                   roll_moment_psd: float = ROLL_MOMENT_PSD,
                   friction_damping_nspm: tuple = ()) -> ContinuousModel:
        """The augmented linear model (module notes) at a speed (m/s; its magnitude, floored
        at :data:`.SPEED_FLOOR_MPS`), a roughness ``Gd(n0)`` (m^3) and a tuning."""
        lay = self.layout
        nw = lay.nw
        nx = lay.nx + len(self.lagged)
        speed = max(abs(float(speed_mps)), SPEED_FLOOR_MPS)
        w_v = 2.0 * math.pi * speed / correlation_length_m
        friction = any(self.friction_n)
        ceq = np.zeros(nw)
        if friction and friction_damping_nspm:   # its equivalent damping in the linear part
            ceq = np.asarray(friction_damping_nspm, float)
        damping = self.damping + self.spring_rows.T @ (ceq[:, None] * self.spring_rows)
        tinv = self.rate_inverse
        acc = np.zeros((lay.n, nx))          # the coordinates' accelerations over the state
        acc[:, lay.pos] = self.force_pos
        acc[:, lay.dx] = -damping @ tinv
        acc[:, lay.du] = self.road_damping
        acc[:, lay.ay] = self.lateral
        acc = self.minv @ acc
        a = np.zeros((nx, nx))
        a[lay.q, lay.dx] = np.eye(nw, lay.n)        # (spring_rows T^-1: the rates' first)
        a[nw, lay.dx] = tinv[2]
        a[nw + 1, lay.dx] = tinv[5]
        a[lay.delta, lay.dx] = self.delta_row @ tinv
        a[lay.w, lay.dx] = -self.wheel_rows @ tinv
        a[lay.w, lay.du] = np.eye(nw)
        a[lay.dx] = self.rate_rows @ acc
        a[lay.du, lay.du] = -w_v * np.eye(nw)
        unlagged = self.unlagged_measurement()
        for m, k in enumerate(self.lagged):      # tau dl = y - l
            tau = self.sensor_time_constant_s[k]
            a[lay.nx + m] = unlagged[k] / tau
            a[lay.nx + m, lay.nx + m] -= 1.0 / tau
        h = self._outputs(a, acc, np.eye(nx), ceq)
        g, psd = self._noise_inputs(force_psd, roll_moment_psd)
        g = np.vstack([g, np.zeros((nx - lay.nx, g.shape[1]))])
        diffusion = road_diffusion(road_gd_m3) * speed
        psd[6 + nw:6 + 2 * nw] = diffusion * w_v ** 2
        road_g = g[:, 6 + nw:6 + 2 * nw] * (math.sqrt(speed) * w_v)
        fb_, fd_, ff = None, None, ()
        if friction:       # a force f per spring where its damper acts: S^T f
            acc_f = self.minv @ self.spring_rows.T
            fb_ = np.zeros((nx, nw))
            fb_[lay.dx] = self.rate_rows @ acc_f
            fd_ = self._outputs(np.zeros((nx, nw)), acc_f, np.zeros((nx, nw)), np.zeros(nw),
                                direct=np.eye(nw))
            ff = self.friction_n
        return ContinuousModel(a, g, np.diag(psd), self._measurement(), h, road_g, fb_, fd_,
                               self.lagged, ff, tuple(float(c) for c in ceq) if friction else ())

    def _outputs(self, a: np.ndarray, acc: np.ndarray, eye: np.ndarray, ceq: np.ndarray,
                 direct: np.ndarray | None = None) -> np.ndarray:
        """H (outputs of :func:`output_names`, columns of ``a``): ``a`` the state's rates and
        ``acc`` the coordinates' accelerations per column, ``eye`` the states per column,
        ``ceq`` the friction's equivalent damping (N s/m) per spring; ``direct``: the columns
        are forces on the springs (:attr:`.ContinuousModel.friction_d`)."""
        lay = self.layout
        kt = np.array([k for ax in self.vehicle.axles for k in ax.tire_stiffness_npm])
        ct = np.array([c for ax in self.vehicle.axles for c in ax.tire_damping_nspm])
        k = np.array([s for ax in self.vehicle.axles for s in ax.suspension_stiffness_npm])
        c = np.array([s for ax in self.vehicle.axles for s in ax.suspension_damping_nspm])
        c = c + ceq
        q, dq, w, dw = eye[lay.q], a[lay.q], eye[lay.w], a[lay.w]
        df = kt[:, None] * w + ct[:, None] * dw
        fb = -(k[:, None] * q + c[:, None] * dq)
        if direct is not None:
            fb = fb + direct
        rows = [q, dq, w, df, fb, eye[lay.phi], eye[lay.ay], acc[[0, 1, 3, 4]],
                self.wheel_rows @ acc]
        return np.vstack(rows)

    def _noise_inputs(self, force_psd: float, roll_moment_psd: float) -> tuple:
        """G (nx, 6 + 2 nw + 2) and the densities: generalised forces on the bodies' heave,
        pitch and roll (the pitch's over its longest lever squared, the roll's over the half
        spring track squared, as the front axle's), a force under every wheel, the road
        velocities' noise (density set by the caller), each unit's a_y random walk (the
        roll-moment density over the tractor's ``(M h)^2`` times :data:`AY_PSD_FACTOR`)."""
        lay, core, v = self.layout, self.core, self.vehicle
        n, nw = lay.n, lay.nw
        forces = np.zeros((n, 6 + nw))
        psd = np.zeros(6 + 2 * nw + 2)
        for b, body in enumerate((v.tractor, v.trailer)):
            axles = [a for a in core.axles if core.body_index(a) == b]
            lever = max(abs(core.lever_m(a)) for a in axles)
            s = max(a.spring_half_track_m for a in axles)
            for i, scale in enumerate((1.0, lever * lever, s * s)):
                forces[3 * b + i, 3 * b + i] = 1.0
                psd[3 * b + i] = force_psd * scale
        forces[:, 6:6 + nw] = self.wheel_rows.T       # a force up under each wheel
        psd[6:6 + nw] = force_psd
        g = np.zeros((lay.nx, psd.size))
        g[lay.dx, :6 + nw] = self.rate_rows @ self.minv @ forces
        g[lay.du, 6 + nw:6 + 2 * nw] = np.eye(nw)
        g[lay.ay, 6 + 2 * nw:] = np.eye(2)
        mh = v.tractor.mass_kg * v.tractor.cg_height_above_roll_axis_m
        psd[6 + 2 * nw:] = AY_PSD_FACTOR * roll_moment_psd / (mh * mh)
        return g, psd

    def unlagged_measurement(self) -> np.ndarray:
        """(ny, nx with the lag states): the measured springs' extensions, bodies' rolls (with
        a pendulum ``+ a_y,b / g``) and the IMU's ``a_y,t``."""
        lay = self.layout
        cm = np.zeros((len(self.channels), lay.nx + len(self.lagged)))
        for k, ch in enumerate(self.channels):
            if ch[0] == 'q':
                cm[k, 2 * ch[1] + ch[2]] = 1.0
            elif ch[0] == 'roll':
                cm[k, lay.nw + ch[1]] = 1.0
                cm[k, lay.ay.start + ch[1]] = self.pendulum
            else:
                cm[k, lay.ay.start + ch[1]] = 1.0
        return cm

    def _measurement(self) -> np.ndarray:
        """C (ny, nx): the measured springs' extensions and bodies' rolls; a lagged sensor
        measures its lag state."""
        cm = self.unlagged_measurement()
        for m, k in enumerate(self.lagged):
            cm[k] = 0.0
            cm[k, self.layout.nx + m] = 1.0
        return cm

    # -- design ----------------------------------------------------------------------------
    def measurement_variances(self, noise_deflection_m: float,
                              noise_roll_rad: float) -> list:
        """``diag(R)``: m^2 per deflection, rad^2 per roll, (m/s^2)^2 for the IMU
        (:data:`IMU_AY_NOISE_MPS2`)."""
        return [noise_deflection_m ** 2 if ch[0] == 'q' else noise_roll_rad ** 2
                if ch[0] == 'roll' else IMU_AY_NOISE_MPS2 ** 2 for ch in self.channels]

    def roll_noise_floor(self, deflection_floor_m: float) -> float:
        """The deflection's floor over the front axle's half spring track (rad)."""
        return deflection_floor_m / self.vehicle.axles[0].spring_half_track_m

    def state_scale(self, nx: int) -> np.ndarray:
        """Typical state magnitudes (m, rad, m/s, rad/s, m/s^2; a lag state as the
        measured ones, 1e-2)."""
        lay = self.layout
        s = np.full(nx, 1e-2)
        s[lay.q], s[lay.phi], s[lay.delta], s[lay.w] = 1e-2, 1e-2, 1e-3, 1e-3
        s[lay.dx], s[lay.du], s[lay.ay] = 1e-1, 1e-1, 1.0
        return s

    def rest_state(self, y) -> np.ndarray:
        """The state at rest closest to one measurement (least squares): the measured
        extensions and rolls, every rate 0, the other positions and a_y that leave the
        fewest accelerations."""
        lay = self.layout
        x = np.zeros(lay.nx + len(self.lagged))
        measured = [int(np.argmax(row)) for row in self.unlagged_measurement()]
        x[measured] = np.asarray(y, float)
        x[lay.nx:] = [float(y[k]) for k in self.lagged]     # a lag state as its sensor
        free = [j for j in list(range(lay.pos.stop)) + list(range(lay.ay.start, lay.ay.stop))
                if j not in measured]
        known = np.hstack([self.force_pos, np.zeros((lay.n, x.size - lay.pos.stop))])
        known[:, lay.ay] = self.lateral
        x[free] = np.linalg.lstsq(known[:, free], -known @ x, rcond=None)[0]
        return x

    def sm_injection(self, nx: int) -> np.ndarray:
        """T (nx, 3 ny): the sliding mode (off by default) corrects the measured states by
        the output error only."""
        t = np.zeros((nx, 3 * len(self.channels)))
        for k, row in enumerate(self._measurement()):
            t[int(np.argmax(row)), 3 * k] = 1.0
        return t

    def sm_lipschitz(self) -> tuple[float, ...]:
        """L per channel: the stiffest tire over its axle's mass times 1 m/s (m/s^3), over
        the front axle's half spring track for the rolls."""
        lq = max(k / a.mass_kg for a in self.vehicle.axles for k in a.tire_stiffness_npm)
        lr = lq / self.vehicle.axles[0].spring_half_track_m
        return tuple(lq if ch[0] == 'q' else lr if ch[0] == 'roll' else 1e3
                     for ch in self.channels)

    def stationary_states(self, cm: ContinuousModel) -> list[int]:
        """All but the rolls (they follow the roads' cross levels), the a_y random walks and
        the roll sensors' lag states (they follow the rolls)."""
        lay = self.layout
        drop = set(range(lay.phi.start, lay.phi.stop)) | set(range(lay.ay.start, lay.ay.stop))
        drop |= {cm.measured[k] for k in self.roll_channels}
        return [j for j in range(cm.nx) if j not in drop]

    # -- tuning ----------------------------------------------------------------------------
    @staticmethod
    def scheduled(noise_deflection_m: float, *, roll_moment: bool = False) -> tuple:
        """The front axle's schedule (:func:`.front_axle.scheduled`)."""
        return front_axle.scheduled(noise_deflection_m, roll_moment=roll_moment)

    @staticmethod
    def profile_scheduled(noise_deflection_m: float, mode: str) -> tuple:
        """The front axle's (:func:`.front_axle.profile_scheduled`)."""
        return front_axle.profile_scheduled(noise_deflection_m, mode)

    # -- reconstruction --------------------------------------------------------------------
    def online_rows(self, observer) -> ArticulatedOnlineRows:
        """Every wheel's load, sample by sample (:class:`.ArticulatedOnlineRows`)."""
        return ArticulatedOnlineRows(self, observer)

    def offline_rows(self, observer) -> ArticulatedOfflineRows:
        """Every wheel's load of smoothed runs (:class:`.ArticulatedOfflineRows`)."""
        return ArticulatedOfflineRows(self, observer)

    def braking_response(self) -> BrakingResponse:
        """The response to the known ``a_x`` (:class:`BrakingResponse`)."""
        return BrakingResponse(self)


class BrakingResponse:
    """The linear model's response to the longitudinal acceleration ``a_x = dv/dt`` (m/s^2),
    the known input: the bodies' pitch moments ``-M_b H_b a_x`` (the core's
    ``LinearSystem.longitudinal``), hence the load transfer between the axles and through the
    fifth wheel.

    The model is linear, so a known input adds its own response: with ``x = x_r + x_a``,
    ``x_a`` the deterministic response to ``a_x`` from rest (no road, no noise), the filter,
    its fixed lag and the smoother estimate ``x_r`` from ``y - C x_a`` and the estimate is
    ``x_r + x_a``: the same numbers as ``a_x`` in the filter's prediction (``B a_x``), without
    a branch in the observer. ``x_a`` moves no road (``du = 0``): ``w_a + z_w,a = 0``, the road
    is ``x_r``'s alone. The mechanical part of the model does not depend on the speed, nor
    does ``x_a``'s step: exact for ``a_x`` constant over each step (zero-order hold), as the
    plant's (the mean over the step, the change of speed over the step).

    :meth:`step` advances one step; :attr:`offset` is ``C x_a`` (the channels' share, m and
    rad) and :attr:`dynamic_n` the dynamic tire forces' share (N, per wheel).
    """

    def __init__(self, model: ArticulatedObserverModel,
                 time_constant_s: float = AX_TIME_CONSTANT_S,
                 offline_time_constant_s: float = AX_OFFLINE_TIME_CONSTANT_S) -> None:
        self.time_constant_s = float(time_constant_s)
        self.offline_time_constant_s = float(offline_time_constant_s)
        lay = model.layout
        n = lay.n
        lin = model.core.linearised()
        a = lin.state_matrix()
        nl = len(model.lagged)
        n2 = 2 * n + nl           # coordinates, rates and the sensors' lag states
        # the observer's state of coordinates, rates and lag states (road 0, a_y 0)
        t = np.zeros((lay.nx + nl, n2))
        t[lay.q, :n] = model.spring_rows
        t[lay.nw, 2] = t[lay.nw + 1, 5] = 1.0
        t[lay.delta, :n] = model.delta_row
        t[lay.w, :n] = -model.wheel_rows
        t[lay.dx, n:2 * n] = model.rate_rows
        t[lay.nx:, 2 * n:] = np.eye(nl)
        self._ab = np.zeros((n2 + 1, n2 + 1))
        self._ab[:2 * n, :2 * n] = a
        self._ab[n:2 * n, n2] = model.minv @ lin.longitudinal
        cm = model.continuous(1.0, 1e-6)
        unlagged = model.unlagged_measurement() @ t
        for m, k in enumerate(model.lagged):     # the sensors read the response lagged
            tau = model.sensor_time_constant_s[k]
            self._ab[2 * n + m, :n2] = unlagged[k] / tau
            self._ab[2 * n + m, 2 * n + m] -= 1.0 / tau
        self._c = cm.c @ t
        self._df = cm.h[list(model.load_outputs)] @ t
        self._n2 = n2
        self._cache: dict = {}
        self.restart()

    def restart(self) -> None:
        """At rest (the start of a run)."""
        self._v = 0.0
        self._ax = 0.0
        self.x = np.zeros(self._n2)
        self.offset = np.zeros(self._c.shape[0])
        self.dynamic_n = np.zeros(self._df.shape[0])
        self._rest = True       # x is 0: a step under a_x = 0 leaves everything 0

    @property
    def at_rest(self) -> bool:
        """Whether the state is 0 (:attr:`offset` and :attr:`dynamic_n` 0): from a restart
        until the first step with ``a_x`` other than 0."""
        return self._rest

    def _step_matrices(self, dt: float) -> tuple:
        """(Phi, Gamma) of a step dt (s), zero-order hold; cached."""
        key = round(dt, 9)
        hit = self._cache.get(key)
        if hit is None:
            e = linalg.expm(self._ab * dt)
            hit = (e[:self._n2, :self._n2], e[:self._n2, self._n2])
            if len(self._cache) > 256:
                self._cache.clear()
            self._cache[key] = hit
        return hit

    def step(self, dt: float, ax_mps2: float) -> None:
        """Advance by dt (s) under ``a_x`` (m/s^2) held over the step."""
        if dt <= 0.0 or (self._rest and ax_mps2 == 0.0):   # (at rest: the products' +0)
            return
        self._rest = False
        phi, gamma = self._step_matrices(dt)
        self.x = phi @ self.x + gamma * ax_mps2
        self.offset = self._c @ self.x
        self.dynamic_n = self._df @ self.x

    def feed(self, dt: float, speed_mps: float) -> None:
        """One sample online: ``a_x`` over the step (dt s; 0: the run's first sample) the
        change of speed (m/s) over it, low-passed causally (:data:`AX_TIME_CONSTANT_S`)."""
        if dt <= 0.0:
            self._v = float(speed_mps)
            return
        raw = (float(speed_mps) - self._v) / dt
        self._v = float(speed_mps)
        self._ax += _alpha(dt, self.time_constant_s) * (raw - self._ax)
        self.step(dt, self._ax)

    def run(self, t_s: np.ndarray, speed_mps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Over a run from rest, offline: ``a_x`` of each step the change of speed over it,
        low-passed forward and backward (zero phase, :data:`AX_OFFLINE_TIME_CONSTANT_S`);
        ``(offset (m, ny), dynamic (nw, m))``."""
        t = np.asarray(t_s, float)
        dts = np.diff(t)
        ax = self.offline_ax(t, speed_mps)
        m = t.size
        off = np.zeros((m, self._c.shape[0]))
        dyn = np.zeros((self._df.shape[0], m))
        for a, b, o, d in self.responses(dts, ax, m):
            off[a:b] = o
            dyn[:, a:b] = d
        return off, dyn

    def offline_ax(self, t_s: np.ndarray, speed_mps: np.ndarray) -> np.ndarray:
        """A run's ``a_x`` offline (m/s^2, (m - 1,): step k -> k + 1), as :meth:`run` takes
        it: the change of speed over each step, low-passed forward and backward."""
        t = np.asarray(t_s, float)
        v = np.asarray(speed_mps, float)
        m = t.size
        dts = np.diff(t)
        ax = np.divide(np.diff(v), dts, out=np.zeros(max(m - 1, 0)), where=dts > 0.0)
        tau = self.offline_time_constant_s
        if tau > 0.0 and ax.size:
            for order in (range(ax.size), range(ax.size - 1, -1, -1)):
                f = float(ax[order[0]])         # each pass starts at its first value
                for k in order:
                    if dts[k] > 0.0:
                        f += _alpha(float(dts[k]), tau) * (ax[k] - f)
                    ax[k] = f
        return ax

    def responses(self, dts: np.ndarray, ax: np.ndarray, chunk: int
                  ) -> Iterator[tuple[int, int, np.ndarray, np.ndarray]]:
        """The response over a run from rest to ``ax`` (:meth:`offline_ax`) over its steps
        ``dts`` (s), ``chunk`` samples at a time: ``(a, b, offset (b - a, ny), dynamic (nw,
        b - a))`` of samples ``a:b`` (the first at rest); at rest again once exhausted."""
        self.restart()
        m = int(np.size(dts)) + 1
        for a in range(0, m, max(int(chunk), 1)):
            b = min(m, a + max(int(chunk), 1))
            off = np.zeros((b - a, self._c.shape[0]))
            dyn = np.zeros((self._df.shape[0], b - a))
            for k in range(max(a, 1), b):
                self.step(float(dts[k - 1]), float(ax[k - 1]))
                off[k - a] = self.offset
                dyn[:, k - a] = self.dynamic_n
            yield a, b, off, dyn
        self.restart()


def _alpha(dt: float, tau: float) -> float:
    """The first-order low-pass's gain of a step dt (s) at time constant tau (s; 0: none)."""
    return 1.0 if tau <= 0.0 else -math.expm1(-dt / tau)
