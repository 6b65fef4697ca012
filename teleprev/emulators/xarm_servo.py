"""The emulated xArm's servo mode (mode 1): a servo cycle that runs only the latest target, judged on the times
the targets arrived, since the box has no other clock for them.

A servo cycle of `period_s` runs only the latest target that arrived in it (a burst is one jump); each
target that runs is judged against the ones that ran before it: a joint faster than its limit (pi rad/s,
10% margin) is error 24, the flange faster than `max_tcp_speed_mm_s` is error 60 ("Linear speed exceeded
limit in servo_j mode", xarm x_code ControllerError 60). Acceleration and jerk have no controller error code;
they are judged on the same arrivals and counted as jolts, the figures a real arm feels.

Every target's arrival is stamped (`arrivals`), so a bench can compute arrival gaps, lateness and targets per
servo cycle.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from teleprev.devices.servo_limits import STREAM_GAP_NS
from teleprev.emulators import xarm_wire as wire
from teleprev.emulators.xarm_kinematics import ArmKinematics

SERVO_PERIOD_S = 0.004  # the box's servo cycle: 250 Hz, UFactory's maximum command rate on port 502
SPEED_TOLERANCE = 0.10
MAX_TCP_SPEED_MM_S = 1000.0  # xArm6 / xArm7 maximum TCP speed, 1 m/s (UFactory specifications)
MAX_ACCELERATION, MAX_JERK = 10.0, 500.0  # rad/s^2, rad/s^3: what jolts are counted against (no error code)
IDLE_AFTER_S = 0.2  # a servo-mode arm with no new target for this long reports READY again
KEPT = 200_000  # records kept of each kind


@dataclass(frozen=True)
class ReceivedCommand:
    received_ns: int  # time.monotonic_ns() when the controller read it
    target: np.ndarray


@dataclass(frozen=True)
class Arrival:
    """A servo target as it reached the box: when, in which servo cycle, and whether it was taken."""

    received_ns: int
    cycle: int
    target: np.ndarray
    taken: bool  # False: the arm was not ready, or it faulted on it


@dataclass(frozen=True)
class Judgement:
    """How one target that ran compared with the one before it, on arrival times: each ratio is the value
    over its limit (speed: the fastest joint over its speed limit)."""

    received_ns: int
    speed_ratio: float
    accel_ratio: float
    jerk_ratio: float
    tcp_speed_mm_s: float


@dataclass(frozen=True)
class ServoFault:
    """A target the arm must not follow: the controller error it latches."""

    code: int
    what: str


@dataclass(frozen=True)
class Ran:
    """A target the arm now runs, and the joint speeds it runs at."""

    target: np.ndarray
    speeds: np.ndarray


@dataclass(frozen=True)
class _Point:
    """A target that ran: when it arrived, in which cycle."""

    received_ns: int
    cycle: int
    q: np.ndarray


class ServoCycle:
    def __init__(self, kinematics: ArmKinematics, lower: np.ndarray, upper: np.ndarray,
                 period_s: float = SERVO_PERIOD_S, max_tcp_speed_mm_s: float = MAX_TCP_SPEED_MM_S):
        self.kinematics = kinematics
        self.lower, self.upper = lower, upper
        self.max_speed = kinematics.velocity_limit()
        self.period_ns = int(period_s * 1e9)
        self.max_tcp_speed_mm_s = max_tcp_speed_mm_s
        self._ran: deque[_Point] = deque(maxlen=4)
        self.last_ran_ns = 0
        self.commands: deque[ReceivedCommand] = deque(maxlen=KEPT)  # servo targets taken
        self.arrivals: deque[Arrival] = deque(maxlen=KEPT)  # every servo target that reached the box
        self.judged: deque[Judgement] = deque(maxlen=KEPT)
        self.jolts = 0  # targets that ran past the acceleration or jerk limit
        self.superseded = 0  # targets replaced by a later one in the same servo cycle, never run

    def cycle(self, now_ns: int) -> int:
        return now_ns // self.period_ns

    def reset(self) -> None:
        """A mode change: the next target starts a stream from rest."""
        self._ran.clear()

    def quiet(self, now_ns: int) -> bool:
        """No target has run for IDLE_AFTER_S."""
        return now_ns - self.last_ran_ns > IDLE_AFTER_S * 1e9

    def refuse(self, target: np.ndarray, now_ns: int) -> None:
        """A target the arm was not ready for: stamped, not run."""
        self.arrivals.append(Arrival(now_ns, self.cycle(now_ns), target, False))

    def run(self, target: np.ndarray, now_ns: int, at: np.ndarray) -> Ran | ServoFault:
        """Take a target for this servo cycle (a later one in the same cycle replaces it), the arm being at
        `at`; judged on arrival times against the targets that ran before."""
        cycle = self.cycle(now_ns)
        outside = (target < self.lower - 1e-6) | (target > self.upper + 1e-6)
        if outside.any():
            j = int(np.argmax(outside))
            self.arrivals.append(Arrival(now_ns, cycle, target, False))
            return ServoFault(wire.JOINT_LIMIT, f"joint{j + 1} target {target[j]:.4f} outside "
                                                f"[{self.lower[j]:.4f}, {self.upper[j]:.4f}]")
        if self._ran and self._ran[-1].cycle == cycle:  # only the latest target of a cycle runs
            self._ran.pop()
            self.superseded += 1
        if not self._ran or now_ns - self._ran[-1].received_ns > STREAM_GAP_NS:  # a stream starts at rest
            self._ran.clear()
            self._ran.append(_Point(now_ns - self.period_ns, cycle - 1, at.copy()))
        while len(self._ran) < 3:  # at rest before the stream's first target
            first = self._ran[0]
            self._ran.appendleft(_Point(first.received_ns - self.period_ns, first.cycle - 1, first.q))
        judged = self._judge(now_ns, target)
        self.arrivals.append(Arrival(now_ns, cycle, target, not isinstance(judged, ServoFault)))
        if isinstance(judged, ServoFault):
            return judged
        self.commands.append(ReceivedCommand(now_ns, target))
        self.judged.append(judged)
        last = self._ran[-1]
        speeds = (target - last.q) / max((now_ns - last.received_ns) / 1e9, self.period_ns / 1e9)
        self._ran.append(_Point(now_ns, cycle, target))
        self.last_ran_ns = now_ns
        return Ran(target, speeds)

    def _judge(self, now_ns: int, target: np.ndarray) -> Judgement | ServoFault:
        """The target against the three that ran before it (divided differences on arrival times); a
        ServoFault when it faults the arm (speed: error 24, flange speed: error 60)."""
        before = list(self._ran)[-3:]
        t = [(p.received_ns - now_ns) / 1e9 for p in before] + [0.0]
        q = [p.q for p in before] + [target]
        dt = max(-t[2], self.period_ns / 1e9)  # a target runs for at least one servo cycle
        speed = np.abs(q[3] - q[2]) / dt
        ratio = speed / self.max_speed
        if ratio.max() > 1.0 + SPEED_TOLERANCE:
            j = int(np.argmax(ratio))
            return ServoFault(wire.SPEED_LIMIT, f"joint{j + 1} commanded at {speed[j]:.3g} rad/s "
                                                f"(limit {self.max_speed[j]:g})")
        flange = self.kinematics.flange
        tcp_speed = float(np.linalg.norm(flange(q[3])[:3, 3] - flange(q[2])[:3, 3])) * 1000.0 / dt
        if tcp_speed > self.max_tcp_speed_mm_s * (1.0 + SPEED_TOLERANCE):
            return ServoFault(wire.SERVO_TCP_SPEED, f"linear speed {tcp_speed:.0f} mm/s "
                                                    f"(limit {self.max_tcp_speed_mm_s:g} mm/s)")
        t[2] = -dt if t[2] > -dt else t[2]
        f1 = [(q[i + 1] - q[i]) / max(t[i + 1] - t[i], 1e-6) for i in range(3)]
        f2 = [(f1[i + 1] - f1[i]) / max(t[i + 2] - t[i], 1e-6) for i in range(2)]
        f3 = (f2[1] - f2[0]) / max(t[3] - t[0], 1e-6)
        accel = float(np.max(np.abs(2.0 * f2[1]))) / MAX_ACCELERATION
        jerk = float(np.max(np.abs(6.0 * f3))) / MAX_JERK
        if max(accel, jerk) > 1.0 + SPEED_TOLERANCE:
            self.jolts += 1
        return Judgement(now_ns, float(ratio.max()), accel, jerk, tcp_speed)
