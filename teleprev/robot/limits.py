"""Motion limits of the robots teleprev drives: the defaults a rig's [pipeline] table may tighten.

Velocity comes from the URDF (<limit velocity=...>); acceleration and jerk are not in a URDF, so they
are here, beside it, per arm and per end effector:

    xarm6, xarm7   10 rad/s^2 and 500 rad/s^3 per joint (UFactory's planners use 10 rad/s^2)
    leap_hand      200 rad/s^2 per joint; commands keep 3 mm of clearance between links
    parallel_gripper  1 m/s^2 on the jaw opening
    vacuum         a switch: no motion limits

A rig sets `arm_acceleration`, `arm_jerk`, `hand_acceleration` and `hand_clearance_mm` in [pipeline];
a key left out takes the value here. A robot that is not in this table needs the keys in the rig.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class ArmLimits:
    acceleration: float  # rad/s^2, every joint
    jerk: float  # rad/s^3, every joint


@dataclass(frozen=True)
class EffectorLimits:
    acceleration: float | None  # rad/s^2 (m/s^2 for a gripper); None: a switch, nothing to limit
    clearance_mm: float = 0.0  # distance kept between the hand's own links along every command segment


# Keyed by the arm's URDF name; a robot "xarm6_leap_hand" is the arm "xarm6" carrying a LEAP Hand.
ARMS: dict[str, ArmLimits] = {
    "xarm6": ArmLimits(acceleration=10.0, jerk=500.0),
    "xarm7": ArmLimits(acceleration=10.0, jerk=500.0),
}

EFFECTORS: dict[str, EffectorLimits] = {
    "leap_hand": EffectorLimits(acceleration=200.0, clearance_mm=3.0),
    "parallel_gripper": EffectorLimits(acceleration=1.0),
    "vacuum": EffectorLimits(acceleration=None),
}


def arm_limits(robot: str) -> ArmLimits | None:
    """The row for a robot URDF name (the arm's name, or the arm's name + "_" + its end effector)."""
    for arm, limits in ARMS.items():
        if robot == arm or robot.startswith(arm + "_"):
            return limits
    return None


def effector_limits(effector: str) -> EffectorLimits | None:
    return EFFECTORS.get(effector)
