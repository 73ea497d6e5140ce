"""The figures of a drive estimated block by block (:mod:`.estimate_stream`).

The detail figures (:func:`.report.figures.write_figures`) show a window of
:data:`~.report.figures.DEFAULT_WINDOW_S` from a third of the converged stretch, which is
known only at the end of the drive. :class:`Snapshots` keeps the online estimator's state
(pickled, ~400 kB) at the start of each block that may still hold that window (those before
the earliest start the converged stretch so far allows are dropped); at the end the
estimator resumes from the snapshot before the window, over the blocks read again, and the
figures are drawn from the estimates of the window's samples (the same numbers as in one
piece: the chain is causal). The profile and overview figures then show the window's
profile (band-passed over the window) with the segments of the whole drive.
"""
from __future__ import annotations

import pickle
from types import SimpleNamespace

import numpy as np

__all__ = ['Snapshots', 'window_bounds', 'draw']


def window_bounds(acc, length_s: float) -> tuple[int, int] | None:
    """``(first, last)`` stamps (ns) of the detail window that :func:`.figures._window` picks
    on the whole drive (from the accumulators ``acc``: :class:`~.report.streamed.
    StreamedSummary`), None without one."""
    if acc.t0_ns is None or acc.last_ns == acc.t0_ns:
        return None
    if acc.first_converged_ns is not None:
        lo = (acc.first_converged_ns - acc.t0_ns) * 1e-9
        hi = (acc.last_converged_ns - acc.t0_ns) * 1e-9
    else:
        lo, hi = 0.0, (acc.last_ns - acc.t0_ns) * 1e-9
    start = lo + max(0.0, (hi - lo - length_s)) / 3.0
    return acc.t0_ns + int(np.floor(start * 1e9)), acc.t0_ns + int(np.ceil(
        (start + length_s) * 1e9))


class Snapshots:
    """The estimator's state at block starts (see the module notes)."""

    def __init__(self, length_s: float) -> None:
        self.length_s = length_s
        self.items: list[tuple[int, int, bytes]] = []     # (block, first stamp, state)

    def keep(self, index: int, first_stamp: int, stream, acc) -> None:
        self.items.append((index, int(first_stamp), pickle.dumps(stream, protocol=5)))
        bounds = window_bounds(acc, self.length_s)
        if bounds is None:
            return
        while len(self.items) > 1 and self.items[1][1] <= bounds[0]:
            self.items.pop(0)

    def resume(self, first_ns: int):
        """``(block index, stream)``: the last snapshot at or before ``first_ns``."""
        best = self.items[0]
        for item in self.items:
            if item[1] <= first_ns:
                best = item
        return best[0], pickle.loads(best[2])


def _window_pieces(reader, index: int, stream, bounds: tuple[int, int]):
    """Estimates and inputs of the samples stamped within ``bounds`` (ns), the estimator
    resumed at block ``index`` of ``reader`` (read again from the start)."""
    lo, hi = bounds
    pieces, inputs = [], []
    for i, block in enumerate(reader):
        if i < index:
            continue
        inside = (block.stamps_ns >= lo) & (block.stamps_ns <= hi)
        if inside.any():
            inputs.append((block.q_m[inside], block.roll_rad[inside]))
        pieces += stream.feed(block.stamps_ns, block.q_m, block.roll_rad, block.speed_mps)
        if pieces and pieces[-1].stamp_ns[-1] > hi:
            break
    else:
        pieces += stream.finish()
    return pieces, inputs


def _select(pieces: list, bounds: tuple[int, int]):
    """One :class:`EstimateArrays` of the pieces' samples within ``bounds``."""
    from road_force_estimator.estimation.outputs import FIELD_COLUMNS, EstimateArrays

    lo, hi = bounds
    parts = []
    for p in pieces:
        m = (p.stamp_ns >= lo) & (p.stamp_ns <= hi)
        if m.any():
            parts.append((p, m))
    if not parts:
        return None
    fields = {name: np.concatenate([getattr(p, name)[m] for p, m in parts])
              for name in ['stamp_ns', 'valid', 'speed_contradicted', 'static_load_n',
                           *FIELD_COLUMNS]}
    return EstimateArrays(status=parts[-1][0].status, **fields)


def draw(folder, input_path, block_samples: int, snapshots: Snapshots, acc, segments: dict,
         title: str, units: str, static_load_n) -> list[str]:
    """The figures' file names written into ``folder`` (none without a window)."""
    from road_force_estimator.bagio.drive_blocks import DriveBlocks
    from road_force_estimator.report.alignment import align
    from road_force_estimator.report.figures import DEFAULT_WINDOW_S, write_figures

    bounds = window_bounds(acc, DEFAULT_WINDOW_S)
    if bounds is None or not snapshots.items:
        return []
    index, stream = snapshots.resume(bounds[0])
    pieces, inputs = _window_pieces(DriveBlocks(input_path, block_samples), index, stream,
                                    bounds)
    est = _select(pieces, bounds)
    if est is None or np.count_nonzero(est.valid) < 2:
        return []
    drive = None
    q = np.concatenate([a for a, _ in inputs]) if inputs else np.zeros((0, 2))
    if len(q) == len(est.stamp_ns):
        drive = SimpleNamespace(q_m=q, roll_rad=np.concatenate([b for _, b in inputs]),
                                truth=None, fixes=None)
    al = align(est, drive)
    al.t_s = (al.stamps_ns - acc.t0_ns) * 1e-9       # the drive's time, as in one piece
    return write_figures(folder, est, al, drive, segments=segments, title=title, units=units,
                         static_load_n=static_load_n)
