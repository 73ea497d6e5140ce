"""A stuck sensor and a slow offset drift, flagged by sensor name (issue 30; MODEL.md "Sensor
faults"): one detector for the node and for the bags, sample by sample (:class:`FaultDetector`)
or over whole arrays (:func:`detect_faults`, the same steps in order: the same flags).

Stuck (``observer.fault_stuck_time``, ``observer.fault_stuck_tolerance``): a channel whose
reading has not changed by more than the tolerance (0: exact repeats) for the stated time while
every other channel moved within that time. A standing truck (every channel still, e.g. without
noise) is not a stuck sensor, nor are two channels still at once (which one is wrong is not
known: a synthetic drive with constant channels, or two failed sensors, flag nothing). The
flag holds until the reading changes.

Drift (``observer.fault_drift_window``, ``observer.fault_drift_offset``; the front axle's two
deflection sensors): the body's momentum balance over the last window of T seconds, MODEL.md's
heave and roll equations averaged over it,

    H = mean(k_1 q_1 + k_2 q_2) + (c_1 dQ_1 + c_2 dQ_2) / T + M dV / T        (= 0)
    R = mean(s (k_1 q_1 - k_2 q_2) - M g h phi) + s (c_1 dQ_1 - c_2 dQ_2) / T
        + I_x dP / T                                                      (= M h a_y)

(dQ_i, dV, dP: the change over the window of q_i, of the body's heave rate and of its roll
rate, the observer's zero-latency estimates; the window moves, and is judged, a block of
:data:`DRIFT_BLOCK` samples at a time). The road moves the deflections by millimetres,
but its slow part, the mean force on the body over seconds, is its momentum's change: H is
about 0 (tens of microns of deflection on class C over 10 s), whatever the road, the curves
(a lateral acceleration enters R only) or a stop. An offset d on the left sensor adds k_1 d
to H and s k_1 d to R, on the right k_2 d and -s k_2 d: |H| / k_i above the stated offset
flags the sensor whose sign agrees (left when H and R have one sign). With
``vehicle.deflection_reference: zero_load`` H is taken against its first window's value.
Not detected (the front axle): a drift of the roll sensor (it enters R only, as a curve
does), drifts of both deflection sensors that cancel in H.

A stuck sensor, deflection or roll, is left out of the model observer while flagged (its
gains designed without it and its prediction taken for its reading,
:meth:`.ModelCore.set_excluded`; the sooner the better: the held readings fed before the flag
leave an error the filter cannot see once the sensor is out, hence 0.05 s; offline the
smoother leaves out the flagged stretch and the held readings before the flag, known before it
runs: :func:`left_out`); a drifting sensor
is flagged and fed (an offset of d costs k d of static load, 0.1 kN at
0.3 mm; left out, the sensor's wheel would lose its dynamic load). While a channel is stuck
the drift window starts again (a held reading is no evidence of a drift).

Counts per channel: episodes (a flag's rising edges) and samples flagged.

The whole vehicle (:meth:`FaultSettings.of_whole_vehicle`): the same detector over its
channels (every deflection, the tractor's and the trailer's roll), stuck by the same rule;
the drift of a deflection judged against its unit's other deflections (:class:`UnitDrift`:
a rigid body's heave, pitch and roll, on units with :data:`UNIT_MIN_AXLES` instrumented
axles or more; the kingpin's force is unknown, so no unit's heave balances alone), from
the readings and the speed (``rates`` is the speed there): the same flags in every mode.
A tractor of two instrumented axles (one degree of freedom left over a rigid fit) and the roll
sensors are judged by the whole vehicle's balances instead (:class:`TractorDrift`,
:func:`tractor_check`): the tractor's pitch about the kingpin, the two units' lateral
accelerations through the fifth wheel's roll stiffness, the road's cross-level under the
front and the drive axle; with the tractor IMU each unit's roll balance against its a_y
instead of the two units' difference, which names the roll sensor that drifts, or both for a
drift common to them. Pendulum roll sensors without the IMU: each unit's roll balance on g
times its pendulum's reading (the balance's g phi + a_y whole), which names the pendulum that
drifts alone; a drift common to both is not judged.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from itertools import repeat
import math
from operator import lt, sub
from typing import Sequence

import numpy as np

__all__ = ['STUCK', 'DRIFT', 'OK', 'CODES', 'flag_codes', 'DRIFT_START_S', 'DRIFT_BLOCK',
           'GAP_S', 'UNIT_WINDOW_FACTOR', 'UNIT_MIN_SPEED_MPS', 'UNIT_CLEAR_FRACTION',
           'UNIT_MIN_AXLES', 'TRACTOR_SCALES', 'IMU_SCALE_MPS2', 'IMU_HELD_S',
           'ROLL_DRIFT_LIMIT_RAD', 'TRACTOR_PERSIST_S', 'FaultSettings', 'TractorDrift',
           'tractor_check', 'FaultDetector', 'UnitDrift', 'detect_faults', 'left_out']

STUCK, DRIFT, OK = 'stuck', 'drift', 'ok'
#: The flags as numbers (:attr:`FaultDetector.events`, :func:`flag_codes`).
CODES = {OK: 0, STUCK: 1, DRIFT: 2}
#: Time (s) after the first sample (or a gap) before a drift window is judged (the
#: observer's start-up transient in its rate estimates).
DRIFT_START_S = 3.0
#: Samples per block of the drift's window (its sums are kept per block; the window moves,
#: and is judged, a block at a time).
DRIFT_BLOCK = 10
#: A step longer than this (s) starts the drift window and the stuck runs again.
GAP_S = 0.5
#: The whole vehicle's drift window (:class:`UnitDrift`) in ``observer.fault_drift_window``s.
UNIT_WINDOW_FACTOR = 2.0
#: The whole vehicle's drift window starts again below this speed (m/s; :class:`UnitDrift`).
UNIT_MIN_SPEED_MPS = 8.0
#: A whole-vehicle drift flag clears a window after it fell below this fraction of the
#: offset (:class:`UnitDrift`; at once below half, the front axle's rule, let a 1 mm/min
#: drift's flag drop for 0.4 s on class C).
UNIT_CLEAR_FRACTION = 0.25
#: With the tractor IMU, an a_y repeated exactly for longer than this (s) is a held value (the
#: pairing's, :mod:`.imu_hold`: stale after :data:`.imu_hold.IMU_MAX_AGE_S`, 0 before the
#: first message), not a measurement: :class:`TractorDrift`'s windows start again (a held a_y
#: through a curve read as a common roll drift). Twice the stale age: an IMU at 10 Hz repeats
#: each a_y for 0.1 s while fresh.
IMU_HELD_S = 0.2
#: Fewest instrumented axles of a unit whose deflections :class:`UnitDrift` judges.
UNIT_MIN_AXLES = 3
#: :class:`TractorDrift`'s statistics' scales: the kingpin pitch balance (m of the first
#: axle's deflection), the two units' lateral accelerations' difference (m/s^2), the road's
#: cross-level angle under the tractor's two axles (rad); about what the clean drives leave
#: (``python -m bench.studies.articulated_sensor_faults --balances``)
TRACTOR_SCALES = (5e-5, 1e-2, 7.5e-5)
_G = 9.81                  # m/s^2, the balances' gravity (tractor_check, TractorDrift)
#: :class:`TractorDrift`'s scale (m/s^2) of each unit's a_y from its roll balance minus the
#: tractor IMU's (the IMU's noise over the window leaves 0.0007-0.0013 on the clean drives:
#: ``python -m bench.studies.articulated_sensor_faults --balances --imu``)
IMU_SCALE_MPS2 = 1e-3
#: A roll sensor's offset (rad) above which :class:`TractorDrift` flags it.
ROLL_DRIFT_LIMIT_RAD = 2e-4
#: Time (s) a :class:`TractorDrift` candidate stays above its limit before it is flagged (a
#: drift keeps growing; sticking leaf springs' offsets come and go: the ``*-stick`` drives of
#: ``python -m bench.studies.articulated_sensor_faults --balances``)
TRACTOR_PERSIST_S = 6.0


@dataclass(frozen=True)
class FaultSettings:
    """The detector's parameters (``observer.fault_*``) and the vehicle's numbers it needs."""

    channels: tuple                    #: channel names, in the order of the values
    stuck_time_s: float = 0.05
    stuck_tolerance: float = 0.0
    drift_window_s: float = 6.0
    drift_offset_m: float = 2e-4
    #: (k_1, k_2, c_1, c_2, s, M, I_x, M g h) of the deflection pair (channels 0, 1) and roll
    #: (channel 2); None: no drift detection
    body: tuple | None = None
    relative: bool = False             #: zero_load: H against its first window's value
    #: the whole vehicle's drift check (:class:`UnitDrift`): per rigid unit judged, its
    #: deflection channels' indices and their rows ``(1, x, +-s)`` (m: position behind the
    #: front axle, half the spring track, + left); None: none (the front axle's ``body``)
    units: tuple | None = None
    #: the tractor's and the roll sensors' drift check (:class:`TractorDrift`): (rows,
    #: a_x coefficients, scales, candidates, limits, flaggable), or None
    tractor: tuple | None = None
    #: the channels the stuck rule judges (indices), or None: every one. Not the tractor IMU's
    #: a_y, which the pairing holds between its messages (its age is
    #: :mod:`.imu_hold`'s stale / missing count)
    stuck_channels: tuple | None = None

    @classmethod
    def of(cls, observer, vehicle, channels: Sequence[str]) -> 'FaultSettings':
        """From :class:`.ObserverParameters` and :class:`.VehicleParameters`."""
        k, c = vehicle.suspension_stiffness_npm, vehicle.suspension_damping_nspm
        m = vehicle.sprung_mass_kg
        body = (k[0], k[1], c[0], c[1], 0.5 * vehicle.track_width_m, m,
                vehicle.roll_inertia_kgm2, m * 9.81 * vehicle.cg_height_m)
        if not observer.fault_drift_offset_m > 0.0:
            body = None
        return cls(tuple(channels), observer.fault_stuck_time_s,
                   observer.fault_stuck_tolerance, observer.fault_drift_window_s,
                   observer.fault_drift_offset_m, body, vehicle.zero_load)

    @classmethod
    def of_whole_vehicle(cls, observer, model) -> 'FaultSettings':
        """The whole vehicle's (:class:`.models.articulated.ArticulatedObserverModel`
        ``model``: its channels and vehicle): every channel for the stuck flag, the
        deflections of each unit with at least :data:`UNIT_MIN_AXLES` instrumented axles for
        the drift (:class:`UnitDrift`)."""
        axles = model.vehicle.axles
        units = []
        for body in ('tractor', 'trailer'):
            idx = [k for k, ch in enumerate(model.channels)
                   if ch[0] == 'q' and axles[ch[1]].body == body]
            if len({model.channels[k][1] for k in idx}) < UNIT_MIN_AXLES:
                continue
            rows = tuple((1.0, axles[model.channels[k][1]].position_m,
                          (1.0 if model.channels[k][2] == 0 else -1.0)
                          * axles[model.channels[k][1]].spring_half_track_m) for k in idx)
            units.append((tuple(idx), rows))
        return cls(tuple(model.channel_names), observer.fault_stuck_time_s,
                   observer.fault_stuck_tolerance, observer.fault_drift_window_s,
                   observer.fault_drift_offset_m, None, model.vehicle.zero_load,
                   tuple(units) or None,
                   tractor_check(model, observer.fault_drift_offset_m, set(
                       k for idx, _ in units for k in idx)),
                   tuple(k for k, ch in enumerate(model.channels) if ch[0] != 'ay'))


@dataclass
class FaultCounts:
    """Per channel: the flag now, episodes and samples flagged (stuck, drift)."""

    flags: dict = field(default_factory=dict)
    stuck_episodes: dict = field(default_factory=dict)
    stuck_samples: dict = field(default_factory=dict)
    drift_episodes: dict = field(default_factory=dict)
    drift_samples: dict = field(default_factory=dict)
    #: per channel, the stamp (ns) of the first flag of each kind: {'stuck': ns, 'drift': ns}
    first_ns: dict = field(default_factory=dict)


class FaultDetector:
    """Stuck and drifting sensors, one accepted sample at a time (:meth:`step`)."""

    def __init__(self, settings: FaultSettings) -> None:
        self.settings = settings
        self.n = len(settings.channels)
        self._judged = (tuple(range(self.n)) if settings.stuck_channels is None
                        else tuple(settings.stuck_channels))     # by the stuck rule
        #: the whole vehicle's drift check, or None (the front axle's momentum balance)
        self.units = (UnitDrift(settings.units, UNIT_WINDOW_FACTOR * settings.drift_window_s,
                                settings.drift_offset_m, settings.relative)
                      if settings.units and settings.drift_offset_m > 0.0 else None)
        #: the tractor's deflections and the roll sensors (:class:`TractorDrift`), or None
        self.tractor = (TractorDrift(*settings.tractor[:7], UNIT_WINDOW_FACTOR
                                     * settings.drift_window_s, settings.relative,
                                     *settings.tractor[7:])
                        if settings.tractor and settings.drift_offset_m > 0.0 else None)
        self.reset()

    def reset(self) -> None:
        n = self.n
        self.flags = [OK] * n
        self.stuck_episodes = [0] * n
        self.stuck_samples = [0] * n
        self.drift_episodes = [0] * n
        self.drift_samples = [0] * n
        self.first_ns: list = [{} for _ in range(n)]
        #: samples stepped, and the flags' changes: (sample, channel, code) with code
        #: :data:`CODES` (0 ok, 1 stuck, 2 drift)
        self.samples = 0
        self.events: list = []
        #: each stuck flag's rise: (sample, channel, the time (s) its still run began, i.e.
        #: the stamp of the first sample of the held reading): :func:`left_out`
        self.stuck_since: list = []
        self._last = None
        if self.units is not None:
            self.units.forget()
        if self.tractor is not None:
            self.tractor.forget()
        self._restart(None)

    def _restart(self, t: float | None) -> None:
        self._t0 = t
        self._last = None                 # the previous values
        self._run = [t] * self.n          # when each channel's still run began
        self._stuck = [False] * self.n
        self._drift = [False] * self.n
        self._flagged = False             # a flag is up (the bookkeeping runs)
        #: the drift's window: blocks (t, q1, q2, vz, dphi of their first sample, their sums
        #: of k q and of the roll balance, samples), and its sums; the block being summed
        self._win: deque = deque()
        self._sh = self._sr = 0.0
        self._sn = 0
        self._bh = self._br = 0.0
        self._bn = 0
        self._ref = None
        if self.units is not None:
            self.units.restart()
        if self.tractor is not None:
            self.tractor.restart()

    def step(self, stamp_ns: int, values: Sequence[float],
             rates: tuple[float, float] | None = None) -> None:
        """One accepted sample: its stamp (ns), its readings (the channels' order; the
        detector keeps the sequence, not a copy) and, for the drift, the body's heave and roll
        rates estimated at it (m/s, rad/s; the whole vehicle's :class:`UnitDrift`: the speed
        (m/s) as a 1-tuple), or None."""
        t = stamp_ns * 1e-9
        last = self._last
        if last is None or t - self._tl > GAP_S:
            self._restart(t)
        self._tl = t
        stuck = self._stuck
        if last is not None and self._stuck_step(t, values, last):
            self._win.clear()      # a held reading is no evidence of a drift: start again
            self._sh = self._sr = self._bh = self._br = 0.0
            self._sn = self._bn = 0
            self._t0 = t
            self._drift = [False] * self.n
            if self.units is not None:
                self.units.restart()
            if self.tractor is not None:
                self.tractor.restart()
        elif rates is not None and self.settings.body is not None:
            self._drift_step(t, values, rates)
        elif rates is not None:
            if self.units is not None:
                self.units.step(t, values, rates[0], self._drift)
            if self.tractor is not None:
                self.tractor.step(t, values, rates[0], self._drift)
        self._last = values
        if self._flagged or True in stuck or True in self._drift:
            self._book(stamp_ns)
        self.samples += 1

    def _book(self, stamp_ns: int) -> None:
        """The flags of this sample: counts, first stamps, events."""
        flags, stuck, drift = self.flags, self._stuck, self._drift
        up = False
        for ch in range(self.n):
            word = STUCK if stuck[ch] else DRIFT if drift[ch] else OK
            if word != OK:
                up = True
                if word == STUCK:
                    self.stuck_samples[ch] += 1
                else:
                    self.drift_samples[ch] += 1
            if flags[ch] != word:
                if word != OK:
                    self.first_ns[ch].setdefault(word, int(stamp_ns))
                    if word == STUCK:
                        self.stuck_episodes[ch] += 1
                        self.stuck_since.append((self.samples, ch, self._run[ch]))
                    else:
                        self.drift_episodes[ch] += 1
                self.events.append((self.samples, ch, CODES[word]))
                flags[ch] = word
        self._flagged = up

    @property
    def stuck(self) -> list:
        """Per channel: flagged stuck now (a list the detector keeps updating)."""
        return self._stuck

    def _stuck_step(self, t: float, values: Sequence[float], last: Sequence[float]) -> bool:
        """The still runs and the stuck flags; True when a channel is flagged stuck."""
        settings = self.settings
        tol, begun = settings.stuck_tolerance, t - settings.stuck_time_s
        run, stuck = self._run, self._stuck
        n = self.n
        if len(self._judged) == n and all(map(lt, repeat(tol, n), map(abs, map(
                sub, values, last)))):   # every channel moved (the loop's outcome, in C)
            run[:] = repeat(t, n)
            if True in stuck:
                stuck[:] = repeat(False, n)
            return False
        still, which = 0, 0
        for ch in self._judged:
            if abs(values[ch] - last[ch]) > tol:
                run[ch] = t
                stuck[ch] = False
            elif run[ch] <= begun:
                still += 1
                which = ch
        if still == 1:             # one channel still while every other one moves
            stuck[which] = True
        return True in stuck

    def _drift_step(self, t: float, values: Sequence[float], rates: tuple) -> None:
        """One sample into the drift's window: summed per block of :data:`DRIFT_BLOCK`
        samples; at a block's end the window (whole blocks) is judged."""
        k1, k2, c1, c2, s, m, ix, mgh = self.settings.body
        q1, q2 = values[0], values[1]
        self._bh += k1 * q1 + k2 * q2
        self._br += s * (k1 * q1 - k2 * q2) - mgh * values[2]
        self._bn += 1
        if self._bn == 1:
            self._b0 = (t, q1, q2, rates[0], rates[1])
        if self._bn < DRIFT_BLOCK:
            return
        win = self._win
        win.append((*self._b0, self._bh, self._br, self._bn))
        self._sh += self._bh
        self._sr += self._br
        self._sn += self._bn
        self._bh = self._br = 0.0
        self._bn = 0
        w = self.settings.drift_window_s
        while t - win[0][0] > w:
            old = win.popleft()
            self._sh -= old[5]
            self._sr -= old[6]
            self._sn -= old[7]
        a = win[0]
        span = t - a[0]
        if t - self._t0 < DRIFT_START_S + w or span < 0.99 * w:
            return
        n = self._sn
        d1, d2 = q1 - a[1], q2 - a[2]
        big_h = self._sh / n + (c1 * d1 + c2 * d2 + m * (rates[0] - a[3])) / span
        big_r = self._sr / n + (s * (c1 * d1 - c2 * d2) + ix * (rates[1] - a[4])) / span
        self._judge(big_h, big_r)

    def _judge(self, big_h: float, big_r: float) -> None:
        """The drift flags from the window's heave and roll balances (N, N m)."""
        k1, k2 = self.settings.body[:2]
        if self.settings.relative:
            if self._ref is None:
                self._ref = (big_h, big_r)
            big_h -= self._ref[0]
            big_r -= self._ref[1]
        side = 0 if big_h * big_r > 0.0 else 1
        offset = abs(big_h) / (k1, k2)[side]
        limit = self.settings.drift_offset_m
        drift = self._drift
        if offset > limit:
            drift[side], drift[1 - side] = True, False
        elif offset < 0.5 * limit:
            drift[0] = drift[1] = False

    def counts(self) -> FaultCounts:
        """The flags and counts, by channel name."""
        names = self.settings.channels

        def by(values: list) -> dict:
            return dict(zip(names, values))

        return FaultCounts(by(list(self.flags)), by(self.stuck_episodes), by(self.stuck_samples),
                           by(self.drift_episodes), by(self.drift_samples),
                           {n: dict(f) for n, f in zip(names, self.first_ns) if f})


class MovingSums:
    """The sums of the entries of the last ``span`` seconds: each entry its start time (s),
    its values and its count of samples, added when pushed and taken off when it falls out
    (:meth:`covers`), the window's and the whole vehicle's drift checks' running means."""

    def __init__(self, m: int) -> None:
        self.entries: deque = deque()       # (t0, values, count)
        self.sums = [0.0] * m
        self.count = 0

    def push(self, t0: float, values: Sequence[float], count: int = 1) -> None:
        self.entries.append((t0, values, count))
        sums = self.sums
        for i, x in enumerate(values):
            sums[i] += x
        self.count += count

    def covers(self, t: float, span: float) -> bool:
        """The entries older than ``span`` before ``t`` taken off; whether the rest span it
        (to 1 %)."""
        entries, sums = self.entries, self.sums
        while t - entries[0][0] > span:
            _, old, n = entries.popleft()
            for i, x in enumerate(old):
                sums[i] -= x
            self.count -= n
        return t - entries[0][0] >= 0.99 * span


class UnitDrift:
    """The whole vehicle's slow offset drift, per rigid unit against its neighbours: each
    deflection's mean over the last window (``window_s``, s; triangular, two running means
    of half of it in series as :class:`TractorDrift`'s; summed per block of
    :data:`DRIFT_BLOCK` samples, judged at a block's end) against what the unit's other
    deflections make of a rigid body's heave, pitch and roll,

        mean(q_i) ~ a + b x_i + c (+-s_i)       (+ left; x_i behind the front axle, m)

    fitted to the unit's deflections but channel i (its deleted residual r_i, m), each
    divided by ``sqrt(1 + h_i)`` (h_i: the fit's variance at channel i, in units of a
    channel's, so that r_i / sqrt(1 + h_i) is the least-squares test of an offset on channel i
    alone): the channel whose |r_i| / sqrt(1 + h_i) is largest, above ``limit_m``, is
    flagged, and stays so (no other of its unit) until its own has been below
    :data:`UNIT_CLEAR_FRACTION` of it for a window. The mean spring force
    over seconds is its body's momentum change, and the rigid fit takes up the bodies' mean
    heave, pitch and roll (a curve, a braking, a payload off-centre); a sensor's offset d is
    not a rigid body's pattern and shows as d in its own r_i. A standing truck carries the
    road's shape under the group (statically indeterminate: mm), so the window starts again
    below :data:`UNIT_MIN_SPEED_MPS`. With ``relative`` (``zero_load``) each r_i is taken
    against its first judged window's.

    ``units``: per unit ``(channel indices, rows (1, x, +-s))`` (:meth:`FaultSettings.
    of_whole_vehicle`)."""

    def __init__(self, units: Sequence, window_s: float, limit_m: float,
                 relative: bool = False) -> None:
        self.window_s, self.limit_m, self.relative = float(window_s), float(limit_m), relative
        self.channels = sorted({k for idx, _ in units for k in idx})
        where = {k: j for j, k in enumerate(self.channels)}
        #: per unit: its channels, their places in :attr:`channels`, the scaled deleted
        #: residuals' operator (n, n)
        self.units = [(tuple(idx), [where[k] for k in idx], _deleted(np.asarray(rows, float)))
                      for idx, rows in units]
        self._seen = [0.0] * len(self.units)   # per unit: when its flag was last up (s)
        self.forget()

    def forget(self) -> None:
        """The window, the relative reference and :attr:`peak` forgotten."""
        self._ref = None
        #: the largest scaled |r_i| judged (m) and its channel (-1: none judged yet)
        self.peak = (0.0, -1)
        self.restart()

    def restart(self) -> None:
        """The window starts again (a gap, a stuck sensor, a stop)."""
        m = len(self.channels)
        self._win = MovingSums(m)            # the blocks' sums over half the window
        self._means = MovingSums(m)          # per block: the half-window's means
        self._blk = [0.0] * m
        self._bn = 0
        self._b0 = 0.0

    def step(self, t: float, values: Sequence[float], speed_mps: float, drift: list) -> None:
        """One sample (s, the readings, m/s) into the window; the flags into ``drift``
        (per channel of the detector) at a judged block's end."""
        if not abs(speed_mps) >= UNIT_MIN_SPEED_MPS:
            if self._win.count or self._bn:
                self.restart()
            return
        blk = self._blk
        for j, k in enumerate(self.channels):
            blk[j] += values[k]
        self._bn += 1
        if self._bn == 1:
            self._b0 = t
        if self._bn < DRIFT_BLOCK:
            return
        win = self._win
        win.push(self._b0, blk, self._bn)
        self._blk = [0.0] * len(blk)
        self._bn = 0
        w = self.window_s
        half = 0.5 * w
        if not win.covers(t, half):
            return
        means = self._means
        means.push(t, [x / win.count for x in win.sums])
        if not means.covers(t, half):
            return
        mean = np.asarray(means.sums) / len(means.entries)
        z = [p @ mean[places] for _, places, p in self.units]
        if self.relative:
            if self._ref is None:
                self._ref = [r.copy() for r in z]
            z = [r - f for r, f in zip(z, self._ref)]
        limit = self.limit_m
        seen = self._seen
        for u, ((idx, _, _), r) in enumerate(zip(self.units, z)):
            a = np.abs(r)
            i = int(np.argmax(a))
            if a[i] > self.peak[0]:
                self.peak = (float(a[i]), idx[i])
            up = [j for j, k in enumerate(idx) if drift[k]]
            if up and a[up[0]] >= UNIT_CLEAR_FRACTION * limit:
                seen[u] = t                     # the flag's own r_i still up
            if up and t - seen[u] <= w:
                continue                        # a flag holds a window after it was last up
            for k in idx:
                drift[k] = False
            if a[i] > limit:
                drift[idx[i]] = True
                seen[u] = t


class TractorDrift:
    """A drift of the tractor's deflections or of a roll sensor, from balances of the whole
    vehicle that hold over seconds whatever the road (MODEL.md "The whole vehicle", its
    equations averaged, the accelerations' means taken as 0): statistics z = rows @ mean(y)
    + ax * mean(a_x) (a_x = dv/dt from the speed), each 0 on a sound truck:

    - P, the tractor's pitch about the kingpin (the kingpin's force has no moment there),
      sum_j k_j (xi_j - xi_5) (q_j,1 + q_j,2) + M_t H_t a_x, divided by k_1 |xi_1 - xi_5|
      (m of the front axle's deflection; > 0: the drive axle's springs extended);
    - A, the tractor's minus the trailer's lateral acceleration (m/s^2), each from its roll
      balance with the fifth wheel's roll moment between them,
      a_y,b = [sum_j K_s,j rel_j +- kphi_5 (phi_t - phi_r)] / (M_b h_b) - g phi_b
      (+ tractor, - trailer; K_s,j = 2 k_j s_j^2 + kphi_j, rel_j = (q_j,1 - q_j,2) / (2 s_j));
    - T, the road's cross-level angle (rad, left up) that the front and the drive axle's
      roll balances put under them, phi_t - rel_j - (K_s,j rel_j + L_j a_y,r) / K_t,j
      (K_t,j = 2 kt_j w_j^2, L_j = h_rc,j S_j / g + rho_j m_j: the load transfer through the
      links), the front's minus the drive's: both axles run in the same wheel paths.

    With the tractor IMU (``imu``; :meth:`FaultSettings.of_whole_vehicle` with the IMU's a_y
    among the channels, ``vehicle.tractor_imu``) A gives way to each unit's a_y from its roll
    balance minus the IMU's a_y (m/s^2; the path's lateral acceleration, gravity-free, as
    INTERFACES.md's ``/imu/tractor`` states it), MODEL.md's body roll equation whole:

      I_b = [sum_j (K_s,j rel_j + s_j (c_j,1 dq_j,1 - c_j,2 dq_j,2)) +- (kphi_5 (phi_t - phi_r)
            + cphi_5 (dphi_t - dphi_r)) + I_x,b dd phi_b] / (M_b h_b)
            - g sin(phi_b) - a_y cos(phi_b)

    (I_t the tractor's, + ; I_r the trailer's, -; a_y the IMU's, MODEL.md's one lateral
    acceleration of the combination; the rates' means over the window from its
    half-window means' change, dd phi_b's from the roll's second difference over it). An
    offset d_t on the tractor's roll
    sensor gives I_t (kphi_5 / (M_t h_t) - g) d_t and I_r -kphi_5 / (M_r h_r) d_t: the
    difference's large terms, and -g d_t, the absolute roll the gravity term sees (9.81
    m/s^2 per rad); a drift common to both, -g d on each. So each sensor's drift and a
    common one are three candidates apart (a specific-force a_y, a_y + g phi, would cancel
    the gravity term and leave the difference only).

    Pendulum roll sensors (reading r_b = phi_b + a_y / g) without the IMU: g r_b is the
    balance's g phi_b + a_y whole, so I_t and I_r hold no a_y in their linear rows; an
    offset d_t on the tractor's gives I_t (kphi_5 / (M_t h_t) - g) d_t, I_r -kphi_5 / (M_r
    h_r) d_t, so each is named alone; a common d only -g d on each, less than what a rough
    road, a curve on a crossfall (a_y phi times the crossfall, which no reading tells from
    a_y) or sticking friction leave there (``python -m
    bench.studies.articulated_sensor_faults --balances --pendulum``): no common candidate.
    T eliminates a_y with the tractor's pendulum, and the bodies' rolls (the inertia and
    non-linear terms) are the readings less an a_y of g times the tractor's reading less its
    roll over a level road (the axles' relative and tire rolls): ``imu``'s a_y is then its
    weights on the channels (no held-value check).

    Means are over a triangular window of ``window_s`` (two running means of half of it in
    series: the bodies' momentum change, which left 0.3 mm of kingpin pitch in a plain 12 s
    mean on class C, enters only by its displacement). Judged at :data:`UNIT_MIN_SPEED_MPS`
    or more, a block at a time as :class:`UnitDrift`: each candidate's offset (``candidates``:
    per candidate its weights on the channels) fitted to z / ``scales`` by least squares; the
    one that explains most, above its limit (m or rad) for :data:`TRACTOR_PERSIST_S`, flags
    its ``names`` (channel indices; without the IMU a roll sensor's candidate is the pair's
    difference, both named: the balances see phi_t - phi_r only, a drift common to both
    reads as a crossfall or a curve; with it each sensor alone and both together), and holds
    as :class:`UnitDrift`'s flags do. ``relative``: z against its first judged window's.
    ``imu``: (the rates' rows (m, n), the IMU's channel, per unit (its row, I_x,b / (M_b
    h_b), its roll's weights (n,))), :func:`tractor_check`'s.
    """

    def __init__(self, rows: Sequence, ax: Sequence, scales: Sequence, candidates: Sequence,
                 names: Sequence, limits: Sequence, flaggable: Sequence, window_s: float,
                 relative: bool = False, imu: tuple | None = None) -> None:
        rows = np.asarray(rows, float)
        self.m = rows.shape[0]
        self.window_s, self.relative = float(window_s), relative
        self.rows = rows
        self.n = rows.shape[1]
        #: the rows summed per block: ``rows``, then (``imu``) the rates' rows, the units'
        #: rolls and the IMU's a_y
        self._rows = rows
        #: per unit balance its row and I_x,b / (M_b h_b), or None
        self._imu = None
        self._ay_ch = None              # the IMU's a_y channel (its held value), or None
        self._me = self.m               # the rows the windows keep (rows, rates)
        if imu is not None:
            rates, ay, units = imu
            rates = np.asarray(rates, float)
            if isinstance(ay, (int, np.integer)):   # the IMU's channel
                measured = np.zeros(self.n)
                measured[int(ay)] = 1.0
            else:                       # a_y's weights on the channels (pendulums alone)
                measured, ay = np.asarray(ay, float), None
            self._rows = np.vstack([rows, rates] + [np.asarray(w, float) for *_, w in units]
                                   + [measured])
            self._imu = tuple((int(r), float(c)) for r, c, _ in units)
            self._me = self.m + rates.shape[0]
            self._ay_ch = None if ay is None else int(ay)
        self._ay_last = math.nan        # the IMU's a_y and since when it has held it (s)
        self._ay_since = 0.0
        self.ax = np.asarray(ax, float)
        self.scales = np.asarray(scales, float)
        #: per candidate: its offset's weights on the channels ((channel, weight), ...) and
        #: the channels its flag names
        self.candidates = tuple(tuple(c) for c in candidates)
        self.names = tuple(tuple(c) for c in names)
        self.limits = np.asarray(limits, float)
        self.flaggable = tuple(bool(f) for f in flaggable)
        cols = np.zeros((rows.shape[1], len(self.candidates)))
        for j, cand in enumerate(self.candidates):
            for k, weight in cand:
                cols[k, j] = weight
        g = rows @ cols / self.scales[:, None]      # (m, candidates): z / scales per offset
        self._g = g
        self._gg = np.einsum('ij,ij->j', g, g)
        self._seen = 0.0
        self.forget()

    def forget(self) -> None:
        """The windows, the relative reference and :attr:`peak` forgotten."""
        self._ref = None
        #: the largest |z| of each statistic judged (P m, A m/s^2, T rad) and the largest
        #: offset of the best candidate over its limit
        self.peak = np.zeros(self.m + 1)
        self.restart()

    def restart(self) -> None:
        """The windows start again (a gap, a stuck sensor, a stop)."""
        m = self._me
        self._win = MovingSums(m + 1)       # blocks: sums (rows, rates, speed)
        self._means = MovingSums(m + 1)     # per block: the half-window's means
        self._vals: list = []               # the block's readings (the callers' sequences)
        self._vs = 0.0                      # and its speeds' sum
        self._bn = 0
        self._b0 = 0.0
        self._over = None                   # (candidate, since when) above its limit
        self._pts: deque = deque()          # (t, the rolls' block means), a window (imu)

    def step(self, t: float, values: Sequence[float], speed_mps: float, drift: list) -> None:
        """One sample (s, the readings, m/s) into the windows; the flags into ``drift`` at a
        judged block's end."""
        if not abs(speed_mps) >= UNIT_MIN_SPEED_MPS:
            if self._win.count or self._bn:
                self.restart()
            return
        if self._ay_ch is not None:
            # a_y repeated for longer than IMU_HELD_S: the pairing's held value (stale, or 0
            # before the first message), not the road's: the windows start again
            a = values[self._ay_ch]
            if a != self._ay_last:
                self._ay_last, self._ay_since = a, t
            elif t - self._ay_since > IMU_HELD_S:
                if self._win.count or self._bn:
                    self.restart()
                return
        if not self._bn:
            self._b0 = t
        self._vals.append(values)
        self._vs += speed_mps
        self._bn += 1
        if self._bn < DRIFT_BLOCK:
            return
        blk = (self._rows @ np.sum(self._vals, axis=0)[:self.n]).tolist()
        if self._imu is not None:
            # MODEL.md's M_b h_b (a_y cos(phi_b) + g sin(phi_b)) beyond the rows' linear
            # terms (the rows divide by M_b h_b), at the block's means (10 ms); the bodies'
            # rolls' block means kept for their acceleration
            bn, me = self._bn, self._me
            ay = blk[-1] / bn
            phis = [x / bn for x in blk[me:-1]]
            for (row, _), phi in zip(self._imu, phis):
                blk[row] += bn * (ay * (1.0 - math.cos(phi)) + _G * (phi - math.sin(phi)))
            del blk[me:]
            pts = self._pts
            pts.append((t, phis))
            while t - pts[0][0] > self.window_s:
                pts.popleft()
        blk.append(self._vs)
        self._vals = []
        self._vs = 0.0
        half = 0.5 * self.window_s
        win = self._win
        win.push(self._b0, blk, self._bn)
        self._bn = 0
        if not win.covers(t, half):
            return
        means = self._means
        now = [x / win.count for x in win.sums]
        means.push(t, now)
        if not means.covers(t, half):
            return
        first_t, first, _ = means.entries[0]
        span = t - first_t
        a_x = (now[-1] - first[-1]) / span if span > 0.0 else 0.0
        m = self.m
        z = np.asarray(means.sums[:m]) / len(means.entries) + self.ax * a_x
        if self._imu is not None:
            # the rates' triangular means: the half-window means' change; phi_t's second
            # difference over the window: the triangular mean of its acceleration
            z = z + (np.asarray(now[m:-1]) - np.asarray(first[m:-1])) / span
            pts = self._pts
            (t2, p2), (t1, p1), p0 = pts[0], pts[len(pts) // 2], pts[-1][1]
            if t1 > t2 and t > t1:
                for (row, inertia), a, b, c in zip(self._imu, p0, p1, p2):
                    z[row] += inertia * ((a - b) / (t - t1) - (b - c) / (t1 - t2)) / (
                        0.5 * (t - t2))
        if self.relative:
            if self._ref is None:
                self._ref = z.copy()
            z = z - self._ref
        self._judge(t, z / self.scales, drift)

    def _judge(self, t: float, u: np.ndarray, drift: list) -> None:
        """The flags from the scaled statistics ``u``."""
        fit = u @ self._g                       # per candidate: g . u
        best = int(np.argmax(fit * fit / self._gg))
        offset = fit / self._gg                 # per candidate: its least-squares offset
        peak = self.peak
        np.maximum(peak[:-1], np.abs(u) * self.scales, out=peak[:-1])
        peak[-1] = max(peak[-1], abs(offset[best]) / self.limits[best])
        names = self.names
        up = sorted((j for j, ks in enumerate(names)    # the flagged candidate: all its
                     if self.flaggable[j] and all(drift[k] for k in ks)),  # names, the most
                    key=lambda j: -len(names[j]))
        if up and abs(offset[up[0]]) >= UNIT_CLEAR_FRACTION * self.limits[up[0]]:
            self._seen = t
        if up and t - self._seen <= self.window_s:
            return
        for j, ks in enumerate(names):
            if self.flaggable[j]:
                for k in ks:
                    drift[k] = False
        if not (self.flaggable[best] and abs(offset[best]) > self.limits[best]):
            self._over = None
            return
        if self._over is None or self._over[0] != best:
            self._over = (best, t)              # above since t
        if t - self._over[1] >= TRACTOR_PERSIST_S:
            for k in names[best]:
                drift[k] = True
            self._seen = t


def tractor_check(model, limit_m: float, judged: set) -> tuple | None:
    """:class:`TractorDrift`'s arguments (but the window) for the whole vehicle's ``model``
    (:class:`.models.articulated.ArticulatedObserverModel`), or None where its balances do
    not close: every axle instrumented, both roll sensors fitted (pendulums: each unit's
    balance then holds g phi_b + a_y,b whole as g times the reading; the bodies' rolls are
    the readings less a_y / g, and the cross-level's a_y is the IMU's, or without it the
    tractor's pendulum's, eliminated), a tractor of two axles with the kingpin between them.
    Candidates: every deflection and the roll sensors (their difference; with the IMU each
    and both; pendulums without it each);
    flaggable: those not in ``judged`` (the channels :class:`UnitDrift` judges), at
    ``limit_m`` (deflections) and :data:`ROLL_DRIFT_LIMIT_RAD`. With the IMU (its a_y among
    ``model``'s channels) the statistics are P, T, I_t, I_r and an eighth item, ``imu``;
    the same for pendulums without it (``imu``'s a_y its weights on the channels)."""
    veh = model.vehicle
    axles = veh.axles
    g = _G
    chans = list(model.channels)
    tractor = [j for j, a in enumerate(axles) if a.body == 'tractor']
    trailer = [j for j, a in enumerate(axles) if a.body == 'trailer']
    x5 = veh.fifth_wheel.position_m
    at = {ch: k for k, ch in enumerate(chans)}
    imu = at.get(('ay', 0))                       # the tractor IMU's a_y, or None
    pendulum = veh.roll_sensor == 'pendulum'
    if (not all(a.instrumented for a in axles) or not veh.trailer_roll_sensor
            or len(tractor) != 2
            or not trailer
            or not axles[tractor[0]].position_m < x5 < axles[tractor[1]].position_m):
        return None
    n = len(chans)
    phi = np.zeros(n)
    phi[at[('roll', 0)]] = 1.0
    phir = np.zeros(n)
    phir[at[('roll', 1)]] = 1.0
    tr, rl = veh.body('tractor'), veh.body('trailer')
    k5 = veh.fifth_wheel.roll_stiffness_nmprad
    spring = model.core.statics().spring_load_n
    pitch, ayt, ayr = np.zeros(n), np.zeros(n), np.zeros(n)
    damp = {'tractor': np.zeros(n), 'trailer': np.zeros(n)}   # the springs' damping moments
    rel, ks = {}, {}
    for j, a in enumerate(axles):
        s = a.spring_half_track_m
        left, right = at[('q', j, 0)], at[('q', j, 1)]
        rel[j] = np.zeros(n)
        rel[j][left], rel[j][right] = 0.5 / s, -0.5 / s
        ks[j] = sum(a.suspension_stiffness_npm) * s * s + a.auxiliary_roll_stiffness_nmprad
        damp[a.body][left] += a.suspension_damping_nspm[0] * s
        damp[a.body][right] -= a.suspension_damping_nspm[1] * s
        if a.body == 'tractor':
            pitch[left] += a.suspension_stiffness_npm[0] * (a.position_m - x5)
            pitch[right] += a.suspension_stiffness_npm[1] * (a.position_m - x5)
            ayt += ks[j] * rel[j]
        else:
            ayr += ks[j] * rel[j]
    mh_t = tr.mass_kg * tr.cg_height_above_roll_axis_m
    mh_r = rl.mass_kg * rl.cg_height_above_roll_axis_m
    ayt = (ayt + k5 * (phi - phir)) / mh_t - g * phi
    ayr = (ayr - k5 * (phi - phir)) / mh_r - g * phir
    measured = np.zeros(n)
    if imu is not None:
        measured[imu] = 1.0
    own = pendulum and imu is None      # the a_y the pendulums and the tractor's axles tell
    if own:
        # cross(j) = phi_t - rel_j - (K_s,j rel_j + lat_j a_y) / K_t,j with a_y = g (r_t -
        # phi_t): phi_t (1 + e_j) - X_j, e_j = g lat_j / K_t,j; the road level under the axle
        # (0 on the window's mean, a crossfall not) gives phi_t = X_j / (1 + e_j)
        lev = {}
        for j in tractor:
            a = axles[j]
            kt = sum(a.tire_stiffness_npm) * a.wheel_half_track_m ** 2
            lat = (a.roll_centre_height_m * float(spring[j].sum()) / g
                   + a.wheel_radius_m * a.mass_kg)
            e = g * lat / kt
            lev[j] = (rel[j] + (ks[j] * rel[j] + g * lat * phi) / kt) / (1.0 + e)
        level = sum(lev.values()) / len(lev)    # the tractor's roll, the road level
        measured = g * (phi - level)            # a_y: g times the reading less the roll

    def cross(j: int) -> np.ndarray:
        a = axles[j]
        w = a.wheel_half_track_m
        kt = sum(a.tire_stiffness_npm) * w * w
        lat = a.roll_centre_height_m * float(spring[j].sum()) / g + a.wheel_radius_m * a.mass_kg
        body = phi if a.body == 'tractor' else phir
        # (a pendulum's balance holds g phi + a_y, its reading: the a_y is the IMU's)
        return body - rel[j] - (ks[j] * rel[j] + lat * (measured if pendulum else ayr)) / kt

    scale0 = abs(pitch[at[('q', tractor[0], 0)]])
    rows = [pitch / scale0, ayt - ayr, cross(tractor[0]) - cross(tractor[1])]
    if own:                     # T with a_y eliminated: the two axles' road levels' difference
        rows[2] = lev[tractor[1]] - lev[tractor[0]]
    scales = TRACTOR_SCALES
    deflections = [at[('q', j, side)] for j in tractor for side in (0, 1)]
    roll = (at[('roll', 0)], at[('roll', 1)])
    cands = tuple(((k, 1.0),) for k in deflections)
    names = tuple((k,) for k in deflections)
    if imu is None and not pendulum:    # the roll difference only: both named
        cands += (((roll[0], 0.5), (roll[1], -0.5)),)
        names += (roll,)
        rolls = 1
    else:                       # each unit's a_y from its roll balance minus the IMU's
        rows[1:2] = []          # A is their difference
        # a pendulum reads phi_b + a_y,b / g: g times it is the balance's g phi_b + a_y whole
        rows += [ayt, ayr] if pendulum else [ayt - measured, ayr - measured]
        scales = (scales[0], scales[2], IMU_SCALE_MPS2, IMU_SCALE_MPS2)
        cands += (((roll[0], 1.0),), ((roll[1], 1.0),))
        names += ((roll[0],), (roll[1],))
        rolls = 2
        if not own:             # (pendulums alone: no common candidate, module notes)
            cands += (((roll[0], 1.0), (roll[1], 1.0)),)
            names += (roll,)
            rolls = 3
    ax = (tr.mass_kg * tr.cg_height_m / scale0,) + (0.0,) * (len(rows) - 1)
    limits = (limit_m,) * len(deflections) + (ROLL_DRIFT_LIMIT_RAD,) * rolls
    flaggable = tuple(k not in judged for k in deflections) + (True,) * rolls
    out = (tuple(map(tuple, np.array(rows))), ax, scales, cands, names, limits, flaggable)
    if imu is None and not pendulum:
        return out
    c5 = veh.fifth_wheel.roll_damping_nmsprad * (phi - phir)
    rates = np.zeros((len(rows), n))   # the damping moments, on the channels' rates
    rates[2] = (damp['tractor'] + c5) / mh_t
    rates[3] = (damp['trailer'] - c5) / mh_r
    if pendulum:                # the bodies' rolls: the readings less a_y / g
        phi, phir = phi - measured / g, phir - measured / g
    units = ((2, tr.roll_inertia_kgm2 / mh_t, tuple(phi)),
             (3, rl.roll_inertia_kgm2 / mh_r, tuple(phir)))
    return out + ((tuple(map(tuple, rates)), tuple(measured) if own else imu, units),)


def _deleted(rows: np.ndarray) -> np.ndarray:
    """The operator (n, n) taking a unit's deflection means to their deleted residuals,
    each divided by ``sqrt(1 + h_i)`` (:class:`UnitDrift`); ``rows`` (n, p)."""
    n = rows.shape[0]
    out = np.zeros((n, n))
    for i in range(n):
        keep = [j for j in range(n) if j != i]
        a = rows[keep]
        pinv = np.linalg.pinv(a)
        coef = rows[i] @ pinv                      # the fit's prediction at i from the others
        h = float(rows[i] @ np.linalg.pinv(a.T @ a) @ rows[i])
        out[i, i] = 1.0
        out[i, keep] = -coef
        out[i] /= math.sqrt(1.0 + h)
    return out


def flag_codes(events: list, n: int, channels: int) -> np.ndarray:
    """The flags per sample, ``(n, channels)`` int8 (:data:`CODES`), from a detector's
    :attr:`~FaultDetector.events` over its ``n`` samples."""
    out = np.zeros((n, channels), dtype=np.int8)
    for k, ch, code in events:
        out[k:, ch] = code
    return out


def detect_faults(settings: FaultSettings, stamps_ns, values, rates=None
                  ) -> tuple[FaultCounts, np.ndarray]:
    """:class:`FaultDetector` over whole arrays (accepted samples, in order): the counts and
    the flags per sample, ``(n, channels)`` int8 (:data:`CODES`: 0 ok, 1 stuck, 2 drift).

    ``values`` (n, channels); ``rates`` per sample what :meth:`FaultDetector.step` takes
    (the front axle's body heave and roll rates, (n, 2); the whole vehicle's speed, (n, 1)),
    or None."""
    det = FaultDetector(settings)
    vals = np.asarray(values, dtype=float).tolist()
    rts = None if rates is None else np.asarray(rates, dtype=float).tolist()
    step = det.step
    for j, (stamp, v) in enumerate(zip(np.asarray(stamps_ns, dtype=np.int64).tolist(), vals)):
        step(stamp, v, None if rts is None else rts[j])
    return det.counts(), flag_codes(det.events, len(vals), det.n)


def left_out(codes: np.ndarray, since: Sequence, stamps_ns) -> np.ndarray | None:
    """The samples an offline smoother leaves out, per channel: bool ``(n, channels)``, or
    None when no channel is flagged stuck.

    Each stretch flagged stuck (``codes``: :func:`flag_codes`' of the samples of
    ``stamps_ns`` (ns), the detector's sample indices) and, before its flag, the held
    readings of its still run (``since``: :attr:`FaultDetector.stuck_since`): from the
    sample after the still run's first one (that one is fed: the reading the sensor then
    held) to the flag. Online those ``observer.fault_stuck_time`` seconds are fed (the flag
    comes after them); offline they are known to be held before the smoother runs.
    """
    if not len(since):               # no stuck flag rose
        return None
    stuck = np.asarray(codes) == CODES[STUCK]
    if not stuck.any():
        return None
    out = stuck.copy()
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    for k, ch, t0 in since:
        if t0 is None:
            continue
        # the first sample whose time (stamp * 1e-9, the detector's) is t0
        j0 = int(np.searchsorted(stamps, int(round(t0 * 1e9)) - 2))
        while j0 < k and int(stamps[j0]) * 1e-9 < t0:
            j0 += 1
        out[j0 + 1:k, ch] = True
    return out
