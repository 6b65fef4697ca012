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

import numpy as np

from teleprev.devices import DeviceContext, DeviceError, JointSample, ServoStreamRule, world_places
from teleprev_devices.sim.actuator import ActuatorSettings, SimActuator
from teleprev_devices.sim.device import timing

_ARM_JOINT = re.compile(r"joint\d+$")


@timing(rate_hz=100.0, latency_ms=1.0, jitter_ms=0.2, clock_offset_s=52.0, clock_drift_ppm=8.0)
class ArmSettings(ActuatorSettings):
    home: tuple[float, ...] = world_places.ARM_HOME  # joint1..: palm forward at about (0.40, 0, 0.30) m
    max_velocity: float = 0.0  # rad/s for every joint; 0: the URDF's velocity limits
    max_acceleration: float = 10.0  # rad/s^2: commands beyond this (+10%) fault the controller
    max_jerk: float = 500.0  # rad/s^3: likewise
    fault_after_s: float = 0.0  # a controller fault (a collision stop) this long after the first command, once; 0: none

    def __post_init__(self):
        super().__post_init__()
        if self.max_velocity < 0 or self.max_acceleration <= 0 or self.max_jerk <= 0:
            raise ValueError("max_velocity must be >= 0, max_acceleration and max_jerk > 0, "
                             f"got {self.max_velocity}, {self.max_acceleration} and {self.max_jerk}")
        if not 0 <= self.fault_after_s < 1e6:
            raise ValueError(f"fault_after_s must be >= 0 (0: no injected fault), got {self.fault_after_s}")




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
        self._rule = ServoStreamRule(joints, settings.max_acceleration, settings.max_jerk, self.period_ns)

    def _open(self) -> None:
        first = getattr(self, "follower", None) is None
        super()._open()
        if first:
            self.world.set_home(dict(zip(self.joint_names, self.home)))
        self.fault, self._fault_raised = "", False
        self._rule.reset()
        if first:
            self._first_command_ns, self._injected_done = None, False

    def _check(self, stamp_ns: int, target: np.ndarray) -> str:
        """"" or the fault this command raises (teleprev.devices.ServoStreamRule: acceleration and jerk by
        divided differences on the stamps)."""
        broken = self._rule.check(stamp_ns, target, self.measured)
        return f"controller fault: {broken.describe()}; the arm stopped" if broken else ""

    def send(self, command: JointSample) -> None:
        if self.fault:
            raise DeviceError(f"{self.fault} (reconnect to clear)", f"device {self.name!r}")
        super().send(command)

    def _refuse(self, stamp_ns: int, target: np.ndarray) -> str:
        # checked before the target reaches the joints (kinematic or physical): a faulting command never runs
        return self._check(stamp_ns, target) or self._injected(stamp_ns)

    def _refused(self, why: str) -> None:
        self.fault = why
        self.hold_here()

    def _injected(self, stamp_ns: int) -> str:
        """The fault `fault_after_s` asks for, when it is due (once per session)."""
        after = self.settings.fault_after_s
        if after <= 0 or self._injected_done:
            return ""
        if self._first_command_ns is None:
            self._first_command_ns = stamp_ns
        if stamp_ns - self._first_command_ns < after * 1e9:
            return ""
        self._injected_done = True
        return (f"controller fault: collision detected at {stamp_ns / 1e9:.3f} s (injected: fault_after_s = "
                f"{after:g}); the arm stopped")

    def read(self, timeout_s: float):
        if self.fault and not self._fault_raised:
            self._fault_raised = True
            raise DeviceError(self.fault, f"device {self.name!r}")
        return super().read(timeout_s)
