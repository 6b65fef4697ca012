"""Assemble a Pipeline from a rig: robot, IK chain, calibration, end effector and Corrector, with the
arithmetic of a session format.

Live recording builds the current format's pipeline; `teleprev eval` builds the one a session was recorded
with, so that it re-runs bit for bit: an older format's classes come from
teleprev/pipeline/older_formats (`_arithmetic`), each a subclass of the current one.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from teleprev.errors import ConfigError
from teleprev.pipeline.arithmetic import Arithmetic
from teleprev.pipeline.config import PipelineConfig
from teleprev.pipeline.driver import InputTopics, PipelineDriver
from teleprev.pipeline.effectors import Effector, GripperEffector, LeapEffector, VacuumEffector
from teleprev.pipeline.guard import JointGuard
from teleprev.pipeline.motion import STREAM_START_JERK_FRAC, Motion
from teleprev.pipeline.step import Pipeline
from teleprev.pipeline.swept import SweptCheck
from teleprev.pipeline.tcp_speed import TcpSpeedCap
from teleprev.pipeline.trajectory import ArmGenerator, HandLimiter
from teleprev.retarget.calibration import Calibration, load_calibration
from teleprev.rig import Rig
from teleprev.robot.collision import SelfCollisionChecker
from teleprev.robot.ik import ArmIK
from teleprev.robot.limits import arm_limits, effector_limits
from teleprev.robot.model import RobotModel, load_robot
from teleprev.topics import FORMAT_VERSION

_CURRENT = Arithmetic()


def _arithmetic(session_format: int) -> Arithmetic:
    if session_format >= FORMAT_VERSION:
        return _CURRENT
    from teleprev.pipeline import older_formats

    return older_formats.arithmetic(session_format)


def rig_calibration(rig: Rig) -> Calibration:
    return load_calibration(rig.resolve(rig.rig.calibration) if rig.rig.calibration else None)


def models_dir(rig: Rig, override: str | Path | None = None) -> Path | None:
    if override:
        return Path(override)
    return rig.resolve(rig.rig.models) if rig.rig.models else None


def _where(rig: Rig, key: str) -> str:
    return f"{rig.path or 'rig'} [pipeline].{key}"


def _limit(rig: Rig, key: str, default: float | None, what: str) -> float:
    """The rig's value for `key`, else the robot table's; a ConfigError naming the key when neither has one."""
    value = getattr(rig.pipeline, key)
    if value is None:
        value = default
    if value is None:
        raise ConfigError(f"no {what} for robot {rig.rig.robot!r} in teleprev/robot/limits.py: set {key} in the rig",
                          _where(rig, key))
    return float(value)


def _capped_speed(rig: Rig, key: str, urdf_velocity: np.ndarray) -> np.ndarray:
    value = getattr(rig.pipeline, key)
    if value > urdf_velocity.min() + 1e-12:
        raise ConfigError(f"{value:g} rad/s is looser than the URDF's velocity limit ({urdf_velocity.min():g} rad/s)",
                          _where(rig, key))
    return np.minimum(urdf_velocity, value)


def _single_arm(rig: Rig) -> None:
    """A bimanual rig has a pipeline and limits per side (teleprev/bimanual.py, rig.side_rig): what asks for
    the rig's one is not built for two sides yet."""
    if rig.bimanual:
        raise ConfigError("a bimanual rig ([sides.left], [sides.right]): eval and rollout are not built for two "
                          "sides yet (record, export, replay and audit are)",
                          str(rig.path or "rig"))


def hand_clearance_m(rig: Rig) -> float:
    cfg, row = rig.pipeline, effector_limits(rig.rig.end_effector)
    return (cfg.hand_clearance_mm if cfg.hand_clearance_mm is not None else (row.clearance_mm if row else 0.0)) / 1000.0


def tcp_speed_cap(rig: Rig, ik: ArmIK, arm_speed: np.ndarray, acceleration: np.ndarray) -> TcpSpeedCap | None:
    """The flange's speed cap: the rig's [pipeline] arm_tcp_speed, else the robot table's; None where
    neither has one (a robot the table lacks: its joints' limits alone)."""
    table = arm_limits(rig.rig.robot)
    value = rig.pipeline.arm_tcp_speed
    if value is None:
        value = table.tcp_speed if table else None
    return None if value is None else TcpSpeedCap(ik.chain, arm_speed, acceleration, value)


def build_motion(rig: Rig, ik: ArmIK, arm_speed: np.ndarray, effector, swept: SweptCheck | None = None,
                 hand_limiter: type = HandLimiter, below_limits: bool = True) -> Motion:
    """The arm's jerk-limited generator and the hand's acceleration cap (`hand_limiter`: the session format's
    class) and swept check, from the robot table (teleprev/robot/limits.py) and the rig's [pipeline] keys;
    the arm planned at [pipeline] arm_plan_fraction of its acceleration and jerk limits, a stream's first
    ticks at STREAM_START_JERK_FRAC of that jerk (`below_limits` False: at them, as formats up to 10 were)."""
    table = arm_limits(rig.rig.robot)
    n = len(arm_speed)
    accel = _limit(rig, "arm_acceleration", table.acceleration if table else None, "arm acceleration limit")
    jerk = _limit(rig, "arm_jerk", table.jerk if table else None, "arm jerk limit")
    fraction = rig.pipeline.arm_plan_fraction if below_limits else 1.0
    arm = ArmGenerator(ik.chain.lower, ik.chain.upper, arm_speed, np.full(n, accel * fraction),
                       np.full(n, jerk * fraction))
    tcp = tcp_speed_cap(rig, ik, arm_speed, arm.acceleration)
    hand = None
    row = effector_limits(rig.rig.end_effector)
    if row is None or row.acceleration is not None:
        g = effector.guard
        hand_accel = _limit(rig, "hand_acceleration", row.acceleration if row else None, "hand acceleration limit")
        hand = hand_limiter(g.lower, g.upper, g.speed, np.full(len(g.lower), hand_accel))
    return Motion(arm, hand, swept, tcp, STREAM_START_JERK_FRAC if below_limits else 1.0, fraction)


def build_pipeline(rig: Rig, models: str | Path | None = None, calibration: Calibration | None = None,
                   session_format: int = FORMAT_VERSION) -> Pipeline:
    """The rig's pipeline, computing as sessions of `session_format` were computed (default: the format
    `record` writes now)."""
    _single_arm(rig)
    how = _arithmetic(session_format)
    cfg = rig.pipeline
    calibration = calibration if calibration is not None else rig_calibration(rig)
    robot = load_robot(rig.rig.robot)
    # Tracking: a bounded number of iterations and no cold-start retry, so an unreachable target costs a
    # bounded step; the best effort within the limits is flagged and the next step continues from it.
    ik = how.arm_ik(robot, cfg.tcp_link or rig.effector.tcp_link, position_tolerance=cfg.ik_position_tolerance,
                    rotation_tolerance=cfg.ik_rotation_tolerance, max_iterations=cfg.ik_iterations, retry=False)
    arm_speed = (_capped_speed(rig, "arm_speed", ik.chain.velocity_limit) if how.motion
                 else np.minimum(ik.chain.velocity_limit, cfg.arm_speed))
    max_dt = cfg.max_command_dt_ms / 1000.0
    arm_guard = JointGuard(ik.chain.lower, ik.chain.upper, arm_speed, max_dt)
    arm = how.arm_retargeter(ik, cfg.wrist_scale, cfg.workspace_min, cfg.workspace_max, calibration.suit_to_robot())
    effector, swept = build_effector(rig, robot, cfg, max_dt, calibration, models, how)
    return how.pipeline(cfg, arm, arm_guard, effector,
                        build_motion(rig, ik, arm_speed, effector, swept, how.hand_limiter, how.plans_below_limits)
                        if how.motion else None)


def build_driver(pipeline: Pipeline, inputs: InputTopics, session_format: int = FORMAT_VERSION) -> PipelineDriver:
    """The driver that feeds `pipeline` (built by build_pipeline for `session_format`) its samples."""
    return _arithmetic(session_format).driver(pipeline, inputs)


def build_effector(rig: Rig, robot: RobotModel, cfg: PipelineConfig, max_dt: float, calibration: Calibration,
                   models: str | Path | None, how: Arithmetic) -> tuple[Effector, SweptCheck | None]:
    """The pipeline's side of the rig's end effector, chosen by its row of the table, and (for a hand
    with self-collision, when motion limits are on) the swept check its commands go through."""
    spec = rig.effector
    if spec.self_colliding:
        from teleprev.noncollision.corrector import Corrector
        from teleprev.noncollision.mirrored import load_corrector

        hand = load_robot(spec.hand_urdf)
        swept = checker = None
        if how.motion:
            # The clearance is part of "collision-free" from the Corrector on: its exact check runs on the
            # hand's shapes grown by half the margin, so targets keep it, and the guard checks the motion.
            swept = how.swept_check(hand, SelfCollisionChecker(hand), hand_clearance_m(rig))
            checker = swept.grown
            _capped_speed(rig, "hand_speed", hand.velocity_limit)
        corrector = load_corrector(how.corrector or Corrector, models_dir(rig, models), hand, checker)
        return LeapEffector(spec, hand, corrector, cfg, max_dt, calibration.leap_map()), swept
    if spec.is_switch:
        return VacuumEffector(spec, cfg, max_dt), None
    return GripperEffector(spec, robot, cfg, max_dt), None


def motion_limits(rig: Rig) -> dict[str, dict]:
    """The limits a rig's commands must keep, per side ("arm", "hand"): joint names, position limits,
    velocity, acceleration, jerk (arm), and for a hand with self-collision its exact checker and the
    link-motion bound (teleprev/pipeline/swept.py). `teleprev audit` measures sessions against these."""
    from teleprev.pipeline.swept import reach_table

    _single_arm(rig)
    cfg = rig.pipeline
    robot = load_robot(rig.rig.robot)
    ik = ArmIK(robot, cfg.tcp_link or rig.effector.tcp_link)
    table = arm_limits(rig.rig.robot)
    arm = {
        "names": ik.chain.joint_names,
        "lower": ik.chain.lower,
        "upper": ik.chain.upper,
        "velocity": _capped_speed(rig, "arm_speed", ik.chain.velocity_limit),
        "acceleration": _limit(
            rig, "arm_acceleration", table.acceleration if table else None, "arm acceleration limit"
        ),
        "jerk": _limit(rig, "arm_jerk", table.jerk if table else None, "arm jerk limit"),
    }
    arm["tcp"] = tcp_speed_cap(rig, ik, arm["velocity"], np.full(len(arm["velocity"]), arm["acceleration"]))
    effector, row = rig.effector, effector_limits(rig.rig.end_effector)
    accel = 0.0
    if row is None or row.acceleration is not None:
        accel = _limit(rig, "hand_acceleration", row.acceleration if row else None, "hand acceleration limit")
    if effector.hand_urdf:
        model = load_robot(effector.hand_urdf)
        checker = SelfCollisionChecker(model)
        hand = {"names": model.joint_names, "lower": model.lower, "upper": model.upper,
                "velocity": _capped_speed(rig, "hand_speed", model.velocity_limit), "acceleration": accel,
                "checker": checker, "reach": reach_table(model, checker.link_names)}
    elif effector.is_switch:
        hand = {"names": effector.joints, "lower": np.zeros(1), "upper": np.ones(1), "velocity": np.array([np.inf]),
                "acceleration": 0.0}
    else:
        idx = robot.indices(effector.joints)
        hand = {"names": effector.joints, "lower": robot.lower[idx], "upper": robot.upper[idx],
                "velocity": robot.velocity_limit[idx], "acceleration": accel}
    return {"arm": arm, "hand": hand}
