"""Pacing read(): wait for the next sample to come due, never past read()'s timeout."""

from __future__ import annotations

import time

from teleprev.clock import SessionClock


def wait_until_due(clock: SessionClock, due_ns: int, timeout_s: float) -> bool:
    """Sleep until `due_ns` on the session clock and return True; if that is more than timeout_s away,
    sleep timeout_s and return False (read() then returns no samples, and is called again)."""
    wait = (due_ns - clock.now_ns()) / 1e9
    if wait > timeout_s:
        time.sleep(timeout_s)
        return False
    if wait > 0:
        time.sleep(wait)
    return True
