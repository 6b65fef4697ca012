"""Speed, acceleration and jerk of a command stream, as a robot's controller measures them: the one
definition that `teleprev audit`, `teleprev eval` and the benches use.

    speed          1! x the first divided difference on the command stamps
    acceleration   2! x the second
    jerk           3! x the third

A stream is split where its commands are more than RESUME_GAP_NS apart (a pause). A servo-mode controller
takes the first command after a pause, and the first of all, as the start of a new stream from the arm at
rest where it stands (sim.arm does, and so does teleprev.devices.ServoStreamRule): so each run is measured
from three commands at rest on the last command before it, one controller cycle (RESUME_PERIOD_NS) apart,
ahead of its own. Where the stream's caller knows better (`rests`: the arm's measured state where its
controller was reset in the pause, or before the first run), that is where the run starts from. A stream that resumes
with a jump reads as
the acceleration the controller sees. A dataset's actions are no command stream a controller starts: they
are measured per episode without that lead-in (`from_rest=False`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

RESUME_GAP_NS = 60_000_000  # commands further apart than this: the arm has stopped at the last one
RESUME_PERIOD_NS = 10_000_000  # a servo controller's cycle (sim.arm's state period): the lead-in's spacing


def divided_differences(t_ns: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Speed, acceleration and jerk (1!, 2!, 3! times the divided differences) of samples q at stamps t_ns."""
    t_ns = np.asarray(t_ns, dtype=np.int64)
    t = (t_ns - t_ns[0]) / 1e9  # difference integer nanoseconds first: epoch seconds lose ~1e-7 s in float64
    v = np.diff(q, axis=0) / np.diff(t)[:, None]
    f2 = np.diff(v, axis=0) / (t[2:] - t[:-2])[:, None]
    f3 = np.diff(f2, axis=0) / (t[3:] - t[:-3])[:, None]
    return v, 2.0 * f2, 6.0 * f3


def runs(t_ns: np.ndarray, gap_ns: int = RESUME_GAP_NS) -> list[slice]:
    """The runs of a command stream: stamps more than gap_ns apart start a new one."""
    breaks = np.flatnonzero(np.diff(np.asarray(t_ns, dtype=np.int64)) > gap_ns) + 1
    edges = [0, *breaks.tolist(), len(t_ns)]
    return [slice(a, b) for a, b in zip(edges, edges[1:]) if b > a]


@dataclass(frozen=True)
class StreamPeaks:
    """Per joint, the largest speed, acceleration and jerk a stream reaches (zeros where too short)."""

    speed: np.ndarray
    acceleration: np.ndarray
    jerk: np.ndarray
    runs: int = 0

    def worst(self) -> tuple[float, float, float]:
        return float(self.speed.max(initial=0.0)), float(self.acceleration.max(initial=0.0)), float(
            self.jerk.max(initial=0.0))


def stream_peaks(t_ns: np.ndarray, q: np.ndarray, from_rest: bool = True, gap_ns: int = RESUME_GAP_NS,
                 rests=None, window: tuple[int, int] | None = None) -> StreamPeaks:
    """The speed, acceleration and jerk peaks of commands q (N, joints) at stamps t_ns (sorted), each run
    measured alone and (from_rest) from rest where the stream stood (see the module docstring);
    `rests(k, start_ns, last)`: where run k (starting at start_ns, after the command `last`, None for the
    first) starts from instead, or None. `window` (lo, hi): only the differences that end at a command
    stamped in [lo, hi) count (an episode of a longer stream, measured as the stream ran)."""
    t_ns = np.asarray(t_ns, dtype=np.int64)
    q = np.asarray(q, dtype=float).reshape(len(t_ns), -1)
    width = q.shape[1]
    peaks = [np.zeros(width), np.zeros(width), np.zeros(width)]
    pieces = runs(t_ns, gap_ns)
    last = None
    for k, run in enumerate(pieces):
        t, x = t_ns[run], q[run]
        before = rests(k, int(t[0]), last) if rests is not None else None
        if before is None:
            before = x[0] if last is None else last
        if from_rest:
            lead = t[0] - RESUME_PERIOD_NS * np.arange(3, 0, -1, dtype=np.int64)
            t, x = np.concatenate([lead, t]), np.concatenate([np.repeat(before[None], 3, axis=0), x])
        last = x[-1]
        if len(t) < 2:
            continue
        for k, values in enumerate(divided_differences(t, x)):
            if window is not None:
                ends = t[k + 1:]
                values = values[(ends >= window[0]) & (ends < window[1])]
            if len(values):
                peaks[k] = np.maximum(peaks[k], np.abs(values).max(axis=0))
    return StreamPeaks(*peaks, runs=len(pieces))
