"""How a drive goes through the pipeline: in one block or in many, from its length and the
memory limit it is given (the only module that decides whether to stream).

A drive is one block (:func:`.run.run_drive` reads it whole, ``estimate_batch`` or
``estimate_recording`` estimates it in one call) below :func:`stream_threshold` samples, many
blocks of :data:`~.bagio.drive_blocks.BLOCK_SAMPLES` from it on. The threshold is
:data:`STREAM_MIN_SAMPLES` (about 35 min at 1 kHz, below which one block takes less than
~1 GB), less when a memory limit is given (an ``estimate_fleet`` worker's) that one block
would pass half of at :data:`ONE_BLOCK_BYTES_PER_SAMPLE`, whatever the drive carries (ground
truth, fixes). Two stay one block: a drive compared with a ``--reference-profile`` (its
alignment is found over the whole drive) and the offline differentiator chain
(``observer.discretization`` other than ``model``: a zero-phase filter over the whole
recording).

An articulated drive (``vehicle.model: articulated``, :mod:`.whole_vehicle`) is one block
offline below the threshold: the estimation layer streams it
(:class:`~.estimation.whole_vehicle.WholeVehicleOfflineStream`: fed in blocks, handed out in
pieces; ``estimate_whole_vehicle`` offline runs it in one feed, its smoother in windows:
``BlockPlan.whole_vehicle_windows``, a run longer than
:data:`~.estimation.whole_vehicle.STREAM_WINDOW_SAMPLES` and its overlap smoothed a window at
a time), but the stages around it take whole arrays (the front axle's stage beside it, the
whole vehicle's sinks, the fused profile). Online (with a metadata.yaml listing its
deflections) the whole vehicle's stage reads the drive in blocks
(``BlockPlan.whole_vehicle_blocks``: :class:`~.bagio.drive_blocks.DriveBlocks` with its
channels, the estimator carried from block to block,
:class:`~.estimation.whole_vehicle.WholeVehicleOnlineStream`: the same bits as the drive read
whole). Below :func:`stream_threshold` (and :data:`WHOLE_VEHICLE_STREAM_MIN_SAMPLES`) its
estimate is gathered whole for the one-block sinks; from it on the front axle's stage and
its sinks go in blocks beside it (``BlockPlan.blocks``: :func:`.blocks.run_blocks` with the
whole vehicle's estimate spilled to temporary files and read back in pieces,
:class:`.whole_vehicle.BlockJoin`: its front wheels' loads and road put into each piece, its
topics, statuses and report sums from pieces, as one block gives them). Offline from the
same threshold (with the model's smoother) the same: the whole vehicle's stage reads the
drive in blocks into :class:`~.estimation.whole_vehicle.WholeVehicleOfflineStream` (its
smoother in windows), its pieces spilled; its fused profile and model fit per axle from the
spilled columns they need (:func:`.whole_vehicle.fused_profile`); the front axle's stage in
blocks beside it (:func:`.blocks.run_blocks` offline, ``BlockJoin``).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

__all__ = ['STREAM_MIN_SAMPLES', 'ONE_BLOCK_BYTES_PER_SAMPLE', 'WHOLE_VEHICLE_STREAM_MIN_SAMPLES',
           'BlockPlan', 'stream_threshold', 'plan_drive']

#: Drives of at least this many deflection messages (metadata.yaml) go in blocks.
STREAM_MIN_SAMPLES = 1 << 21
#: An articulated drive goes in blocks from this many deflection messages (17.5 min at
#: 1 kHz), online and offline: one block grows by ~915 bytes a sample online there, ~1300
#: offline (its front axle's stage and the whole vehicle's estimate held whole, ``python -m
#: bench.probes.estimate_bag_process --articulated``), ~1 GB at this count; in blocks the
#: outputs are one block's but for the front axle's (the figures' window, the truth's
#: profile figures: :mod:`.blocks`).
WHOLE_VEHICLE_STREAM_MIN_SAMPLES = 1 << 20
#: What a sample costs one block at its peak, figures on (bytes; measured 545 offline and
#: ~720 online without truth, ``bench/probes/long_drive_memory.py``), rounded up.
ONE_BLOCK_BYTES_PER_SAMPLE = 1000


@dataclass(frozen=True)
class BlockPlan:
    """A drive's way through the pipeline: ``blocks`` False (one block) or True (many);
    ``samples``: the deflection messages metadata.yaml lists (0: unknown);
    ``whole_vehicle_windows``: an articulated drive offline, the whole vehicle's smoother in
    windows (with ``blocks``: its stage read in blocks and spilled too);
    ``whole_vehicle_blocks``: an articulated drive online, its stage's input read
    in blocks (module notes)."""

    blocks: bool
    samples: int
    whole_vehicle_windows: bool = False
    whole_vehicle_blocks: bool = False


def stream_threshold(memory_limit_bytes: float | None = None) -> int:
    """Deflection messages from which a drive goes in blocks: :data:`STREAM_MIN_SAMPLES`,
    less when one block would pass half of ``memory_limit_bytes`` (bytes, > 0; None: no
    limit) at :data:`ONE_BLOCK_BYTES_PER_SAMPLE` a sample."""
    if memory_limit_bytes is None:
        return STREAM_MIN_SAMPLES
    if not memory_limit_bytes > 0:
        raise ValueError(f'memory limit {memory_limit_bytes!r} bytes: must be > 0')
    return max(1, min(STREAM_MIN_SAMPLES,
                      int(0.5 * memory_limit_bytes / ONE_BLOCK_BYTES_PER_SAMPLE)))


def plan_drive(input_path: str | Path, mode: str, observer, reference=None, *,
               memory_limit_bytes: float | None = None,
               min_samples: int | None = None, vehicle=None) -> BlockPlan:
    """The :class:`BlockPlan` of a drive bag (see the module notes); ``reference``: the
    ``--reference-profile`` (one block); ``min_samples``: the threshold instead of
    :func:`stream_threshold` (tests); ``vehicle``: an articulated one goes in blocks from the
    threshold on, offline and online (module notes)."""
    from road_force_estimator.bagio.drive_blocks import listed_messages
    from road_force_estimator.interfaces import DEFLECTIONS
    from road_force_estimator.pipeline.whole_vehicle import is_whole_vehicle

    listed = listed_messages(Path(input_path))
    samples = listed.get(DEFLECTIONS, 0)
    limit = stream_threshold(memory_limit_bytes) if min_samples is None else min_samples
    if mode not in ('online', 'offline') or samples == 0 or reference is not None:
        return BlockPlan(False, samples)
    if is_whole_vehicle(vehicle):     # both stages in pieces from the threshold on
        if min_samples is None:
            limit = min(limit, WHOLE_VEHICLE_STREAM_MIN_SAMPLES)
        pieces = samples >= limit and (mode == 'online' or observer.discretization == 'model')
        return BlockPlan(pieces, samples, mode == 'offline', mode == 'online')
    if mode == 'offline' and observer.discretization != 'model':
        return BlockPlan(False, samples)        # the differentiators' zero-phase chain
    return BlockPlan(samples >= limit, samples)
