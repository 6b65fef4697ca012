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

    Once locked, a pair that would pull the offset down by more than `outlier_ns` (a stamp from the
    future, a sender that glitched) is an outlier: it is mapped with the current offset and kept out of
    the window, so one bad stamp cannot drag every later sample off until it leaves the window.
    `rejected` counts them and `last_rejected_ns` is the receive time of the latest. `relock_after` pairs
    in a row that agree with each other and sit more than `outlier_ns` away from the offset (below it, or
    above every difference in the window) are a real clock jump (the sender restarted or was reset): the
    sync starts over from them, and `relocks` counts that.
    """

    def __init__(self, window: int = 256, latency_ns: int = 0, outlier_ns: int = 50_000_000, relock_after: int = 8,
                 lock_after: int = 4):
        self._diffs: deque[int] = deque(maxlen=window)
        self._min: int | None = None
        self.latency_ns = latency_ns
        self.outlier_ns = outlier_ns
        self.relock_after = relock_after
        self.lock_after = lock_after
        self._suspects: list[int] = []  # consecutive outliers' differences, while they agree
        self.rejected = 0
        self.relocks = 0
        self.last_rejected_ns: int | None = None

    @property
    def locked(self) -> bool:
        return len(self._diffs) >= self.lock_after

    def observe(self, device_ns: int, receive_ns: int) -> int:
        """Record one pair and return the device time converted to the session clock."""
        d = receive_ns - device_ns
        if not self.locked:
            self._add(d)
            return self.to_session(device_ns)
        ahead = d < self._min - self.outlier_ns  # the stamp ran ahead of the session clock
        behind = d > max(self._diffs) + self.outlier_ns  # late beyond any delay seen: maybe the clock went back
        if not (ahead or behind):
            self._suspects.clear()
            self._add(d)
            return self.to_session(device_ns)
        if self._suspects and abs(d - self._suspects[-1]) > self.outlier_ns:
            self._suspects.clear()
        self._suspects.append(d)
        if len(self._suspects) >= self.relock_after:
            # A jump, not a glitch: start over from the run that agreed.
            self._diffs.clear()
            self._min = None
            for s in self._suspects:
                self._add(s)
            self._suspects.clear()
            self.relocks += 1
        elif ahead:
            self.rejected += 1
            self.last_rejected_ns = receive_ns
        # else: a late delivery, mapped with the offset as any other (it could not have lowered it); kept
        # out of the window so that a run of them stays recognisable as a jump
        return self.to_session(device_ns)

    def _add(self, d: int) -> None:
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

    def to_session(self, device_ns: int) -> int:
        if self._min is None:
            raise ValueError("ClockSync has no observations yet")
        return device_ns + self._min - self.latency_ns
