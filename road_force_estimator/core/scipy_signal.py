"""``scipy.signal`` without ``scipy.stats``: the filters the package uses, at half the import.

Importing :mod:`scipy.signal` (scipy 1.15-1.17) imports every submodule, and one of them
(``_peak_finding``) takes ``scoreatpercentile`` from :mod:`scipy.stats`, which alone costs
more than the rest of ``scipy.signal`` (measured here: 1.25 s of CPU for ``import
scipy.signal`` against ~0.5 s without ``scipy.stats``). The package uses only filters
(``butter``, ``sosfilt``, ``sosfiltfilt``, ``lfilter``, ``welch``...), none of which needs
``scipy.stats``. :func:`signal` imports ``scipy.signal`` with a stand-in for ``scipy.stats``
in :data:`sys.modules` whose ``scoreatpercentile`` imports the real one when first called,
then removes the stand-in, so that a later ``import scipy.stats`` (by anyone) imports the
real module. When ``scipy.signal`` or ``scipy.stats`` is already imported, nothing changes.

The functions are scipy's own: the numbers are the same to the bit.
"""
from __future__ import annotations

import sys
import threading
import types

__all__ = ['signal']

_LOCK = threading.Lock()


def _score_at_percentile(*args, **kwargs):
    """``scipy.stats.scoreatpercentile``, imported when first called."""
    from scipy.stats import scoreatpercentile
    return scoreatpercentile(*args, **kwargs)


def signal() -> types.ModuleType:
    """The :mod:`scipy.signal` module, imported without importing :mod:`scipy.stats`."""
    mod = sys.modules.get('scipy.signal')
    if mod is not None:
        return mod
    with _LOCK:
        if 'scipy.stats' in sys.modules:
            import scipy.signal
            return scipy.signal
        stand_in = types.ModuleType('scipy.stats', 'stand-in while scipy.signal imports')
        stand_in.scoreatpercentile = _score_at_percentile
        sys.modules['scipy.stats'] = stand_in
        try:
            import scipy.signal
        finally:
            if sys.modules.get('scipy.stats') is stand_in:
                del sys.modules['scipy.stats']
        return scipy.signal
