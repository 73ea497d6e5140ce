"""A varying vehicle speed (``simulator.speed_profile``): knots, the distance, the CSV file.

The speed is linearly interpolated between knots ``(time_s, speed_mps)`` from t = 0 and held
after the last one; speeds are >= 0 (stops allowed). The distance is its exact integral
(quadratic within a segment), so at v = 0 the road under the tires does not move. The file:
a CSV with the header ``time_s,speed_mps`` (INTERFACES.md).
"""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

__all__ = ['speed_knots', 'profile_distance', 'read_speed_profile']


def speed_knots(time_s, speed_mps) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Checked knots of a speed profile and the distance (m) travelled at each (exact
    integral of the linear interpolation; held at the last speed after the last knot)."""
    ts = np.asarray(time_s, dtype=float).reshape(-1)
    vs = np.asarray(speed_mps, dtype=float).reshape(-1)
    if ts.size < 1 or ts.shape != vs.shape:
        raise ValueError('speed profile: time_s and speed_mps must be equal, non-empty arrays')
    if not (np.isfinite(ts).all() and np.isfinite(vs).all()) or np.any(vs < 0.0):
        raise ValueError('speed profile: finite times and speeds >= 0 m/s only')
    if ts[0] != 0.0 or np.any(np.diff(ts) <= 0.0):
        raise ValueError('speed profile: times must start at 0 s and increase strictly')
    xs = np.concatenate([[0.0], np.cumsum(0.5 * (vs[1:] + vs[:-1]) * np.diff(ts))])
    return ts, vs, xs


def profile_distance(knots: tuple, t_s):
    """Distance (m) travelled at time(s) t_s (s) of a speed profile (:func:`speed_knots`):
    the integral of the linearly interpolated speed, exact (quadratic within a segment)."""
    ts, vs, xs = knots
    t = np.asarray(t_s, dtype=float)
    i = np.clip(np.searchsorted(ts, t, side='right') - 1, 0, ts.size - 1)
    tau = t - ts[i]
    nxt = np.minimum(i + 1, ts.size - 1)
    span = np.where(nxt > i, ts[nxt] - ts[i], 1.0)
    accel = np.where(nxt > i, (vs[nxt] - vs[i]) / span, 0.0)
    tau_in = np.where(nxt > i, np.minimum(tau, span), tau)
    x = xs[i] + vs[i] * tau_in + 0.5 * accel * tau_in * tau_in
    return x if x.ndim else float(x)


def read_speed_profile(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """The ``(time_s, speed_mps)`` arrays of a speed-profile CSV (header ``time_s,speed_mps``),
    checked as :func:`speed_knots` does.

    Raises
    ------
    ValueError
        A missing column, a non-number, or knots :func:`speed_knots` refuses.
    """
    with Path(path).open(newline='') as f:
        rows = list(csv.reader(f))
    if not rows or [c.strip() for c in rows[0][:2]] != ['time_s', 'speed_mps']:
        raise ValueError(f'{path}: a speed profile needs the header time_s,speed_mps')
    try:
        data = np.array([[float(r[0]), float(r[1])] for r in rows[1:] if r], dtype=float)
    except (ValueError, IndexError) as exc:
        raise ValueError(f'{path}: {exc}') from None
    if data.size == 0:
        raise ValueError(f'{path}: no speed samples')
    try:
        speed_knots(data[:, 0], data[:, 1])
    except ValueError as exc:
        raise ValueError(f'{path}: {exc}') from None
    return data[:, 0], data[:, 1]
