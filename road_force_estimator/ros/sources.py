"""The publishers of one topic, told apart by their sequence numbers; messages lost on the way.

Every DDS publisher numbers its messages 1, 2, 3... (``publication_sequence_number`` of the
message info). A :class:`Sources` puts each message of a topic on the run of numbers it
continues (a source: one publisher, or one life of a publisher that restarts at 1), so that
two publishers interleaving on one topic are two sources, and a step of k in one source's
numbers means k - 1 messages that were published but never taken (lost in the transport, or
dropped from a full queue: the recorder and the observer count them). No rclpy: the numbers
come in, the verdicts go out.
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ['MAX_SOURCES', 'MAX_STEP', 'Source', 'Sources']

#: Sources followed at most per topic (a further one replaces the one heard least recently).
MAX_SOURCES = 8
#: The largest step of one source's numbers taken as losses (a longer one starts a source).
MAX_STEP = 1_000_000


@dataclass
class Source:
    """One run of sequence numbers: the last one, the messages taken and missed, when it was
    last heard (s, the caller's clock)."""

    last: int
    taken: int = 1
    missed: int = 0
    heard_s: float = 0.0


class Sources:
    """The sources of one topic (see the module); :meth:`add` for every message, in the
    order taken."""

    def __init__(self) -> None:
        self.sources: list[Source] = []
        self.missed = 0             # messages the numbers say were published but not taken
        self.started = 0            # sources seen (a publisher restarting counts again)
        self.primary = 0            # index of the source the observer follows

    def add(self, sequence: int | None, now_s: float) -> int:
        """The index of the source of a message numbered ``sequence`` (None: no numbers,
        one source), taken at ``now_s``; its losses are counted."""
        if sequence is None:
            if not self.sources:
                self.sources.append(Source(0, 0))
            src = self.sources[0]
            src.taken += 1
            src.heard_s = now_s
            return 0
        best = -1
        for i, src in enumerate(self.sources):
            if src.last < sequence <= src.last + MAX_STEP and (
                    best < 0 or src.last > self.sources[best].last):
                best = i
        if best < 0:
            return self._new(sequence, now_s)
        src = self.sources[best]
        step = sequence - src.last
        src.missed += step - 1
        self.missed += step - 1
        src.last = sequence
        src.taken += 1
        src.heard_s = now_s
        return best

    def _new(self, sequence: int, now_s: float) -> int:
        self.started += 1
        src = Source(sequence, heard_s=now_s)
        if len(self.sources) < MAX_SOURCES:
            self.sources.append(src)
            return len(self.sources) - 1
        oldest = min(range(len(self.sources)), key=lambda i: self.sources[i].heard_s)
        if oldest == self.primary:
            self.primary = -1
        self.sources[oldest] = src
        return oldest

    def live(self, now_s: float, within_s: float) -> int:
        """How many sources were heard within the last ``within_s``."""
        return sum(now_s - s.heard_s <= within_s for s in self.sources)

    def follow(self, index: int, now_s: float, silence_s: float) -> bool:
        """Whether a message of source ``index`` is the observer's to take: the source it
        follows (the first one), or another once that one has been silent for ``silence_s``
        (a publisher that restarted, a replacement): then it follows that one."""
        if self.primary < 0 or self.primary >= len(self.sources):
            self.primary = index
        if index == self.primary:
            return True
        if now_s - self.sources[self.primary].heard_s > silence_s:
            self.primary = index
            return True
        return False
