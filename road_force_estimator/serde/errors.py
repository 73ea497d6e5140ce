"""The serializer's error (one exception class per concern)."""
from __future__ import annotations

__all__ = ['SerdeError']


class SerdeError(ValueError):
    """A value that has no CDR form (a stamp beyond ROS time, a wrong dtype); the message names
    it."""
