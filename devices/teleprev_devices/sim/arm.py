"""sim.arm: a kinematic xArm that follows position commands within its velocity and acceleration
limits and reports its joint state, like the real arm's 100 Hz report."""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from teleprev_devices.sim.actuator import SimActuator
from teleprev_devices.sim.device import TimingSettings
from teleprev_devices.sim.world import DEFAULT_HOME
from teleprev.topics import device_topic

_ARM_JOINT = re.compile(r"joint\d+$")


@dataclass
class ArmSettings(TimingSettings):
    rate_hz: float = 100.0
    latency_ms: float = 1.0
    jitter_ms: float = 0.2
    clock_offset_s: float = 52.0
    clock_drift_ppm: float = 8.0
    home: tuple[float, ...] = DEFAULT_HOME  # joint1..: palm forward at about (0.40, 0, 0.30) m
    max_velocity: float = 0.0  # rad/s for every joint; 0: the URDF's velocity limits
    max_acceleration: float = 10.0  # rad/s^2 (the planners' value for the xArm)

    def __post_init__(self):
        super().__post_init__()
        if self.max_velocity < 0 or self.max_acceleration <= 0:
            raise ValueError("max_velocity must be >= 0 and max_acceleration > 0, "
                             f"got {self.max_velocity} and {self.max_acceleration}")


class SimArm(SimActuator):
    """JointSample of joint1..jointN (positions and velocities) on /arm/<name>/state."""

    kind = "arm"
    Settings = ArmSettings

    def __init__(self, name, settings, context):
        super().__init__(name, settings, context)
        model = self.world.model
        self.joint_names = tuple(n for n in model.joint_names if _ARM_JOINT.match(n))
        if not self.joint_names:
            raise self.bad_setting(None, f"robot {model.name!r} has no arm joints (joint1, joint2, ...)")
        idx = model.indices(self.joint_names)
        self.lower, self.upper = model.lower[idx], model.upper[idx]
        self.home = self.check_home(np.array(settings.home, dtype=float))
        self.max_velocity = self.velocity_caps(model.velocity_limit[idx], settings.max_velocity)
        self.max_acceleration = settings.max_acceleration
        self.topic = device_topic("arm", name, "state")

    def _open(self) -> None:
        super()._open()
        self.world.set_home(dict(zip(self.joint_names, self.home)))
