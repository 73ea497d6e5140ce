"""What the model observer needs of a vehicle model (:class:`VehicleModel`), and the pieces
every model shares: the linear model of one operating point (:class:`ContinuousModel`) and
the road as an unknown input (:func:`road_diffusion`).

The filters and smoothers (:mod:`..observer`, :mod:`..smoothing`) never know which truck they
estimate: a model hands them its linear state space with the unknown inputs as states
(:meth:`VehicleModel.continuous`), its measured channels and their kinds (the noise of a
deflection or of a roll sensor), its state at rest, its known nonlinear input (leaf-spring
friction) and its tuning; what the estimated states mean (loads, profile, LTR) is the
model's reconstruction, online (:class:`OnlineRows`) and offline (:class:`OfflineRows`),
into the rows of its own output columns. A new vehicle is a new module here, never a new
observer (:mod:`.front_axle`: MODEL.md's roll-plane front axle).
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any, Protocol

import numpy as np

__all__ = ['ISO_N0', 'FORCE_PSD', 'ROLL_MOMENT_PSD', 'ContinuousModel', 'road_diffusion',
           'VehicleModel', 'OnlineRows', 'OfflineRows', 'row_layout']

#: Reference spatial frequency of ISO 8608 (cycles/m).
ISO_N0 = 0.1
#: Defaults of a linear model's process noise: the generalised force-noise density on each
#: equation of motion (N^2 s) and the random-walk density of an unknown moment ((N m)^2 / s).
FORCE_PSD = 1.0
ROLL_MOMENT_PSD = 1e7


def road_diffusion(gd_n0_m3: float) -> float:
    """Diffusion constant D (m^2/m) of a Brownian road with ISO 8608 ``Gd(n0)`` (m^3).

    ``Var[u(x + dx) - u(x)] = D dx`` gives the one-sided PSD ``D / (2 pi^2 n^2)``, hence
    ``D = 2 pi^2 Gd(n0) n0^2``.
    """
    return 2.0 * math.pi ** 2 * gd_n0_m3 * ISO_N0 ** 2


def row_layout(nx: int, ny: int = 3) -> tuple[int, int, int, int, int]:
    """``(rho, x+, nu, y, size)``: the offsets of the parts of the online observer's buffer
    row (:mod:`..observer.gains`) for nx states and ny channels, and its length:
    ``[rho (3 ny) | x+ (nx) | nu (ny) | y (ny)]``."""
    return 0, 3 * ny, 3 * ny + nx, 4 * ny + nx, 5 * ny + nx


@dataclass(frozen=True)
class ContinuousModel:
    """``dx = A x dt + G dW`` (``E[dW dW^T] = Q dt``), ``y = C x``, linear outputs ``H x``,
    of one operating point of a vehicle model (speed, roughness, tuning)."""

    a: np.ndarray     #: (nx, nx)
    g: np.ndarray     #: (nx, nw): the process noise's inputs
    q: np.ndarray     #: (nw, nw) densities
    c: np.ndarray     #: (ny, nx)
    h: np.ndarray     #: (no, nx), rows the model's ``outputs``
    road_g: np.ndarray  #: (nx, nr) road-noise input columns (unit density), moment matching
    #: (nx, nf): dx/dt per newton of each friction element's force (the known input)
    friction_b: np.ndarray | None = None
    #: (no, nf): the outputs' direct part per newton of friction force
    friction_d: np.ndarray | None = None
    #: the lagged channels (indices into y), their states appended after the model's own
    lagged: tuple = ()
    #: the friction elements' F_f (N)
    friction_n: tuple = ()
    #: the friction's equivalent damping c_eq (N s/m) per element in the linear part (the
    #: known input is then the rest)
    friction_damping_nspm: tuple = ()

    @property
    def nx(self) -> int:
        """Number of states."""
        return self.a.shape[0]

    @property
    def ny(self) -> int:
        """Number of measured channels."""
        return self.c.shape[0]

    @property
    def measured(self) -> tuple[int, ...]:
        """The state measured by each channel."""
        return tuple(int(np.argmax(row)) for row in self.c)


class OnlineRows(Protocol):
    """A model's reconstruction one sample at a time (:class:`..observer.online.ModelCore`):
    from the linear outputs of the estimate (the model's ``outputs``, friction's direct part
    in) to a row of the model's columns."""

    def restart(self) -> None:
        """The next row starts a run (the integrals of the body's motion start there)."""

    def row(self, o: list, meta: tuple, op: list | None) -> tuple:
        """The row of one sample: ``o`` its outputs, ``meta`` = (distance (m), dt (s),
        speed (m/s), converged), ``op`` the zero-latency profile filter's outputs or None
        (always None when the class sets ``uses_profile = False``: then the core runs no
        profile filter)."""

    def set_vehicle(self, vehicle: Any) -> None:
        """The parameters of the rows from now on (an estimated payload)."""

    def set_static(self, *static_n: float) -> None:
        """The static wheel loads (N) of the rows from now on."""


class OfflineRows(Protocol):
    """A model's reconstruction of a smoothed run (:class:`..smoothing.smoother.Smoother`):
    columns of the model's rows from arrays of outputs, then what needs the whole run."""

    #: the rows of ``H`` (indices into the model's ``outputs``) the smoother evaluates
    outputs: list
    #: the column of the distance (the caller's)
    distance_column: int
    #: the road's columns, one per wheel path, from the profile pass (none: no profile pass)
    road_columns: tuple
    #: the columns the profile pass keeps whole, and those of the load pass its roll moment
    #: needs (:meth:`roll_moment_psd`)
    profile_columns: tuple
    moment_columns: tuple

    def field_columns(self, m: int) -> tuple[dict, list]:
        """``(fields, columns)`` of m rows: the arrays and their column views."""

    def columns(self, o: np.ndarray, out: list) -> None:
        """Fill the columns ``out`` of some rows from their smoothed outputs ``o`` (the rows of
        :attr:`outputs`, one column per sample); the whole-run parts come later."""

    def finish_run(self, out: list, t: np.ndarray, dt: float, speed: float,
                   settle_s: float, t_start: float | None = None) -> None:
        """What a run's columns need of the whole run (the body's motion, the quasi-static
        LTR, the converged flags) at the times t (s)."""

    def roll_moment_psd(self, cols, dt: float) -> float:
        """The profile pass's unknown-moment density ((N m)^2 / s) from the load pass's
        columns (at least :attr:`moment_columns`) of a run sampled every dt (s)."""

    def road(self, cols, dt: float, speed: float, dts: np.ndarray | None, uniform: bool,
             pos: np.ndarray | None, v: np.ndarray) -> tuple:
        """The road of each wheel path (m) of a run's samples from the profile pass's columns
        ``cols`` (on the grid ``pos`` when not None; the run's steps ``dts``, median step dt
        (s), ``uniform``, |speed| (m/s) and the model speeds ``v`` (m/s))."""


class VehicleModel(Protocol):
    """What the model observer needs of a vehicle (see the module notes)."""

    #: the parameters the model was built from
    vehicle: Any
    #: the linear outputs, names of the rows of ``H``
    outputs: tuple[str, ...]
    #: the measured channels' names, in ``y``'s order
    channel_names: tuple[str, ...]
    #: indices into ``y`` of the deflection channels (m) and of the roll channels (rad)
    deflection_channels: tuple[int, ...]
    roll_channels: tuple[int, ...]
    #: the outputs whose start-up error decides the settling time (the dynamic tire forces)
    load_outputs: tuple[int, ...]

    def with_vehicle(self, vehicle: Any) -> VehicleModel:
        """The same model with other parameters (an estimated payload)."""

    def continuous(self, speed_mps: float, road_gd_m3: float, *,
                   correlation_length_m: float = 0.8, force_psd: float = 1.0,
                   roll_moment_psd: float = 1e7,
                   friction_damping_nspm: tuple = ()) -> ContinuousModel:
        """The linear model at a speed (m/s), a roughness ``Gd(n0)`` (m^3) and a tuning."""

    def measurement_variances(self, noise_deflection_m: float,
                              noise_roll_rad: float) -> np.ndarray:
        """``diag(R)``: each channel's noise variance."""

    def roll_noise_floor(self, deflection_floor_m: float) -> float:
        """The roll channels' noise floor (rad) that goes with a deflection floor (m)."""

    def state_scale(self, nx: int) -> np.ndarray:
        """Typical magnitudes of the states (the Riccati equation's scaling)."""

    def rest_state(self, y) -> np.ndarray:
        """The state at rest that reproduces one measurement ``y``."""

    def sm_injection(self, nx: int) -> np.ndarray:
        """``T`` (nx, 3 ny): the state correction of the sliding-mode estimates."""

    def sm_lipschitz(self) -> tuple[float, ...]:
        """L per channel of the sliding-mode differentiators on the output errors."""

    #: the friction elements' F_f (N; empty: none), and their rates' states and outputs
    friction_n: tuple
    friction_rate_states: tuple[int, ...]
    friction_rate_outputs: tuple[int, ...]
    #: per element, its deflection channel (index into y) and the reading's sign per metre of
    #: the spring's extension, or None (no channel); the law (``'tanh'``, ``'stick'``), the
    #: stick springs' k_f (N/m), and whether the stick element is carried from the readings
    #: (:class:`.leaf_friction.LeafSpringFriction`)
    friction_channels: tuple
    friction_model: str
    stick_stiffness_npm: tuple
    friction_sticks: bool

    def friction_forces(self, dq, ceq) -> np.ndarray:
        """The friction's known input (N) per element at its rates dq (m/s), less the share
        ``-c_eq dq`` of its equivalent damping ``ceq`` (N s/m) that the linear model carries;
        one sample."""

    def friction_forces_array(self, dq: np.ndarray, ceq: np.ndarray) -> np.ndarray:
        """:meth:`friction_forces` over arrays (nf, ...)."""

    def friction_damping(self, dq_std_mps: float, delayed: bool = False) -> tuple:
        """The friction's equivalent damping (N s/m) per element at an RMS rate (m/s);
        ``delayed``: for a filter with a latency, whose friction is corrected at the smoothed
        rates (:meth:`..observer.friction.KnownFriction.correction`)."""

    def stationary_states(self, cm: ContinuousModel) -> list[int]:
        """The states of ``cm`` whose variance the road's moment matching solves for."""

    def scheduled(self, noise_deflection_m: float, *, roll_moment: bool = False) -> tuple:
        """The tuning at a deflection-noise level (force PSD, road correlation length,
        roughness factor[, roll-moment density])."""

    def profile_scheduled(self, noise_deflection_m: float, mode: str) -> tuple:
        """The profile filter's tuning (mode 'online' or 'offline')."""

    def online_rows(self, observer: Any) -> OnlineRows:
        """A reconstruction one sample at a time."""

    def offline_rows(self, observer: Any) -> OfflineRows:
        """A reconstruction of smoothed runs."""
