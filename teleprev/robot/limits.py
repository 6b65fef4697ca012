"""Motion limits of the robots teleprev drives: the defaults a rig's [pipeline] table may tighten.

Velocity comes from the URDF (<limit velocity=...>); acceleration and jerk are not in a URDF, so they
are here, beside it, per arm and per end effector:

    xarm6, xarm7   10 rad/s^2 and 500 rad/s^3 per joint (UFactory's planners use 10 rad/s^2); the flange
                   (TCP) at most 1.0 m/s (servo mode faults past 1000 mm/s, error C60: UFactory's servo mode
                   guide, and the SDK's xarm/x3/base.py _max_tcp_speed)
    leap_hand      200 rad/s^2 per joint; commands keep 3 mm of clearance between links
    parallel_gripper  1 m/s^2 on the jaw opening
    vacuum         a switch: no motion limits

A rig sets `arm_acceleration`, `arm_jerk`, `arm_tcp_speed`, `hand_acceleration` and `hand_clearance_mm` in [pipeline];
a key left out takes the value here. A robot that is not in this table needs the keys in the rig.

The LEAP Hand's numbers, from its motors: every joint is a Dynamixel XC330-M288-T (ROBOTIS e-Manual:
gear 288.35:1, 0.517 N.m/A at the output, stall 0.93 N.m at 1.8 A and no-load 81 rev/min = 8.48 rad/s at
5 V, the URDF's velocity), run in current-based position control with a current limit of 350 mA (Lite) or
550 mA (Full). At the limit a joint has 0.18 N.m (Lite) or 0.28 N.m (Full); on the motor's speed-torque
line it turns at most 8.48 x (1 - 0.18 / 0.93) = 6.8 rad/s while giving it (5.9 rad/s for the Full), so
`hand_speed` 6.0 rad/s (pipeline/config.py) keeps torque in hand. Its acceleration is that torque over the
joint's inertia, dominated by the rotor's reflected through the gear (288^2), which ROBOTIS does not
publish: a coreless motor of this class has a mechanical time constant of 5 to 10 ms, that is an output
inertia of tau_m x 0.93 N.m / 8.48 rad/s = 0.55 to 1.1 g.m^2, and so 165 to 330 rad/s^2 (Lite) or 260 to
520 rad/s^2 (Full). 200 rad/s^2 lies inside the Lite hand's range. What the cap costs in lag
(bench/realtime.py, hand_lag_ms_p50, and docs/motion-limits.md) is small beside the swept check's braking near the
clearance margin: on 20 s sim sessions /command/hand followed the retargeted fingers with a median lag of
67, 62 and 117 ms at 100, 200 and 400 rad/s^2.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class ArmLimits:
    acceleration: float  # rad/s^2, every joint
    jerk: float  # rad/s^3, every joint
    tcp_speed: float | None = None  # m/s, the flange's linear speed (teleprev/pipeline/tcp_speed.py)


@dataclass(frozen=True)
class EffectorLimits:
    acceleration: float | None  # rad/s^2 (m/s^2 for a gripper); None: a switch, nothing to limit
    clearance_mm: float = 0.0  # distance kept between the hand's own links along every command segment


# Keyed by the arm's URDF name; a robot "xarm6_leap_hand" is the arm "xarm6" carrying a LEAP Hand.
ARMS: dict[str, ArmLimits] = {
    "xarm6": ArmLimits(acceleration=10.0, jerk=500.0, tcp_speed=1.0),
    "xarm7": ArmLimits(acceleration=10.0, jerk=500.0, tcp_speed=1.0),
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
