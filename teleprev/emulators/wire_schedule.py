"""Lateness at the wire: each servo target's arrival at the emulated box against the instant its sender planned
to send it.

The box stamps every target on arrival (ServoCycle.arrivals, time.monotonic_ns()); it cannot know when a
target was meant to leave, so the sender keeps its own schedule, one PlannedSend per target it sent, and
`lateness_ns` pairs the two. Targets cross the wire as float32 (xarm_wire), so a planned target matches an
arrival whose float32 values are the same, in the order both were sent: a target the sender planned but
never sent (refused before it left) matches nothing and is left out.

A sender on the session clock (the paced command sender plans each tick's `due` on it) converts with
`from_session_clock`, since the box stamps on the machine's monotonic clock.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from teleprev.emulators.xarm_servo import Arrival

SEARCH_AHEAD = 64  # arrivals looked through for a planned target (others: targets of another client)


@dataclass(frozen=True)
class PlannedSend:
    """One target as its sender planned it: the instant it was due to leave (time.monotonic_ns()) and what."""

    due_ns: int
    target: np.ndarray


def from_session_clock(clock, due_session_ns: int, target) -> PlannedSend:
    """A target planned on a teleprev.clock.SessionClock (its `due` tick instant), on the box's clock."""
    return PlannedSend(due_session_ns - clock.from_monotonic(0), np.asarray(target, dtype=float))


def lateness_ns(planned: Iterable[PlannedSend], arrivals: Sequence[Arrival]) -> list[int]:
    """For every planned target that reached the box: its arrival time minus the time it was due, in order."""
    wire = [np.asarray(a.target, dtype=np.float32) for a in arrivals]
    out, k = [], 0
    for plan in planned:
        sent = np.asarray(plan.target, dtype=np.float32)
        for j in range(k, min(k + SEARCH_AHEAD, len(wire))):
            if wire[j].shape == sent.shape and np.array_equal(wire[j], sent):
                out.append(arrivals[j].received_ns - plan.due_ns)
                k = j + 1
                break
    return out
