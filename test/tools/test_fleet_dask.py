"""tools.fleet_dask: a --scheduler that is not a Dask scheduler (a TCP service that says
nothing, one that sends garbage), and addresses a separate process cannot use (tls:// without
TLS settings, inproc://): a one-line reason and exit status 2 within the connect timeout,
never a hang or a traceback (issue 16).

References: plain TCP servers on 127.0.0.1 written here, and a real ``distributed.Scheduler``
(its handshake must pass the probe)."""
import socket
import threading
import time

import pytest

from road_force_estimator.tools import estimate_fleet, fleet_dask
from road_force_estimator.tools.fleet_drives import FleetError

pytestmark = pytest.mark.slow   # `pytest -m 'not slow'` skips it; scripts/test runs it

TIMEOUT_S = 0.5


class Server:
    """A TCP server on 127.0.0.1 that accepts and sends ``greeting`` (b'' = nothing)."""

    def __init__(self, greeting: bytes) -> None:
        self.sock = socket.create_server(('127.0.0.1', 0))
        self.port = self.sock.getsockname()[1]
        self.greeting = greeting
        self.conns = []
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self) -> None:
        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            self.conns.append(conn)
            if self.greeting:
                conn.sendall(self.greeting)

    def close(self) -> None:
        self.sock.close()
        for c in self.conns:
            c.close()


@pytest.fixture
def server(request):
    s = Server(request.param)
    yield s
    s.close()


@pytest.fixture
def fleet_args(tmp_path, monkeypatch):
    monkeypatch.setattr(fleet_dask, 'CONNECT_TIMEOUT_S', TIMEOUT_S)
    bag = tmp_path / 'in' / 'bag'
    bag.mkdir(parents=True)
    (bag / 'metadata.yaml').write_text('x: 1\n')
    params = tmp_path / 'p.yaml'
    params.write_text('/**:\n  ros__parameters:\n    vehicle.sprung_mass: 5000.0\n')
    return [str(tmp_path / 'in'), '--params-file', str(params), '--output',
            str(tmp_path / 'out')]


GARBAGE = b'HTTP/1.0 200 OK\r\n\r\n' + bytes(range(256)) * 4
HUGE = (2**40).to_bytes(8, 'little') + b'\x00' * 64           # declares a 1 TiB frame


@pytest.mark.parametrize('server, text', [
    (b'', 'no Dask handshake'),
    (GARBAGE, 'not a Dask scheduler'),
    (HUGE, 'not a Dask scheduler'),
], indirect=['server'])
def test_a_tcp_service_that_is_not_dask(server, fleet_args, tmp_path, capsys, text):
    t0 = time.monotonic()
    rc = estimate_fleet.main(fleet_args + ['--scheduler', f'tcp://127.0.0.1:{server.port}'])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and text in err[0], err
    assert 'Traceback' not in err[0]
    assert time.monotonic() - t0 < 10 * TIMEOUT_S + 5.0
    assert not (tmp_path / 'out').exists()


@pytest.mark.parametrize('address, text', [
    ('tls://127.0.0.1:{port}', 'tls://'),
    ('inproc://127.0.0.1/123/1', 'inproc://'),
    ('nosuch://127.0.0.1:{port}', 'nosuch://'),
])
def test_addresses_another_process_cannot_use(fleet_args, tmp_path, capsys, address, text):
    s = Server(b'')
    try:
        rc = estimate_fleet.main(fleet_args + ['--scheduler', address.format(port=s.port)])
    finally:
        s.close()
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and text in err[0], err
    assert 'Traceback' not in err[0]
    assert not (tmp_path / 'out').exists()


def test_a_real_scheduler_passes_the_probe_and_a_worker_does_not(monkeypatch):
    import asyncio

    from distributed import Scheduler, Worker

    monkeypatch.setattr(fleet_dask, 'CONNECT_TIMEOUT_S', 10.0)

    async def serve():
        async with Scheduler(host='127.0.0.1', port=0, dashboard_address=None) as sched:
            async with Worker(sched.address, host='127.0.0.1', nthreads=1) as worker:
                loop = asyncio.get_running_loop()
                await loop.run_in_executor(None, fleet_dask.probe_scheduler, sched.address)
                try:
                    await loop.run_in_executor(None, fleet_dask.probe_scheduler,
                                               worker.address)
                except FleetError as err:
                    return str(err)
        return ''

    assert 'not a Dask scheduler (it says it is a Worker' in asyncio.run(serve())
    with pytest.raises(FleetError, match='cannot reach'):
        with socket.socket() as free:
            free.bind(('127.0.0.1', 0))
            port = free.getsockname()[1]
        fleet_dask.probe_scheduler(f'tcp://127.0.0.1:{port}')
