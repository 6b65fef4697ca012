"""Speed, acceleration and jerk of a command stream, as a robot's controller measures them."""

from __future__ import annotations

import numpy as np


def divided_differences(t_ns: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Speed, acceleration and jerk (1!, 2!, 3! times the divided differences) of samples q at stamps t_ns."""
    t_ns = np.asarray(t_ns, dtype=np.int64)
    t = (t_ns - t_ns[0]) / 1e9  # difference integer nanoseconds first: epoch seconds lose ~1e-7 s in float64
    v = np.diff(q, axis=0) / np.diff(t)[:, None]
    f2 = np.diff(v, axis=0) / (t[2:] - t[:-2])[:, None]
    f3 = np.diff(f2, axis=0) / (t[3:] - t[:-3])[:, None]
    return v, 2.0 * f2, 6.0 * f3


def runs(t_ns: np.ndarray, gap_ns: int) -> list[slice]:
    """The runs of a command stream: stamps more than gap_ns apart start a new one (after such a pause
    the commands start again from rest, so each run is measured alone)."""
    breaks = np.flatnonzero(np.diff(np.asarray(t_ns, dtype=np.int64)) > gap_ns) + 1
    edges = [0, *breaks.tolist(), len(t_ns)]
    return [slice(a, b) for a, b in zip(edges, edges[1:]) if b > a]
