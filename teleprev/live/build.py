"""Assemble a Pipeline from a rig: robot, IK chain, calibration, end effector and Corrector."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from teleprev.pipeline.config import PipelineConfig
from teleprev.pipeline.effectors import Effector, GripperEffector, LeapEffector, VacuumEffector
from teleprev.pipeline.guard import JointGuard
from teleprev.pipeline.step import Pipeline
from teleprev.retarget.arm import ArmRetargeter
from teleprev.retarget.calibration import Calibration, load_calibration
from teleprev.rig import Rig
from teleprev.robot.ik import ArmIK
from teleprev.robot.model import RobotModel, load_robot


def rig_calibration(rig: Rig) -> Calibration:
    return load_calibration(rig.resolve(rig.rig.calibration) if rig.rig.calibration else None)


def models_dir(rig: Rig, override: str | Path | None = None) -> Path | None:
    if override:
        return Path(override)
    return rig.resolve(rig.rig.models) if rig.rig.models else None


def build_pipeline(rig: Rig, models: str | Path | None = None, calibration: Calibration | None = None) -> Pipeline:
    cfg = rig.pipeline
    calibration = calibration if calibration is not None else rig_calibration(rig)
    robot = load_robot(rig.rig.robot)
    # Tracking: a bounded number of iterations and no cold-start retry, so an unreachable target costs a
    # bounded step; the best effort within the limits is flagged and the next step continues from it.
    ik = ArmIK(robot, cfg.tcp_link or rig.effector.tcp_link, position_tolerance=cfg.ik_position_tolerance,
               rotation_tolerance=cfg.ik_rotation_tolerance, max_iterations=cfg.ik_iterations, retry=False)
    arm_speed = np.minimum(ik.chain.velocity_limit, cfg.arm_speed)
    max_dt = cfg.max_command_dt_ms / 1000.0
    arm_guard = JointGuard(ik.chain.lower, ik.chain.upper, arm_speed, max_dt)
    arm = ArmRetargeter(ik, cfg.wrist_scale, cfg.workspace_min, cfg.workspace_max, calibration.suit_to_robot())
    return Pipeline(cfg, arm, arm_guard, build_effector(rig, robot, cfg, max_dt, calibration, models))


def build_effector(rig: Rig, robot: RobotModel, cfg: PipelineConfig, max_dt: float, calibration: Calibration,
                   models: str | Path | None = None) -> Effector:
    """The pipeline's side of the rig's end effector, chosen by its row of the table."""
    spec = rig.effector
    if spec.self_colliding:
        from teleprev.noncollision.corrector import Corrector

        hand = load_robot(spec.hand_urdf)
        corrector = Corrector.load(models_dir(rig, models), hand)
        return LeapEffector(spec, hand, corrector, cfg, max_dt, calibration.leap_map())
    if spec.is_switch:
        return VacuumEffector(spec, cfg, max_dt)
    return GripperEffector(spec, robot, cfg, max_dt)
