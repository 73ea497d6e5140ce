"""The offline smoother's speed over a run that is not driven at one speed (a stop, braking,
pulling away): the samples its noise and roughness statistics take (:func:`run_statistics`)
and the stretches of speed whose own gains it runs (:func:`speed_segments`).

Runs at a steady speed (every sample at least :data:`MOVING_SPEED_FRACTION` of the run's
median |v|) are taken whole with the gains of that median speed, as before: both functions
then change nothing. On a run with a stop, the standing samples would understate the road's
roughness (the same road at constant speed gives the roughness of the samples at speed), and
one design at the median speed would misfit the stretches braking and pulling away: the
offline load error of such a run, beside the RTS peer's, is the stop drive of the real-truck
family (ISO C, 20 m/s, braking at 5 m/s^2, 10 s standing, pulling away; 10 um):
``python -m bench.accuracy.real_truck --drives stop``.
"""
from __future__ import annotations

import numpy as np

from road_force_estimator.estimation.observer.noise import NOISE_DIFF_ORDER
from road_force_estimator.estimation.observer.schedule import (
    SPEED_LEVEL_RATIO, GainSchedule, requantise)
from road_force_estimator.estimation.body_heave import SPEED_FLOOR_MPS

__all__ = ['MOVING_SPEED_FRACTION', 'unsteady', 'run_statistics', 'speed_segments',
           'level_segments']

#: Samples slower than this fraction of a run's design speed (its median |v|) make the run
#: unsteady: they are left out of its statistics and its gains follow the speed.
MOVING_SPEED_FRACTION = 0.5


def unsteady(v: np.ndarray, speed: float) -> np.ndarray | None:
    """The samples at speed (bool (m,)) when some sample of the run is slower than
    :data:`MOVING_SPEED_FRACTION` of ``speed`` (m/s, the run's median |v|); None when none is
    (a steady run)."""
    fast = np.abs(v) >= MOVING_SPEED_FRACTION * speed
    return None if fast.all() else fast


def run_statistics(sched: GainSchedule, y: np.ndarray, dts: np.ndarray, v: np.ndarray,
                   speed: float) -> None:
    """The noise and roughness of a run (:meth:`.GainSchedule.statistics`) from its samples
    at speed: in an unsteady run (:func:`unsteady`) the slow samples are left out (their
    deflections barely move, so the roughness matched at the design speed would come out low),
    the stretches left joined (one step of the median dt across each join: a few outliers that
    the medians of the estimates ignore). ``y`` (m, 3) measurements (or rows in a file,
    :class:`~.core.spill.SpillRows`: a steady run's taken in pieces, an unsteady one's read
    whole), ``dts`` (m - 1,) steps (s), ``v`` (m,) speeds (m/s), ``speed`` the design speed
    (m/s)."""
    fast = unsteady(v, speed)
    if fast is None or np.count_nonzero(fast) <= 8 * NOISE_DIFF_ORDER:
        sched.statistics(y, dts)
        return
    idx = np.flatnonzero(fast)
    y = y if isinstance(y, np.ndarray) else y[0:y.shape[0]]
    steps = dts[idx[1:] - 1].copy()
    steps[np.diff(idx) > 1] = float(np.median(dts))
    sched.statistics(y[idx], steps)


def speed_segments(sched: GainSchedule, dt: float, v: np.ndarray, speed: float
                   ) -> list | None:
    """The stretches of an unsteady run (:func:`unsteady`) at one speed level and their gains:
    ``[(start, end, Gains), ...]`` (samples ``start:end``), or None for a steady run (one
    design at the run's level).

    The levels are the online observer's (:data:`.schedule.SPEED_LEVEL_RATIO`, with its
    hysteresis, |v| floored at the speed floor): standing, the road model's input is that of
    the floor speed, so the smoother no longer expects the road to move the wheels. The gains
    in use (``sched.gains``) are the run's level's again afterwards (its settling time).
    """
    if unsteady(v, speed) is None:
        return None
    return level_segments(sched, dt, v)


def level_segments(sched: GainSchedule, dt: float, v: np.ndarray) -> list:
    """:func:`speed_segments` of samples of an unsteady run (a window of one: its levels
    from the window's first sample, the hysteresis going on from there)."""
    av = np.maximum(np.abs(np.asarray(v, dtype=float)), SPEED_FLOOR_MPS)
    levels = np.empty(av.size, dtype=np.int64)
    level = None
    for k, x in enumerate(av.tolist()):
        level = requantise(level, x, SPEED_LEVEL_RATIO)
        levels[k] = level
    edges = np.flatnonzero(np.diff(levels)) + 1
    starts = [0, *edges.tolist()]
    ends = [*edges.tolist(), av.size]
    run_level = sched.levels['v']
    out = []
    try:
        for a, b in zip(starts, ends):
            sched.levels['v'] = int(levels[a])
            out.append((a, b, sched.design(dt, 0)))
    finally:
        sched.levels['v'] = run_level
        sched.design(dt, 0)
    return out
