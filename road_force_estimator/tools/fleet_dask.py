"""estimate_fleet's engine: a Dask client (an existing scheduler or a local cluster) and the
drive tasks on it.

A scheduler that cannot be reached is a :class:`~.fleet_drives.FleetError` (exit status 2),
never a silent local fallback, nor a hang: :func:`probe_scheduler` reads the scheduler's
handshake within :data:`CONNECT_TIMEOUT_S` and names what answered instead. A task whose
worker dies is run again elsewhere (Dask's ``allowed-failures`` for lost workers, plus
:data:`RETRIES`).
"""
from __future__ import annotations

from contextlib import contextmanager
import os
import sys
import time
from typing import Any, Iterator
import uuid

from road_force_estimator.tools.cli import one_line
from road_force_estimator.tools.fleet_drives import (
    DriveOutcome, DriveTask, FleetError, process_drive)

__all__ = ['RETRIES', 'CONNECT_TIMEOUT_S', 'HANDSHAKE_MAX_BYTES', 'WORKER_WAIT_S',
           'default_workers', 'probe_scheduler', 'dask_client', 'run_tasks']

#: Extra attempts of a task that raised (lost workers are retried by the scheduler too).
RETRIES = 2
#: Time allowed to reach a --scheduler and read its handshake (s).
CONNECT_TIMEOUT_S = 10.0
#: Largest first message accepted from a --scheduler (bytes; Dask's handshake is ~60).
HANDSHAKE_MAX_BYTES = 1 << 16
#: Time allowed for a --scheduler to have at least one worker (s).
WORKER_WAIT_S = 120.0


def default_workers() -> int:
    """Worker processes of the local cluster: the CPUs this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


class _NotDask(Exception):
    """What a --scheduler sent is not a Dask handshake."""


def probe_scheduler(address: str) -> None:
    """Fail within :data:`CONNECT_TIMEOUT_S` unless ``address`` answers as a Dask scheduler
    (Dask's own client waits forever on a TCP service that accepts and says nothing).

    ``tcp://HOST:PORT`` (or ``HOST:PORT``): the first message must be a Dask handshake (at
    most :data:`HANDSHAKE_MAX_BYTES`); ``inproc://`` is refused (it lives inside one
    process); other protocols (``tls://`` with the TLS settings of the Dask configuration)
    must connect with Dask's own comm.

    Raises
    ------
    FleetError
        The reason, in one line.
    """
    text = address if '://' in address else 'tcp://' + address
    scheme = text.split('://', 1)[0].lower()
    if scheme == 'inproc':
        raise FleetError(f'--scheduler {address}: an inproc:// address lives inside one '
                         "process; give the scheduler's tcp:// address")
    if scheme == 'tcp':
        _probe_tcp(address, text)
    else:
        _probe_comm(address, text, scheme)


def _probe_tcp(address: str, text: str) -> None:
    """:func:`probe_scheduler` for ``tcp://``: connect, then read the Dask handshake."""
    import socket
    from urllib.parse import urlsplit

    try:
        parts = urlsplit(text)
        host, port = parts.hostname, parts.port
    except ValueError as err:
        raise FleetError(f'--scheduler {address!r}: {err}') from None
    if not host or port is None:
        raise FleetError(f'--scheduler {address!r}: expected tcp://HOST:PORT')
    timeout = CONNECT_TIMEOUT_S
    deadline = time.monotonic() + timeout
    try:
        sock = socket.create_connection((host, port), timeout=timeout)
    except OSError as err:
        reason = err.strerror or type(err).__name__
        if isinstance(err, socket.timeout):
            reason = f'no answer within {timeout:g} s'
        raise FleetError(f'cannot reach the Dask scheduler at {address}: {reason}') from None
    try:
        with sock:
            size = int.from_bytes(_receive(sock, 8, deadline), 'little')
            if not 16 <= size <= HANDSHAKE_MAX_BYTES:
                raise _NotDask(f'its first message declares {size} bytes')
            _check_handshake(_receive(sock, size, deadline))
    except _NotDask as err:
        raise FleetError(f'--scheduler {address}: not a Dask scheduler ({err})') from None
    except socket.timeout:
        raise FleetError(f'cannot reach the Dask scheduler at {address}: the service there '
                         f'sent no Dask handshake within {timeout:g} s (is it a Dask '
                         'scheduler?)') from None
    except OSError as err:
        raise FleetError(f'cannot reach the Dask scheduler at {address}: '
                         f'{err.strerror or type(err).__name__}') from None
    _probe_comm(address, text, 'tcp')


def _receive(sock, n: int, deadline: float) -> bytes:
    """Exactly ``n`` bytes from ``sock`` before ``deadline`` (time.monotonic, s)."""
    import socket

    data = bytearray()
    while len(data) < n:
        left = deadline - time.monotonic()
        if left <= 0:
            raise socket.timeout('timed out')
        sock.settimeout(left)
        block = sock.recv(min(n - len(data), 1 << 16))
        if not block:
            raise _NotDask('it closed the connection before a Dask handshake')
        data += block
    return bytes(data)


def _check_handshake(body: bytes) -> None:
    """Raise :class:`_NotDask` unless ``body`` holds Dask frames whose first is a msgpack map
    (the handshake: ``compression``, ``python``, ``pickle-protocol``)."""
    import struct

    import msgpack

    n = struct.unpack_from('<Q', body)[0]
    if not 1 <= n <= 16 or 8 + 8 * n > len(body):
        raise _NotDask(f'{n} frames in its first message')
    lengths = struct.unpack_from(f'<{n}Q', body, 8)
    start = 8 + 8 * n
    if start + sum(lengths) != len(body):
        raise _NotDask('frame lengths that do not add up')
    try:
        first = msgpack.unpackb(body[start:start + lengths[0]], raw=False)
    except Exception:  # noqa: BLE001 - any decoding failure: not Dask
        first = None
    if not isinstance(first, dict):
        raise _NotDask('its first message is not a handshake')


def _probe_comm(address: str, text: str, scheme: str) -> None:
    """:func:`probe_scheduler` with Dask's own comm (after the handshake check for tcp):
    connect and ask its identity, each step within :data:`CONNECT_TIMEOUT_S`; it must be a
    ``Scheduler`` (a worker's address is refused)."""
    import asyncio

    from distributed.comm import connect
    from distributed.security import Security

    timeout = CONNECT_TIMEOUT_S
    try:
        args = Security().get_connection_args('client')
    except Exception as err:  # noqa: BLE001 - a bad TLS configuration
        raise FleetError(f'--scheduler {address}: {one_line(err)}') from None
    if scheme == 'tls' and args.get('ssl_context') is None:
        raise FleetError(f'--scheduler {address}: tls:// needs TLS settings in the Dask '
                         'configuration (distributed.comm.tls.ca-file, .client.cert, '
                         '.client.key); none are set')

    async def identity() -> dict:
        comm = await asyncio.wait_for(connect(text, timeout=timeout, **args), timeout)
        try:
            await asyncio.wait_for(comm.write({'op': 'identity', 'reply': True}), timeout)
            return await asyncio.wait_for(comm.read(), timeout)
        finally:
            await comm.close()

    try:
        kind = asyncio.run(identity())
        kind = kind.get('type') if isinstance(kind, dict) else None
    except (asyncio.TimeoutError, TimeoutError):
        raise FleetError(f'cannot reach the Dask scheduler at {address}: no Dask handshake '
                         f'within {timeout:g} s') from None
    except Exception as err:  # noqa: BLE001 - whatever the comm raises: one line
        raise FleetError(f'cannot reach the Dask scheduler at {address}: '
                         f'{type(err).__name__}: {one_line(err)}') from None
    if kind != 'Scheduler':
        raise FleetError(f'--scheduler {address}: not a Dask scheduler (it says it is a '
                         f'{kind or "service of unknown type"}: give the scheduler\'s address)')


def _ignoring_sigint(make):
    """``make()`` with SIGINT ignored, so that the worker processes it starts inherit that
    (an ignored signal stays ignored through fork and exec): Ctrl-C reaches the whole process
    group, and only this process acts on it, stopping the cluster (one line, no worker
    traceback). A Ctrl-C during the cluster's start (a second or two) is not seen."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return make()
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        return make()
    finally:
        signal.signal(signal.SIGINT, previous)


def _quiet_cluster(local_cluster, workers: int, log_level: int):
    """A local cluster, without distributed's warning that its HTTP port (8787) is taken by
    another cluster of the machine (it takes another one: a run prints nothing of it)."""
    import warnings

    with warnings.catch_warnings():
        warnings.filterwarnings('ignore', message=r'Port \d+ is already in use',
                                category=UserWarning)
        return local_cluster(n_workers=workers, threads_per_worker=1, processes=True,
                             host='127.0.0.1', dashboard_address=None,
                             scheduler_kwargs={'dashboard_address': '127.0.0.1:0'},
                             silence_logs=log_level)


@contextmanager
def dask_client(scheduler: str | None, workers: int) -> Iterator[tuple[Any, str]]:
    """A Dask client: on ``scheduler``, or on a local cluster of ``workers`` processes."""
    import logging

    import dask
    from distributed import Client, LocalCluster

    if scheduler:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
        except Exception as err:  # noqa: BLE001 - whatever Dask raises: one line
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
    # No dashboard, and no HTTP routes: Dask's scheduler opens its HTTP listener whatever
    # dashboard_address says (on 8787 by default, warning on stderr when that port is taken):
    # here it is on a free loopback port with nothing to serve. Worker logs below CRITICAL are
    # silenced: a stopped run's heartbeat errors are noise, and a drive that fails says why in
    # failures.csv.
    with dask.config.set({'distributed.scheduler.http.routes': [],
                          'distributed.worker.http.routes': []}):
        cluster = _ignoring_sigint(lambda: _quiet_cluster(LocalCluster, workers,
                                                          logging.CRITICAL))
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
