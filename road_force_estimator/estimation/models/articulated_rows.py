"""The whole vehicle's reconstruction for the model observer (``vehicle.model: articulated``):
every wheel's vertical load, the static share plus the dynamic tire force, and each unit's
lateral acceleration, as rows of :func:`columns` (online, :class:`ArticulatedOnlineRows`) and
columns of smoothed runs (:class:`ArticulatedOfflineRows`).

Columns of N axles (``nw = 2 N`` wheels, axle j front first, left then right)::

    [distance, converged, F_n (nw), dF (nw), a_y,t, a_y,r, road (nw), dd z_w (nw)]

Online rows stop after ``a_y``. Offline, the road under every wheel comes from the smoother's
profile pass (:meth:`ArticulatedOfflineRows.road`): ``u = w + z_w``, ``z_w`` the zero-phase
band-limited double integral (:func:`.body_heave.zero_phase`, cutoff
:data:`ROAD_CUTOFF_FACTOR` x ``observer.profile_cutoff_wavelength``) of the wheel's vertical
acceleration; each axle's road on its own (their fusion by distance:
:func:`..articulated.fuse_roads`).
"""
from __future__ import annotations

import math

import numpy as np

from road_force_estimator.core.articulated_model import ArticulatedModel
from road_force_estimator.estimation import body_heave
from road_force_estimator.estimation.body_heave import SPEED_FLOOR_MPS
from road_force_estimator.estimation.models.front_axle import PROFILE_OFFLINE_ROLL_MOMENT_PSD

__all__ = ['DIST', 'CONV', 'ROAD_START_S', 'ROAD_RAMP_S', 'ROAD_CUTOFF_FACTOR', 'columns',
           'ArticulatedOnlineRows', 'ArticulatedOfflineRows']

#: The distance (m) and converged columns; the rest: :func:`columns`.
DIST, CONV = 0, 1
#: The start of a run (s) whose smoothed wheel accelerations the road leaves out, and the
#: cosine ramp (s) after it: the estimate starts at rest (every rate 0) where the truck was
#: moving, and the first second's acceleration errors (measured on class C at 20 m/s, 1 um:
#: 1.8-2.8 m/s^2 RMS against 0.3-0.4 after) would ring through the double integral for tens
#: of metres.
ROAD_START_S = 1.0
ROAD_RAMP_S = 0.5
#: The wheel heave's double integral is band-limited at this factor times
#: ``observer.profile_cutoff_wavelength`` (the front axle's 100 m by default): the fused profile
#: holds the 30-100 m band (issue 32). Measured on the drive family's C20 (25 s, 10 um,
#: ``python -m bench.accuracy.articulated_fusion``): the front axle's road's 30-100 m band
#: error 11.8 % of the band's RMS with 1 (the 100 m high-pass itself), 3.3 % with 2, 3.1 % with
#: 3, 3.1 % with 10; its 0.5-30 m band 0.60 % with 1, 0.51 % with 2 and more.
ROAD_CUTOFF_FACTOR = 3.0


def columns(nw: int) -> dict[str, slice | int]:
    """The columns of ``nw`` wheels: slices ``'load'`` (F_n, N), ``'dynamic'`` (dF, N),
    ``'ay'`` (a_y of tractor and trailer, m/s^2), ``'road'`` (m) and ``'wheel_accel'``
    (m/s^2), and ``'size'``."""
    return {'load': slice(2, 2 + nw), 'dynamic': slice(2 + nw, 2 + 2 * nw),
            'ay': slice(2 + 2 * nw, 4 + 2 * nw), 'road': slice(4 + 2 * nw, 4 + 3 * nw),
            'wheel_accel': slice(4 + 3 * nw, 4 + 4 * nw), 'size': 4 + 4 * nw}


def _output_index(model) -> tuple[list, list]:
    """The outputs of the dynamic tire forces and of the two a_y."""
    names = model.outputs
    return list(model.load_outputs), [names.index('ay_tractor'), names.index('ay_trailer')]


def _road_index(model) -> list:
    """The outputs of every tire's deflection, then of every wheel's acceleration."""
    names = model.outputs
    wheels = [n[len('df_'):] for n in (names[i] for i in model.load_outputs)]
    return [names.index(f'w_{w}') for w in wheels] + [names.index(f'ddzw_{w}') for w in wheels]


class ArticulatedOnlineRows:
    """Rows one sample at a time (:class:`.protocol.OnlineRows`)."""

    #: the rows take no road online: the core runs no zero-latency profile filter for them
    #: (its design and its product per sample saved; the loads are the same numbers)
    uses_profile = False

    def __init__(self, model) -> None:
        self.static = [float(f) for f in model.static_wheel_load_n]
        self._df, self._ay = _output_index(model)

    def restart(self) -> None:
        """Nothing carries over a sample."""

    def set_vehicle(self, vehicle) -> None:
        """The static loads of other parameters."""
        self.static = [float(f) for f in
                       ArticulatedModel(vehicle).statics().output_wheel_load_n.reshape(-1)]

    def set_static(self, *static_n: float) -> None:
        """The static wheel loads (N), one per wheel."""
        if len(static_n) != len(self.static):
            raise ValueError(f'{len(static_n)} static loads for {len(self.static)} wheels')
        self.static = [float(f) for f in static_n]

    def row(self, o: list, meta: tuple, op) -> tuple:
        """``(distance, converged, F_n..., dF..., a_y,t, a_y,r)``."""
        x, _, _, conv = meta
        df = [o[i] for i in self._df]
        return (x, conv, *[s + d for s, d in zip(self.static, df)], *df,
                *[o[i] for i in self._ay])


class ArticulatedOfflineRows:
    """Columns of smoothed runs (:class:`.protocol.OfflineRows`): loads, a_y and, from the
    profile pass, the road under every wheel."""

    distance_column = DIST
    moment_columns: tuple = ()

    def __init__(self, model, observer) -> None:
        self.static = np.asarray(model.static_wheel_load_n, float)
        df, ay = _output_index(model)
        # (then the springs' rates, whose friction the smoother evaluates: no column)
        self.outputs = df + ay + _road_index(model) + list(model.friction_rate_outputs)
        self.cols = columns(self.static.size)
        road, accel = self.cols['road'], self.cols['wheel_accel']
        self.road_columns = tuple(range(road.start, road.stop))
        self.profile_columns = self.road_columns + tuple(range(accel.start, accel.stop))
        self.cutoff_m = ROAD_CUTOFF_FACTOR * observer.profile_cutoff_wavelength_m

    def field_columns(self, m: int) -> tuple[dict, list]:
        """m rows of every column."""
        cols = [np.zeros(m) for _ in range(self.cols['size'])]
        return {'columns': cols}, cols

    def columns(self, o: np.ndarray, out: list) -> None:
        """Loads, dynamic loads and a_y from the smoothed outputs (rows of :attr:`outputs`)."""
        nw = self.static.size
        load, dyn, ay = self.cols['load'], self.cols['dynamic'], self.cols['ay']
        for k in range(nw):
            out[dyn.start + k][:] = o[k]
            out[load.start + k][:] = self.static[k] + o[k]
        out[ay.start][:], out[ay.start + 1][:] = o[nw], o[nw + 1]
        road, accel = self.cols['road'].start, self.cols['wheel_accel'].start
        for k in range(nw):      # the tire's deflection now, the wheel's heave in road()
            out[road + k][:] = o[nw + 2 + k]
            out[accel + k][:] = o[2 * nw + 2 + k]

    @staticmethod
    def finish_run(out: list, t: np.ndarray, dt: float, speed: float, settle_s: float,
                   t_start: float | None = None) -> None:
        """The converged flags: the settling time after the run's start."""
        out[CONV][:] = (t - (t[0] if t_start is None else t_start)) >= settle_s

    @staticmethod
    def roll_moment_psd(cols, dt: float) -> float:
        """The profile pass's roll-moment density: the front axle's offline constant (the
        a_y states' density follows from it, :mod:`.articulated`)."""
        return PROFILE_OFFLINE_ROLL_MOMENT_PSD

    def road(self, cols, dt: float, speed: float, dts, uniform: bool, pos, v) -> tuple:
        """The road under every wheel (m): ``w + z_w`` (module notes), on the grid ``pos``
        when given."""
        w_c = 2.0 * math.pi * max(speed, SPEED_FLOOR_MPS) / self.cutoff_m
        road, accel = self.cols['road'].start, self.cols['wheel_accel'].start
        m = cols[road].size
        n0 = min(int(round(ROAD_START_S / dt)), m)
        ramp = np.ones(m)            # the start left out of the integral, then a cosine ramp
        ramp[:n0] = 0.0
        n1 = min(int(round(ROAD_RAMP_S / dt)), m - n0)
        ramp[n0:n0 + n1] = 0.5 - 0.5 * np.cos(np.pi * np.arange(n1) / max(n1, 1))
        out = []
        for k in range(self.static.size):
            u = cols[road + k] + body_heave.zero_phase(cols[accel + k] * ramp, dt, w_c)
            out.append(u if pos is None else u[pos])
        return tuple(out)
