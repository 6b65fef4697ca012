"""Where a controller starts a command stream after it was reset: the arm's measured state.

A servo controller that faulted and was cleared (its device reconnected: a "connected" device event)
starts the next stream from where the arm stands, not from the last command it ran before the fault; a
session's first stream starts there too. `teleprev audit` and `teleprev eval` measure such runs from
there (teleprev/pipeline/derivatives.py: stream_peaks's `rests`), as the controller does.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class ActuatorHistory:
    """One actuator's measured states (stamps, positions in the commands' joint order) and the times its
    device (re)connected."""

    state_ns: list[int] = field(default_factory=list)
    state_q: list[np.ndarray] = field(default_factory=list)
    connects_ns: list[int] = field(default_factory=list)

    def add_state(self, stamp_ns: int, positions: np.ndarray) -> None:
        self.state_ns.append(int(stamp_ns))
        self.state_q.append(np.asarray(positions, dtype=float))

    def add_states(self, stamps_ns: list[int], positions: np.ndarray) -> None:
        """add_state of each stamp and row of positions, in order."""
        self.state_ns.extend(int(t) for t in stamps_ns)
        self.state_q.extend(positions)

    def rests(self, k: int, start_ns: int, last: np.ndarray | None, previous_end_ns: int | None = None):
        """stream_peaks's `rests`: the measured state at a run's start where the controller starts there
        (the first run; a run after a reconnect), else None (from rest on the last command)."""
        if k > 0 and not any(previous_end_ns is None or previous_end_ns < c <= start_ns for c in self.connects_ns):
            return None
        i = int(np.searchsorted(self.state_ns, start_ns, side="right")) - 1
        return self.state_q[i] if i >= 0 else None

    def for_stream(self, t_ns: np.ndarray):
        """`rests` for the command stream at stamps t_ns (each run's previous end from the stream)."""
        from teleprev.pipeline.derivatives import runs

        pieces = runs(t_ns)
        ends = [None] + [int(t_ns[p.stop - 1]) for p in pieces[:-1]]
        return lambda k, start_ns, last: self.rests(k, start_ns, last, ends[k])
