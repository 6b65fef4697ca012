"""The end effectors teleprev drives: one table that every other module reads.

    leap_hand         16-DoF LEAP Hand: joints "0".."15", joint-to-joint retargeting, self-collision corrected
    parallel_gripper  one joint "gripper": jaw opening in metres, from one finger's flexion
    vacuum            one switch "vacuum": 0 off / 1 on, flexion thresholds with hysteresis

Each row names the arm + end-effector URDF in urdf/, the link the operator's wrist drives (TCP), the
end effector's joints (always addressed by name) and the point that closes on objects.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from teleprev.errors import ConfigError

EffectorName = Literal["leap_hand", "parallel_gripper", "vacuum"]


@dataclass(frozen=True)
class EndEffector:
    name: str
    title: str  # as the user-study tables print it
    robot: str  # the xArm6 carrying it, a URDF in urdf/
    tcp_link: str  # the link the wrist drives
    joints: tuple[str, ...]
    hand_urdf: str = ""  # the end effector alone, for the self-collision check and models ("": none needed)
    grasp_link: str = ""  # where a held object is carried (the sim world), and its offset in that link
    grasp_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def is_switch(self) -> bool:
        """A binary tool (no URDF joint, no speed): its one "joint" is 0 or 1."""
        return self.name == "vacuum"

    @property
    def self_colliding(self) -> bool:
        """Whether its commands go through the Corrector and the exact self-collision check."""
        return bool(self.hand_urdf)


EFFECTORS: dict[str, EndEffector] = {
    e.name: e
    for e in (
        EndEffector(
            "leap_hand",
            "LeapHand (16-DoF)",
            "xarm6_leap_hand",
            "palm_lower",
            tuple(str(i) for i in range(16)),
            hand_urdf="leap_hand_right",
            grasp_link="palm_lower",
            grasp_offset=(-0.03, -0.035, -0.05),
        ),
        EndEffector(
            "parallel_gripper",
            "Parallel-jaw Gripper (1-DoF)",
            "xarm6_parallel_gripper",
            "gripper_tcp",
            ("gripper",),
            grasp_link="gripper_tcp",
        ),
        EndEffector(
            "vacuum", "Vacuum Gripper (binary)", "xarm6_vacuum", "vacuum_tcp", ("vacuum",), grasp_link="vacuum_tcp"
        ),
    )
}


def end_effector(name: str, where: str | None = None) -> EndEffector:
    """The table's row for `name`; a ConfigError naming the known ones otherwise."""
    try:
        return EFFECTORS[name]
    except KeyError:
        raise ConfigError(f"unknown end effector {name!r} (expected {', '.join(EFFECTORS)})", where) from None
