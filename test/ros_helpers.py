"""Helpers for launch-free node tests: spin until a condition holds, with a timeout."""
from __future__ import annotations

import time
from typing import Callable


def spin_until(executor, condition: Callable[[], bool], timeout_s: float = 10.0,
               step_s: float = 0.01) -> bool:
    """Spin ``executor`` until ``condition()`` is true; False if ``timeout_s`` passes first."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return True
        executor.spin_once(timeout_sec=step_s)
    return condition()
