"""The zero-latency road of the model core (:mod:`.model_core`, its notes: "Profile"): the
road from the profile filter's outputs, with its own body-heave integral, held at a stop.
"""
from __future__ import annotations

import math

import road_force_estimator.estimation.body_heave as body_heave
from road_force_estimator.estimation.models.front_axle import PROFILE_ONLINE_CUTOFF_RATIO

__all__ = ['OnlineRoad']


class OnlineRoad:
    """The road ``(u_1, u_2)`` of the profile filter's outputs, one sample at a time.

    Parameters
    ----------
    wc_per_speed : float
        The body heave's cutoff per speed (rad/m, :func:`.body_heave.cutoff_per_speed` of
        ``observer.profile_cutoff_wavelength``); the road's is that over
        :data:`.model.PROFILE_ONLINE_CUTOFF_RATIO` (:attr:`wc`).
    half_track_m : float
        s (m).

    Notes
    -----
    :meth:`restart` at each run's start; :meth:`road` per sample.
    """

    def __init__(self, wc_per_speed: float, half_track_m: float) -> None:
        self.wc = wc_per_speed / PROFILE_ONLINE_CUTOFF_RATIO
        self._floor = PROFILE_ONLINE_CUTOFF_RATIO * body_heave.SPEED_FLOOR_MPS
        self._s = half_track_m
        self._state = body_heave.start(0.0)
        self._started = False
        self._prev = (0.0, 0.0, math.nan)     # the last (u_1, u_2, distance), unheld
        self._off = (0.0, 0.0)                # what standing added to the road (m)

    def restart(self) -> None:
        """The next sample starts a run (the body heave restarts there)."""
        self._started = False

    def road(self, op: list, dt: float, v: float, x: float) -> tuple[float, float]:
        """The road ``(u_1, u_2)`` (m) at distance ``x`` (m) from the profile filter's outputs
        ``op`` (:data:`.OUTPUTS`): ``u_i = z_s +- s sin(phi) - q_i + w_i``, ``z_s`` its body
        acceleration's band-limited double integral at the profile's cutoff
        (:data:`.model.PROFILE_ONLINE_CUTOFF_RATIO` x ``observer.profile_cutoff_wavelength``,
        the speed floored at that ratio times :data:`.body_heave.SPEED_FLOOR_MPS`; restarted
        with each run); held at a stop (the distance stands still, the model's speed ``v``
        (m/s) below that floor)."""
        ddzs = op[10]
        if self._started:
            av = v if v > 0.0 else -v
            if body_heave.STANDING_MPS <= av < self._floor:
                av = self._floor       # (standing, below STANDING_MPS, it holds)
            h = self._state = body_heave.step(self._state, ddzs, dt, av, self.wc)
            zs = h[-2]
        else:
            zs = 0.0
            self._state = body_heave.start(ddzs)
            self._started = True
            self._prev = (0.0, 0.0, math.nan)
            self._off = (0.0, 0.0)
        ssin = self._s * math.sin(op[2])
        u1 = zs + ssin - op[0] + op[15]
        u2 = zs - ssin - op[1] + op[16]
        p1, p2, px = self._prev
        self._prev = (u1, u2, x)
        o1, o2 = self._off
        if x == px and -body_heave.SPEED_FLOOR_MPS < v < body_heave.SPEED_FLOOR_MPS:
            # a stop: the distance stands still and the model's speed is below the body
            # heave's floor (a dropped-out speed that the deflections contradict keeps the
            # last trusted one, :mod:`.speed_check`); the road at one distance is one value:
            # what the estimate does then (the body heave's drift, or the integral's memory
            # of the rate before the stop) is no road
            o1 += u1 - p1
            o2 += u2 - p2
            self._off = (o1, o2)
        return u1 - o1, u2 - o2
