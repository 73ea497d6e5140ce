"""Sensor faults (MODEL.md "Sensor faults", ``simulator.sensor_faults``): the one place both
plants' sensor models take them from.

A fault is ``KIND@CHANNEL:KEY=VALUE,...``; faults are separated by ``;``. CHANNEL is a joint
name of ``/suspension/deflections`` (front axle: ``left_suspension``, ``right_suspension``,
``roll``; articulated: ``<axle>_left_suspension``, ..., ``tractor_roll``, ``trailer_roll``).
Units are the channel's (m or rad) and seconds:

``spikes@C:count=N,size=S[,start=T0][,end=T1]``
    N single samples off by +-S (a random sign each), at distinct samples drawn uniformly in
    [T0, T1] (default the whole drive, ``simulator.duration``): electrical noise or a linkage
    knock (MODEL.md: 0.1-1 mm, a few per minute).
``stuck@C:start=T,duration=D``
    From the sample at T the reading repeats that sample's value for D seconds.
``drift@C:rate=R[,start=T]``
    An offset growing by R per second from T on (a slow drift, e.g. 1 mm/min = 1.667e-5).

In the measurement chain spikes and drift add to the noisy reading; a stuck sensor holds its
output last of all. Random draws come from ``numpy.random.default_rng([seed, 2, i])`` for the
i-th fault, so the batch path (:meth:`FaultPlan.apply`) and the per-sample path
(:meth:`FaultPlan.sampler`) give the same numbers; :meth:`FaultPlan.truth` says where each
fault struck (for the bag's ``custom_data``: what a detector must find).
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import Sequence

import numpy as np

__all__ = ['Fault', 'FaultPlan', 'parse_faults', 'KINDS']

#: Each kind's keys: required, then optional with defaults (None = the drive's end).
KINDS = {
    'spikes': (('count', 'size'), {'start': 0.0, 'end': None}),
    'stuck': (('start', 'duration'), {}),
    'drift': (('rate',), {'start': 0.0}),
}


@dataclass(frozen=True)
class Fault:
    """One fault: ``kind``, ``channel`` and its keys (``values``)."""

    kind: str
    channel: str
    values: dict = field(default_factory=dict)

    def __getitem__(self, key: str) -> float:
        return self.values[key]


def parse_faults(text: str, channels: Sequence[str]) -> tuple[Fault, ...]:
    """The faults of ``simulator.sensor_faults`` on the given channels.

    Raises
    ------
    ValueError
        One line naming the fault: an unknown kind or channel (the channels are listed), a
        bad, missing or unknown key, a negative count, size, duration.
    """
    out = []
    for item in (p.strip() for p in str(text).split(';')):
        if not item:
            continue
        head, _, rest = item.partition(':')
        kind, at, channel = head.partition('@')
        kind, channel = kind.strip().lower(), channel.strip()
        where = f'simulator.sensor_faults: {item!r}'
        if kind not in KINDS or not at:
            raise ValueError(f'{where}: expected KIND@CHANNEL:KEY=VALUE,... with KIND one of '
                             f'{", ".join(KINDS)}')
        if channel not in channels:
            raise ValueError(f'{where}: no channel {channel!r} (the channels: '
                             f'{", ".join(channels)})')
        need, optional = KINDS[kind]
        values = dict(optional)
        for pair in (p for p in rest.split(',') if p.strip()):
            key, eq, number = pair.partition('=')
            key = key.strip()
            if key not in need and key not in optional:
                raise ValueError(f'{where}: unknown key {key!r} (keys: '
                                 f'{", ".join((*need, *optional))})')
            try:
                values[key] = float(number)
            except ValueError:
                raise ValueError(f'{where}: {pair!r} is not KEY=NUMBER') from None
            if not math.isfinite(values[key]):
                raise ValueError(f'{where}: {key} must be finite')
        missing = [k for k in need if k not in values]
        if missing:
            raise ValueError(f'{where}: {", ".join(missing)} not given')
        for key in ('count', 'size', 'duration', 'start'):
            if key in values and values[key] is not None and values[key] < 0.0:
                raise ValueError(f'{where}: {key} must be >= 0')
        if kind == 'spikes' and values['count'] != int(values['count']):
            raise ValueError(f'{where}: count must be a whole number')
        out.append(Fault(kind, channel, values))
    return tuple(out)


class FaultPlan:
    """Where and how each fault strikes a drive of ``rate_hz`` and ``duration_s``.

    Parameters
    ----------
    faults : sequence of Fault
    channels : sequence of str
        The channels, in the column order of the values the plan is applied to.
    rate_hz, duration_s : float
        The sample rate (Hz) and the drive's length (s): spike times are drawn in it.
    seed : int
        ``simulator.seed``.
    """

    def __init__(self, faults: Sequence[Fault], channels: Sequence[str], rate_hz: float,
                 duration_s: float, seed: int) -> None:
        self.faults = tuple(faults)
        self.channels = tuple(channels)
        self.rate_hz = float(rate_hz)
        last = int(math.floor(duration_s * rate_hz + 1e-9))
        #: per channel: {sample: offset} of the spikes; (rate per sample, first sample) of
        #: the drifts; [(first, stop)) of the stuck windows
        self.spikes: list[dict[int, float]] = [{} for _ in self.channels]
        self.drifts: list[list[tuple[float, int]]] = [[] for _ in self.channels]
        self.stuck: list[list[tuple[int, int]]] = [[] for _ in self.channels]
        self._where: list = []          # per fault: its samples (spikes, stuck window)
        for i, f in enumerate(self.faults):
            ch = self.channels.index(f.channel)
            if f.kind == 'spikes':
                k0 = max(0, int(math.ceil(f['start'] * rate_hz - 1e-9)))
                end = duration_s if f['end'] is None else min(f['end'], duration_s)
                k1 = min(last, int(math.floor(end * rate_hz + 1e-9)))
                count = int(f['count'])
                if count > max(k1 - k0 + 1, 0):
                    raise ValueError(f'simulator.sensor_faults: {count} spikes on {f.channel} '
                                     f'do not fit in {max(k1 - k0 + 1, 0)} samples')
                rng = np.random.default_rng([int(seed), 2, i])
                at = np.sort(rng.choice(np.arange(k0, k1 + 1), size=count, replace=False))
                sign = rng.choice([-1.0, 1.0], size=count)
                for k, s in zip(at.tolist(), sign.tolist()):
                    self.spikes[ch][k] = self.spikes[ch].get(k, 0.0) + s * f['size']
                self._where.append(at.tolist())
            elif f.kind == 'drift':
                k0 = int(math.ceil(f['start'] * rate_hz - 1e-9))
                self.drifts[ch].append((f['rate'] / rate_hz, k0))
                self._where.append([k0])
            else:
                k0 = int(math.ceil(f['start'] * rate_hz - 1e-9))
                self.stuck[ch].append((k0, k0 + int(round(f['duration'] * rate_hz))))
                self._where.append(list(self.stuck[ch][-1]))

    @property
    def active(self) -> bool:
        return bool(self.faults)

    def apply(self, values: np.ndarray, first: int = 0) -> np.ndarray:
        """The readings with the faults, for samples ``first ..`` (rows) x channels
        (columns); a new array (before a stuck sensor's hold: :meth:`hold`)."""
        out = np.array(values, dtype=np.float64, copy=True)
        k = np.arange(first, first + out.shape[0])
        for ch in range(len(self.channels)):
            for per_sample, k0 in self.drifts[ch]:
                on = k >= k0
                out[on, ch] += per_sample * (k[on] - k0)
            for s, offset in self.spikes[ch].items():
                if first <= s < first + out.shape[0]:
                    out[s - first, ch] += offset
        return out

    def hold(self, values: np.ndarray, first: int = 0) -> np.ndarray:
        """A stuck sensor's readings held (in place, samples ``first ..``): every stuck
        window must start inside ``values`` (the batch path: the whole drive)."""
        n = values.shape[0]
        for ch in range(len(self.channels)):
            for k0, k1 in self.stuck[ch]:
                a, b = max(k0, first), min(k1, first + n)
                if a < b and first <= k0 < first + n:
                    values[a - first:b - first, ch] = values[k0 - first, ch]
        return values

    def sampler(self):
        """The per-sample path: ``f(k, values) -> values``, sample k's readings (a list, one
        per channel) with the spikes and drifts, then the stuck hold (calls in sample order;
        each sampler holds its own stuck values)."""
        held: list = [None] * len(self.channels)
        spikes, drifts, stuck = self.spikes, self.drifts, self.stuck

        def apply_one(k: int, values: list[float]) -> list[float]:
            for ch in range(len(values)):
                v = values[ch]
                for per_sample, k0 in drifts[ch]:
                    if k >= k0:
                        v += per_sample * (k - k0)
                offset = spikes[ch].get(k)
                if offset is not None:
                    v += offset
                for k0, k1 in stuck[ch]:
                    if k == k0:
                        held[ch] = v
                    if k0 <= k < k1:
                        v = held[ch]
                values[ch] = v
            return values

        return apply_one

    def truth(self) -> list[dict]:
        """Where each fault struck: ``{kind, channel, ...}`` with the spike samples, the stuck
        window's samples [first, stop), the drift's first sample (JSON-ready)."""
        return [{'kind': f.kind, 'channel': f.channel,
                 **{k: v for k, v in f.values.items() if v is not None},
                 {'spikes': 'samples', 'stuck': 'window', 'drift': 'first_sample'}[f.kind]:
                     where if f.kind != 'drift' else where[0]}
                for f, where in zip(self.faults, self._where)]
