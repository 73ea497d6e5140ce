"""The nodes' console entry points (``ros2 run road_force_estimator NAME``): SIGINT and
SIGTERM caught (:mod:`.stop_signal`) before the node's module and its heavy imports load,
so that a Ctrl-C during the start is a stop request, never an ``ImportError`` a fallback
swallows. Each function runs ``road_force_estimator.ros.<NAME>.main()``.
"""
from __future__ import annotations

import importlib

from road_force_estimator.ros import stop_signal

__all__ = ['plant_simulator', 'observer', 'bag_recorder', 'bag_player']


def _run(name: str) -> int:
    stop_signal.install()
    return importlib.import_module(f'road_force_estimator.ros.{name}').main()


def plant_simulator() -> int:
    return _run('plant_simulator')


def observer() -> int:
    return _run('observer')


def bag_recorder() -> int:
    return _run('bag_recorder')


def bag_player() -> int:
    return _run('bag_player')
