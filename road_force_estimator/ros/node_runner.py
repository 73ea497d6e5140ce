"""``main()`` of our nodes: the robust Jazzy pattern once (demo_nodes_py), with our signals.

rclpy 7.1's own SIGINT handler shuts the context down before a node can act, so the nodes
catch SIGINT/SIGTERM themselves (:mod:`.stop_signal`: a request no thread's state can lose, a
second signal or a shutdown past its grace ends the process): the request stops the spin loop,
then ``finish`` runs while the context is still valid (publish what is held back, drain a
queue, wait for acknowledgements), then the node is destroyed and rclpy shut down. The
executor is rclpy's EventsExecutor (its callbacks cost a fraction of the
SingleThreadedExecutor's: bench/probes/node_latency.py), spun with ``spin_once`` because its
``spin()`` busy-waits in rclpy 7.1.6.
"""
from __future__ import annotations

import faulthandler
import signal
import sys
from typing import Callable, Iterable

import rclpy
from rclpy.executors import ExternalShutdownException
try:  # rclpy >= 7.1.4
    from rclpy.experimental import EventsExecutor as Executor
except ImportError:  # pragma: no cover
    from rclpy.executors import SingleThreadedExecutor as Executor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from road_force_estimator.core.parameters import ParameterSpec
from road_force_estimator.ros import stop_signal
from road_force_estimator.ros.ros_parameters import ParameterError, init_ros

__all__ = ['Executor', 'run_node']


def run_node(prog: str, description: str, specs: Iterable[ParameterSpec], args,
             make_node: Callable[[], Node], *,
             done: Callable[[Node], bool] | None = None,
             finish: Callable[[object, Node], None] | None = None,
             cleanup: Callable[[Node], None] | None = None) -> int:
    """Run one node until SIGINT/SIGTERM, an external shutdown or ``done(node)``.

    ``finish(executor, node)`` runs after the loop while the context is valid; ``cleanup(node)``
    always runs before ``destroy_node``. Returns the node's ``exit_status`` (0 when it has
    none: a node that had to stop, e.g. a recorder on a full disk, sets 1), or 1 after a
    one-line message on stderr when a parameter (or a ROS argument) is refused.
    """
    stop_signal.install()   # (done already when started by its console entry point)
    # SIGUSR1: every thread's stack on stderr (what a stuck node is doing; the tests send it
    # before they kill a node that did not exit)
    faulthandler.register(signal.SIGUSR1, all_threads=True)
    try:
        init_ros(prog, description, specs, args,
                 signal_handler_options=SignalHandlerOptions.NO)
    except ParameterError as exc:
        print(exc, file=sys.stderr)
        return 1
    node = None
    try:
        if stop_signal.requested():  # stopped while starting
            return 0
        node = make_node()
        executor = Executor()
        executor.add_node(node)
        while (not stop_signal.requested() and rclpy.ok()
               and not (done is not None and done(node))):
            executor.spin_once(timeout_sec=0.1)
        if finish is not None and rclpy.ok():
            finish(executor, node)
        return int(getattr(node, 'exit_status', 0))
    except ParameterError as exc:
        print(exc, file=sys.stderr)
        return 1
    except (KeyboardInterrupt, ExternalShutdownException):
        return 0
    finally:
        if node is not None:
            if cleanup is not None:
                cleanup(node)
            node.destroy_node()
        rclpy.try_shutdown()
