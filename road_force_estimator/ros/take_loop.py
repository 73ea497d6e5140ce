"""Subscriptions served by a thread of their own: every queued message taken at once, with its
message info.

rclpy hands a subscription's messages to an executor one callback at a time, and its
EventsExecutor queues one event per arriving message (a queue that grows without bound when
the callbacks fall behind a flood, ahead of every timer) and cannot give the message info
(publisher sequence numbers, reception times) to a callback. A :class:`TakeLoop` instead owns
a node that no executor spins (hidden: its name starts with ``_``): a thread waits on its
subscriptions (an rcl wait set, and a guard condition to wake it) and takes what is queued,
up to ``batch`` messages per subscription and round, each with its info
(``source_timestamp``, ``received_timestamp``, ``publication_sequence_number``), and hands
each round to ``sink(batch)`` in that thread. What waits is bounded by the subscriptions'
own history depth (DDS drops the oldest beyond it); the node that uses it keeps its timers and
services on its executor, on time.

Cost: one rcl wait set, kept while the subscriptions stay; after a wait only the subscriptions
it found ready are taken from; the wait lasts ``period_s`` at most, never less unless woken
(an idle loop does not poll: :attr:`TakeLoop.waits`). A subscription added with
``wakes=False`` (the observer's ``/vehicle/twist``, which comes with every deflection
message) does not wake the thread: one wake-up a sample instead of two. The observer's
thread costs no more CPU than an executor's callbacks for the same messages
(``python -m bench.probes.node_latency --node take`` against ``--node bare``).

The two users: the bag recorder (:mod:`.bag_recorder`: the receive time is the log time, a
stop drains exactly what was received before it) and the observer (:mod:`.observer`: what
queued up is estimated in one go).
"""
from __future__ import annotations

from contextlib import ExitStack
from dataclasses import dataclass
import threading
import time
from typing import Callable

from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node

__all__ = ['Taken', 'TakeLoop', 'input_node_name']


def input_node_name(owner: str) -> str:
    """The hidden node whose subscriptions carry the inputs of the node ``owner``: what the
    graph shows as the subscriber of those topics (``_observer_input`` for ``observer``;
    :class:`.start_gate.SubscriberGate` counts it as its owner)."""
    return f'_{owner}_input'


@dataclass(frozen=True)
class Taken:
    """One message: the index of its subscription, its CDR bytes, reception time (ns, the
    system clock), the publisher's sequence number (None when the middleware gives none)."""

    index: int
    data: bytes
    received_ns: int
    sequence: int | None


class TakeLoop:
    """A hidden node whose subscriptions a thread of its own takes from (see the module).

    Parameters
    ----------
    owner : str
        The name of the node that uses it: the hidden node is :func:`input_node_name` of it.
    context : rclpy Context
        The context of the node that uses it.
    batch : int
        Messages taken per subscription and round at most (a round's share of the time).
    """

    def __init__(self, owner: str, context, *, batch: int = 1000) -> None:
        self.node = Node(input_node_name(owner), context=context,
                         start_parameter_services=False, enable_rosout=False)
        self.context = self.node.context
        self.batch = int(batch)
        self.subscriptions: list = []
        self._guard = None
        self._wait_set = None     # (the subscriptions it is for, the rcl wait set, by pointer)
        self._riders: frozenset = frozenset()   # indices of the subscriptions that do not wake
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._sink: Callable | None = None
        self._idle: Callable | None = None
        self.rounds = 0
        #: waits on the wait set (each at most ``period_s``): an idle loop waits about once
        #: per ``period_s``, it does not poll
        self.waits = 0
        self.error: BaseException | None = None

    def add(self, msg_class, topic: str, qos, *, wakes: bool = True) -> int:
        """Subscribe (raw) to ``topic``; the subscription's index (also while running: the
        thread takes from it from its next round on). ``wakes=False``: its messages do not
        wake the thread; they are taken with every round (what another subscription woke,
        and at least every ``period_s``): for a topic that comes with another's messages
        (the observer's twist with its deflections), one wake-up a sample instead of two."""
        sub = self.node.create_subscription(msg_class, topic, _never, qos, raw=True)
        self.subscriptions = [*self.subscriptions, sub]   # (a new list: the thread's stays)
        if not wakes:
            self._riders = self._riders | {len(self.subscriptions) - 1}
        return len(self.subscriptions) - 1

    def start(self, sink: Callable[[list[Taken]], None],
              idle: Callable[[], None] | None = None, period_s: float = 0.1) -> None:
        """Run the thread: ``sink(batch)`` for every round that took something, ``idle()``
        at least every ``period_s`` (e.g. to close a chunk by time)."""
        self._sink, self._idle, self._period_s = sink, idle, float(period_s)
        self._stop.clear()                 # (a loop stopped can start again)
        if self._guard is None:
            with self.context.handle:
                self._guard = _rclpy.GuardCondition(self.context.handle)
        self._thread = threading.Thread(target=self._run, name=self.node.get_name(),
                                        daemon=True)
        self._thread.start()

    def take_all(self, until_ns: int | None = None) -> list[Taken]:
        """What is queued now, every subscription once (at most ``batch`` each); with
        ``until_ns`` only what was received up to that time (ns, system clock) and, with it,
        the first message received after it (taken, so not left for later: the caller drops
        it). For the thread, and for a drain once the thread is stopped."""
        return self._take(list(enumerate(self.subscriptions)), until_ns)

    def _take(self, subs: list, until_ns: int | None = None) -> list[Taken]:
        """What is queued on ``subs`` (``(index, subscription)`` pairs): see :meth:`take_all`."""
        out: list[Taken] = []
        for index, sub in subs:
            try:
                with sub.handle:
                    take = sub.handle.take_message
                    for _ in range(self.batch):
                        got = take(sub.msg_type, True)
                        if got is None:
                            break
                        data, info = got
                        taken = Taken(index, data, int(info.get('received_timestamp') or 0),
                                      info.get('publication_sequence_number'))
                        out.append(taken)
                        if until_ns is not None and taken.received_ns > until_ns:
                            break
            except Exception:            # a destroyed handle (shutdown): nothing more there
                continue
        return out

    def _run(self) -> None:
        next_idle = time.monotonic() + self._period_s
        ready = list(enumerate(self.subscriptions))      # at first: every subscription
        try:
            while not self._stop.is_set():
                batch = self._take(ready)
                if batch:
                    self.rounds += 1
                    self._sink(batch)
                now = time.monotonic()
                if now >= next_idle:   # (also without idle: else the wait below is 0 s, a spin)
                    next_idle = now + self._period_s
                    if self._idle is not None:
                        self._idle()
                # what came meanwhile makes the wait return at once, with what is ready
                ready = self._wait(max(0.0, min(next_idle - now, self._period_s)))
        except BaseException as exc:  # noqa: BLE001 - kept for the owner (never a crash here)
            self.error = exc

    def _wait(self, timeout_s: float) -> list:
        """Wait up to ``timeout_s`` for a message or the guard; the ``(index, subscription)``
        pairs that have messages (every one when the guard woke it)."""
        self.waits += 1
        subs = self.subscriptions
        with ExitStack() as stack:
            stack.enter_context(self.context.handle)
            if not self.context.ok():
                self._stop.set()
                return []
            for sub in subs:
                stack.enter_context(sub.handle)
            if self._wait_set is None or self._wait_set[0] is not subs:
                # one wait set while the subscriptions stay (riders left out)
                riders = [(i, sub) for i, sub in enumerate(subs) if i in self._riders]
                wakers = [(i, sub) for i, sub in enumerate(subs) if i not in self._riders]
                ws = _rclpy.WaitSet(len(wakers), 1, 0, 0, 0, 0, self.context.handle)
                self._wait_set = (subs, ws, {sub.handle.pointer: (i, sub) for i, sub in wakers},
                                  riders)
            _, wait_set, by_pointer, riders = self._wait_set
            wait_set.clear_entities()
            for _, sub in by_pointer.values():
                wait_set.add_subscription(sub.handle)
            wait_set.add_guard_condition(self._guard)
            wait_set.wait(int(timeout_s * 1e9))
            if wait_set.get_ready_entities('guard_condition'):
                return list(enumerate(subs))
            ready = [by_pointer[p] for p in wait_set.get_ready_entities('subscription')
                     if p in by_pointer]
            if not ready:      # the period passed: every subscription once
                return list(enumerate(subs))
            return riders + sorted(ready, key=lambda pair: pair[0]) if riders else ready

    def request_stop(self) -> None:
        """Ask the thread to end after its round (callable from the thread itself)."""
        self._stop.set()

    def stop(self, timeout_s: float = 2.0) -> None:
        """Stop the thread (it finishes its round); idempotent. The subscriptions stay, so
        that what is queued can still be taken (:meth:`take_all`)."""
        self._stop.set()
        if self._guard is not None:
            try:
                self._guard.trigger_guard_condition()
            except Exception:  # noqa: BLE001 - already gone with the context
                pass
        if self._thread is not None and self._thread.is_alive():
            self._thread.join(timeout=timeout_s)

    def destroy(self) -> None:
        """Stop and destroy the hidden node."""
        self.stop()
        if self._wait_set is not None and not self.running:
            self._wait_set[1].destroy_when_not_in_use()
            self._wait_set = None
        self.node.destroy_node()

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()


def _never(msg) -> None:   # the hidden node is never spun: no callback runs
    pass
