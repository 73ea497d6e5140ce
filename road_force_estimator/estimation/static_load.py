"""Static wheel loads and the sprung mass from deflections read from a mechanical zero.

With ``vehicle.deflection_reference: zero_load`` a deflection sensor reads
``q_meas,i = q_i - (F_s,i - F_0,i) / k_i`` (MODEL.md "Measurements"): the extension q_i from
static equilibrium plus a constant set by the static sprung load ``F_s,i = F_c,i - m_i g``
and the zero-load setting ``F_0,i`` (``vehicle.deflection_zero_load``). The extension from
equilibrium has a zero mean (the suspension force's mean is the rate of change of the
body's momentum over the time averaged, which stays bounded), so the slow part of each
reading is a scale (on-board weighing):

    F_c,i = m_i g + F_0,i - k_i mean(q_meas,i),     M = (F_s,1 + F_s,2) / g.

:class:`StaticLoadTracker` keeps that mean causally, one accepted sample at a time: the
plain mean of all samples so far until it has averaged :data:`TIME_CONSTANT_S` seconds of
them, then an exponential forgetting with that time constant (each sample weighs
``max(1 / n, dt / tau)``), so that a payload that changes while the truck stands is followed
within a few tau. The estimated F_c,i go to the observer's reconstruction (the loads); the
core gets each reading minus an offset that follows the mean through a further first-order
lag of :data:`CORE_OFFSET_TIME_CONSTANT_S` (started at the first reading). The model observer
has no state for a deflection offset: an offset error of 1 mm on both sides costs about 10
points of dynamic-load error, and it takes a change of the offset for a motion. From the
plant's equilibrium start (a truck that sets off from standing: its first reading is the
scale) a longer lag is better (the running mean's 1/n phase wanders a few mm in the first
second); from a start in mid-drive (the first reading mm off) a shorter one is, and 30 s
costs several times the load error of 3 s. 10 s is the compromise (class C, 20 m/s, 10 um:
``python -m bench.studies.static_load --classes C --modes online --start 20 --duration 30``,
and ``--start 0 --duration 12``). A restart
after a gap keeps the mean and the offset (the load has not changed).

The sprung mass moves the observer's model: when it has moved more than
:data:`MASS_REDESIGN_FRACTION` from the mass of the gains in use, the core gets a vehicle of
the new mass (:func:`vehicle_of_mass`: ``I_x`` scaled with M, the payload taken as spread like
the body; ``h`` kept, the payload's height is not observable from two deflections) and
designs its gains again.

The per-sample estimator (:class:`.Estimator`) and the offline paths (:func:`track_arrays`,
the same update sample by sample) give identical numbers. With ``equilibrium`` (the default)
none of this runs: the static loads are the configured ones.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from road_force_estimator.core.parameters import GRAVITY_MPS2, SPECS, VehicleParameters

__all__ = ['TIME_CONSTANT_S', 'CORE_OFFSET_TIME_CONSTANT_S', 'MASS_REDESIGN_FRACTION',
           'StaticLoadTracker', 'vehicle_of_mass', 'track_arrays', 'track_recording']

#: Averaging time (s) of the running mean of the readings (plain mean until then).
TIME_CONSTANT_S = 10.0
#: Time constant (s) of the lag between the running mean and the offset taken off the
#: readings that the observer's core gets.
CORE_OFFSET_TIME_CONSTANT_S = 10.0
#: Relative change of the estimated sprung mass beyond which the model's gains are designed
#: again for the new mass.
MASS_REDESIGN_FRACTION = 0.02

_MASS_RANGE = (SPECS['vehicle.sprung_mass'].low, SPECS['vehicle.sprung_mass'].high)
_INERTIA_RANGE = (SPECS['vehicle.roll_inertia'].low, SPECS['vehicle.roll_inertia'].high)


def vehicle_of_mass(vehicle: VehicleParameters, static_n: tuple[float, float]
                    ) -> VehicleParameters:
    """``vehicle`` with the static loads ``static_n`` (N, [left, right]) and the sprung mass
    ``M = (F_s,1 + F_s,2) / g`` they imply (clipped to the parameter's range); the roll
    inertia scaled by ``M / M_vehicle``, the centre-of-gravity height kept."""
    sprung = sum(max(fc - m * GRAVITY_MPS2, 0.0)
                 for fc, m in zip(static_n, vehicle.unsprung_mass_kg)) / GRAVITY_MPS2
    mass = min(max(sprung, _MASS_RANGE[0]), _MASS_RANGE[1])
    inertia = vehicle.roll_inertia_kgm2 * mass / vehicle.sprung_mass_kg
    inertia = min(max(inertia, _INERTIA_RANGE[0]), _INERTIA_RANGE[1])
    loads = tuple(max(float(f), 1e-3) for f in static_n)   # 0 would mean "from the masses"
    return replace(vehicle, sprung_mass_kg=mass, roll_inertia_kgm2=inertia,
                   static_load_setting_n=loads)


class StaticLoadTracker:
    """Running estimate of the static wheel loads from zero-load readings (module notes).

    Parameters
    ----------
    vehicle : VehicleParameters
        The configured vehicle: unsprung masses, stiffnesses, ``deflection_zero_load``; its
        sprung mass is the one the model starts from.
    time_constant_s : float
        Averaging time tau (s), > 0.

    Notes
    -----
    :meth:`update` takes each accepted sample; :attr:`static_n` and :attr:`sprung_mass_kg`
    are the estimates after it, :attr:`redesign` the vehicle the core should take now (None
    while the mass stays within :data:`MASS_REDESIGN_FRACTION` of the last one given).
    """

    def __init__(self, vehicle: VehicleParameters,
                 time_constant_s: float = TIME_CONSTANT_S) -> None:
        if not time_constant_s > 0.0:
            raise ValueError(f'time_constant_s = {time_constant_s!r} must be > 0 s')
        self.vehicle = vehicle
        self.tau = float(time_constant_s)
        k1, k2 = vehicle.suspension_stiffness_npm
        b1, b2 = (m * GRAVITY_MPS2 + f0 for m, f0 in zip(vehicle.unsprung_mass_kg,
                                                          vehicle.deflection_zero_load_n))
        self._c = (k1, k2, b1, b2)
        self.reset()

    def reset(self) -> None:
        """Forget the readings; the next sample starts the mean."""
        self._n = 0
        self._mean = (0.0, 0.0)
        self._offset = (0.0, 0.0)
        self.static_n = self.vehicle.static_load_n
        self.sprung_mass_kg = self.vehicle.sprung_mass_kg
        self._designed_kg = self.vehicle.sprung_mass_kg
        self.redesigns = 0
        self.redesign: VehicleParameters | None = None

    def update(self, q1: float, q2: float, dt: float) -> tuple[float, float]:
        """One accepted reading (m, [left, right]) after a step dt (s; ignored for the first);
        returns the readings less the core's offset (m): the extensions from the
        equilibrium the core works with."""
        n = self._n = self._n + 1
        a = 1.0 / n
        if n > 1:
            b = dt / self.tau
            if b > a:
                a = b if b < 1.0 else 1.0
        m1, m2 = self._mean
        m1 += a * (q1 - m1)
        m2 += a * (q2 - m2)
        self._mean = (m1, m2)
        if n == 1:
            o1, o2 = m1, m2
        else:
            o1, o2 = self._offset
            c = dt / CORE_OFFSET_TIME_CONSTANT_S
            if c > 1.0:
                c = 1.0
            o1 += c * (m1 - o1)
            o2 += c * (m2 - o2)
        self._offset = (o1, o2)
        k1, k2, b1, b2 = self._c
        fc = self.static_n = (b1 - k1 * m1, b2 - k2 * m2)
        self.redesign = None
        mass = self.sprung_mass_kg = self._mass(fc)
        if abs(mass - self._designed_kg) > MASS_REDESIGN_FRACTION * self._designed_kg:
            self._designed_kg = mass
            self.redesigns += 1
            self.redesign = vehicle_of_mass(self.vehicle, fc)
        return q1 - o1, q2 - o2

    def _mass(self, fc: tuple[float, float]) -> float:
        """M = (F_s,1 + F_s,2) / g (kg), each sprung load floored at 0."""
        m1, m2 = self.vehicle.unsprung_mass_kg
        s1 = fc[0] - m1 * GRAVITY_MPS2
        s2 = fc[1] - m2 * GRAVITY_MPS2
        return ((s1 if s1 > 0.0 else 0.0) + (s2 if s2 > 0.0 else 0.0)) / GRAVITY_MPS2


def track_arrays(vehicle: VehicleParameters, q: np.ndarray, steps_s: np.ndarray,
                 time_constant_s: float = TIME_CONSTANT_S
                 ) -> tuple[np.ndarray, np.ndarray, float]:
    """:class:`StaticLoadTracker` over the accepted samples of a recording.

    Parameters
    ----------
    vehicle : VehicleParameters
    q : ndarray, shape (m, 2)
        The zero-load readings of the accepted samples, in order (m).
    steps_s : ndarray, shape (m,)
        Step before each (s; the first is ignored).

    Returns
    -------
    q_eq : ndarray, shape (m, 2)
        The readings less the core's offset (m), as :meth:`StaticLoadTracker.update`.
    static_n : ndarray, shape (m, 2)
        F_c,i after each sample (N).
    sprung_mass_kg : float
        The sprung mass after the last sample (kg); the configured one for no sample.
    """
    tracker = StaticLoadTracker(vehicle, time_constant_s)
    update = tracker.update
    m = q.shape[0]
    q_eq = np.empty((m, 2))
    static = np.empty((m, 2))
    for j, ((a, b), dt) in enumerate(zip(q.tolist(), np.asarray(steps_s).tolist())):
        q_eq[j] = update(a, b, dt)
        static[j] = tracker.static_n
    return q_eq, static, tracker.sprung_mass_kg


def track_recording(vehicle: VehicleParameters, q: np.ndarray, acc: np.ndarray,
                    stamp_ns: np.ndarray, restart: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray | None, VehicleParameters]:
    """The offline paths' static loads: :func:`track_arrays` over the accepted samples.

    Parameters
    ----------
    vehicle : VehicleParameters
    q : ndarray, shape (n, 2)
        The readings of every sample (m).
    acc : ndarray of int
        The accepted rows, in order; ``stamp_ns`` their integer stamps (all rows) and
        ``restart`` (all rows) the first of each run (a step of 0 there, as the estimator).

    Returns
    -------
    q : ndarray, shape (n, 2)
        The readings with the accepted rows less the core's offset (``q`` itself under
        ``equilibrium``).
    static_n : ndarray, shape (acc.size, 2), or None
        F_c,i after each accepted sample (N); None under ``equilibrium``.
    vehicle : VehicleParameters
        The vehicle to design for: the sprung mass of the last estimate (the whole drive,
        the offline modes are not causal), or ``vehicle`` under ``equilibrium``.
    """
    if not vehicle.zero_load or acc.size == 0:
        return q, None, vehicle
    steps = np.zeros(acc.size)
    steps[1:] = np.diff(stamp_ns[acc]) * 1e-9
    steps[np.asarray(restart)[acc]] = 0.0
    q_eq, static, _ = track_arrays(vehicle, q[acc], steps)
    q = q.copy()
    q[acc] = q_eq
    return q, static, vehicle_of_mass(vehicle, tuple(static[-1]))
