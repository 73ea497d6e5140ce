"""The operating point of the model observer and its gains: noise and roughness statistics,
levels on logarithmic grids with hysteresis, the cache of gain designs.

Gains depend on the operating point ``(dt, v, sigma_q, sigma_phi, Gd)``; each is tracked on
a logarithmic grid with hysteresis, which only decides *when* to design again: a design (a
few ms, :func:`.gains.design`) uses the estimates of that moment and is cached, never per
sample. The noise is estimated per block from the sixth differences (:func:`.noise.noise_std`;
median of the last :data:`HISTORY_BLOCKS` blocks), the roughness by moment matching of the
first differences of the deflections (median of the last :data:`ROUGHNESS_HISTORY_BLOCKS`);
see :mod:`.models.front_axle` for the whole story. :class:`GainSchedule` is shared by the online
observer (:mod:`.observer.online`) and the offline smoother (:mod:`.smoother`).
"""
from __future__ import annotations

from collections import deque
import math
import warnings

import numpy as np
from scipy import linalg

from road_force_estimator.core.parameters import ObserverParameters
from road_force_estimator.estimation.body_heave import SPEED_FLOOR_MPS
from road_force_estimator.estimation.models.protocol import VehicleModel, road_diffusion
from road_force_estimator.estimation.observer.gains import NOISE_FLOOR_M, Gains, design
from road_force_estimator.core.pieces import medians, pairwise_mean
from road_force_estimator.estimation.observer.noise import (MAD_GAUSSIAN, NOISE_DIFF_ORDER,
                                                            mad_std, noise_std)
from road_force_estimator.estimation.observer.riccati import van_loan

__all__ = [
    'HISTORY_BLOCKS', 'ROUGHNESS_HISTORY_BLOCKS', 'NOISE_LEVEL_RATIO', 'ROUGHNESS_LEVEL_RATIO',
    'SPEED_LEVEL_RATIO', 'DT_LEVEL_RATIO', 'LEVEL_HYSTERESIS', 'MIN_SETTLE_S', 'MAX_GAINS',
    'DEFAULT_NOISE_M', 'DEFAULT_NOISE_RAD', 'DEFAULT_ROAD_GD_M3', 'MIN_ROAD_GD_M3',
    'ROUGHNESS_CORRELATION_M', 'DEFAULT_DQ_STD_MPS', 'NEUTRAL_TOLERANCE', 'requantise',
    'dt_level', 'difference_covariance', 'GainSchedule', 'PIECE_ROWS',
]

#: Rows of a block in a file (:class:`~.core.spill.SpillRows`) that :meth:`GainSchedule.
#: statistics` takes at a time (its temporaries: ~30 values a row).
PIECE_ROWS = 1 << 16
#: Blocks whose median is the current noise estimate.
HISTORY_BLOCKS = 8
#: Blocks whose median is the current roughness estimate (a block's roughness varies by a
#: factor 3 either way with the stretch of road it covers; 32 blocks, 8 s at 1 kHz, keep the
#: median within ~15 % on ISO roads).
ROUGHNESS_HISTORY_BLOCKS = 32
#: Quantisation ratios of the operating point (gains are designed per level).
NOISE_LEVEL_RATIO = 2.0 ** 0.25
ROUGHNESS_LEVEL_RATIO = 2.0 ** 0.5
SPEED_LEVEL_RATIO = 1.1
DT_LEVEL_RATIO = 1.1
#: ... of the RMS suspension rate (with leaf-spring friction only: its equivalent damping).
DQ_LEVEL_RATIO = 2.0 ** 0.5
_LOG_DT_RATIO = math.log(DT_LEVEL_RATIO)
#: A level changes once the estimate is this many levels away from it (hysteresis).
LEVEL_HYSTERESIS = 0.75
#: Shortest settling time (s) after a (re)start or a change of the noise levels.
MIN_SETTLE_S = 0.1
#: Cache size.
MAX_GAINS = 128
#: Noise and roughness assumed until the first block of data has been seen.
DEFAULT_NOISE_M = 1e-5
DEFAULT_NOISE_RAD = 1e-4
DEFAULT_ROAD_GD_M3 = 256e-6
#: Floor of the estimated roughness (m^3): a quarter of ISO class A's Gd(n0), so that a
#: glass-smooth stretch does not make the observer too slow for the next bump.
MIN_ROAD_GD_M3 = 4e-6
#: Correlation length (m) of the road model whose variance the roughness estimate matches:
#: a moving average of 0.25 m (the tire envelope) over a Brownian road has the variance of
#: an Ornstein-Uhlenbeck velocity with this length (pi x 0.25 m).
ROUGHNESS_CORRELATION_M = 0.8
#: Distance |lambda - 1| below which a mode of a discretized model is neutral (a family of
#: equilibria: :func:`difference_covariance`).
NEUTRAL_TOLERANCE = 1e-7
#: RMS suspension rate (m/s) assumed until the first block of data has been seen.
DEFAULT_DQ_STD_MPS = 0.05


def _level(x: float, ratio: float) -> float:
    return math.log(x) / math.log(ratio)


def requantise(current: int | None, x: float, ratio: float) -> int:
    """Level of x with hysteresis around the current level."""
    lv = _level(x, ratio)
    if current is None or abs(lv - current) > LEVEL_HYSTERESIS:
        return int(round(lv))
    return current


def dt_level(dt: float) -> int:
    """Level of the step dt (s)."""
    return int(round(math.log(dt) / _LOG_DT_RATIO))


def difference_covariance(a: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Covariance of the first difference ``x_k - x_(k-1)`` of ``x_(k+1) = a x_k + w_k``
    (``Cov w = q``) in its stationary state: ``d P d^T + q``, ``d = a - I``, P the discrete
    Lyapunov solution. Modes of ``a`` at 1 (within :data:`NEUTRAL_TOLERANCE`: a family of
    equilibria, e.g. the road levels under the axles of a whole vehicle, which a random walk
    moves without bound) have no stationary variance but do not move a difference: they are
    left out (the stable modes' Lyapunov solution in the eigenvectors' coordinates); a model
    without them (the front axle's stationary states) takes the direct solution as ever."""
    lam, vecs = np.linalg.eig(a)
    stable = np.abs(lam - 1.0) > NEUTRAL_TOLERANCE
    if np.all(stable):
        with warnings.catch_warnings():   # undamped models: no stationary variance
            warnings.simplefilter('ignore')
            p = linalg.solve_discrete_lyapunov(a, q, method='direct')
        d = a - np.eye(a.shape[0])
        return d @ p @ d.T + q
    qm = np.linalg.solve(vecs, np.linalg.solve(vecs, q.T).conj().T)[np.ix_(stable, stable)]
    ls = lam[stable]
    p = qm / (1.0 - np.outer(ls, ls.conj()))
    d = (a - np.eye(a.shape[0])) @ vecs[:, stable]
    return (d @ p @ d.conj().T).real + q


class GainSchedule:
    """Noise and roughness estimates, the operating-point levels and the gains in use.

    Parameters
    ----------
    model : VehicleModel
        The vehicle (:mod:`..models`): its linear model, channels and tuning.
    observer : ObserverParameters
        ``noise_deflection_m`` / ``noise_roll_rad`` / ``road_roughness_m3`` (0 = estimate),
        ``road_correlation_length_m`` (0 = scheduled).

    Notes
    -----
    ``levels`` holds the levels ``'dt'``, ``'v'``, ``'nq'``, ``'nr'``, ``'gd'``; ``stale`` is
    True when the gains in use (``gains``) are not those of the levels.
    """

    def __init__(self, model: VehicleModel, observer: ObserverParameters) -> None:
        self.model = model
        self.observer = observer
        self._gains: dict[tuple, Gains] = {}
        self._profile_gains: dict[tuple, Gains] = {}
        self._var_dq: dict[tuple, float] = {}
        self.reset()

    def reset(self) -> None:
        """Forget the estimates and levels (the caches of designs stay)."""
        obs = self.observer
        self.noise_fixed = (obs.noise_deflection_m > 0.0, obs.noise_roll_rad > 0.0)
        self.roughness_fixed = obs.road_roughness_m3 > 0.0
        self.noise_deflection_m = obs.noise_deflection_m or DEFAULT_NOISE_M
        self.noise_roll_rad = obs.noise_roll_rad or DEFAULT_NOISE_RAD
        self.road_gd_m3 = obs.road_roughness_m3 or DEFAULT_ROAD_GD_M3
        #: RMS suspension rate (m/s), estimated per block with the roughness (it sets the
        #: friction's equivalent damping in the designs; only with leaf-spring friction)
        self.dq_std_mps = DEFAULT_DQ_STD_MPS
        self.friction = any(self.model.friction_n)
        self.all_fixed = all(self.noise_fixed) and self.roughness_fixed
        self.blocks = 0                    # statistics blocks seen
        self.design_count = 0              # gain designs (cache misses)
        self.profile_design_count = 0      # ... of the profile filter
        self.design_failures = 0           # designs that fell back to the default levels
        self.history = (deque(maxlen=HISTORY_BLOCKS), deque(maxlen=HISTORY_BLOCKS),
                        deque(maxlen=ROUGHNESS_HISTORY_BLOCKS))
        self.dq_history: deque = deque(maxlen=ROUGHNESS_HISTORY_BLOCKS)
        self.levels: dict[str, int | None] = {'nq': None, 'nr': None, 'gd': None,
                                              'v': None, 'dt': None, 'dq': None}
        self.gains: Gains | None = None
        self.stale = True
        #: channels the designs leave out (a stuck sensor: :meth:`.ModelCore.set_excluded`)
        self.excluded: tuple = ()
        self.v_band = (math.inf, -math.inf)
        self.requantise_noise()

    @property
    def estimated(self) -> bool:
        """True once the noise and roughness are known (configured, or one block seen)."""
        return self.blocks > 0 or self.all_fixed

    def settling_time_s(self, dt_s: float) -> float:
        """Time after a (re)start after which the estimate counts as converged (s).

        The time in which the current gains take a start-up error's effect on the tire forces
        down to 5 % (:func:`.gains.design`), at least 20 steps and :data:`MIN_SETTLE_S`.
        """
        settle = self.gains.settle_s if self.gains is not None else 0.0
        return max(settle, 20.0 * dt_s, MIN_SETTLE_S)

    def set_model(self, model: VehicleModel) -> None:
        """Design for ``model`` from now on (an estimated sprung mass): the caches of designs
        are dropped, the estimates and levels stay; the gains in use stay until the next design
        (``stale``), so that samples held back can still be finalized."""
        self.model = model
        self._gains.clear()
        self._var_dq.clear()
        self.stale = True

    def invalidate(self) -> None:
        """Drop the gains in use (e.g. the lag changed)."""
        self.gains = None
        self.stale = True

    def requantise_noise(self) -> bool:
        """Noise and roughness levels from the estimates; True when a noise changed by more
        than a factor 2 or the roughness by more than 4 (the settling time restarts)."""
        lv = self.levels
        old = (lv['nq'], lv['nr'], lv['gd'])
        lv['nq'] = requantise(lv['nq'], max(self.noise_deflection_m, NOISE_FLOOR_M),
                              NOISE_LEVEL_RATIO)
        lv['nr'] = requantise(lv['nr'], max(self.noise_roll_rad, NOISE_FLOOR_M),
                              NOISE_LEVEL_RATIO)
        lv['gd'] = requantise(lv['gd'], self.road_gd_m3, ROUGHNESS_LEVEL_RATIO)
        g = self.gains
        if self.friction:
            lv['dq'] = requantise(lv['dq'], self.dq_std_mps, DQ_LEVEL_RATIO)
            if g is not None and g.key[6:] != (lv['dq'],):
                self.stale = True
        if g is None or g.key[2:5] != (lv['nq'], lv['nr'], lv['gd']):
            self.stale = True
            if None in old or (abs(lv['nq'] - old[0]) > 4 or abs(lv['nr'] - old[1]) > 4
                               or abs(lv['gd'] - old[2]) > 4):
                return True
        return False

    def set_speed(self, v: float) -> None:
        """Speed level (with hysteresis) and the band of speeds that keep it."""
        lv = self.levels
        av = v if v > 0.0 else -v
        lv['v'] = requantise(lv['v'], av if av > SPEED_FLOOR_MPS else SPEED_FLOOR_MPS,
                             SPEED_LEVEL_RATIO)
        h = LEVEL_HYSTERESIS
        lo = SPEED_LEVEL_RATIO ** (lv['v'] - h)
        self.v_band = (-math.inf if lo <= SPEED_FLOOR_MPS else lo,
                       SPEED_LEVEL_RATIO ** (lv['v'] + h))
        g = self.gains
        if g is None or g.key[1] != lv['v']:
            self.stale = True

    def set_run(self, dt: float, speed: float) -> None:
        """Levels of a whole run (the smoother): its median step dt (s), |speed| (m/s)."""
        lv = self.levels
        lv['v'] = requantise(None, max(speed, SPEED_FLOOR_MPS), SPEED_LEVEL_RATIO)
        lv['dt'] = dt_level(dt)

    def design(self, dt: float, lag: int) -> Gains:
        """The gains of the current levels and the lag N (cached); a new design is made at
        the step dt (s) that asked for it, so that a regular stream uses its exact transition."""
        g = self._design(dt, lag, '')
        self.gains = g
        self.stale = False
        return g

    def profile_design(self, dt: float, mode: str,
                       roll_moment_psd: float | None = None) -> Gains:
        """The profile filter's gains (no lag) at the current levels (cached, as
        :meth:`design`; the gains in use stay): :func:`.model.profile_scheduled` of ``mode``
        (``'online'`` or ``'offline'``), with its roll-moment density replaced by
        ``roll_moment_psd`` ((N m)^2 / s) when given."""
        return self._design(dt, 0, mode, roll_moment_psd)

    def _design(self, dt: float, lag: int, mode: str,
                roll_moment_psd: float | None = None) -> Gains:
        """The gains of the current levels, the lag and the tuning ``mode`` ('' = the load's,
        else the profile's; its roll-moment density ``roll_moment_psd`` if given), cached."""
        lv = self.levels
        key = (lv['dt'], lv['v'], lv['nq'], lv['nr'], lv['gd'], lag)
        if self.friction:
            key += (lv['dq'],)
        if mode:
            key += (mode,)
        if roll_moment_psd is not None:
            key += (roll_moment_psd,)
        if self.excluded:
            key += ('excluded', self.excluded)
        cache = self._profile_gains if mode else self._gains    # (apart: the load's cache
        g = cache.get(key)                                      # misses stay as they were)
        if g is None:
            if len(cache) >= MAX_GAINS:
                cache.clear()
            # the levels decide when to design; a design uses the estimates of that moment
            noise = max(self.noise_deflection_m, NOISE_FLOOR_M)
            model = self.model
            force_psd, corr, gd_factor, moment_psd = (
                model.profile_scheduled(noise, mode) if mode
                else model.scheduled(noise, roll_moment=True))
            if roll_moment_psd is not None:
                moment_psd = roll_moment_psd
            if self.observer.road_correlation_length_m > 0.0:
                corr = self.observer.road_correlation_length_m
            kwargs = dict(dt_s=dt, speed_mps=SPEED_LEVEL_RATIO ** lv['v'], lag=lag,
                          correlation_length_m=corr, force_psd=force_psd,
                          roll_moment_psd=moment_psd, key=key, excluded=self.excluded)
            if self.friction:
                kwargs['friction_damping_nspm'] = model.friction_damping(self.dq_std_mps,
                                                                         delayed=lag > 0)
            try:
                g = design(model, noise_deflection_m=noise,
                           noise_roll_rad=self.noise_roll_rad,
                           road_gd_m3=gd_factor * self.road_gd_m3, **kwargs)
            except ValueError:   # never seen; the defaults always give a stable filter
                self.design_failures += 1
                g = design(model, noise_deflection_m=DEFAULT_NOISE_M,
                           noise_roll_rad=DEFAULT_NOISE_RAD, road_gd_m3=DEFAULT_ROAD_GD_M3,
                           **kwargs)
            cache[key] = g
            if mode:
                self.profile_design_count += 1
            else:
                self.design_count += 1
        return g

    def _var_dq_per_diffusion(self) -> float:
        """Var(q_k - q_{k-1}) per unit road diffusion D at the current dt and speed levels."""
        lv = self.levels
        key = (lv['dt'], lv['v'])
        extra = {}
        if self.friction:   # friction damps the motion: its equivalent damping (model notes)
            key += (lv['dq'],)
            extra['friction_damping_nspm'] = self.model.friction_damping(
                DQ_LEVEL_RATIO ** lv['dq'])
        val = self._var_dq.get(key)
        if val is None:
            cm = self.model.continuous(SPEED_LEVEL_RATIO ** lv['v'], 1.0,
                                       correlation_length_m=ROUGHNESS_CORRELATION_M, **extra)
            a, q = van_loan(cm.a, cm.road_g, np.eye(cm.road_g.shape[1]),
                            DT_LEVEL_RATIO ** lv['dt'])
            # The states the road drives to a stationary variance (the model says which:
            # :meth:`.VehicleModel.stationary_states`); the deflections among them.
            keep = self.model.stationary_states(cm)
            var = difference_covariance(a[np.ix_(keep, keep)], q[np.ix_(keep, keep)])
            idx = [keep.index(cm.measured[ch]) for ch in self.model.deflection_channels]
            val = float(sum(var[i, i] for i in idx) / len(idx))
            self._var_dq[key] = val
        return val

    def statistics(self, y, dts: list, moving: bool = True) -> bool:
        """One block of consecutive measurements y (m, 3), steps dts (m - 1): noise and
        roughness estimates; True when the settling time restarts (see
        :meth:`requantise_noise`). A block that is not ``moving`` (some sample below the
        speed floor: the road under the tires barely moves) updates the noise only. ``y``
        may be rows in a file (:class:`~.core.spill.SpillRows`): evenly stepped, taken a
        piece at a time (:meth:`_block_in_pieces`, the same bits), else read whole."""
        if y.shape[0] < 8 * NOISE_DIFF_ORDER or len(dts) != y.shape[0] - 1:
            return False
        steps = np.asarray(dts)
        dt_mean = float(np.mean(steps))
        if not isinstance(y, np.ndarray):
            if _even_in_pieces(steps, dt_mean):
                return self._take(*self._block_in_pieces(y, steps, dt_mean, moving),
                                  dt_mean, moving)
            y = y[0:y.shape[0]]
        even = float(np.max(np.abs(steps - dt_mean))) <= 1e-6 * dt_mean
        t = None if even else np.concatenate([[0.0], np.cumsum(steps)])
        model = self.model
        noise_q = max(noise_std(y[:, ch], t) for ch in model.deflection_channels)
        noise_r = (max(noise_std(y[:, ch], t) for ch in model.roll_channels)
                   if model.roll_channels else None)
        # first differences scaled to the typical step (a smooth signal's change is ~ dq dt)
        scale = (dt_mean / steps)[:, None]
        d1 = (np.diff(y[:, list(model.deflection_channels)], axis=0) * scale).reshape(-1)
        rate2 = float(np.mean(d1 * d1)) if self.friction and moving else None
        return self._take(noise_q, noise_r, mad_std(d1), float(np.mean(scale ** 2)), rate2,
                          dt_mean, moving)

    def _block_in_pieces(self, y, steps: np.ndarray, dt_mean: float, moving: bool
                         ) -> tuple:
        """:meth:`statistics`' numbers of an evenly stepped block of rows ``y`` (sliced
        ``y[a:b]``) at most ``piece`` rows (and the differences' overlap) at a time: each
        channel's noise (:func:`.noise.noise_std`) and the first differences' MAD as exact
        medians over the pieces (:func:`~.core.pieces.medians`), the means as numpy's
        pairwise sums (:func:`~.core.pieces.pairwise_mean`); the differences computed
        per piece are the whole block's, element by element."""
        m = y.shape[0]
        model = self.model
        defl = list(model.deflection_channels)
        chans = defl + list(model.roll_channels)
        n = NOISE_DIFF_ORDER
        norm = math.sqrt(math.comb(2 * n, n))
        piece = max(int(PIECE_ROWS), 1)

        def first_differences(a: int, b: int, x: np.ndarray) -> np.ndarray:
            """Rows a:b of the scaled first differences from the rows x (y[a:b + 1] on)."""
            return np.diff(x[:b + 1 - a, defl], axis=0) * (dt_mean / steps[a:b])[:, None]

        def passes():
            for a in range(0, m - 1, piece):
                b1, b6 = min(m - 1, a + piece), max(a, min(m - n, a + piece))
                x = y[a:max(b1 + 1, b6 + n)]
                d6 = np.diff(x[:b6 + n - a, chans], n, axis=0) / norm
                yield [*np.abs(d6).T, np.abs(first_differences(a, b1, x)).reshape(-1)]

        med = [v / MAD_GAUSSIAN for v in medians(passes, len(chans) + 1)]
        noise_q = max(med[:len(defl)])
        noise_r = max(med[len(defl):-1]) if len(chans) > len(defl) else None

        def cut(read, k: int, rows: int):
            """read(lo, hi) of k values as consecutive pieces of ``rows``."""
            return (read(lo, min(lo + rows, k)) for lo in range(0, k, rows))

        mean_scale2 = pairwise_mean(m - 1, cut(lambda a, b: (dt_mean / steps[a:b]) ** 2,
                                               m - 1, piece), piece)
        rate2 = None
        if self.friction and moving:
            w = len(defl)

            def rates2(lo: int, hi: int) -> np.ndarray:
                r0, r1 = lo // w, -(-hi // w)
                d = first_differences(r0, r1, y[r0:r1 + 1]).reshape(-1)
                return (d * d)[lo - r0 * w:hi - r0 * w]

            rate2 = pairwise_mean((m - 1) * w, cut(rates2, (m - 1) * w, piece * w), piece * w)
        return noise_q, noise_r, med[-1], mean_scale2, rate2

    def _take(self, noise_q: float, noise_r: float | None, mad_d1: float, mean_scale2: float,
              rate2: float | None, dt_mean: float, moving: bool) -> bool:
        """:meth:`statistics` of a block's numbers: the largest noise of the deflection and
        of the roll channels (None: no roll sensor), the MAD (:func:`.noise.mad_std`) of the
        scaled first differences of the deflections and the means of the scales squared and
        (with friction, ``moving``; else None) of the differences squared."""
        self.blocks += 1
        hq, hr, hg = self.history
        hq.append(noise_q)
        if noise_r is not None:           # (a vehicle without a roll sensor keeps the default)
            hr.append(noise_r)
        if not self.noise_fixed[0]:
            self.noise_deflection_m = float(np.median(hq))
        if not self.noise_fixed[1] and hr:
            self.noise_roll_rad = float(np.median(hr))
        signal_var = mad_d1 ** 2 - 2.0 * self.noise_deflection_m ** 2 * mean_scale2
        if self.friction and moving:   # the RMS rate (not the MAD: friction: dq heavy-tailed)
            rms2 = rate2 - 2.0 * self.noise_deflection_m ** 2 * mean_scale2
            if rms2 > 0.0:
                self.dq_history.append(math.sqrt(rms2) / dt_mean)
                self.dq_std_mps = float(np.median(self.dq_history))
                self.levels['dq'] = requantise(self.levels['dq'], self.dq_std_mps,
                                               DQ_LEVEL_RATIO)
        per_d = self._var_dq_per_diffusion() if moving else 0.0
        if per_d > 0.0 and math.isfinite(per_d):     # (an undamped model has no stationary
            hg.append(max(signal_var / per_d / road_diffusion(1.0), MIN_ROAD_GD_M3))  # variance)
        if hg and not self.roughness_fixed:
            self.road_gd_m3 = float(np.median(hg))
        return self.requantise_noise()


def _even_in_pieces(steps: np.ndarray, dt_mean: float) -> bool:
    """:meth:`GainSchedule.statistics`' test of even steps (s) without a temporary of them
    all: every step within 1e-6 of their mean ``dt_mean`` (s)."""
    piece = PIECE_ROWS
    return all(float(np.max(np.abs(steps[a:a + piece] - dt_mean))) <= 1e-6 * dt_mean
               for a in range(0, steps.size, piece))
