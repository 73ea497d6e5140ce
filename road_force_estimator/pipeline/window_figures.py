"""The figures of a drive in many blocks (:mod:`.blocks`): the sink of the detail window.

The detail figures (:func:`.report.figures.write_figures`) show a window of
:data:`~.report.figures.DEFAULT_WINDOW_S` from a third of the converged stretch, which is
known only at the end of the drive. :class:`Snapshots` keeps the online estimator's state
(pickled, ~400 kB) at the start of each block that may still hold that window (those before
the earliest start the converged stretch so far allows are dropped); at the end the
estimator resumes from the snapshot before the window, over the blocks read again, and the
figures are drawn from the estimates of the window's samples (the same numbers as in one
piece: the chain is causal). The profile and overview figures then show the window's
profile (band-passed over the window) with the segments of the whole drive.

Offline (:class:`.OfflineStream`) the pieces come only once the whole drive is read, and the
smoother cannot resume: :class:`OfflineWindow` keeps the pieces within the window predicted
with the drive's last estimated stamp as the end of its converged stretch (the smoother's
flag only rises within a run), and the figures are drawn from them when the final window is
that one; else the drive is estimated again for them (the same numbers).
"""
from __future__ import annotations

from dataclasses import dataclass
import pickle

import numpy as np

from road_force_estimator.report.figures import window_start

__all__ = ['Snapshots', 'OfflineWindow', 'Window', 'window_bounds', 'window_of', 'draw']


@dataclass(frozen=True)
class Window:
    """A detail window as one block's figures pick it (:func:`.figures.window_start`): the
    samples whose time
    ``(stamp - t0_ns) * 1e-9`` (s, the same float expression) lies in ``[start_s, end_s]``."""

    t0_ns: int
    start_s: float
    end_s: float

    def inside(self, stamps_ns) -> np.ndarray:
        """Which stamps (ns) are in the window (bool)."""
        t = (np.asarray(stamps_ns) - self.t0_ns) * 1e-9
        return (t >= self.start_s) & (t <= self.end_s)

    @property
    def ns(self) -> tuple[int, int]:
        """Stamps (ns) just outside the window on either side."""
        return (self.t0_ns + int(np.floor(self.start_s * 1e9)) - 1,
                self.t0_ns + int(np.ceil(self.end_s * 1e9)) + 1)


def window_bounds(acc, length_s: float) -> Window | None:
    """The detail window of the whole drive (from the accumulators ``acc``:
    :class:`~.report.streamed.StreamedSummary`), None without one."""
    return window_of(acc.t0_ns, acc.last_ns, acc.first_converged_ns, acc.last_converged_ns,
                     length_s)


def window_of(t0_ns: int | None, last_ns: int | None, first_converged_ns: int | None,
              last_converged_ns: int | None, length_s: float) -> Window | None:
    """The detail window (:func:`.figures.window_start`) of a drive whose accepted samples
    run from ``t0_ns`` to ``last_ns`` (ns) and converged ones from ``first_converged_ns`` to
    ``last_converged_ns`` (None: none converged); None without a window."""
    if t0_ns is None or last_ns == t0_ns:
        return None
    if first_converged_ns is not None:
        lo = (first_converged_ns - t0_ns) * 1e-9
        hi = (last_converged_ns - t0_ns) * 1e-9
    else:
        lo, hi = 0.0, (last_ns - t0_ns) * 1e-9
    start = window_start(lo, hi, length_s)
    return Window(int(t0_ns), start, start + length_s)


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
        while len(self.items) > 1 and self.items[1][1] <= bounds.ns[0]:
            self.items.pop(0)

    def resume(self, first_ns: int):
        """``(block index, stream)``: the last snapshot at or before ``first_ns``."""
        best = self.items[0]
        for item in self.items:
            if item[1] <= first_ns:
                best = item
        return best[0], pickle.loads(best[2])


class OfflineWindow:
    """The offline detail window's pieces (see the module notes): :meth:`keep` each piece once
    the accumulators ``acc`` (:class:`~.report.streamed.StreamedSummary`) have it; ``stream``
    the :class:`.OfflineStream` (its ``last_stamp_ns``)."""

    def __init__(self, length_s: float, stream) -> None:
        self.length_s, self.stream = length_s, stream
        self.bounds: Window | None = None
        self.pieces: list = []

    def keep(self, piece, acc) -> None:
        end = self.stream.last_stamp_ns
        first = acc.first_converged_ns
        bounds = window_of(acc.t0_ns, end, first, None if first is None else end,
                           self.length_s)
        if bounds != self.bounds:
            self.bounds = bounds
            self.pieces = [p for p in self.pieces if _inside(p, bounds).any()]
        if bounds is not None and _inside(piece, bounds).any():
            self.pieces.append(piece)


def _inside(piece, bounds: Window | None) -> np.ndarray:
    """Which rows of a piece are in the window ``bounds``."""
    if bounds is None:
        return np.zeros(len(piece.stamp_ns), bool)
    return bounds.inside(piece.stamp_ns)


def _inside_inputs(block, inside: np.ndarray) -> tuple:
    """``(q, roll, truth)`` of a block's samples ``inside`` (truth: its GroundTruth or
    None)."""
    from road_force_estimator.bagio.drive import GroundTruth

    t = block.truth
    truth = None if t is None else GroundTruth(
        t.stamps_ns[inside], t.wheel_load_n[inside], t.road_m[inside], t.distance_m[inside])
    return block.q_m[inside], block.roll_rad[inside], truth


def _window_inputs(reader, bounds: Window) -> list:
    """The inputs ``(q, roll, truth)`` of the samples in the window ``bounds``, per block."""
    inputs = []
    for block in reader:
        inside = bounds.inside(block.stamps_ns)
        if inside.any():
            inputs.append(_inside_inputs(block, inside))
        if block.stamps_ns.size and block.stamps_ns[-1] > bounds.ns[1]:
            break
    return inputs


def _window_pieces(reader, index: int, stream, bounds: Window):
    """Estimates and inputs of the samples in the window ``bounds``, the estimator resumed
    at block ``index`` of ``reader`` (read again from the start)."""
    hi = bounds.ns[1]
    pieces, inputs = [], []
    for i, block in enumerate(reader):
        if i < index:
            continue
        inside = bounds.inside(block.stamps_ns)
        if inside.any():
            inputs.append(_inside_inputs(block, inside))
        pieces += stream.feed(block.stamps_ns, block.q_m, block.roll_rad, block.speed_mps)
        if pieces and pieces[-1].stamp_ns[-1] > hi:
            break
    else:
        pieces += stream.finish()
    return pieces, inputs


def _select(pieces: list, bounds: Window):
    """One :class:`EstimateArrays` of the pieces' samples in the window ``bounds``."""
    from road_force_estimator.estimation.outputs import FIELD_COLUMNS, EstimateArrays

    parts = []
    for p in pieces:
        m = bounds.inside(p.stamp_ns)
        if m.any():
            parts.append((p, m))
    if not parts:
        return None
    fields = {name: np.concatenate([getattr(p, name)[m] for p, m in parts])
              for name in ['stamp_ns', 'valid', 'speed_contradicted', 'static_load_n',
                           *FIELD_COLUMNS]}
    return EstimateArrays(status=parts[-1][0].status, **fields)


def draw(folder, input_path, block_samples: int, keeper, acc, segments: dict,
         title: str, units: str, static_load_n, rerun=None, join=None) -> list[str]:
    """The figures' file names written into ``folder`` (none without a window). ``keeper``:
    the :class:`Snapshots` of an online drive or the :class:`OfflineWindow` of an offline
    one (``rerun()``: the drive's pieces again, when its guess missed); ``join(piece)``:
    online, each estimated piece as the sinks took it (an articulated drive's front wheels,
    :meth:`.whole_vehicle.BlockJoin.piece`; None: as estimated)."""
    from road_force_estimator.bagio.drive_blocks import DriveBlocks
    from road_force_estimator.report.alignment import align
    from road_force_estimator.report.figures import DEFAULT_WINDOW_S, FigureDrive, write_figures

    bounds = window_bounds(acc, DEFAULT_WINDOW_S)
    if bounds is None:
        return []
    if isinstance(keeper, OfflineWindow):
        pieces = (keeper.pieces if keeper.bounds == bounds else
                  [p for p in rerun() if _inside(p, bounds).any()])
        inputs = _window_inputs(DriveBlocks(input_path, block_samples), bounds)
    elif keeper.items:
        index, stream = keeper.resume(bounds.ns[0])
        pieces, inputs = _window_pieces(DriveBlocks(input_path, block_samples), index,
                                        stream, bounds)
        if join is not None:
            pieces = [join(p) for p in pieces]
    else:
        return []
    est = _select(pieces, bounds)
    if est is None or np.count_nonzero(est.valid) < 2:
        return []
    drive = None
    q = np.concatenate([a for a, _, _ in inputs]) if inputs else np.zeros((0, 2))
    if len(q) == len(est.stamp_ns):
        drive = FigureDrive(q, np.concatenate([b for _, b, _ in inputs]),
                            _joined([t for _, _, t in inputs]))
    al = align(est, drive)
    al.t_s = (al.stamps_ns - acc.t0_ns) * 1e-9       # the drive's time, as in one piece
    return write_figures(folder, est, al, drive, segments=segments, title=title, units=units,
                         static_load_n=static_load_n)


def _joined(truths: list):
    """The window's GroundTruth from its blocks' (None when the drive has none)."""
    from road_force_estimator.bagio.drive import GroundTruth

    if not truths or any(t is None for t in truths):
        return None
    return GroundTruth(*(np.concatenate([getattr(t, name) for t in truths])
                         for name in ('stamps_ns', 'wheel_load_n', 'road_m', 'distance_m')))
