"""The rule a servo-mode arm judges a command stream by: acceleration and jerk of the commands, by divided
differences on the instants they are meant for (the commands' stamps).

A servo-mode xArm runs each target at once with no smoothing of its own, so a stream it should not follow
is one whose commands accelerate or jerk a joint past its limits. `ServoStreamRule` is that judgement, in
one place: the simulated arm faults by it (devices/teleprev_devices/sim/arm.py), and the xArm plugin
refuses by it before a command leaves the host, so no command reaches a controller outside its limits.

    rule = ServoStreamRule(joint_names, max_acceleration=10.0, max_jerk=500.0, period_ns=10_000_000)
    broken = rule.check(stamp_ns, target, lambda: (q_now, v_now))   # None, or what the command breaks
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

FAULT_TOLERANCE = 0.10  # a command over the acceleration or jerk limit by more than this breaks the rule
STREAM_GAP_NS = 60_000_000  # commands further apart than this start a new stream (from the arm as it is: at rest)


@dataclass(frozen=True)
class ServoViolation:
    """What one command broke: `what` is "accelerates" or "jerks"."""

    stamp_ns: int
    joint: str
    what: str
    value: float
    limit: float
    unit: str

    def describe(self) -> str:
        return (f"the command stamped {self.stamp_ns / 1e9:.3f} s {self.what} {self.joint} at {self.value:.4g} "
                f"{self.unit} (limit {self.limit:g} + {FAULT_TOLERANCE:.0%})")


class ServoStreamRule:
    """Acceleration and jerk of a command stream by divided differences over its last four commands.

    A stream starts (first command, or one more than STREAM_GAP_NS after the last) from the arm as it is,
    extrapolated back at its velocity one `period_ns` apart; after a pause that is at rest on the last
    command (servo mode ran it at once), whatever `state()` says.
    """

    def __init__(self, joint_names: tuple[str, ...], max_acceleration: float, max_jerk: float, period_ns: int):
        self.joint_names = joint_names
        self.max_acceleration = max_acceleration
        self.max_jerk = max_jerk
        self.period_ns = period_ns
        self._history: deque[tuple[int, np.ndarray]] = deque(maxlen=3)  # the last commands (stamp, positions)

    def reset(self) -> None:
        self._history.clear()

    def check(self, stamp_ns: int, target: np.ndarray,
              state: Callable[[], tuple[np.ndarray, np.ndarray]]) -> ServoViolation | None:
        """None, or what this command breaks; `state()` gives the arm's (positions, velocities) when a
        stream starts. The command joins the history either way."""
        h = self._history
        if not h or stamp_ns - h[-1][0] > STREAM_GAP_NS:
            if h:
                q, v = h[-1][1].copy(), np.zeros_like(h[-1][1])
            else:
                q, v = (np.asarray(a, dtype=float).copy() for a in state())
            h.clear()
            for k in (3, 2, 1):
                h.append((stamp_ns - k * self.period_ns, q - v * (k - 1) * self.period_ns / 1e9))
        if stamp_ns <= h[-1][0]:
            return None
        t = [(s - stamp_ns) / 1e9 for s, _ in h] + [0.0]  # differences of integer ns: epoch seconds lose ~1e-7 s
        q = [p for _, p in h] + [np.asarray(target, dtype=float)]
        f1 = [(q[i + 1] - q[i]) / (t[i + 1] - t[i]) for i in range(3)]
        f2 = [(f1[i + 1] - f1[i]) / (t[i + 2] - t[i]) for i in range(2)]
        f3 = (f2[1] - f2[0]) / (t[3] - t[0])
        h.append((stamp_ns, q[-1]))
        for what, value, limit, unit in (("accelerates", 2.0 * f2[1], self.max_acceleration, "rad/s^2"),
                                         ("jerks", 6.0 * f3, self.max_jerk, "rad/s^3")):
            j = int(np.argmax(np.abs(value)))
            if abs(value[j]) > limit * (1.0 + FAULT_TOLERANCE):
                return ServoViolation(stamp_ns, self.joint_names[j], what, float(abs(value[j])), limit, unit)
        return None
