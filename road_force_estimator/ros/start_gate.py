"""The start of a drive loses nothing: publishers wait for the subscribers that matter.

A publisher that starts on *any* subscriber loses the start of the drive to the slower nodes:
a recorder, which subscribes to every topic of INTERFACES.md at once, is usually first, and
the observer (or the plant, for a profile played on ``/lpa/*``) comes a second later. So
``plant_simulator`` and ``bag_player`` wait (:class:`SubscriberGate`) until named nodes
subscribe (by default the package's node that reads each topic: :data:`.interfaces.READERS`),
or until a topic has a given number of subscribers, then :data:`SETTLE_S` for the
subscribers' side of the discovery to complete.

Both also say in their ``/diagnostics`` the stamp of the first message they published on each
measurement topic (:func:`first_stamp_values`: the key ``first_stamp_ns:<topic>``), so that a
node which starts late counts what it missed (the observer's ``missed_before_first_input``).
"""
from __future__ import annotations

from typing import Iterable, Mapping, Sequence

from rclpy.node import Node

from road_force_estimator.interfaces import FIRST_STAMP_KEY
from road_force_estimator.ros.take_loop import input_node_name

__all__ = ['SETTLE_S', 'SubscriberGate', 'first_stamp_values', 'first_stamps']

#: Once the subscribers that matter are matched on the publisher's side: time for the
#: subscribers' side of the discovery to complete before the first message (s).
SETTLE_S = 0.3


def _matches(wanted: str, namespace: str, name: str) -> bool:
    """A node name as given (``observer``: any namespace; ``/ns/observer``: that one); the
    hidden node that takes a node's inputs (:func:`.take_loop.input_node_name`) counts as
    that node."""
    if wanted.startswith('/'):
        ns, _, base = wanted.rpartition('/')
        return namespace.rstrip('/') == ns and name in (base, input_node_name(base))
    return name in (wanted, input_node_name(wanted))


class SubscriberGate:
    """What a publisher waits for before its first message.

    Parameters
    ----------
    node : rclpy.node.Node
        The publishing node (its graph queries).
    wanted : mapping topic -> node names
        Per topic, the nodes that must subscribe to it (``observer`` in any namespace,
        ``/ns/observer`` in that one); an empty tuple: any one subscriber.
    count : int
        > 0: instead, every topic needs this many subscribers (whoever they are).
    """

    def __init__(self, node: Node, wanted: Mapping[str, Sequence[str]], count: int = 0):
        self.node = node
        self.wanted = {topic: tuple(names) for topic, names in wanted.items()}
        self.count = int(count)

    def missing(self) -> list[str]:
        """What is still missing, one phrase each (empty: ready)."""
        out = []
        for topic, names in self.wanted.items():
            if self.count > 0 or not names:
                need = max(self.count, 1)
                have = self.node.count_subscribers(topic)
                if have < need:
                    out.append(f'{need - have} more subscriber(s) on {topic}')
                continue
            infos = self.node.get_subscriptions_info_by_topic(topic)
            for wanted in names:
                if not any(_matches(wanted, i.node_namespace, i.node_name) for i in infos):
                    out.append(f'{wanted} on {topic}')
        return out

    def describe(self) -> str:
        """What the gate waits for, in words (for the log)."""
        if self.count > 0:
            return f'{self.count} subscriber(s) on each of {", ".join(self.wanted)}'
        parts = []
        for names in dict.fromkeys(self.wanted.values()):
            topics = ', '.join(t for t, n in self.wanted.items() if n == names)
            parts.append(f'{" and ".join(names) or "a subscriber"} on {topics}')
        return '; '.join(parts)


def first_stamp_values(first_stamps_ns: Mapping[str, int]) -> dict[str, str]:
    """The ``/diagnostics`` values saying the first stamp published per topic."""
    return {f'{FIRST_STAMP_KEY}{topic}': str(int(ns)) for topic, ns in first_stamps_ns.items()}


def first_stamps(values: Iterable[tuple[str, str]], topic: str) -> int | None:
    """The first stamp (ns) a publisher's diagnostics give for ``topic``, or None."""
    key = f'{FIRST_STAMP_KEY}{topic}'
    for k, v in values:
        if k == key:
            try:
                return int(v)
            except ValueError:
                return None
    return None
