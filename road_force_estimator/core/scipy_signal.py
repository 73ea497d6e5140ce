""":mod:`scipy.signal`, imported when first used (:func:`signal`).

Importing :mod:`scipy.signal` costs about a second of CPU (it imports every submodule,
``scipy.stats`` among them); the nodes and the commands that never filter need not pay it at
start. The functions are scipy's own. (An earlier version swapped a stand-in for
``scipy.stats`` into :data:`sys.modules` while ``scipy.signal`` imported, to save a third of
that: a global side effect on every other importer, removed.)
"""
from __future__ import annotations

import types

__all__ = ['signal']


def signal() -> types.ModuleType:
    """The :mod:`scipy.signal` module."""
    import scipy.signal
    return scipy.signal
