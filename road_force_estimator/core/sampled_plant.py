"""What the front axle's plant (:class:`.plant.Plant`) and the whole vehicle's
(:class:`.articulated_plant.ArticulatedPlant`) share: a plant driven over a road one output
sample at a time, its samples on stage times ``t_j = j / (2 substeps rate)``, the inputs
prepared in blocks, the drive ending at the last sample whose distance the road holds (never
extrapolated) and going on when the road is extended (a profile that arrives as measured).

A subclass sets, before :meth:`_find_last_sample` is first called, ``road`` (the enveloped
:class:`.road.RoadProfile`), ``tire_envelope_m``, ``speed_mps``, ``rate_hz``, ``substeps``,
``speed_profile`` (the knots of :func:`.speed_profile.speed_knots` or None), ``start_m`` (m)
and ``_half_rate`` (stage-time indices per second), and provides :meth:`_prepare` (the inputs
at the stage times of a block from a sample on: ``_chunk_first``, ``_chunk_last``),
:meth:`_row` (sample k's output row), :meth:`_advance` (the state from sample k to k + 1) and
:meth:`_sample` (a row as the plant's sample type).
"""
from __future__ import annotations

import math

import numpy as np

from road_force_estimator.core.road import RoadProfile
from road_force_estimator.core.speed_profile import profile_distance

__all__ = ['SampledPlant', 'END_TOLERANCE_M', 'NO_END_SAMPLE', 'STABLE_LAMBDA_H',
           'checked_rates', 'checked_substeps']

#: RK4 is stable for |lambda| h up to about 2.8 (real axis) and 2.8 (imaginary axis): the
#: step is refused beyond this bound on the linear model's fastest pole.
STABLE_LAMBDA_H = 2.0
#: Tolerance on the end of the road for round-off in x0 + v t (m).
END_TOLERANCE_M = 1e-9
#: The last sample of a drive that stops for good before the road ends (none).
NO_END_SAMPLE = 2 ** 62


def checked_rates(road, speed_mps, rate_hz) -> tuple[float, float]:
    """``(speed_mps, rate_hz)`` as floats.

    Raises
    ------
    TypeError
        ``road`` is not a :class:`.road.RoadProfile`.
    ValueError
        The speed (m/s) or the rate (Hz) not finite and > 0.
    """
    if not isinstance(road, RoadProfile):
        raise TypeError(f'road must be a RoadProfile, got {type(road).__name__}')
    speed_mps, rate_hz = float(speed_mps), float(rate_hz)
    if not (math.isfinite(speed_mps) and speed_mps > 0.0):
        raise ValueError(f'speed_mps = {speed_mps!r} must be > 0 m/s')
    if not (math.isfinite(rate_hz) and rate_hz > 0.0):
        raise ValueError(f'rate_hz = {rate_hz!r} must be > 0 Hz')
    return speed_mps, rate_hz


def checked_substeps(substeps, fastest: float, rate_hz: float) -> tuple[int, float]:
    """``(substeps, step_s)``: RK4 steps per sample (an int >= 1) and the step (s), stable on
    the model's fastest pole ``fastest`` (1/s; :data:`STABLE_LAMBDA_H`).

    Raises
    ------
    ValueError
        ``substeps`` not an integer >= 1, or too few for stability (the least stable count
        named).
    """
    if isinstance(substeps, bool) or not isinstance(substeps, (int, np.integer)) \
            or substeps < 1:
        raise ValueError(f'substeps = {substeps!r} must be an integer >= 1')
    substeps = int(substeps)
    step_s = 1.0 / (rate_hz * substeps)
    if fastest * step_s > STABLE_LAMBDA_H:
        need = int(math.ceil(fastest / (STABLE_LAMBDA_H * rate_hz)))
        raise ValueError(f'substeps = {substeps} at {rate_hz:g} Hz: RK4 step {step_s:.3g} s '
                         f'is unstable for this vehicle (fastest pole {fastest:.4g} 1/s); '
                         f'use at least {need}')
    return substeps, step_s


class SampledPlant:
    """The sample loop, the drive's end and the road's extension (module notes)."""

    road: RoadProfile
    stop_reason: str

    @property
    def sample_index(self) -> int:
        """Index of the last sample returned (-1 before the first :meth:`step`)."""
        return self._k

    @property
    def last_sample_index(self) -> int:
        """Index of the last sample the road allows."""
        return self._last_sample

    @property
    def finished(self) -> bool:
        """True once :meth:`step` has returned None (end of the road)."""
        return bool(self.stop_reason)

    @property
    def state(self) -> np.ndarray:
        """The current state (the model's coordinates and their rates), a copy."""
        return np.array(self._state)

    def step(self):
        """The next sample, or None at the end of the road (:attr:`stop_reason` says so)."""
        row = self._next_row()
        return None if row is None else self._sample(row)

    def extend_road(self, road: RoadProfile) -> None:
        """Drive on over ``road``, the current road and more (a profile that arrives as it is
        measured: :mod:`.road_stream`).

        The samples already returned keep their numbers; the next ones are prepared on the
        longer road (the enveloped profile of a prefix is that of the whole road up to
        ``L/2`` before the prefix's end, where the tires can be). :attr:`last_sample_index`
        grows with it and a drive that had stopped at the end of the road goes on.

        Raises
        ------
        ValueError
            ``road`` does not start where the current one starts, or is shorter.
        """
        new = road.enveloped(self.tire_envelope_m)
        if new.start_m != self.road.start_m or new.end_m < self.road.end_m:
            raise ValueError(f'extend_road: [{new.start_m:g}, {new.end_m:g}] m does not extend '
                             f'[{self.road.start_m:g}, {self.road.end_m:g}] m')
        self.road = new
        self._road_changed()
        self._last_sample = self._find_last_sample()
        self._chunk_last = min(self._chunk_last, max(self._k, 0))  # prepare again from here
        self.stop_reason = ''

    def speed_at(self, t_s):
        """The speed (m/s) at time(s) t_s (s): constant, or the profile interpolated."""
        if self.speed_profile is None:
            return np.full(np.shape(t_s), self.speed_mps) if np.ndim(t_s) else self.speed_mps
        ts, vs, _ = self.speed_profile
        return np.interp(t_s, ts, vs)

    # ----------------------------------------------------------------------------------------

    def _road_changed(self) -> None:
        """The road was extended (what a subclass derives from it)."""

    def _distance(self, j):
        """Distance (m) at stage-time index j (int or int array): x0 + v t_j, or x0 + the
        integral of the speed profile."""
        if self.speed_profile is not None:
            return self.start_m + profile_distance(self.speed_profile, j / self._half_rate)
        return self.start_m + self.speed_mps * (j / self._half_rate)

    def _find_last_sample(self) -> int:
        """The last sample whose distance the road holds (the distance never decreases)."""
        per = 2 * self.substeps
        limit = self.road.end_m + END_TOLERANCE_M
        if self.speed_profile is None:
            k = int((self.road.end_m - self.start_m) / self.speed_mps * self.rate_hz)
            while k > 0 and self._distance(per * k) > limit:
                k -= 1
            while self._distance(per * (k + 1)) <= limit:
                k += 1
            return k
        ts, vs, xs = self.speed_profile
        if self.start_m + xs[-1] <= limit and vs[-1] <= 0.0:
            return NO_END_SAMPLE          # it stops for good before the end
        lo, hi = 0, 1                     # bisection
        while self._distance(per * hi) <= limit:
            lo, hi = hi, 2 * hi
        while hi - lo > 1:
            mid = (lo + hi) // 2
            lo, hi = (mid, hi) if self._distance(per * mid) <= limit else (lo, mid)
        return lo

    def _next_row(self) -> tuple | None:
        if self._k < 0:
            self._k = 0
            return self._row(0)
        k = self._k
        if k >= self._last_sample:
            if not self.stop_reason:
                self.stop_reason = (f'end of road: {self.road.end_m:g} m reached after sample '
                                    f'{k} (t = {k / self.rate_hz:g} s); never extrapolated')
            return None
        if k + 1 > self._chunk_last:
            self._prepare(k)
        self._advance(2 * self.substeps * (k - self._chunk_first))
        self._k = k + 1
        return self._row(k + 1)

    def _prepare(self, first: int) -> None:
        raise NotImplementedError

    def _row(self, k: int) -> tuple:
        raise NotImplementedError

    def _advance(self, base: int) -> None:
        """The state from one sample to the next; ``base`` the stage-time index of the
        sample's start in the prepared block."""
        raise NotImplementedError

    def _sample(self, row: tuple):
        raise NotImplementedError
