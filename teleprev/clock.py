"""The one session clock, and the conversion of a device's own timestamps onto it.

Session time is integer nanoseconds since the Unix epoch (so Foxglove shows wall-clock time), advanced by
the monotonic clock after the session starts (so it never jumps backwards with NTP).
"""

from __future__ import annotations

import time
from collections import deque


class SessionClock:
    def __init__(self, start_ns: int | None = None):
        self._mono0 = time.monotonic_ns()
        self.start_ns = time.time_ns() if start_ns is None else start_ns

    def now_ns(self) -> int:
        return self.start_ns + (time.monotonic_ns() - self._mono0)

    def from_monotonic(self, mono_ns: int) -> int:
        """A time.monotonic_ns() reading on the session clock."""
        return self.start_ns + (mono_ns - self._mono0)


class ClockSync:
    """Maps a device clock onto the session clock from (device time, host receive time) pairs.

    The offset is the smallest (receive - device) over a sliding window: the message that travelled
    fastest carries the least transport delay, so the minimum tracks offset + minimum latency and ignores
    jitter. `latency_ns` is the device's known minimum transport latency, subtracted from the estimate.
    A window of a few seconds follows slow drift between the clocks.
    """

    def __init__(self, window: int = 256, latency_ns: int = 0):
        self._diffs: deque[int] = deque(maxlen=window)
        self._min: int | None = None
        self.latency_ns = latency_ns

    def observe(self, device_ns: int, receive_ns: int) -> int:
        """Record one pair and return the device time converted to the session clock."""
        d = receive_ns - device_ns
        if len(self._diffs) == self._diffs.maxlen:
            dropped = self._diffs[0]
            self._diffs.append(d)
            if dropped == self._min:
                self._min = min(self._diffs)
            elif d < self._min:
                self._min = d
        else:
            self._diffs.append(d)
            self._min = d if self._min is None else min(self._min, d)
        return self.to_session(device_ns)

    def to_session(self, device_ns: int) -> int:
        if self._min is None:
            raise ValueError("ClockSync has no observations yet")
        return device_ns + self._min - self.latency_ns
