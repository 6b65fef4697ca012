"""sim.arm: a kinematic xArm in servo mode, reporting its joint state like the real arm's 100 Hz report.

Like set_servo_angle_j, it runs the latest target at once, only as fast as its velocity limit allows,
with no smoothing of its own. Like the real controller, it faults on a command stream it should not
follow: a command whose acceleration or jerk (divided differences on the command stamps, the times
the pipeline meant them for) exceeds max_acceleration or max_jerk by more than 10% latches a fault.
The arm stops where it is, refuses commands, and the next read() raises a DeviceError naming the joint
and the figure, which the runner records as an error event on /events/device; reconnecting clears it
(the operator clearing the controller's error), and the arm carries on from where it stopped.
"""

from __future__ import annotations

import re
from collections import deque

import numpy as np

from teleprev.devices import DeviceContext, DeviceError, JointSample
from teleprev_devices.sim.actuator import ActuatorSettings, SimActuator
from teleprev_devices.sim.device import timing
from teleprev_devices.sim.world import DEFAULT_HOME

_ARM_JOINT = re.compile(r"joint\d+$")


@timing(rate_hz=100.0, latency_ms=1.0, jitter_ms=0.2, clock_offset_s=52.0, clock_drift_ppm=8.0)
class ArmSettings(ActuatorSettings):
    home: tuple[float, ...] = DEFAULT_HOME  # joint1..: palm forward at about (0.40, 0, 0.30) m
    max_velocity: float = 0.0  # rad/s for every joint; 0: the URDF's velocity limits
    max_acceleration: float = 10.0  # rad/s^2: commands beyond this (+10%) fault the controller
    max_jerk: float = 500.0  # rad/s^3: likewise

    def __post_init__(self):
        super().__post_init__()
        if self.max_velocity < 0 or self.max_acceleration <= 0 or self.max_jerk <= 0:
            raise ValueError("max_velocity must be >= 0, max_acceleration and max_jerk > 0, "
                             f"got {self.max_velocity}, {self.max_acceleration} and {self.max_jerk}")


FAULT_TOLERANCE = 0.10  # a command over the acceleration or jerk limit by more than this faults
STREAM_GAP_NS = 60_000_000  # commands further apart than this start a new stream (from the arm as it is: at rest)


class SimArm(SimActuator[ArmSettings], kind="arm"):
    """JointSample of joint1..jointN (positions and velocities) on /arm/<name>/state."""

    def __init__(self, name: str, settings: ArmSettings, context: DeviceContext):
        super().__init__(name, settings, context)
        model = self.world.model
        joints = tuple(n for n in model.joint_names if _ARM_JOINT.match(n))
        if not joints:
            raise self.bad_setting(None, f"robot {model.name!r} has no arm joints (joint1, joint2, ...)")
        self.use_urdf_joints(joints)
        self.home = self.check_home(np.array(settings.home, dtype=float))
        self.max_acceleration = np.inf  # servo mode: the target at once, rate-limited only
        self.fault = ""  # the latched controller fault ("": none)
        self._fault_raised = False
        self._history: deque[tuple[int, np.ndarray]] = deque(maxlen=3)  # the last commands (stamp, positions)

    def _open(self) -> None:
        first = getattr(self, "follower", None) is None
        super()._open()
        if first:
            self.world.set_home(dict(zip(self.joint_names, self.home)))
        self.fault, self._fault_raised = "", False
        self._history.clear()

    def _check(self, stamp_ns: int, target: np.ndarray) -> str:
        """"" or the fault this command raises: acceleration and jerk by divided differences on the stamps."""
        h = self._history
        if not h or stamp_ns - h[-1][0] > STREAM_GAP_NS:
            # A new stream starts from the arm as it is, extrapolated back at its velocity, one state period
            # apart. After a pause that is at rest on the last command (servo mode ran it at once), whatever
            # the simulated follower says: starved of CPU, its state can be that of the pause's start.
            if h:
                q, v = h[-1][1].copy(), np.zeros_like(h[-1][1])
            else:
                q, v = self.follower.q.copy(), self.follower.v.copy()
            h.clear()
            for k in (3, 2, 1):
                h.append((stamp_ns - k * self.period_ns, q - v * (k - 1) * self.period_ns / 1e9))
        if stamp_ns <= h[-1][0]:
            return ""
        t = [(s - stamp_ns) / 1e9 for s, _ in h] + [0.0]  # differences of integer ns: epoch seconds lose ~1e-7 s
        q = [p for _, p in h] + [target]
        f1 = [(q[i + 1] - q[i]) / (t[i + 1] - t[i]) for i in range(3)]
        f2 = [(f1[i + 1] - f1[i]) / (t[i + 2] - t[i]) for i in range(2)]
        f3 = (f2[1] - f2[0]) / (t[3] - t[0])
        h.append((stamp_ns, target))
        for what, value, limit, unit in (("accelerates", 2.0 * f2[1], self.settings.max_acceleration, "rad/s^2"),
                                         ("jerks", 6.0 * f3, self.settings.max_jerk, "rad/s^3")):
            j = int(np.argmax(np.abs(value)))
            if abs(value[j]) > limit * (1.0 + FAULT_TOLERANCE):
                return (f"controller fault: the command stamped {stamp_ns / 1e9:.3f} s {what} {self.joint_names[j]} "
                        f"at {abs(value[j]):.4g} {unit} (limit {limit:g} + {FAULT_TOLERANCE:.0%}); the arm stopped")
        return ""

    def send(self, command: JointSample) -> None:
        if self.fault:
            raise DeviceError(f"{self.fault} (reconnect to clear)", f"device {self.name!r}")
        super().send(command)
        with self._lock:
            target = self._commands[-1][1]
            fault = self._check(command.stamp_ns, target)
            if fault:
                self.fault = fault
                self._commands.clear()
                self.follower.set_target(self.follower.q)
                self.follower.v[:] = 0.0

    def read(self, timeout_s: float):
        if self.fault and not self._fault_raised:
            self._fault_raised = True
            raise DeviceError(self.fault, f"device {self.name!r}")
        return super().read(timeout_s)
