"""The tractor IMU's a_y paired with the deflection samples (``vehicle.tractor_imu: true``,
issues 30 and 32): one rule for the observer node (:class:`ImuHold`, message by message) and
``estimate_bag`` / ``estimate_fleet`` (:func:`pair_imu`, over a drive's arrays), the same
numbers.

The rule: each deflection sample takes the a_y (m/s^2, ``/imu/tractor``'s
``linear_acceleration.y``, + to the left as the plant's lateral acceleration) of the latest
IMU message stamped at or before it, as the twist's speed is held. The plant stamps both
with the sample's stamp (the pair is exact); a truck's IMU at its own rate gives the sample
the a_y up to one IMU period old. Its limit: an a_y older than :data:`IMU_MAX_AGE_S` is
``stale``, and a sample with no IMU message at or before it is ``missing``. Neither stops
the estimate: the sample carries the held a_y (0 when missing), every mode leaves the IMU's
row out of it (with pendulum roll sensors their rows too: :func:`.whole_vehicle.
imu_left_out`), and both are counted by name (:data:`STATES`: ``/diagnostics``,
estimate_bag's status and report). Fed instead, a held a_y that is off by ``e`` reads a
pendulum's roll off by ``e / g`` rad (``python -m bench.studies.imu_dropout``).
"""
from __future__ import annotations

from collections import deque

import numpy as np

__all__ = ['IMU_MAX_AGE_S', 'FRESH', 'STALE', 'MISSING', 'STATES', 'pair_imu', 'ImuHold']

#: The oldest a_y a sample takes as fresh (s): 5 periods of a 50 Hz ESC unit's IMU.
IMU_MAX_AGE_S = 0.1
#: Per-sample codes of :func:`pair_imu` and :meth:`ImuHold.at`.
FRESH, STALE, MISSING = 0, 1, 2
#: The codes' names (the counters' keys: ``imu.stale``, ``imu.missing``).
STATES = ('fresh', 'stale', 'missing')


def pair_imu(stamps_ns, imu_stamps_ns, imu_ay_mps2, max_age_s: float = IMU_MAX_AGE_S
             ) -> tuple[np.ndarray, np.ndarray]:
    """Each sample's a_y (m/s^2) and code (:data:`FRESH`, :data:`STALE`, :data:`MISSING`):
    the IMU message's (``imu_stamps_ns`` increasing, ns) latest at or before the sample's
    stamp (module notes; a repeated IMU stamp: the last of them)."""
    stamps = np.asarray(stamps_ns, np.int64)
    t = np.asarray(imu_stamps_ns, np.int64)
    a = np.asarray(imu_ay_mps2, float)
    if t.size:                         # one older than a message before it: dropped
        newest = t >= np.maximum.accumulate(t)
        t, a = t[newest], a[newest]
    held = np.searchsorted(t, stamps, side='right') - 1
    have = held >= 0
    ay = np.zeros(stamps.size)
    ay[have] = a[held[have]]
    code = np.full(stamps.size, MISSING, np.int8)
    age = np.zeros(stamps.size, np.int64)
    age[have] = stamps[have] - t[held[have]]
    limit = int(round(max_age_s * 1e9))
    code[have] = np.where(age[have] > limit, STALE, FRESH)
    return ay, code


class ImuHold:
    """:func:`pair_imu` message by message (the node's input thread): :meth:`push` each IMU
    message as taken, :meth:`at` each sample's ``(a_y, code)``. Messages older than the one
    a sample used are forgotten (the samples' stamps go forward); at most ``kept`` held."""

    def __init__(self, max_age_s: float = IMU_MAX_AGE_S, kept: int = 4096) -> None:
        self.max_age_ns = int(round(max_age_s * 1e9))
        self.held: deque = deque(maxlen=int(kept))     # (stamp_ns, a_y), as taken

    def push(self, stamp_ns: int, ay_mps2: float) -> None:
        """One IMU message (stamps in the order taken; an older one than the newest held
        replaces nothing: it is dropped)."""
        held = self.held
        if held and stamp_ns < held[-1][0]:
            return
        held.append((int(stamp_ns), float(ay_mps2)))

    def at(self, stamp_ns: int) -> tuple[float, int]:
        """The sample's ``(a_y (m/s^2), code)``."""
        held = self.held
        while len(held) > 1 and held[1][0] <= stamp_ns:
            held.popleft()
        if not held or held[0][0] > stamp_ns:
            return 0.0, MISSING
        t, ay = held[0]
        return ay, (STALE if stamp_ns - t > self.max_age_ns else FRESH)
