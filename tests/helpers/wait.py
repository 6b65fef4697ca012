"""One way for a test to wait for something that happens on another thread or process.

A test that sleeps a fixed time and then asserts passes on a quiet machine and fails on a busy one;
`wait_until` polls the condition instead and, when the time runs out, fails naming what it waited for
and the last value it saw, so a flaky wait reads as the timeout it is.
"""

from __future__ import annotations

import time
from collections.abc import Callable


class WaitTimeout(AssertionError):
    """The condition did not hold within the time given."""


def wait_until[T](condition: Callable[[], T], timeout_s: float = 10.0, *, what: str = "", poll_s: float = 0.01) -> T:
    """Poll `condition` until it returns something truthy and return that; fail after `timeout_s`."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() >= deadline:
            name = what or getattr(condition, "__name__", "condition")
            raise WaitTimeout(f"waited {timeout_s:g} s for {name}; last value {value!r}")
        time.sleep(poll_s)
