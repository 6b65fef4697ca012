"""The emulated xArm's position mode (mode 0): set_servo_angle (register 23), set_position (21, by our IK) and
reset (25, move_gohome: all joints to 0) move the arm at the requested speed, one move after another; the
box is in state 1 until the last is done, then state 2 (what the SDK's wait=True polls for).
"""

from __future__ import annotations

import struct
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from teleprev.emulators import xarm_wire as wire
from teleprev.emulators.xarm_kinematics import ArmKinematics


@dataclass
class Motion:
    """A position-mode move: from `start` to `goal` in joint space over `duration_s`."""

    start: np.ndarray
    goal: np.ndarray
    duration_s: float
    began: float = field(default=0.0)


@dataclass(frozen=True)
class Where:
    """Where the moves have the arm at an instant: joint angles and speeds, and whether they are all done."""

    angles: np.ndarray
    speeds: np.ndarray
    done: bool


class PositionMoves:
    """The queue of position-mode moves, the first one running."""

    def __init__(self, kinematics: ArmKinematics, lower: np.ndarray, upper: np.ndarray):
        self.kinematics = kinematics
        self.lower, self.upper = lower, upper
        self._queue: deque[Motion] = deque()

    def __len__(self) -> int:
        return len(self._queue)

    def clear(self) -> None:
        self._queue.clear()

    def add(self, register: int, data: bytes, angles: np.ndarray, now_ns: int) -> bool:
        """Queue the move a request asks for, after the moves queued (the arm at `angles` when there are
        none); False when the box refuses it (a short request, a goal outside the joint table, no IK)."""
        dof = len(angles)
        start = self._queue[-1].goal if self._queue else angles
        if register == wire.MOVE_HOME and len(data) >= 12:
            speed = struct.unpack("<3f", data[:12])[0]
            goal = np.zeros(dof)
        elif register == wire.MOVE_JOINT and len(data) >= 40:
            values = struct.unpack("<10f", data[:40])
            goal, speed = np.array(values[:dof]), values[7]
        elif register == wire.MOVE_LINE and len(data) >= 36:
            values = struct.unpack("<9f", data[:36])
            goal = self.kinematics.solve(values[:6], start)
            if goal is None:
                return False
            flange = self.kinematics.flange(start)[:3, 3] * 1000.0
            distance_mm = float(np.linalg.norm(np.array(values[:3]) - flange))
            speed = 0.0 if values[6] <= 0 else values[6]
            self._append(start, goal, distance_mm / speed if speed > 0 else 0.0, now_ns)
            return True
        else:
            return False
        if np.any(goal < self.lower - 1e-6) or np.any(goal > self.upper + 1e-6):
            return False
        self._append(start, goal, float(np.max(np.abs(goal - start))) / speed if speed > 0 else 0.0, now_ns)
        return True

    def _append(self, start: np.ndarray, goal: np.ndarray, duration: float, now_ns: int) -> None:
        self._queue.append(Motion(np.array(start, dtype=float), np.array(goal, dtype=float), max(duration, 0.0),
                                  now_ns / 1e9 if not self._queue else 0.0))

    def advance(self, now_ns: int) -> Where | None:
        """Where the moves have the arm at `now_ns` (finished moves leave the queue); None with none queued."""
        if not self._queue:
            return None
        now = now_ns / 1e9
        while self._queue:
            m = self._queue[0]
            if not m.began:
                m.began = now
            done = 1.0 if m.duration_s <= 0 else (now - m.began) / m.duration_s
            if done < 1.0:
                return Where(m.start + (m.goal - m.start) * done, (m.goal - m.start) / m.duration_s, False)
            self._queue.popleft()
            if self._queue:
                self._queue[0].began = m.began + m.duration_s
        return Where(m.goal.copy(), np.zeros(len(m.goal)), True)
