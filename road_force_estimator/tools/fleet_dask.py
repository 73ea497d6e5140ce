"""estimate_fleet's engine: a Dask client (an existing scheduler or a local cluster) and the
drive tasks on it.

A scheduler that cannot be reached is a :class:`~.fleet_drives.FleetError` (exit status 2),
never a silent local fallback. A task whose worker dies is run again elsewhere (Dask's
``allowed-failures`` for lost workers, plus :data:`RETRIES`).
"""
from __future__ import annotations

from contextlib import contextmanager
import os
import sys
from typing import Any, Iterator
import uuid

from road_force_estimator.tools.cli import one_line
from road_force_estimator.tools.fleet_drives import (
    DriveOutcome, DriveTask, FleetError, process_drive)

__all__ = ['RETRIES', 'CONNECT_TIMEOUT_S', 'WORKER_WAIT_S', 'default_workers',
           'probe_scheduler', 'dask_client', 'run_tasks']

#: Extra attempts of a task that raised (lost workers are retried by the scheduler too).
RETRIES = 2
#: Time allowed to reach a --scheduler (s).
CONNECT_TIMEOUT_S = 10.0
#: Time allowed for a --scheduler to have at least one worker (s).
WORKER_WAIT_S = 120.0


def default_workers() -> int:
    """Worker processes of the local cluster: the CPUs this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def probe_scheduler(address: str) -> None:
    """Fail at once when a ``tcp://HOST:PORT`` (or ``HOST:PORT``) scheduler does not accept a
    connection (Dask itself would retry until its timeout); other protocols go to Dask."""
    import socket
    from urllib.parse import urlsplit

    text = address if '://' in address else 'tcp://' + address
    parts = urlsplit(text)
    if parts.scheme != 'tcp':
        return
    try:
        host, port = parts.hostname, parts.port
    except ValueError as err:
        raise FleetError(f'--scheduler {address!r}: {err}') from None
    if not host or port is None:
        raise FleetError(f'--scheduler {address!r}: expected tcp://HOST:PORT')
    try:
        with socket.create_connection((host, port), timeout=CONNECT_TIMEOUT_S):
            pass
    except OSError as err:
        reason = err.strerror or type(err).__name__
        if isinstance(err, socket.timeout):
            reason = f'no answer within {CONNECT_TIMEOUT_S:g} s'
        raise FleetError(f'cannot reach the Dask scheduler at {address}: {reason}') from None


@contextmanager
def dask_client(scheduler: str | None, workers: int) -> Iterator[tuple[Any, str]]:
    """A Dask client: on ``scheduler``, or on a local cluster of ``workers`` processes."""
    import logging

    from distributed import Client, LocalCluster

    if scheduler:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
        except (OSError, TimeoutError, ValueError) as err:
            raise FleetError(f'cannot reach the Dask scheduler at {scheduler} within '
                             f'{CONNECT_TIMEOUT_S:g} s ({one_line(err)})') from None
        try:
            try:
                client.wait_for_workers(1, timeout=WORKER_WAIT_S)
            except (TimeoutError, OSError) as err:
                raise FleetError(f'the Dask scheduler at {scheduler} has no worker after '
                                 f'{WORKER_WAIT_S:g} s ({one_line(err)})') from None
            n = len(client.scheduler_info().get('workers', {}))
            yield client, f'scheduler {scheduler} ({n} workers at start)'
        finally:
            client.close()
        return
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                           host='127.0.0.1', dashboard_address=None,
                           silence_logs=logging.ERROR)
    try:
        client = Client(cluster, set_as_default=False)
        try:
            yield client, f'local cluster of {workers} worker process' + \
                ('es' if workers > 1 else '')
        finally:
            client.close()
    finally:
        cluster.close()


def run_tasks(client, tasks: list[DriveTask], outcomes: dict[str, DriveOutcome], *,
              total: int, progress: bool, name: str) -> None:
    """Run :func:`~.fleet_drives.process_drive` for every task on ``client``; each outcome into
    ``outcomes`` (by drive id) as it comes back (a task lost beyond its retries: ``failed``).

    ``total``: the drives of the run (those done before count as done on the progress bar);
    ``name``: the prefix of the task keys and the bar's label.
    """
    from distributed import as_completed
    from tqdm import tqdm

    run_id = uuid.uuid4().hex[:8]
    futures = {}
    for i, task in enumerate(tasks):
        fut = client.submit(process_drive, task, key=f'{name}-{run_id}-{i}', pure=False,
                            retries=RETRIES)
        futures[fut.key] = (fut, task)
    done_before = total - len(tasks)
    failed = 0
    with tqdm(total=total, initial=done_before, desc=name, unit='drive', file=sys.stderr,
              disable=not progress, dynamic_ncols=True) as bar:
        for fut in as_completed([f for f, _ in futures.values()], loop=client.loop):
            task = futures[fut.key][1]
            try:
                outcome = fut.result()
            except Exception as err:  # noqa: BLE001 - a task lost beyond its retries
                outcome = DriveOutcome(task.drive_id, 'failed',
                                       reason=f'{type(err).__name__}: {one_line(err)}',
                                       input_path=task.input_path)
            outcomes[task.drive_id] = outcome
            failed += outcome.status == 'failed'
            bar.set_postfix(failed=failed, refresh=False)
            bar.update(1)
            fut.release()
