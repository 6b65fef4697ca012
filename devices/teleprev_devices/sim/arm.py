"""sim.arm: a kinematic xArm that follows position commands within its velocity and acceleration
limits and reports its joint state, like the real arm's 100 Hz report."""

from __future__ import annotations

import re

import numpy as np

from teleprev.devices import DeviceContext
from teleprev_devices.sim.actuator import ActuatorSettings, SimActuator
from teleprev_devices.sim.device import timing
from teleprev_devices.sim.world import DEFAULT_HOME

_ARM_JOINT = re.compile(r"joint\d+$")


@timing(rate_hz=100.0, latency_ms=1.0, jitter_ms=0.2, clock_offset_s=52.0, clock_drift_ppm=8.0)
class ArmSettings(ActuatorSettings):
    home: tuple[float, ...] = DEFAULT_HOME  # joint1..: palm forward at about (0.40, 0, 0.30) m
    max_velocity: float = 0.0  # rad/s for every joint; 0: the URDF's velocity limits
    max_acceleration: float = 10.0  # rad/s^2 (the planners' value for the xArm)

    def __post_init__(self):
        super().__post_init__()
        if self.max_velocity < 0 or self.max_acceleration <= 0:
            raise ValueError("max_velocity must be >= 0 and max_acceleration > 0, "
                             f"got {self.max_velocity} and {self.max_acceleration}")


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
        self.max_acceleration = settings.max_acceleration

    def _open(self) -> None:
        super()._open()
        self.world.set_home(dict(zip(self.joint_names, self.home)))
