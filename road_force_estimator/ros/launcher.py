"""The nodes' console entry points (``ros2 run road_force_estimator NAME``): SIGINT and
SIGTERM caught (:mod:`.stop_signal`) before the node's module and its heavy imports load,
so that a Ctrl-C during the start is a stop request, never an ``ImportError`` a fallback
swallows. Each function runs ``road_force_estimator.ros.<NAME>.main()``.

One BLAS thread (``OPENBLAS_NUM_THREADS``, ``OMP_NUM_THREADS``, ``MKL_NUM_THREADS`` set to 1
unless the environment sets them, before numpy loads): a node works sample by sample on small
arrays, where a BLAS thread pool costs more than it gives: the whole vehicle's online model
fit (:class:`~.estimation.axle_fit.OnlineAxleFit`) with and without the pool,
``python -m bench.probes.blas_threads``.
"""
from __future__ import annotations

import importlib
import os

from road_force_estimator.ros import stop_signal

#: The variables set to one thread (unless set) before a node's numpy loads.
BLAS_THREAD_VARIABLES = ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS')

__all__ = ['BLAS_THREAD_VARIABLES', 'plant_simulator', 'observer', 'bag_recorder', 'bag_player']


def _run(name: str) -> int:
    stop_signal.install()
    for variable in BLAS_THREAD_VARIABLES:
        os.environ.setdefault(variable, '1')
    return importlib.import_module(f'road_force_estimator.ros.{name}').main()


def plant_simulator() -> int:
    return _run('plant_simulator')


def observer() -> int:
    return _run('observer')


def bag_recorder() -> int:
    return _run('bag_recorder')


def bag_player() -> int:
    return _run('bag_player')
