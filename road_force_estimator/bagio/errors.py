"""The two errors of the bag layer: a bag that cannot be read, or written."""
from __future__ import annotations

__all__ = ['BagReadError', 'BagWriteError']


class BagReadError(Exception):
    """A bag that cannot be read at all (missing, not a bag, no usable message)."""


class BagWriteError(Exception):
    """A bag that cannot be written (the folder exists, bad stamps, unknown topic)."""
