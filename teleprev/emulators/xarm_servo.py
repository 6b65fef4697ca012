"""The emulated xArm's servo mode (mode 1): targets run on the box's own servo cycle, the latest one each cycle,
and are judged as the box runs them, on that cycle's clock, not on the client's stamps (the box has none).

What a real box does (UFactory, "Robot Arm Servo Mode Usage Guide", docs.supportarticle.ufactory.cc; xArm
user manual 2.1.2 "Mode 1: Servoj mode"; XArmAPI.set_servo_angle_j's docstring, xarm-python-sdk 1.18):
- servoj "moves to the given joint position with the fastest joint speed (180°/s) and acceleration"; "these
  commands do not set buffers and only execute the latest received target point";
- the controller takes commands at 250 Hz at most, "if the command frequency exceeds 250 Hz, redundant
  commands will be lost": a 4 ms servo cycle that runs the latest target it holds;
- the client must send "at a fixed frequency with interpolated smooth trajectory points"; the box does no
  planning of its own, so the stream's own smoothness is what the motors get;
- a joint past its speed is error 24 "Speed Exceeds Limit", the flange past its linear speed in servo mode is
  error 60 "Linear speed exceeded limit in servo_j mode. Linear speed limit is {} mm/s" (xarm/core/config/
  x_code.py ControllerError); the SDK's TCP speed range is 0.1-1000 mm/s (xarm/x3/base.py _max_tcp_speed).

How this box runs a stream: each target runs at the servo cycle it arrived in (`cycle`); a second target in
the same cycle replaces the first, which never runs, so a burst is one jump. The motors move from target to
target at the stream's pace: the box's clock sees a steady stream as a steady number of servo cycles per
target, and the motors only act at cycle boundaries, so when within a cycle a target arrived (the network's
and the host's jitter: 0.1 ms quiet, gaps of 7.5-9.2 ms at 8.33 ms under the realtime bench's load) never
reaches them. The pace is the stream's period as a least-squares line through the arrivals of its last
PACE_WINDOW steady targets. Their mean gap is that line through the window's two end points alone, so each
new arrival moved it by its own jitter / PACE_WINDOW: a pace that wobbles by ~0.02 ms from target to target,
which third-differenced at 2 rad/s read as 1.4-1.55x the jerk limit on a stream whose stamps were within it
(tests/devices/test_xarm_servo_cycle.py); the line's slope moves ~10x less. A steady stream's pace is the
same either way. A target that arrives more than one servo cycle off the pace is judged on what the motors
did with it: after a stall the arm stood on the last target until this one came, then went on (a stop
and a start, and a burst's last target one jump); a late target with the next close behind leaves the next
the whole cycles it had (one cycle: 8 ms of motion in 4 ms). A stream starts from rest one servo cycle
before its first target (a first target far from the arm is a jump).

Judging 120 Hz targets on raw arrival stamps instead turns 0.1 ms of arrival jitter, third-differenced over
8.33 ms, into 5-50x the jerk limit of a stream whose stamps are within it; stamping each target with its cycle
alone (8 or 12 ms between 120 Hz targets on a 4 ms cycle) turns the beat between the two rates into a
speed ripple of +4 %/-31 % that no motor follows. Neither is what the arm does.

Each target that runs is judged against the three that ran before it (divided differences on the box's
clock): a joint faster than its limit (pi rad/s, 10% margin) is error 24, the flange faster than
`max_tcp_speed_mm_s` is error 60. Acceleration and jerk have no controller error code; they are counted as
jolts, the figures a real arm feels.

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
MAX_TCP_SPEED_MM_S = 1000.0  # servo mode's TCP speed, 1000 mm/s (servo mode guide; SDK x3/base.py _max_tcp_speed)
PACE_WINDOW = 32  # targets the stream's pace is measured over (0.27 s at 120 Hz: 0.1 ms jitter -> 0.02 ms)
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
    """A target that ran: when it arrived, in which cycle, and when the motors reached it on the box's clock."""

    received_ns: int
    cycle: int
    q: np.ndarray
    ran_ns: int
    paced: bool = False  # its arrival gap is in the pace window
    at_rest: bool = False  # the arm at rest before a stream's first target
    held: bool = False  # the arm standing on the last target through a stall


class ServoCycle:
    def __init__(self, kinematics: ArmKinematics, lower: np.ndarray, upper: np.ndarray,
                 period_s: float = SERVO_PERIOD_S, max_tcp_speed_mm_s: float = MAX_TCP_SPEED_MM_S):
        self.kinematics = kinematics
        self.lower, self.upper = lower, upper
        self.max_speed = kinematics.velocity_limit()
        self.period_ns = int(period_s * 1e9)
        self.max_tcp_speed_mm_s = max_tcp_speed_mm_s
        self._ran: deque[_Point] = deque(maxlen=4)
        self._gaps: deque[int] = deque(maxlen=PACE_WINDOW)  # arrival gaps (ns) of the stream's steady targets
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
        self._gaps.clear()

    def quiet(self, now_ns: int) -> bool:
        """No target has run for IDLE_AFTER_S."""
        return now_ns - self.last_ran_ns > IDLE_AFTER_S * 1e9

    def refuse(self, target: np.ndarray, now_ns: int) -> None:
        """A target the arm was not ready for: stamped, not run."""
        self.arrivals.append(Arrival(now_ns, self.cycle(now_ns), target, False))

    def run(self, target: np.ndarray, now_ns: int, at: np.ndarray) -> Ran | ServoFault:
        """Take a target for this servo cycle (a later one in the same cycle replaces it), the arm being at
        `at`; judged on the box's clock against the targets that ran before."""
        cycle = self.cycle(now_ns)
        outside = (target < self.lower - 1e-6) | (target > self.upper + 1e-6)
        if outside.any():
            j = int(np.argmax(outside))
            self.arrivals.append(Arrival(now_ns, cycle, target, False))
            return ServoFault(wire.JOINT_LIMIT, f"joint{j + 1} target {target[j]:.4f} outside "
                                                f"[{self.lower[j]:.4f}, {self.upper[j]:.4f}]")
        if self._ran and self._ran[-1].cycle == cycle:  # only the latest target of a cycle runs
            if self._ran.pop().paced:
                self._gaps.pop()
            self.superseded += 1
        if not self._ran or now_ns - self._ran[-1].received_ns > STREAM_GAP_NS:  # a stream starts at rest
            self._ran.clear()
            self._gaps.clear()
            rest_ns = now_ns - self.period_ns
            self._ran.append(_Point(rest_ns, cycle - 1, at.copy(), rest_ns, at_rest=True))
        while len(self._ran) < 3:  # at rest before the stream's first target
            first = self._ran[0]
            self._ran.appendleft(_Point(first.received_ns - self.period_ns, first.cycle - 1, first.q,
                                        first.ran_ns - self.period_ns, at_rest=True))
        step_ns, paced = self._step_ns(now_ns, cycle)
        ran_ns = self._ran[-1].ran_ns + step_ns
        judged = self._judge(now_ns, ran_ns, target)
        self.arrivals.append(Arrival(now_ns, cycle, target, not isinstance(judged, ServoFault)))
        if isinstance(judged, ServoFault):
            if paced:
                self._gaps.pop()
            return judged
        self.commands.append(ReceivedCommand(now_ns, target))
        self.judged.append(judged)
        last = self._ran[-1]
        speeds = (target - last.q) / ((ran_ns - last.ran_ns) / 1e9)
        self._ran.append(_Point(now_ns, cycle, target, ran_ns, paced))
        self.last_ran_ns = now_ns
        return Ran(target, speeds)

    def _step_ns(self, now_ns: int, cycle: int) -> tuple[int, bool]:
        """How long after the target before it the motors reach this one, on the box's clock, and whether
        this target's gap counts towards the pace. The stream's pace, when it arrived within a cycle of it;
        one cycle for a stream's first target (from rest); the whole cycles it had when it came early (a late
        target with the next close behind). After a stall the arm stood on the last target: that hold is
        recorded, and this target is reached one pace after it."""
        last = self._ran[-1]
        if last.at_rest:
            return self.period_ns, False
        if last.held:
            return self._pace_ns(), False
        gap_ns = now_ns - last.received_ns
        if not self._gaps or abs(gap_ns - self._pace_ns()) <= self.period_ns:
            self._gaps.append(gap_ns)
            return self._pace_ns(), True
        if gap_ns < self._pace_ns():
            return max(cycle - last.cycle, 1) * self.period_ns, False
        pace_ns = self._pace_ns()
        held_ns = (cycle - last.cycle) * self.period_ns
        self._ran.append(_Point(last.received_ns, last.cycle, last.q, last.ran_ns + held_ns - pace_ns, held=True))
        return pace_ns, False

    def _pace_ns(self) -> int:
        """The slope of the least-squares line through the window's arrivals (the gaps' running sums)."""
        if not self._gaps:
            return self.period_ns
        arrived = np.concatenate(([0.0], np.cumsum(np.fromiter(self._gaps, dtype=float))))
        k = np.arange(len(arrived), dtype=float)
        k -= k.mean()
        return max(int(np.dot(k, arrived) / np.dot(k, k)), self.period_ns)

    def _judge(self, now_ns: int, ran_ns: int, target: np.ndarray) -> Judgement | ServoFault:
        """The target, reached at `ran_ns` on the box's clock, against the three that ran before it (divided
        differences on that clock); a ServoFault when it faults the arm (speed: error 24, flange speed:
        error 60)."""
        before = list(self._ran)[-3:]
        t = [(p.ran_ns - ran_ns) / 1e9 for p in before] + [0.0]
        q = [p.q for p in before] + [target]
        dt = -t[2]
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
        f1 = [(q[i + 1] - q[i]) / (t[i + 1] - t[i]) for i in range(3)]
        f2 = [(f1[i + 1] - f1[i]) / (t[i + 2] - t[i]) for i in range(2)]
        f3 = (f2[1] - f2[0]) / (t[3] - t[0])
        accel = float(np.max(np.abs(2.0 * f2[1]))) / MAX_ACCELERATION
        jerk = float(np.max(np.abs(6.0 * f3))) / MAX_JERK
        if max(accel, jerk) > 1.0 + SPEED_TOLERANCE:
            self.jolts += 1
        return Judgement(now_ns, float(ratio.max()), accel, jerk, tcp_speed)
