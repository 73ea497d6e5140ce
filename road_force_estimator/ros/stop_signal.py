"""SIGINT/SIGTERM for our nodes: a stop request that no thread's state can lose, and a bounded
shutdown.

Python runs a signal handler in the main thread between two bytecodes, and the default
SIGINT handler raises ``KeyboardInterrupt`` there. Two ways a node lost a Ctrl-C that way
(seen under load, `test/ros/test_stop_signal.py`): a SIGINT during the process's start
raised ``KeyboardInterrupt`` inside an extension module's import, which Python turns into
an ``ImportError`` ("initialization failed") that an ``except ImportError`` fallback
swallows, and the node then ran on, deaf; and a handler never runs while the main thread
waits in C++ code that does not come back. Here the handler raises nothing and the C-level
handler also writes the signal's number to a pipe (``signal.set_wakeup_fd``) that a thread
of its own reads, whatever the main thread does:

- the first SIGINT or SIGTERM sets :func:`requested` (the node's spin loop checks it every
  turn, then finishes: publishes what is held back, closes its bag) and starts a watchdog:
  if the process has not ended :data:`GRACE_S` later, every thread's stack goes to stderr
  (what it was stuck in) and the process exits with status 1;
- a second one ends the process at once (status 130), as a second Ctrl-C does elsewhere.

:func:`install` is idempotent; the nodes' console entry points (:mod:`.launcher`) call it
before they import anything heavy, :func:`.node_runner.run_node` again (for ``python -m``).
"""
from __future__ import annotations

import faulthandler
import os
import signal
import sys
import threading

__all__ = ['GRACE_S', 'install', 'requested', 'wait', 'signals_received']

#: Seconds a node has to end after the first SIGINT/SIGTERM before the watchdog ends it
#: (status 1, every thread's stack on stderr). A node's own finish takes a few seconds at
#: most (the observer waits up to 1 s per output topic for acknowledgements).
GRACE_S = 30.0
#: Exit status of a second SIGINT/SIGTERM (128 + SIGINT, the shell's convention).
FORCED_EXIT_STATUS = 130

_stop = threading.Event()
_count = [0]
_lock = threading.Lock()
_installed = [False]


def requested() -> bool:
    """True once a SIGINT or SIGTERM has arrived."""
    return _stop.is_set()


def wait(timeout_s: float | None = None) -> bool:
    """Block until a stop is requested (True) or ``timeout_s`` passes (False)."""
    return _stop.wait(timeout_s)


def signals_received() -> int:
    """SIGINT/SIGTERM received so far."""
    return _count[0]


def _received(signum: int) -> None:
    with _lock:
        _count[0] += 1
        first = _count[0] == 1
    if first:
        _stop.set()
        # C-level: fires from its own thread even if no Python code runs again
        faulthandler.dump_traceback_later(GRACE_S, exit=True)
        return
    os.write(2, f'{signal.Signals(signum).name} again: exiting now\n'.encode())
    os._exit(FORCED_EXIT_STATUS)


def _python_handler(signum, frame) -> None:
    """The Python-level handler: nothing to do, the pipe's reader counts the signal (a
    handler must be installed for the C-level one to write to the pipe)."""


def _reader(fd: int) -> None:
    while True:
        try:
            data = os.read(fd, 64)
        except OSError:
            return
        if not data:
            return
        for signum in data:
            if signum in (signal.SIGINT, signal.SIGTERM):
                _received(signum)


def install() -> None:
    """Catch SIGINT and SIGTERM as the module says (idempotent; from the main thread)."""
    if _installed[0]:
        return
    if threading.current_thread() is not threading.main_thread():
        raise RuntimeError('stop_signal.install: call it from the main thread')
    read_fd, write_fd = os.pipe()
    os.set_blocking(write_fd, False)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _python_handler)
    signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)
    threading.Thread(target=_reader, args=(read_fd,), name='stop_signal', daemon=True).start()
    _installed[0] = True
    # the watchdog's stacks (and faulthandler's on a crash) go to stderr
    if not faulthandler.is_enabled():
        faulthandler.enable(file=sys.stderr, all_threads=True)
