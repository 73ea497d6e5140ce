"""The front axle's reconstruction for the model observer (MODEL.md steps 4-9): the rows of
:class:`.outputs.Column` from the observer's linear outputs (:data:`.front_axle.OUTPUTS`),
one sample at a time (:class:`OnlineRows`, for :class:`..observer.online.ModelCore`) and over
a smoothed run (:class:`OfflineRows`, for :class:`..smoothing.smoother.Smoother`).

Online: the body heave is the causal band-limited double integral of the body acceleration
(:mod:`..body_heave`, restarted with each run), the rest :class:`.Reconstruction`'s; at zero
latency the road is the profile filter's (:class:`OnlineRoad`: its own body-heave integral at
the profile's long-wave cutoff, held at a stop). Offline: the body heave is the zero-phase
integral over the run, and the road the profile pass's (:meth:`OfflineRows.road`).
"""
from __future__ import annotations

import math

import numpy as np

import road_force_estimator.estimation.body_heave as body_heave
from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
from road_force_estimator.estimation.outputs import Column, field_columns
from road_force_estimator.estimation.reconstruction import Reconstruction

__all__ = ['OnlineRoad', 'OnlineRows', 'OfflineRows', 'SMOOTH_NAMES', 'PROFILE_DETREND_DEGREE',
           'PROFILE_CUTOFF_RATIO', 'PROFILE_ONLINE_CUTOFF_RATIO']

#: The outputs (:data:`.front_axle.OUTPUTS`) the offline rows need, in this order.
SMOOTH_NAMES = ('q1', 'q2', 'phi', 'dq1', 'dq2', 'dphi', 'ddq1', 'ddq2', 'ddphi', 'ddzs',
                'ddzu1', 'ddzu2', 'w1', 'w2', 'df1', 'df2', 'fb1', 'fb2')
#: Degree of the polynomial taken off the profile's body heave over each run (see
#: :meth:`OfflineRows.road`).
PROFILE_DETREND_DEGREE = 3
#: The profile's long-wave cutoff (m) is this many times ``observer.profile_cutoff_wavelength``
#: (the body heave's, MODEL.md step 4): the profile's judges see longer waves than the body
#: heave needs (the 0.5-30 m band-pass of order 2 passes 0.8 % at 100 m, where the ISO road's
#: amplitude is ten times that at 10 m; the body heave's 100 m cutoff alone cost the
#: noise-free C20-1k-0um almost all its profile error, a 10 km one next to none). Longer
#: cutoffs let the
#: double integral's low-frequency error and the zero-phase filter's edges wander further (on
#: a 120 m run after a stale stretch, test_speed_check, true road within 5 cm: 6.6 m at 30 x),
#: so the smoother takes the run's least-squares cubic off (:mod:`.smoother`): then 0.05 m, and
#: C20-1k-0um as good as at 10 km (``python -m bench.accuracy.run_benchmark --scenarios
#: C20-1k-0um``).
PROFILE_CUTOFF_RATIO = 100.0
#: The same for the zero-latency profile, whose causal integral follows the speed with a floor
#: of this ratio times the body heave's (1 m/s; never below the body heave's cutoff frequency
#: at its floor). The causal integral wanders further than the zero-phase one (largest |u| on
#: test_speed_check's drive: 0.43 m at 1 x, 0.81 m at 2 x, 1.19 m at 3 x, 2.8 m at 10 x);
#: the profile error on C20-1k-0um hardly falls beyond 2 x and is well below the load filter's
#: road at any (``python -m bench.accuracy.run_benchmark --scenarios C20-1k-0um``); 2 x gives
#: 1.03 m after a stale stretch (test_speed_check): 1.
PROFILE_ONLINE_CUTOFF_RATIO = 1.0


class OnlineRoad:
    """The road ``(u_1, u_2)`` of the profile filter's outputs, one sample at a time.

    Parameters
    ----------
    wc_per_speed : float
        The body heave's cutoff per speed (rad/m, :func:`.body_heave.cutoff_per_speed` of
        ``observer.profile_cutoff_wavelength``); the road's is that over
        :data:`PROFILE_ONLINE_CUTOFF_RATIO` (:attr:`wc`).
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
        (:data:`PROFILE_ONLINE_CUTOFF_RATIO` x ``observer.profile_cutoff_wavelength``,
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


class OnlineRows:
    """The rows of one run after another, sample by sample (:class:`.protocol.OnlineRows`):
    the body heave (:func:`.body_heave.step`, restarted with each run at the cutoff of
    ``observer.profile_cutoff_wavelength``), :meth:`.Reconstruction.row`, and at zero latency
    the profile filter's road (:class:`OnlineRoad`)."""

    def __init__(self, vehicle: VehicleParameters, observer: ObserverParameters) -> None:
        self._rows = Reconstruction(vehicle, observer.rollover_cutoff_frequency_hz)
        self._wc_per_speed = body_heave.cutoff_per_speed(observer.profile_cutoff_wavelength_m)
        self._road = OnlineRoad(self._wc_per_speed, vehicle.half_track_m)
        self._hstate = body_heave.start(0.0)
        self._body_started = False

    def set_vehicle(self, vehicle: VehicleParameters) -> None:
        """The vehicle of the rows from now on (:meth:`.Reconstruction.set_vehicle`)."""
        self._rows.set_vehicle(vehicle)

    def set_static(self, fc1: float, fc2: float) -> None:
        """The static wheel loads F_c,i (N) of the rows from now on."""
        self._rows.set_static(fc1, fc2)

    def restart(self) -> None:
        """The next row starts a run: the body heave and the road start again there."""
        self._body_started = False
        self._road.restart()

    def row(self, o: list, meta: tuple, op: list | None) -> tuple:
        """The row of the outputs o (:data:`.front_axle.OUTPUTS`), ``meta`` = (distance (m),
        dt (s), speed (m/s), converged); with the profile filter's outputs ``op`` (zero
        latency) the road is :class:`OnlineRoad`'s."""
        (q1, q2, phi, dq1, dq2, dphi, ddq1, ddq2, ddphi, _, ddzs, _, _, ddzu1, ddzu2, w1, w2,
         df1, df2, fb1, fb2) = o
        x_dist, dt, v, conv = meta
        if self._body_started:
            h = self._hstate = body_heave.step(self._hstate, ddzs, dt, v, self._wc_per_speed)
            zs = h[-2]
            dzs = h[-1]
        else:
            zs = dzs = 0.0
            self._hstate = body_heave.start(ddzs)
            self._body_started = True
            self._rows.restart()
        return self._rows.row(x_dist, q1, q2, dq1, dq2, ddq1, ddq2, phi, dphi, ddphi, zs, dzs,
                              ddzs, ddzu1, ddzu2, w1, w2, df1, df2, fb1, fb2, conv, dt,
                              None if op is None else self._road.road(op, dt, v, x_dist))


class OfflineRows:
    """The rows of smoothed runs (:class:`.protocol.OfflineRows`): the columns of
    :meth:`.Reconstruction.columns` from the smoothed outputs :data:`SMOOTH_NAMES`, the body
    heave of the whole run (zero phase) and the profile pass's road."""

    #: the columns of a piece's rows, their distance, and the columns the profile pass keeps
    distance_column = Column.DISTANCE
    #: the columns of the load pass the profile pass's roll moment needs (the residual)
    moment_columns = (Column.RESIDUAL,)
    road_columns = (Column.U1, Column.U2)
    profile_columns = (Column.U1, Column.U2, Column.DDZS)

    def __init__(self, vehicle: VehicleParameters, observer: ObserverParameters,
                 outputs: tuple, roll_moment_psd) -> None:
        """``outputs``: the model's output names; ``roll_moment_psd(residual, dt)``: the
        profile pass's roll-moment density from a run's roll residual."""
        self.observer = observer
        self.rows = Reconstruction(vehicle, observer.rollover_cutoff_frequency_hz)
        self.outputs = [outputs.index(name) for name in SMOOTH_NAMES]
        self._roll_moment_psd = roll_moment_psd

    @staticmethod
    def field_columns(m: int) -> tuple[dict, list]:
        """:func:`.outputs.field_columns`."""
        return field_columns(m)

    def columns(self, o: np.ndarray, out: list) -> None:
        """Rows of the columns ``out`` from the smoothed outputs ``o`` (:data:`SMOOTH_NAMES`,
        one per row) of those samples; the body heave comes later (:meth:`finish_run`)."""
        (q1, q2, ph, dq1, dq2, dph, ddq1, ddq2, ddph, ddzs, ddzu1, ddzu2, w1, w2, df1, df2, fb1,
         fb2) = o
        self.rows.columns(out, (q1, q2), (dq1, dq2), (ddq1, ddq2), ph, dph, ddph, ddzs,
                          (ddzu1, ddzu2), (w1, w2), (df1, df2), (fb1, fb2), None)

    def finish_run(self, out: list, t: np.ndarray, dt: float, speed: float, settle_s: float,
                   t_start: float | None = None) -> None:
        """The body heave of the whole run (zero phase, from dd z_s) added to the columns;
        the quasi-static LTR; the converged flag (``settle_s`` after ``t_start``, default
        ``t[0]``). ``dt`` and ``speed``: the run's median step (s) and |speed| (m/s)."""
        m = t.size
        if m >= 8:
            w_c = (2.0 * math.pi * max(speed, body_heave.SPEED_FLOOR_MPS)
                   / self.observer.profile_cutoff_wavelength_m)
            zs = body_heave.zero_phase(out[Column.DDZS], dt, w_c)
            dzs = np.gradient(zs, t, edge_order=2)
            self.rows.add_heave(out, zs, dzs)
        self.rows.add_quasi_static(out, t)
        out[Column.CONVERGED][:] = (t - (t[0] if t_start is None else t_start)) >= settle_s

    def roll_moment_psd(self, out, dt: float) -> float:
        """The profile pass's roll-moment density ((N m)^2 / s) from a run's roll residual:
        :func:`.front_axle.offline_roll_moment_psd`."""
        return self._roll_moment_psd(out[Column.RESIDUAL], dt)

    def road(self, cols, dt: float, speed: float, dts: np.ndarray | None, uniform: bool,
             pos: np.ndarray | None, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The road ``(u_1, u_2)`` (m) of a run's samples from the profile pass's columns
        ``cols`` (on the grid ``pos`` when not None): ``u_i = z_s + s sin(phi) - q_i + w_i``
        with the body heave's zero-phase integral at the profile's cutoff
        (:data:`PROFILE_CUTOFF_RATIO` x ``observer.profile_cutoff_wavelength``,
        less its cubic over the run, :data:`PROFILE_DETREND_DEGREE`): in time when the speed
        is steady, else in distance (:func:`.body_heave.offline_profile`); where the model's
        speed ``v`` (m/s) is 0 the road is held."""
        zs = self._profile_heave(cols, dt, speed, dts, uniform, pos, v)
        # standing: the model's speed 0 (a real stop; a dropped-out speed that the deflections
        # contradict keeps the last trusted speed, :mod:`.speed_check`)
        standing = (v[1:] == 0.0) & (v[:-1] == 0.0)
        road = []
        for j in (Column.U1, Column.U2):
            u = cols[j] + zs
            u = u if pos is None else u[pos]
            if standing.any():
                # standing, the road under the tires does not change: what the estimate does
                # then (the body heave's drift, integrated in time) is no road
                du = np.diff(u)
                du[standing] = 0.0
                u = u[0] + np.concatenate([[0.0], np.cumsum(du)])
            road.append(u)
        return road[0], road[1]

    def road_pieces(self, kept, m: int, dt: float, speed: float, folder,
                    piece: int | None = None, v: np.ndarray | None = None):
        """:meth:`road` of an evenly sampled run (``pos`` None) from the profile pass's columns
        in a file, ``kept`` (:class:`~.core.spill.SpillColumn` (m, 3): u_1, u_2, dd z_s,
        :attr:`profile_columns`' order), ``piece`` rows at a time (default
        :data:`.body_heave.CHUNK`), the model speeds ``v`` (m/s, (m,)): the body heave's
        zero-phase integral in a file (:func:`.body_heave.zero_phase_pieces`), its cubic fitted
        over it (:func:`.body_heave.polynomial_fit_pieces`), then ``u_i = w_i + z_s`` a piece
        at a time, held where the model stands (the steps' running sum carried from piece to
        piece, as ``np.cumsum``). Returns the roads (m, 2), m, in a file in ``folder``: the
        same bits as :meth:`road` on the columns in memory, none held whole. A run with a stop
        (the integral in distance, :func:`.body_heave.in_distance`) reads the columns whole
        and is :meth:`road` itself."""
        from road_force_estimator.core.spill import SpillColumn

        piece = max(int(piece or body_heave.CHUNK), 1)
        bounds = [(i, min(m, i + piece)) for i in range(0, m, piece)]
        way = (body_heave.offline_profile_way(
            v, speed, self.observer.profile_cutoff_wavelength_m, PROFILE_CUTOFF_RATIO)
            if m >= 8 else (None, False))
        roads = SpillColumn(float, 2, folder)
        zs = coef = None
        try:
            if way is None:                      # in distance: over the whole run
                cols = {j: np.ascontiguousarray(c) for j, c in zip(self.profile_columns,
                                                                kept.array().T)}
                roads.append(np.column_stack(self.road(cols, dt, speed, None, True, None, v)))
                return roads
            w, detrend = way
            if w is not None:
                zs = body_heave.zero_phase_pieces(
                    m, lambda i, j: kept.read(i, j)[:, 2:], 1, dt, w, folder, piece)
                if detrend:
                    coef = body_heave.polynomial_fit_pieces(
                        m, lambda i, j: zs.read(i, j)[:, 0], PROFILE_DETREND_DEGREE)
            standing = (v[1:] == 0.0) & (v[:-1] == 0.0)
            held = bool(standing.any())
            u0 = last = total = None
            for i, j in bounds:
                z = 0.0 if zs is None else zs.read(i, j)[:, 0]
                if coef is not None:
                    z -= body_heave.polynomial_values(coef, m, i, j)
                u = kept.read(i, j)[:, :2] + (z if np.ndim(z) == 0 else z[:, None])
                if held:                         # standing: the road does not change
                    du = np.diff(u if last is None else np.vstack([last, u]), axis=0)
                    last = u[-1:].copy()
                    du[standing[max(i - 1, 0):j - 1]] = 0.0
                    if u0 is None:
                        u0 = u[0].copy()
                        run = np.cumsum(du, axis=0)
                        u = u0 + np.vstack([np.zeros((1, 2)), run])
                    else:
                        run = np.cumsum(du if total is None else np.vstack([total, du]),
                                        axis=0)[0 if total is None else 1:]
                        u = u0 + run
                    if run.shape[0]:
                        total = run[-1:].copy()
                roads.append(u)
        except BaseException:
            roads.close()
            raise
        finally:
            if zs is not None:
                zs.close()
        return roads

    def _profile_heave(self, cols: list, dt: float, speed: float, dts: np.ndarray | None,
                       uniform: bool, pos: np.ndarray | None, v: np.ndarray):
        """The profile's body heave (m) from the profile pass's columns ``cols`` (on the grid
        ``pos`` when not None): :func:`.body_heave.offline_profile`."""
        m = cols[Column.DDZS].size
        vg = v if pos is None else np.interp(np.arange(m), pos, v)
        tg = (dt * np.arange(m) if uniform or pos is not None else
              np.concatenate([[0.0], np.cumsum(dts)]))
        return body_heave.offline_profile(
            cols[Column.DDZS], 0.5 * (cols[Column.U1] + cols[Column.U2]), tg, vg, dt,
            speed, self.observer.profile_cutoff_wavelength_m,
            PROFILE_CUTOFF_RATIO, PROFILE_DETREND_DEGREE)
