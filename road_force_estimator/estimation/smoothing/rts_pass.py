"""The steady-state filter and RTS smoother of an evenly sampled run in chunks, in memory that
does not grow with the run (issue 21): :func:`smoothed_chunks`.

The forward filter keeps only the state before each chunk (:class:`ForwardPass`); when the
backward pass reaches a chunk, the chunk's filtered states and innovations are computed again
from that state, with the same products on the same rows, so the bits are those the forward
pass had (test_offline_stream). The price: the forward recursion runs twice on a long run (the
last :data:`CACHE_BYTES` of chunks are kept); the gain: a run's forward states (8 nx bytes a
sample) and innovations (24) are never held whole, so the profile
pass (:meth:`.smoother.Smoother._profile`), which cannot be windowed (its slowest mode is
~720 s), runs over a 4-hour drive.

numpy only.
"""
from __future__ import annotations

from collections import OrderedDict
from typing import Iterator

import numpy as np

from road_force_estimator.estimation.smoothing.lti import lti

__all__ = ['ForwardPass', 'smoothed_chunks', 'GATE_WINDOW']

#: Samples the gate's first pass computes again after a gated sample before it looks on
#: (then the next window, and so on): a gated sample costs this many, not the rest of the
#: chunk (the chunk is computed once more in one go when its gate is done; the replaced
#: values, predictions computed in windows, differ from those of one run to the chunk's end
#: by rounding only: 1e-9 N of load on a 20 s articulated drive with 111 gated samples,
#: whose smoother took 2.5 s instead of 6.6 s).
GATE_WINDOW = 1024
#: Bytes of forward chunks kept (at least three: a backward chunk spans at most two forward
#: chunks): a run of up to ~0.5 M samples is never recomputed (as fast as holding it whole).
CACHE_BYTES = 64 << 20


class ForwardPass:
    """The forward filter of :func:`smoothed_chunks` over ``y`` (m, ny), chunk by chunk.

    ``segs``: ``(start, end, _)`` stretches of the run and ``mats`` their matrices
    (:meth:`.smoother.Smoother._pass_matrices`: the forward ``(I - K C) A`` as
    :class:`.lti.Powers`, ``K^T``, ``(C A)^T``, ..., the friction parts or None, the
    innovation gate per channel or None); ``x0`` is ``x+_0``; chunks of ``chunk`` samples
    from sample 1 (each inside one stretch).

    The innovation gate (from sample ``gate_from`` on) is the online observer's
    (:meth:`..observer.online.ModelCore._innovation_gate`): a channel whose innovation lies
    beyond its gate is replaced by its prediction for that sample (its innovation 0), once;
    outside again at the next sample, it is fed until it comes back inside. The first pass
    decides, sample by sample (the chunk computed again from a gated sample on), and keeps
    the replaced samples (:attr:`overrides`), so that a chunk computed again later has the
    same bits; :attr:`gated` counts them per channel.
    """

    def __init__(self, segs: list, mats: list, y: np.ndarray, x0: np.ndarray,
                 chunk: int, gate_from: int = 0) -> None:
        self.y, self.mats, self.x0 = y, mats, np.asarray(x0, dtype=float)
        self.chunks = [(k0, min(s1, k0 + chunk), i) for i, (s0, s1, _) in enumerate(segs)
                       for k0 in range(max(1, s0), s1, chunk)]
        self.starts = np.array([c[0] for c in self.chunks], dtype=np.int64)
        nx = self.x0.size
        ny = y.shape[1]
        self.before = np.empty((len(self.chunks), nx))      # x+_(k0 - 1) of each chunk
        self._cache: OrderedDict[int, tuple[np.ndarray, np.ndarray]] = OrderedDict()
        #: the gated samples' measurements (sample -> the row of y used), in sample order
        self.overrides: dict[int, np.ndarray] = {}
        self.gated = np.zeros(ny, dtype=np.int64)
        self._gate_from = int(gate_from)
        self._flags = np.zeros(ny, dtype=np.int8)       # 0 inside, 1 gated, 2 fed outside
        prev = self.x0
        for c in range(len(self.chunks)):
            self.before[c] = prev
            xf, nu = self._compute(c, gate=True)
            self._keep(c, xf, nu)
            prev = xf[-1]

    def _rows(self, k0: int, k1: int) -> np.ndarray:
        """``y[k0:k1]`` with the gated samples' replacements."""
        y = self.y[k0:k1]
        keys = [k for k in self.overrides if k0 <= k < k1] if self.overrides else ()
        if keys:
            y = y.copy()
            for k in keys:
                y[k - k0] = self.overrides[k]
        return y

    def _run(self, mats: tuple, y: np.ndarray, k0: int, prev: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
        """``x+_k`` and ``nu_k`` of the samples k0 .. k0 + len(y) - 1 from ``x+_(k0-1) =
        prev``."""
        a_run, kt, ca_t, _, _, _, fin, _ = mats
        k1 = k0 + y.shape[0]
        drive = y @ kt
        if fin is not None:
            drive += fin[0][k0 - 1:k1 - 1]
        xf = lti(a_run, drive, prev)
        lagged = np.empty_like(xf)
        lagged[0] = prev
        lagged[1:] = xf[:-1]
        nu = y - lagged @ ca_t
        if fin is not None:
            nu -= fin[1][k0 - 1:k1 - 1]
        return xf, nu

    def _compute(self, c: int, gate: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Chunk c's ``x+_k`` and ``nu_k = y_k - C A x+_(k-1)`` (less the friction's part);
        ``gate``: the first pass, which decides the gated samples."""
        k0, k1, i = self.chunks[c]
        mats = self.mats[i]
        xf, nu = self._run(mats, self._rows(k0, k1), k0, self.before[c])
        if gate and mats[7] is not None and k1 > self._gate_from:
            if self._gate_chunk(c, mats, xf, nu):       # the chunk again, in one go
                xf, nu = self._run(mats, self._rows(k0, k1), k0, self.before[c])
        return xf, nu

    def _gate_chunk(self, c: int, mats: tuple, xf: np.ndarray, nu: np.ndarray) -> bool:
        """The gate over chunk c, sample by sample (``xf``, ``nu`` updated from each changed
        sample on); True when the chunk's measurements changed. A gated channel outside
        again at the next sample was real, not a spike: its measurement is restored there
        (not across a chunk's start)."""
        k0, k1, _ = self.chunks[c]
        gate = mats[7]
        flags = self._flags
        first = max(0, self._gate_from - k0)
        last = first - 1               # the last sample looked at
        changed = False
        n = k1 - k0
        valid = n                      # xf, nu hold this run's values up to here
        j = first
        while j < n:
            if j >= valid:             # the next window after a change, from its state
                end = min(n, valid + GATE_WINDOW)
                xf[valid:end], nu[valid:end] = self._run(
                    mats, self._rows(k0 + valid, k0 + end), k0 + valid, xf[valid - 1])
                valid = end
            rows = np.flatnonzero((np.abs(nu[j:valid]) > gate).any(axis=1))
            hit = None
            for r in rows.tolist():
                jj = j + r
                if jj > last + 1:
                    flags[:] = 0           # samples inside between: every channel inside
                out = np.abs(nu[jj]) > gate
                back = [ch for ch in range(gate.size) if out[ch] and flags[ch] == 1
                        and jj > first and k0 + jj - 1 in self.overrides]
                gated = [ch for ch in range(gate.size) if out[ch] and flags[ch] == 0]
                flags[~out] = 0
                flags[out] = 2
                last = jj
                if back or gated:
                    hit = (jj, back, gated)
                    break
            if hit is None:
                if valid == n:
                    break
                j = valid
                continue
            jj, back, gated = hit
            if back:                       # the last sample's gate undone, then this again
                self._restore(k0 + jj - 1, back)
                at = jj - 1
            else:
                row = self._rows(k0 + jj, k0 + jj + 1)[0].copy()
                for ch in gated:
                    flags[ch] = 1
                    row[ch] -= nu[jj, ch]
                    self.gated[ch] += 1
                self.overrides[k0 + jj] = row
                at = jj
            changed = True
            prev = xf[at - 1] if at else self.before[c]
            valid = min(n, at + GATE_WINDOW)
            xf[at:valid], nu[at:valid] = self._run(mats, self._rows(k0 + at, k0 + valid),
                                                   k0 + at, prev)
            j = jj + 1 if not back else jj
            if back:
                last = jj - 1              # this sample is looked at again
        if last < k1 - k0 - 1:
            flags[:] = 0                   # the chunk ends with samples inside
        return changed

    def _restore(self, k: int, channels: list) -> None:
        """Sample k's measured values of ``channels`` instead of their predictions (a real
        excursion): uncounted; the override gone when nothing of it is left."""
        row = self.overrides[k]
        raw = self.y[k]
        for ch in channels:
            row[ch] = raw[ch]
            self.gated[ch] -= 1
        if np.array_equal(row, raw):
            del self.overrides[k]

    def _keep(self, c: int, xf: np.ndarray, nu: np.ndarray) -> None:
        self._cache[c] = (xf, nu)
        self._cache.move_to_end(c)
        limit = max(3, CACHE_BYTES // max(1, xf.nbytes + nu.nbytes))
        while len(self._cache) > limit:
            self._cache.popitem(last=False)

    def _chunk(self, c: int) -> tuple[np.ndarray, np.ndarray]:
        got = self._cache.get(c)
        if got is None:
            got = self._compute(c)
            self._keep(c, *got)
        return got

    def states(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
        """``x+_k`` (b - a, nx) and ``nu_k`` (b - a, ny) for k = a .. b - 1 (new arrays;
        ``x+_0 = x0``, ``nu_0 = 0``)."""
        xf = np.empty((b - a, self.x0.size))
        nu = np.empty((b - a, self.y.shape[1]))
        k = a
        if a == 0 and b > 0:
            xf[0] = self.x0
            nu[0] = 0.0
            k = 1
        while k < b:
            c = int(np.searchsorted(self.starts, k, side='right')) - 1
            k0, k1, _ = self.chunks[c]
            cx, cn = self._chunk(c)
            e = min(b, k1)
            xf[k - a:e - a] = cx[k - k0:e - k0]
            nu[k - a:e - a] = cn[k - k0:e - k0]
            k = e
        return xf, nu


def smoothed_chunks(segs: list, mats: list, y: np.ndarray, x0: np.ndarray,
                    chunk: int, gate_from: int = 0) -> Iterator[tuple[int, int, np.ndarray]]:
    """The smoothed states of an evenly sampled run, ``(k0, k1, x_(k|m))`` chunk by chunk
    from the end (see :meth:`.smoother.Smoother._uniform_pass` for the equations: the
    adjoint form of the RTS smoother), the innovation gate on from sample ``gate_from``
    (:class:`ForwardPass`). Then, as its last item, ``(-1, -1, forward)``: the
    :class:`ForwardPass` (for a state where the next window starts, and its gate's counts)."""
    m = y.shape[0]
    fwd = ForwardPass(segs, mats, y, x0, chunk, gate_from)
    lam_next = np.zeros(fwd.x0.size)             # lam_(k1+1): lam_m = 0
    for (s0, s1, _), (_, _, _, phi_t, u_t, pa_t, _, _) in zip(segs[::-1], mats[::-1]):
        for k1 in range(s1, s0, -chunk):
            k0 = max(s0, k1 - chunk)
            # row k of the chunk takes lam_(k+1): lam_j for j = k0 + 1 .. min(k1, m - 1),
            # from lam_(k1+1) (the later chunk's first) backwards; lam_m = 0
            lo, hi = k0 + 1, min(k1, m - 1)
            xf, nu = fwd.states(k0, min(k1 + 1, m))
            xs = xf[:k1 - k0]
            lam = np.zeros((k1 - k0, fwd.x0.size))
            if hi >= lo:
                seq = lti(phi_t, (nu[lo - k0:hi + 1 - k0] @ u_t)[::-1], lam_next)[::-1]
                lam[:hi - lo + 1] = seq
                lam_next = seq[0]
            xs += lam @ pa_t
            yield k0, k1, xs
    yield -1, -1, fwd
