"""The whole vehicle's outputs per sample and per drive (``vehicle.model: articulated``,
INTERFACES.md "The whole vehicle"): every wheel's load, every wheel's static load, each
unit's load transfer ratio (tractor, trailer, combination; instantaneous and quasi-static)
and each unit's lateral acceleration, from the readings of ``/suspension/deflections`` as
they come (the model's channel order, from the vehicle's ``deflection_reference``).

:class:`WholeVehicleEstimator` is the one per-sample path (the observer node's);
:func:`estimate_whole_vehicle` runs it over a drive online (the same numbers, sample by
sample) or runs the smoother offline and the same load-transfer recursion over its loads.
The model observer is :mod:`.articulated`'s; the LTR the truth's
(:class:`~.core.unit_loads.UnitLoadTransfer`: right minus left over their sum, each unit's
wheels, the quasi-static one low-passed by two first-order lags at
:data:`~.core.unit_loads.QUASI_STATIC_CUTOFF_HZ`), stepped by each sample's own step.
Signs: loads >= 0 pressing the road (N), LTR > 0 when the right wheels carry more.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from road_force_estimator.core.articulated_parameters import ArticulatedParameters
from road_force_estimator.core.parameters import ObserverParameters
from road_force_estimator.core.unit_loads import UnitLoadTransfer
from road_force_estimator.estimation.articulated import (
    ArticulatedEstimate, ArticulatedOnline, equilibrium_readings, estimate_articulated)
from road_force_estimator.estimation.models.articulated_rows import CONV, DIST, columns

__all__ = ['UNITS', 'WholeVehicleSample', 'WholeVehicleArrays', 'WholeVehicleEstimator',
           'estimate_whole_vehicle']

#: The units whose load transfer is estimated, in the order of the LTR fields.
UNITS = ('tractor', 'trailer', 'combination')


@dataclass(frozen=True)
class WholeVehicleSample:
    """One sample's estimate: ``load_n`` and ``static_n`` per wheel (N, the order of
    :attr:`WholeVehicleEstimator.wheel_names`), ``ltr`` and ``ltr_quasi_static`` per unit of
    :data:`UNITS`, ``lateral_mps2`` of the tractor and the trailer (m/s^2)."""

    stamp_ns: int
    distance_m: float
    converged: bool
    load_n: tuple
    static_n: tuple
    ltr: tuple
    ltr_quasi_static: tuple
    lateral_mps2: tuple


@dataclass(frozen=True)
class WholeVehicleArrays:
    """A drive's estimate, the fields of :class:`WholeVehicleSample` as arrays: per sample
    (m,), per wheel or unit (k, m); ``road_m`` offline (every wheel's road, m), else None."""

    stamps_ns: np.ndarray
    distance_m: np.ndarray
    converged: np.ndarray
    wheel_names: tuple
    axle_names: tuple
    axle_bodies: tuple
    load_n: np.ndarray
    static_n: np.ndarray
    ltr: np.ndarray
    ltr_quasi_static: np.ndarray
    lateral_mps2: np.ndarray
    road_m: np.ndarray | None = None

    @property
    def axle_load_n(self) -> np.ndarray:
        """The static axle loads (N; (axles, m)): both wheels' static loads."""
        return self.static_n.reshape(len(self.axle_names), 2, -1).sum(axis=1)

    @property
    def gross_weight_n(self) -> np.ndarray:
        """The gross vehicle weight (N; (m,)): every wheel's static load."""
        return self.static_n.sum(axis=0)


class _Transfer:
    """Each unit's LTR from finalized rows, stepped by their stamps."""

    def __init__(self, vehicle: ArticulatedParameters, static_n) -> None:
        bodies = [a.body for a in vehicle.axles]
        self.ltr = UnitLoadTransfer(bodies, np.reshape(static_n, (-1, 2)), 1e-3)
        self.last: int | None = None

    def update(self, stamp_ns: int, loads: Sequence[float]) -> list:
        dt = None if self.last is None else (stamp_ns - self.last) * 1e-9
        self.last = stamp_ns
        return self.ltr.update(loads, dt if dt is not None else 0.0)


class WholeVehicleEstimator:
    """Every output of the whole vehicle one sample at a time: :meth:`step` returns the samples
    finalized by that input (an ``observer.latency``'s samples late), :meth:`finish` the
    rest."""

    def __init__(self, vehicle: ArticulatedParameters,
                 observer: ObserverParameters | None = None) -> None:
        obs = ObserverParameters() if observer is None else observer
        self.vehicle = vehicle
        self.online = ArticulatedOnline(vehicle, obs.latency_s, obs)
        self.model = self.online.model
        self.wheel_names = self.online.wheel_names
        self.axle_names = vehicle.axle_names
        self.axle_bodies = tuple(a.body for a in vehicle.axles)
        self.channel_names = self.model.channel_names
        self.static_n = tuple(float(f) for f in self.model.static_wheel_load_n)
        nw = len(self.wheel_names)
        cols = columns(nw)
        self._load, self._ay = cols['load'], cols['ay']
        self._transfer = _Transfer(vehicle, self.static_n)

    def step(self, stamp_ns: int, readings: Sequence[float], speed_mps: float
             ) -> list[WholeVehicleSample]:
        """One input: ``readings`` the model's channels (:attr:`channel_names`; m, rad, from
        the vehicle's deflection reference), ``speed_mps`` (m/s).

        Raises
        ------
        ValueError
            A reading or the speed not finite.
        """
        y = equilibrium_readings(self.model, np.asarray(readings, float))
        return self._samples(self.online.step(int(stamp_ns), y.tolist(), float(speed_mps)))

    def finish(self) -> list[WholeVehicleSample]:
        """The samples a latency still held."""
        return self._samples(self.online.finish())

    def _samples(self, ready: list) -> list[WholeVehicleSample]:
        out = []
        for stamp, row in ready:
            loads = row[self._load]
            t = self._transfer.update(int(stamp), loads)
            out.append(WholeVehicleSample(int(stamp), float(row[DIST]), bool(row[CONV] > 0.5),
                                          tuple(loads), self.static_n, tuple(t[0::2]),
                                          tuple(t[1::2]), tuple(row[self._ay])))
        return out


def _arrays(est: WholeVehicleEstimator, samples: list, road=None) -> WholeVehicleArrays:
    m = len(samples)

    def field(name: str) -> np.ndarray:
        return np.array([getattr(s, name) for s in samples], float).reshape(m, -1).T.copy()

    return WholeVehicleArrays(
        np.array([s.stamp_ns for s in samples], np.int64),
        np.array([s.distance_m for s in samples], float),
        np.array([s.converged for s in samples], bool), est.wheel_names, est.axle_names,
        est.axle_bodies, field('load_n'), field('static_n'), field('ltr'),
        field('ltr_quasi_static'), field('lateral_mps2'), road)


def estimate_whole_vehicle(vehicle: ArticulatedParameters, stamps_ns, readings, speed_mps, *,
                           observer: ObserverParameters | None = None,
                           offline: bool = False) -> WholeVehicleArrays:
    """Every output over a drive: online :class:`WholeVehicleEstimator` sample by sample (its
    numbers exactly), offline the smoother (:func:`.articulated.estimate_articulated`) and the
    same load transfer over its loads.

    Parameters
    ----------
    stamps_ns : (m,) int, increasing
    readings : (m, channels) as :meth:`WholeVehicleEstimator.step` takes them
    speed_mps : (m,) or float (m/s)
    """
    est = WholeVehicleEstimator(vehicle, observer)
    stamps = np.asarray(stamps_ns, np.int64)
    v = np.broadcast_to(np.asarray(speed_mps, float), stamps.shape)
    if not offline:
        samples = []
        for s, y, vi in zip(stamps.tolist(), np.asarray(readings, float), v.tolist()):
            samples += est.step(s, y, vi)
        samples += est.finish()
        return _arrays(est, samples)
    smoothed: ArticulatedEstimate = estimate_articulated(
        vehicle, stamps, readings, v, offline=True, observer=observer)
    samples = []
    for k, stamp in enumerate(stamps.tolist()):
        loads = smoothed.load_n[:, k].tolist()
        t = est._transfer.update(stamp, loads)
        samples.append(WholeVehicleSample(
            stamp, float(smoothed.distance_m[k]), bool(smoothed.converged[k]), tuple(loads),
            est.static_n, tuple(t[0::2]), tuple(t[1::2]),
            tuple(smoothed.lateral_mps2[:, k])))
    return _arrays(est, samples, smoothed.road_m)
