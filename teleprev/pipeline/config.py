"""The [pipeline] table of a rig file: how human motion becomes robot commands.

A pipeline step runs on every glove sample (commands come at the glove's rate), and the arm's state
samples brake the commands between them when the glove goes quiet; there is no other trigger.
"""

from __future__ import annotations

from dataclasses import dataclass

from teleprev.human.smplx import HAND_JOINTS

REACH_M = 5.0  # no arm this drives reaches further from its base


@dataclass(frozen=True)
class PipelineConfig:
    wrist_scale: float = 1.0  # metres of robot motion per metre of wrist motion
    workspace_min: tuple[float, float, float] = (0.15, -0.45, 0.05)  # TCP box in the arm base frame, metres
    workspace_max: tuple[float, float, float] = (0.70, 0.45, 0.65)
    tcp_link: str = ""  # the robot link the wrist drives; empty: palm_lower, gripper_tcp or vacuum_tcp by end effector
    stale_ms: float = 150.0  # inputs older than this hold the last valid command
    arm_speed: float = 2.14  # rad/s cap on arm command steps (planners' value; the URDF's limit is 3.14)
    hand_speed: float = 6.0  # rad/s cap on hand command steps (the URDF's limit is 8.48)
    engage_speed_frac: float = 0.5  # fraction of the caps used while ramping to the preview on engage
    max_command_dt_ms: float = 25.0  # a gap between commands longer than this still allows only this much motion
    command_rate_hz: float = 120.0  # the paced sender's rate: commands to the arm and the end effector per second
    ik_iterations: int = 10  # per step; tracking continues from a best effort within limits next step
    ik_position_tolerance: float = 1e-3  # metres: well under a human wrist's tremor
    ik_rotation_tolerance: float = 1e-2  # radians
    gripper_joint: str = "index1"  # SMPL-X joint whose flexion drives a parallel-jaw or vacuum gripper
    gripper_closed_flexion: float = 1.2  # flexion (rad) at which the gripper is fully closed
    vacuum_on_flexion: float = 0.9  # hysteresis: vacuum switches on above this flexion ...
    vacuum_off_flexion: float = 0.6  # ... and off below this one
    tf_rate_hz: float = 0.0  # cap on the rate of robot link frames on /tf; 0: one per arm state sample
    # Motion limits of the commands (teleprev/robot/limits.py has the defaults; leave a key out to use them).
    arm_acceleration: float | None = None  # rad/s^2 per arm joint
    arm_jerk: float | None = None  # rad/s^3 per arm joint
    arm_tcp_speed: float | None = None  # m/s: the flange's linear speed (none in the table or the rig: uncapped)
    # The fraction of arm_acceleration and arm_jerk the planner plans with. A servo-mode controller judges
    # the stream on its own clock, which places each target from arrivals that jitter (0.5-1 ms on a busy
    # host): a stream planned at the limits reads up to ~10% over them at a stream's start, where the box has
    # one or two gaps to pace it by (tests/devices/test_xarm_servo_cycle.py, bench/hardware.py).
    arm_plan_fraction: float = 0.9
    arm_feedforward: bool = True  # track the target's own velocity (less lag); false: plan to rest at each target
    hand_acceleration: float | None = None  # rad/s^2 per hand joint (m/s^2 for a gripper)
    hand_clearance_mm: float | None = None  # distance kept between the hand's links along each command segment

    def __post_init__(self):
        lo, hi = self.workspace_min, self.workspace_max
        if not all(-REACH_M <= a < b <= REACH_M for a, b in zip(lo, hi)):
            raise ValueError(f"workspace_min must be below workspace_max on every axis, both within ±{REACH_M:g} m "
                             f"of the arm's base; got {list(lo)} and {list(hi)}")
        if not 0 < self.wrist_scale <= 10:
            raise ValueError(f"wrist_scale must be in (0, 10], got {self.wrist_scale!r}")
        for key in ("stale_ms", "max_command_dt_ms"):
            if not 0 < getattr(self, key) <= 10_000:
                raise ValueError(f"{key} must be in (0, 10000] ms, got {getattr(self, key)!r}")
        if not 0 < self.arm_plan_fraction <= 1:
            raise ValueError(f"arm_plan_fraction must be in (0, 1], got {self.arm_plan_fraction!r}")
        if not 0 < self.engage_speed_frac <= 1:
            raise ValueError(f"engage_speed_frac must be in (0, 1], got {self.engage_speed_frac!r}")
        if self.gripper_joint not in HAND_JOINTS:
            raise ValueError(
                f"gripper_joint must be an SMPL-X hand joint ({', '.join(HAND_JOINTS)}), got {self.gripper_joint!r}"
            )
        if not 10 <= self.command_rate_hz <= 1000:
            raise ValueError(f"command_rate_hz must be in [10, 1000], got {self.command_rate_hz!r}")
        if not 0 <= self.tf_rate_hz < float("inf"):
            raise ValueError(f"tf_rate_hz must be >= 0 (0: every arm state sample), got {self.tf_rate_hz!r}")
        for key in ("arm_speed", "hand_speed", "arm_acceleration", "arm_jerk", "arm_tcp_speed", "hand_acceleration"):
            value = getattr(self, key)
            if value is not None and not 0 < value < float("inf"):
                raise ValueError(f"{key} must be a positive, finite number, got {value!r}")
        if self.hand_clearance_mm is not None and not 0 <= self.hand_clearance_mm < 20:
            raise ValueError(f"hand_clearance_mm must be in [0, 20), got {self.hand_clearance_mm!r}")
