"""The whole vehicle's reconstruction for the model observer (``vehicle.model: articulated``):
every wheel's vertical load, the static share plus the dynamic tire force, and each unit's
lateral acceleration, as rows of :func:`columns` (online, :class:`ArticulatedOnlineRows`) and
columns of smoothed runs (:class:`ArticulatedOfflineRows`).

Columns of N axles (``nw = 2 N`` wheels, axle j front first, left then right)::

    [distance, converged, F_n (nw), dF (nw), a_y,t, a_y,r, road (nw), dd z_w (nw)]

Online rows stop after the road, every wheel's. At zero latency (:data:`ROAD_FROM_BODIES`)
from the bodies, as the front axle's (:class:`BodyRoads`): its axle's heave and roll from the
bodies' heave, pitch and roll and its springs' extensions, plus the tire's deflection, the
bodies' heave and pitch the causal band-limited double integrals of their accelerations from
the model's force balance (the zero-latency profile filter's outputs). With
``observer.latency`` from the wheels: ``u = w + z_w`` with ``z_w`` the causal band-limited
double integral (:func:`.body_heave.step`'s filter, every wheel's in one product of
:func:`.body_heave.step_matrix`) of the wheel's acceleration from the fixed-lag outputs
(:class:`WheelRoads`). Both: cutoff :data:`ROAD_CUTOFF_FACTOR` x
``observer.profile_cutoff_wavelength``, the run's start ramped in as offline, held at a stop
(:class:`WheelRoads`). Offline, the road under every wheel comes from the smoother's
profile pass (:meth:`ArticulatedOfflineRows.road`): ``u = w + z_w``, ``z_w`` the zero-phase
band-limited double integral (:func:`.body_heave.zero_phase`, cutoff
:data:`ROAD_CUTOFF_FACTOR` x ``observer.profile_cutoff_wavelength``) of the wheel's vertical
acceleration; each axle's road on its own (their fusion by distance:
:func:`..articulated.fuse_roads`).
"""
from __future__ import annotations

import math
from operator import add, itemgetter

import numpy as np

from road_force_estimator.core.articulated_model import ArticulatedModel
from road_force_estimator.estimation import body_heave
from road_force_estimator.estimation.body_heave import SPEED_FLOOR_MPS
from road_force_estimator.estimation.models.front_axle import PROFILE_OFFLINE_ROLL_MOMENT_PSD

__all__ = ['DIST', 'CONV', 'ROAD_START_S', 'ROAD_RAMP_S', 'ROAD_CUTOFF_FACTOR', 'columns',
           'WheelRoads', 'BodyRoads', 'body_road_gains', 'ROAD_FROM_BODIES',
           'ArticulatedOnlineRows', 'ArticulatedOfflineRows', 'ROAD_PIECE_ROWS']

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
#: Online, every wheel's road from the bodies (:class:`BodyRoads`) rather than from the
#: wheels' own accelerations (:class:`WheelRoads`): at zero latency and with
#: ``observer.latency``. The bodies' at zero latency; the wheels' with 10 ms, where the bodies'
#: halve the 0.5-30 m band's error but lower the IRI-filtered cross correlation (their 1-3 m
#: band's error larger): ``python -m bench.accuracy.articulated_fusion --duration 25 --online
#: 0 0.01``, docs/articulated.md "The road online".
ROAD_FROM_BODIES = (True, False)


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


def _body_road_index(model) -> tuple[list, list]:
    """The outputs of the bodies' heave and pitch accelerations (:class:`BodyRoads`' order),
    then of the bodies' roll, every spring's extension and every tire's deflection."""
    names = model.outputs
    wheels = [n[len('df_'):] for n in (names[i] for i in model.load_outputs)]
    acc = [names.index(f'{a}_{b}') for b in ('tractor', 'trailer') for a in ('ddz', 'ddtheta')]
    lin = [names.index(f'phi_{b}') for b in ('tractor', 'trailer')]
    lin += [names.index(f'q_{w}') for w in wheels] + [names.index(f'w_{w}') for w in wheels]
    return acc, lin


def _road_index(model) -> list:
    """The outputs of every tire's deflection, then of every wheel's acceleration."""
    names = model.outputs
    wheels = [n[len('df_'):] for n in (names[i] for i in model.load_outputs)]
    return [names.index(f'w_{w}') for w in wheels] + [names.index(f'ddzw_{w}') for w in wheels]


class WheelRoads:
    """Every wheel's road (m) one finalized sample at a time: ``u = w + z_w``, ``z_w`` the
    causal band-limited double integral of the wheel's acceleration (:func:`.body_heave.step`'s
    filter, ``wc_per_speed`` rad/m; the speed floored at :data:`.body_heave.SPEED_FLOOR_MPS`),
    the acceleration left out for :data:`ROAD_START_S` of a run and ramped in over
    :data:`ROAD_RAMP_S` (the offline road's start); at a stop (the distance stands still and
    the speed below the floor) the road holds (what the integral does then is no road, as
    the front axle's :class:`.front_axle_rows.OnlineRoad`). Every wheel's filter steps in one
    product (:func:`.body_heave.step_matrix`, a column per wheel): the numbers of
    :func:`.body_heave.step` per wheel within rounding (test_articulated_rows.py), the
    speed's rescaling and the hold while standing as it does them."""

    def __init__(self, nw: int, wc_per_speed: float, n_integrals: int | None = None) -> None:
        self.nw = int(nw)
        #: the double integrals stepped (one per wheel here; :class:`BodyRoads`: four)
        self.ni = self.nw if n_integrals is None else int(n_integrals)
        self.wc = float(wc_per_speed)
        self._key: tuple | None = None       # (dt, wc) of the step matrix
        self._m = np.empty((0, 0))
        self.restart()

    def restart(self) -> None:
        """The next sample starts a run."""
        self._t = -1.0                  # time since the run's start (s); < 0: not started
        # the filters' states, a column per integral: y_1..y_8, then a_old + accel (scratch);
        # the product writes the other buffer (its last row z_s)
        self._y = np.zeros((body_heave.ORDER + 1, self.ni))
        self._n = np.zeros((body_heave.ORDER + 1, self.ni))
        self._a_old: list = [0.0] * self.ni
        self._w_old = 0.0               # the cutoff of the last step (rad/s; 0: none yet)
        self._z: list = [0.0] * self.ni
        self._prev: list | None = None
        self._x = math.nan
        self._off = [0.0] * self.nw
        self._offset = False            # whether an offset was ever taken (a stop)

    def _integrate(self, accel: list, dt: float, v: float) -> list:
        """Every wheel's ``z_w`` (m) after a step (:func:`.body_heave.step`'s rules)."""
        av = v if v > 0.0 else -v
        if av < body_heave.STANDING_MPS:       # standing: held, the newest accel kept
            self._a_old = accel
            return self._z
        wc = self.wc * (av if av > SPEED_FLOOR_MPS else SPEED_FLOOR_MPS)
        if (dt, wc) != self._key:
            self._key = (dt, wc)
            self._m = body_heave.step_matrix(dt, wc)
        m = self._m
        w_old = self._w_old
        if wc > w_old > 0.0:     # the states in distance kept (body_heave.step): y_k scaled
            r = w_old / wc
            r2 = r * r
            r4 = r2 * r2
            m = m * np.array((1.0 / r, 1.0, r, r2, r2 * r, r4, r4 * r, r4 * r2, 1.0))
        y = self._y
        y[body_heave.ORDER] = list(map(add, self._a_old, accel))   # (the same sums as numpy's)
        n = self._n
        m.dot(y, n)           # (np.dot's product, without its dispatch in Python)
        self._y, self._n = n, y
        self._w_old = wc
        self._a_old = accel
        z = self._z = n[body_heave.ORDER].tolist()
        return z

    def road(self, w: list, accel: list, dt: float, v: float, x: float) -> list:
        """The roads (m) from the tires' deflections ``w`` (m) and the wheels' accelerations
        ``accel`` (m/s^2, up) after a step ``dt`` (s) at speed ``v`` (m/s), distance ``x``
        (m)."""
        return self._hold(list(map(add, w, self._heave(accel, dt, v))), v, x)

    def _heave(self, accel: list, dt: float, v: float) -> list:
        """The double integrals (the accelerations' units times s^2) after a step: the run's
        start left out and ramped in."""
        t = self._t
        if t < 0.0:
            t = self._t = 0.0
            self.restart()
            self._t = 0.0
        else:
            t = self._t = t + dt
        if t < ROAD_START_S:
            ramp = 0.0
        elif t < ROAD_START_S + ROAD_RAMP_S:
            ramp = 0.5 - 0.5 * math.cos(math.pi * (t - ROAD_START_S) / ROAD_RAMP_S)
        else:
            ramp = 1.0
        acc = accel if ramp == 1.0 else [ramp * a for a in accel]
        if self._prev is None:                 # the run's first sample: body_heave.start
            self._a_old = acc
            return self._z
        return self._integrate(acc, dt, v)

    def _hold(self, u: list, v: float, x: float) -> list:
        """The roads ``u`` (m) held at a stop (the distance ``x`` (m) stands still and the
        speed ``v`` (m/s) below the floor)."""
        prev, px = self._prev, self._x
        self._prev, self._x = u, x
        off = self._off
        if prev is not None and x == px and -SPEED_FLOOR_MPS < v < SPEED_FLOOR_MPS:
            for k in range(self.nw):
                off[k] += u[k] - prev[k]
            self._offset = True
        # (u - 0.0 is u, bit for bit: no offset yet, none taken)
        return [a - b for a, b in zip(u, off)] if self._offset else u


def body_road_gains(model: ArticulatedModel) -> np.ndarray:
    """``C`` (nw, 6 + 2 nw) of every wheel's road ``u = C [Z_t, Theta_t, Z_r, Theta_r, phi_t,
    phi_r, q (nw), w (nw)]`` from the linearised kinematics (MODEL.md, the core's
    :meth:`~.core.articulated_model.ArticulatedModel.kinematics`): the axle's heave and roll
    from its springs' extensions ``q_j,i = z_b + d_j theta_b +- s_j phi_b - (z_a,j +- s_j
    phi_a,j)`` (m, rad; theta nose down, phi left side up), the wheel's heave ``z_a,j +- w_j
    phi_a,j`` plus the tire's deflection ``w = u - z_w``; ``Z``, ``Theta`` the bodies' heave
    (m, up) and pitch (rad)."""
    springs, wheels, _, _ = model.kinematics()
    n_axles = springs.shape[0]
    nw = 2 * n_axles
    body_cols = [0, 1, 3, 4, 2, 5]         # z_t, theta_t, z_r, theta_r, phi_t, phi_r
    c = np.zeros((nw, 6 + 2 * nw))
    for j in range(n_axles):
        ia = 6 + 2 * j
        k = wheels[j][:, ia:ia + 2] @ np.linalg.inv(springs[j][:, ia:ia + 2])
        rows = slice(2 * j, 2 * j + 2)
        c[rows, :6] = -k @ springs[j][:, body_cols]
        c[rows, 6 + 2 * j:8 + 2 * j] = k
        c[rows, 6 + nw + 2 * j:8 + nw + 2 * j] = np.eye(2)
    return c


class BodyRoads(WheelRoads):
    """Every wheel's road (m) one finalized sample at a time from the bodies (as the front
    axle's :class:`.front_axle_rows.OnlineRoad`): ``u = C [Z, Theta, phi, q, w]``
    (:func:`body_road_gains`), ``Z``, ``Theta`` the causal band-limited double integrals of
    the tractor's and the trailer's heave and pitch accelerations (the model's force balance:
    smooth, where the wheels' are the least known at zero latency); the start, the stop and
    the speed floor as :class:`WheelRoads`' (four integrals instead of one per wheel)."""

    def __init__(self, gains: np.ndarray, wc_per_speed: float) -> None:
        self.gains = np.asarray(gains, float)
        super().__init__(self.gains.shape[0], wc_per_speed, n_integrals=4)

    def road(self, lin: tuple, accel: tuple, dt: float, v: float, x: float) -> list:
        """The roads (m) from ``lin`` = ``[phi_t, phi_r, q (nw), w (nw)]`` (rad, m) and the
        bodies' accelerations ``accel`` = ``[dd z_t, dd theta_t, dd z_r, dd theta_r]`` (m/s^2
        up, rad/s^2 nose down) after a step ``dt`` (s) at speed ``v`` (m/s), distance ``x``
        (m)."""
        z = self._heave(accel, dt, v)
        return self._hold(self.gains.dot([*z, *lin]).tolist(), v, x)


class ArticulatedOnlineRows:
    """Rows one sample at a time (:class:`.protocol.OnlineRows`): loads, a_y and every
    wheel's road (:class:`WheelRoads`) from the finalized outputs."""

    #: the rows take their road from the load filter's outputs: the core runs no zero-latency
    #: profile filter for them (its design and its product per sample saved)
    uses_profile = True

    def __init__(self, model, observer=None) -> None:
        self.static = [float(f) for f in model.static_wheel_load_n]
        self._df, self._ay = _output_index(model)
        idx = _road_index(model)
        nw = len(self.static)
        # the outputs each part of a row takes, gathered at once
        self._take_df, self._take_ay = itemgetter(*self._df), itemgetter(*self._ay)
        cutoff = ROAD_CUTOFF_FACTOR * (100.0 if observer is None
                                       else observer.profile_cutoff_wavelength_m)
        lag = observer is not None and observer.latency_s > 0.0
        #: whether the roads come from the bodies (:data:`ROAD_FROM_BODIES`)
        self.from_bodies = ROAD_FROM_BODIES[1 if lag else 0]
        if self.from_bodies:
            acc, lin = _body_road_index(model)
            self._take_w, self._take_acc = itemgetter(*lin), itemgetter(*acc)
            self.roads = BodyRoads(body_road_gains(model.core),
                                   body_heave.cutoff_per_speed(cutoff))
        else:
            self._take_w, self._take_acc = itemgetter(*idx[:nw]), itemgetter(*idx[nw:])
            self.roads = WheelRoads(nw, body_heave.cutoff_per_speed(cutoff))

    def restart(self) -> None:
        """The next row starts a run (the roads' integrals restart)."""
        self.roads.restart()

    def set_vehicle(self, vehicle) -> None:
        """The static loads (and the bodies' road gains) of other parameters."""
        core = ArticulatedModel(vehicle)
        self.static = [float(f) for f in core.statics().output_wheel_load_n.reshape(-1)]
        if self.from_bodies:
            self.roads.gains = body_road_gains(core)

    def set_static(self, *static_n: float) -> None:
        """The static wheel loads (N), one per wheel."""
        if len(static_n) != len(self.static):
            raise ValueError(f'{len(static_n)} static loads for {len(self.static)} wheels')
        self.static = [float(f) for f in static_n]

    def row(self, o: list, meta: tuple, op) -> tuple:
        """``(distance, converged, F_n..., dF..., a_y,t, a_y,r, u...)``."""
        x, dt, v, conv = meta
        df = self._take_df(o)
        r = o if op is None else op
        u = self.roads.road(self._take_w(r), self._take_acc(r), dt, v, x)
        return (x, conv, *map(add, self.static, df), *df, *self._take_ay(o), *u)


#: The rows :meth:`ArticulatedOfflineRows.road_pieces` reads at a time (20 columns: ~10 MB).
ROAD_PIECE_ROWS = 1 << 16


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

    def road_pieces(self, kept, m: int, dt: float, speed: float, folder,
                    piece: int | None = None, v=None):
        """:meth:`road` of an evenly sampled run (``pos`` None) from the profile pass's
        columns in a file, ``kept`` (:class:`~.core.spill.SpillColumn` (m, 2 wheels): every
        wheel's tire deflection then its acceleration, :attr:`profile_columns`' order),
        ``piece`` rows at a time (:data:`ROAD_PIECE_ROWS`): the double integral over them
        (:func:`.body_heave.zero_phase_pieces`: the forward pass in order, its state carried
        and its output in a file in ``folder``, the backward pass over them in reverse); the
        roads (m, wheels) in a file there (returned). The same bits as :meth:`road` on the
        columns in memory (``v``, the model speeds, not needed: the road in time)."""
        from road_force_estimator.core.spill import SpillColumn

        nw = self.static.size
        w_c = 2.0 * math.pi * max(speed, SPEED_FLOOR_MPS) / self.cutoff_m
        n0 = min(int(round(ROAD_START_S / dt)), m)
        n1 = min(int(round(ROAD_RAMP_S / dt)), m - n0)

        def ramp(i: int, j: int) -> np.ndarray:  # :meth:`road`'s ramp, rows i:j
            r = np.ones(j - i)
            r[:max(0, min(j, n0) - i)] = 0.0
            a, b = max(i, n0), min(j, n0 + n1)
            if b > a:
                r[a - i:b - i] = 0.5 - 0.5 * np.cos(np.pi * np.arange(a - n0, b - n0)
                                                    / max(n1, 1))
            return r

        piece = max(int(piece or ROAD_PIECE_ROWS), 1)
        bounds = [(i, min(m, i + piece)) for i in range(0, m, piece)]
        roads = SpillColumn(float, nw, folder)
        if m < 8:                             # zero_phase: no integral
            for i, j in bounds:
                roads.append(kept.read(i, j)[:, :nw] + 0.0)
            return roads
        zs = None
        try:
            zs = body_heave.zero_phase_pieces(
                m, lambda i, j: kept.read(i, j)[:, nw:] * ramp(i, j)[:, None], nw, dt, w_c,
                folder, piece)
            for i, j in bounds:
                roads.append(kept.read(i, j)[:, :nw] + zs.read(i, j))
        except BaseException:
            roads.close()
            raise
        finally:
            if zs is not None:
                zs.close()
        return roads

    def road(self, cols, dt: float, speed: float, dts, uniform: bool, pos, v) -> tuple:
        """The road under every wheel (m): ``w + z_w`` (module notes), on the grid ``pos``
        when given. ``cols`` is the profile pass's scratch: each wheel's road is built in its
        tire-deflection column and, where ``cols`` keeps its columns in a dict (``kept``,
        :class:`.smoothing.smoother.KeptColumns`), its acceleration column let go once used
        (a long run's road takes no memory beyond the pass's columns)."""
        w_c = 2.0 * math.pi * max(speed, SPEED_FLOOR_MPS) / self.cutoff_m
        road, accel = self.cols['road'].start, self.cols['wheel_accel'].start
        m = cols[road].size
        n0 = min(int(round(ROAD_START_S / dt)), m)
        ramp = np.ones(m)            # the start left out of the integral, then a cosine ramp
        ramp[:n0] = 0.0
        n1 = min(int(round(ROAD_RAMP_S / dt)), m - n0)
        ramp[n0:n0 + n1] = 0.5 - 0.5 * np.cos(np.pi * np.arange(n1) / max(n1, 1))
        out = []
        kept = getattr(cols, 'kept', None)
        for k in range(self.static.size):
            u = cols[road + k]
            u += body_heave.zero_phase(cols[accel + k] * ramp, dt, w_c)
            if isinstance(kept, dict):
                kept.pop(accel + k, None)
            out.append(u if pos is None else u[pos])
        return tuple(out)
