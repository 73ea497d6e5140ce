"""What the pipeline hands back (:class:`EstimateResult`), its input error, and the checks
and notes both ways through it share (one block or many)."""
from __future__ import annotations

from dataclasses import dataclass, field
import math
from pathlib import Path
from typing import Any, Protocol

__all__ = ['InputError', 'Stages', 'EstimateResult', 'check_spacing', 'fit_note',
           'estimate_counts', 'nothing_estimated', 'PROG']

#: The command whose outputs the pipeline writes (the bag's ``writer_command``, the
#: diagnostics' names).
PROG = 'estimate_bag'


class InputError(Exception):
    """Bad input (``estimate_bag``'s exit status 1): not a drive bag, no usable sample or
    speed, no sample estimated, an output folder that exists."""


class Stages(Protocol):
    """The progress display of a run (``estimate_bag``'s line on stderr): :meth:`next`
    names the stage that starts, :meth:`samples` is a context manager with ``update(n)``
    over ``total`` samples; ``enabled``: whether anything shows."""

    enabled: bool

    def next(self, name: str) -> None: ...

    def samples(self, total: int, desc: str) -> Any: ...


@dataclass
class EstimateResult:
    """What a run did: the summary of the report, the paths, the estimates, the bag's
    messages written (``written``), warnings (breaks in the bag), the drive read and notes.

    ``estimates``: the :class:`~.estimation.outputs.EstimateArrays` of one block, or of many
    the :class:`~.report.streamed.Track` of the accepted samples (never held whole);
    ``drive``: the :class:`~.bagio.Drive` of one block, or of many its
    :class:`~.bagio.drive_blocks.DriveRecord` (no arrays)."""

    summary: dict[str, Any]
    bag: Path
    report: Path
    estimates: Any = None
    written: dict[str, int] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    drive: Any = None
    #: what the reader took (an articulated drive: its front axle), one line each
    notes: list[str] = field(default_factory=list)


def check_spacing(segment_length_m: float, stamps_ns, speed_mps) -> None:
    """Raise :class:`InputError` when the segments are shorter than the drive's sample
    spacing (:func:`.core.segments.check_segment_length`): refused before the work."""
    from road_force_estimator.core.segments import check_segment_length, sample_spacing
    from road_force_estimator.estimation.acceptance import MAX_SPEED_MPS

    try:
        check_segment_length(segment_length_m,
                             sample_spacing(stamps_ns, speed_mps, MAX_SPEED_MPS))
    except ValueError as err:
        raise InputError(str(err)) from None


def fit_note(fit: tuple[float, str]) -> str:
    """The report's line of a model-fit verdict ``(ratio, verdict)``."""
    from road_force_estimator.estimation.fit_check import ADVICE, MISMATCH

    return (f'{fit[1]} (residual band RMS {fit[0]:.3g} x sigma_M)'
            + (f': {ADVICE}' if fit[1] == MISMATCH else ''))


def estimate_counts(samples: int, status, rejected_by_reader: int, odometer) -> dict:
    """The totals of the last ``/diagnostics`` message: samples, estimated, rejected (by the
    reader, by the estimator), restarts and, when a GNSS fit was made, the odometer scale
    (``odometer``: the :class:`.odometer.OdometerFit` or None)."""
    counts = {'samples': int(samples), 'estimated': int(status.accepted),
              'rejected_by_reader': int(rejected_by_reader),
              'rejected_by_estimator': int(status.rejected), 'resets': int(status.resets)}
    if odometer is not None and not odometer.problem:
        counts.update(odometer_scale=odometer.scale, odometer_scale_std=odometer.scale_sigma,
                      odometer_fixes_rejected=odometer.rejected)
    return counts


def nothing_estimated(input_path: Path, n: int, status) -> str:
    """The reason when none of ``n`` samples was estimated (the counts of ``status``)."""
    return (f'{input_path}: no sample could be estimated: all {n} samples rejected '
            f'({status.rejected_range} out of range, {status.rejected_nonfinite} non-finite, '
            f'{status.rejected_time} with a bad stamp)')


def finite_fit(ratio: float, word: str) -> tuple[float, str] | None:
    """``(ratio, verdict)``, None when the ratio is not finite (too few samples)."""
    return None if not math.isfinite(ratio) else (ratio, word)
