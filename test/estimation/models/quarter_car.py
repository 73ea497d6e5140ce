"""A test-only vehicle model: the quarter car (one wheel, one deflection sensor), written
against the model protocol (road_force_estimator.estimation.models.protocol) and nothing of
the front axle, to prove that the observer, its fixed lag and the smoother never know which
vehicle they estimate.

State ``x = [q, dq, dz_s, w, du]``: suspension extension q = z_s - z_u (m), its rate, the
body's heave rate, the tire deflection w = u - z_u and the road velocity du (an
Ornstein-Uhlenbeck process, the unknown input). ``F_b = -(k q + c dq)``, ``dd z_s = F_b / M``,
``dz_u = dz_s - dq``, ``dw = du - dz_u``, ``dF = kt w + ct dw``, ``dd z_u = (dF - F_b) / m``.
Measured: q. Rows: [distance, q, dq, dF, F_n, w, road, converged, dd z_s].
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from road_force_estimator.estimation import body_heave
from road_force_estimator.estimation.models.protocol import ContinuousModel, road_diffusion

Q, DQ, DZS, W, DU = range(5)
NX = 5
OUTPUTS = ('q', 'dq', 'ddq', 'dzs', 'ddzs', 'dzu', 'ddzu', 'w', 'df', 'fb')
#: Row columns.
DIST, RQ, RDQ, RDF, RFN, RW, RU, RCONV, RDDZS = range(9)
NCOL = 9
GRAVITY = 9.80665


@dataclass(frozen=True)
class QuarterCar:
    """Parameters (SI)."""

    sprung_mass_kg: float = 2500.0
    unsprung_mass_kg: float = 450.0
    suspension_stiffness_npm: float = 400e3
    suspension_damping_nspm: float = 15e3
    tire_stiffness_npm: float = 1000e3
    tire_damping_nspm: float = 0.0

    @property
    def static_load_n(self) -> float:
        return (self.sprung_mass_kg + self.unsprung_mass_kg) * GRAVITY


class QuarterCarModel:
    """The quarter car as a :class:`VehicleModel` (tuning fixed, no roll, no friction)."""

    outputs = OUTPUTS
    channel_names = ('suspension',)
    deflection_channels = (0,)
    roll_channels = ()
    load_outputs = (OUTPUTS.index('df'),)
    friction_n = ()
    friction_rate_states = ()
    friction_rate_outputs = ()

    def __init__(self, vehicle: QuarterCar | None = None) -> None:
        self.vehicle = QuarterCar() if vehicle is None else vehicle

    def with_vehicle(self, vehicle: QuarterCar) -> QuarterCarModel:
        return QuarterCarModel(vehicle)

    def continuous(self, speed_mps: float, road_gd_m3: float, *,
                   correlation_length_m: float = 0.8, force_psd: float = 1.0,
                   roll_moment_psd: float = 1e7,
                   friction_damping_nspm: tuple = ()) -> ContinuousModel:
        p = self.vehicle
        mass, m = p.sprung_mass_kg, p.unsprung_mass_kg
        k, c = p.suspension_stiffness_npm, p.suspension_damping_nspm
        kt, ct = p.tire_stiffness_npm, p.tire_damping_nspm
        speed = max(abs(float(speed_mps)), 1.0)
        w_v = 2.0 * math.pi * speed / correlation_length_m
        x = np.eye(NX)
        fb = -(k * x[Q] + c * x[DQ])
        ddzs = fb / mass
        dzu = x[DZS] - x[DQ]
        dw = x[DU] - dzu
        df = kt * x[W] + ct * dw
        ddzu = (df - fb) / m
        ddq = ddzs - ddzu
        a = np.zeros((NX, NX))
        a[Q], a[DQ], a[DZS], a[W], a[DU] = x[DQ], ddq, ddzs, dw, -w_v * x[DU]
        h = np.array([x[Q], x[DQ], ddq, x[DZS], ddzs, dzu, ddzu, x[W], df, fb])
        g = np.zeros((NX, 3))
        g[DZS, 0] = g[DQ, 0] = 1.0 / mass          # a force on the body
        g[DQ, 1] = -1.0 / m                         # a force on the wheel
        g[DU, 2] = 1.0                              # the road velocity's noise
        diffusion = road_diffusion(road_gd_m3) * speed
        qc = np.diag([force_psd, force_psd, diffusion * w_v ** 2])
        cm = np.zeros((1, NX))
        cm[0, Q] = 1.0
        road_g = g[:, 2:3] * (math.sqrt(speed) * w_v)
        return ContinuousModel(a, g, qc, cm, h, road_g)

    @staticmethod
    def measurement_variances(noise_deflection_m: float, noise_roll_rad: float) -> list:
        return [noise_deflection_m * noise_deflection_m]

    @staticmethod
    def roll_noise_floor(deflection_floor_m: float) -> float:
        return deflection_floor_m

    @staticmethod
    def state_scale(nx: int) -> np.ndarray:
        return np.array([1e-2, 1e-1, 1e-1, 1e-3, 1e-1])

    def rest_state(self, y) -> np.ndarray:
        """At rest with the measured q: the tire carries the body's spring force."""
        p = self.vehicle
        x = np.zeros(NX)
        x[Q] = y[0]
        fb = -p.suspension_stiffness_npm * y[0]
        x[W] = (fb + p.unsprung_mass_kg * fb / p.sprung_mass_kg) / p.tire_stiffness_npm
        return x

    def sm_injection(self, nx: int) -> np.ndarray:
        p = self.vehicle
        t = np.zeros((nx, 3))
        t[Q, 0] = t[DQ, 1] = 1.0
        t[W, 2] = -p.unsprung_mass_kg / p.tire_stiffness_npm
        return t

    def sm_lipschitz(self) -> tuple[float]:
        p = self.vehicle
        return (p.tire_stiffness_npm / p.unsprung_mass_kg,)

    @staticmethod
    def stationary_states(cm: ContinuousModel) -> list[int]:
        return list(range(cm.nx))

    @staticmethod
    def scheduled(noise_deflection_m: float, *, roll_moment: bool = False) -> tuple:
        return (238.0, 0.8, 1.41, 1e7) if roll_moment else (238.0, 0.8, 1.41)

    @staticmethod
    def profile_scheduled(noise_deflection_m: float, mode: str) -> tuple:
        return (238.0, 0.8, 1.41, 1e7)

    def friction_damping(self, dq_std_mps: float, delayed: bool = False) -> tuple:
        return ()

    def online_rows(self, observer) -> QuarterCarRows:
        return QuarterCarRows(self.vehicle)

    def offline_rows(self, observer) -> QuarterCarOfflineRows:
        return QuarterCarOfflineRows(self.vehicle, observer)


class QuarterCarRows:
    """Rows one sample at a time (no profile: the road column holds w - q)."""

    def __init__(self, vehicle: QuarterCar) -> None:
        self.static = vehicle.static_load_n

    def restart(self) -> None:
        pass

    def set_vehicle(self, vehicle: QuarterCar) -> None:
        self.static = vehicle.static_load_n

    def set_static(self, static_n: float) -> None:
        self.static = static_n

    def row(self, o: list, meta: tuple, op) -> tuple:
        x, _, _, conv = meta
        q, dq, df, w = o[0], o[1], o[8], o[7]
        return (x, q, dq, df, self.static + df, w, w - q, conv, o[4])


class QuarterCarOfflineRows:
    """Rows of smoothed runs; the road ``u = z_s - q + w`` from the profile pass, z_s the
    zero-phase integral of its body acceleration."""

    outputs = [OUTPUTS.index(n) for n in ('q', 'dq', 'df', 'w', 'ddzs')]
    distance_column = DIST
    road_columns = (RU,)
    profile_columns = (RU, RDDZS)      # (the profile pass keeps w - q and dd z_s)
    moment_columns = ()

    def __init__(self, vehicle: QuarterCar, observer) -> None:
        self.static = vehicle.static_load_n
        self.cutoff_m = observer.profile_cutoff_wavelength_m

    @staticmethod
    def field_columns(m: int) -> tuple[dict, list]:
        cols = [np.zeros(m) for _ in range(NCOL)]
        return {'columns': cols}, cols

    def columns(self, o: np.ndarray, out: list) -> None:
        q, dq, df, w, ddzs = o
        out[RQ][:], out[RDQ][:], out[RDF][:], out[RW][:] = q, dq, df, w
        out[RFN][:] = self.static + df
        out[RU][:] = w - q
        out[RDDZS][:] = ddzs

    def finish_run(self, out: list, t: np.ndarray, dt: float, speed: float, settle_s: float,
                   t_start: float | None = None) -> None:
        out[RCONV][:] = (t - (t[0] if t_start is None else t_start)) >= settle_s

    @staticmethod
    def roll_moment_psd(cols, dt: float) -> float:
        return 1e6

    def road(self, cols, dt: float, speed: float, dts, uniform: bool, pos, v) -> tuple:
        w_c = 2.0 * math.pi * max(speed, 1.0) / self.cutoff_m
        zs = body_heave.zero_phase(cols[RDDZS], dt, w_c)
        u = cols[RU] + zs
        return (u if pos is None else u[pos],)
