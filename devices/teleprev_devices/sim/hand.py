"""sim.hand: the rig's end effector: a LEAP Hand ("0".."15"), a parallel-jaw gripper ("gripper", metres
of opening) or a vacuum tool ("vacuum", 0 off / 1 on), following commands within its speed limits and
reporting its state; kinematic, or in the physics world on a physics rig (see actuator.py)."""

from __future__ import annotations

import numpy as np

from teleprev.devices import ConfigError, DeviceContext
from teleprev_devices.sim.actuator import ActuatorSettings, SimActuator
from teleprev_devices.sim.device import timing


# rate: the LEAP Hand's position read-out tops out around 90 Hz
@timing(rate_hz=90.0, latency_ms=1.5, jitter_ms=0.3, clock_offset_s=77.7, clock_drift_ppm=-6.0)
class HandSettings(ActuatorSettings):
    home: tuple[float, ...] = ()  # starting positions; empty: open (LEAP all zeros, gripper 0.085 m, vacuum off)
    max_velocity: float = 0.0  # rad/s (m/s for the gripper) for every joint; 0: the URDF's velocity limits
    switch_ms: float = 60.0  # vacuum: time for the suction to build up or release

    def __post_init__(self):
        super().__post_init__()
        if self.max_velocity < 0 or self.switch_ms <= 0:
            raise ValueError(
                f"max_velocity must be >= 0 and switch_ms > 0, got {self.max_velocity} and {self.switch_ms}"
            )


class SimHand(SimActuator[HandSettings], kind="hand"):
    """JointSample of the end effector's joints on /hand/<name>/state (context.end_effector decides which)."""

    def __init__(self, name: str, settings: HandSettings, context: DeviceContext):
        super().__init__(name, settings, context)
        model = self.world.model
        try:
            effector = context.effector
        except ConfigError as exc:
            raise self.bad_setting(None, exc.message) from None
        ee = self.end_effector = effector.name
        self.joint_names = effector.joints
        if ee == "vacuum":
            # A switch, not a URDF joint: a 0..1 level ramps over 2 x switch_ms and the state flips half way.
            self.lower, self.upper = np.zeros(1), np.ones(1)
            self.max_velocity = np.array([1000.0 / (2 * settings.switch_ms)])
            default_home = np.zeros(1)
        else:
            missing = [n for n in self.joint_names if n not in model.joint_index]
            if missing:
                raise self.bad_setting(None, f"robot {model.name!r} has no joints {missing} for end effector "
                                             f"{ee!r}; check [rig] robot and end_effector")
            self.use_urdf_joints(self.joint_names)
            default_home = (np.clip(np.zeros(len(self.joint_names)), self.lower, self.upper) if ee == "leap_hand"
                            else self.upper.copy())
        self.home = self.check_home(np.array(settings.home, dtype=float) if settings.home else default_home)

    def state_positions(self) -> np.ndarray:
        if self.end_effector == "vacuum" and self.link is None:
            return (self.follower.q >= 0.5).astype(float)
        return self.follower.q.copy()

    def state_velocities(self) -> np.ndarray:
        if self.end_effector == "vacuum" and self.link is None:
            return np.zeros(1)
        return self.follower.v.copy()
