"""The drive pipeline: a drive bag through the estimator into the bag of estimates and the
report, the one way every drive goes (``estimate_bag``, each ``estimate_fleet`` drive).

:func:`.run.run_drive` is the one downward pass: the source (the drive's blocks, with ground
truth and fixes) -> the estimator stage (online or offline) -> the sinks (the estimate bag,
the diagnostics, the report's accumulators, the figures), closed once. :mod:`.plan` alone
decides whether a drive goes in one block (:mod:`.one_block`) or in many (:mod:`.blocks`,
:mod:`.sinks`, :mod:`.window_figures`), from its length and the memory limit it is given;
:mod:`.result` holds what both hand back. It imports ``report/``, ``bagio/``,
``calibration/``, ``estimation/`` and ``core/``; only ``tools/`` imports it. Nothing is
imported here.
"""

__all__ = ['plan', 'run', 'result', 'one_block', 'blocks', 'sinks', 'window_figures']
