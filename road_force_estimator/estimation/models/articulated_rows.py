"""The whole vehicle's reconstruction for the model observer (``vehicle.model: articulated``):
every wheel's vertical load, the static share plus the dynamic tire force, and each unit's
lateral acceleration, as rows of :func:`columns` (online, :class:`ArticulatedOnlineRows`) and
columns of smoothed runs (:class:`ArticulatedOfflineRows`).

Columns of N axles (``nw = 2 N`` wheels, axle j front first, left then right)::

    [distance, converged, F_n (nw), dF (nw), a_y,t, a_y,r]

No road yet: the profile pass (:meth:`.OfflineRows.road`) and the zero-latency profile filter
are not used (the wheel paths' road and its fusion over the axles come next).
"""
from __future__ import annotations

import numpy as np

from road_force_estimator.core.articulated_model import ArticulatedModel

__all__ = ['DIST', 'CONV', 'columns', 'ArticulatedOnlineRows', 'ArticulatedOfflineRows']

#: The distance (m) and converged columns; the rest: :func:`columns`.
DIST, CONV = 0, 1


def columns(nw: int) -> dict[str, slice | int]:
    """The columns of ``nw`` wheels: ``'load'`` (F_n, N) and ``'dynamic'`` (dF, N) slices,
    ``'ay'`` (a_y of tractor and trailer, m/s^2) slice, ``'size'``."""
    return {'load': slice(2, 2 + nw), 'dynamic': slice(2 + nw, 2 + 2 * nw),
            'ay': slice(2 + 2 * nw, 4 + 2 * nw), 'size': 4 + 2 * nw}


def _output_index(model) -> tuple[list, list]:
    """The outputs of the dynamic tire forces and of the two a_y."""
    names = model.outputs
    return list(model.load_outputs), [names.index('ay_tractor'), names.index('ay_trailer')]


class ArticulatedOnlineRows:
    """Rows one sample at a time (:class:`.protocol.OnlineRows`)."""

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
    """Columns of smoothed runs (:class:`.protocol.OfflineRows`); no profile pass."""

    distance_column = DIST
    road_columns: tuple = ()
    profile_columns: tuple = ()
    moment_columns: tuple = ()

    def __init__(self, model) -> None:
        self.static = np.asarray(model.static_wheel_load_n, float)
        df, ay = _output_index(model)
        self.outputs = df + ay
        self.cols = columns(self.static.size)

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

    @staticmethod
    def finish_run(out: list, t: np.ndarray, dt: float, speed: float, settle_s: float,
                   t_start: float | None = None) -> None:
        """The converged flags: the settling time after the run's start."""
        out[CONV][:] = (t - (t[0] if t_start is None else t_start)) >= settle_s

    @staticmethod
    def roll_moment_psd(cols, dt: float) -> float:
        """(No profile pass.)"""
        return 0.0

    @staticmethod
    def road(cols, dt: float, speed: float, dts, uniform: bool, pos, v) -> tuple:
        """(No profile pass: no road.)"""
        return ()
