"""A bimanual rig's pipelines: one per side, each a single-arm pipeline built from its side's rig.

Each side has its own retargeting, Corrector (the left LEAP Hand's from the right hand's networks,
teleprev/noncollision/mirrored.py), motion limits and command planner; what joins them is the
BimanualDriver (teleprev/pipeline/bimanual.py): one mode for both, a fault on either side braking both.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from teleprev.assembly import build_driver, build_pipeline, rig_calibration
from teleprev.pipeline.bimanual import BimanualDriver, SideInputs
from teleprev.pipeline.cross_side import CROSS_SIDE_CLEARANCE_M, CrossSideGuard, SideJoints
from teleprev.pipeline.driver import InputTopics
from teleprev.pipeline.step import Pipeline
from teleprev.retarget.calibration import Calibration
from teleprev.rig import Rig, side_rig
from teleprev.robot.cross_collision import CrossCollisionChecker
from teleprev.robot.model import load_robot
from teleprev.sides import SIDES
from teleprev.topics import FORMAT_VERSION
from teleprev.transforms import make_transform, rpy_to_matrix


def side_calibration(rig: Rig, side: str) -> Calibration:
    """A side's calibration (its own file, else the rig's), with the suit's yaw turned into its arm's base."""
    calibration = rig_calibration(side_rig(rig, side))
    yaw = rig.sides[side].section.mount_yaw
    return replace(calibration, calibration=replace(calibration.calibration,
                                                    suit_yaw=calibration.calibration.suit_yaw - yaw))


def build_side_pipelines(rig: Rig, models: str | Path | None = None,
                         session_format: int = FORMAT_VERSION) -> dict[str, Pipeline]:
    """Both sides' pipelines, left first."""
    return {side: build_pipeline(side_rig(rig, side), models, side_calibration(rig, side), session_format)
            for side in SIDES}


def side_inputs(rig: Rig, side: str) -> SideInputs:
    """The topics a side's pipeline reads: its glove, suit, arm and hand devices' streams."""
    d = rig.sides[side].devices
    topics = InputTopics.for_devices(d["glove"], d["suit"], d["arm"], d["hand"])
    return SideInputs(side, topics, mirrored=side == "left")


def mount(rig: Rig, side: str) -> np.ndarray:
    """A side's arm base in the world (4x4): its mount_xyz, turned by mount_yaw about z."""
    section = rig.sides[side].section
    return make_transform(rpy_to_matrix(0.0, 0.0, section.mount_yaw), section.mount_xyz)


def build_guard(rig: Rig, pipelines: dict[str, Pipeline]) -> CrossSideGuard:
    """The check that keeps the two sides apart, with both robots at their mounts."""
    robots = {side: load_robot(rig.sides[side].robot) for side in SIDES}
    checker = CrossCollisionChecker(robots["left"], mount(rig, "left"), robots["right"], mount(rig, "right"),
                                    CROSS_SIDE_CLEARANCE_M)
    return CrossSideGuard(checker, {side: SideJoints.of(robots[side], pipelines[side].arm_names,
                                                        pipelines[side].effector_names, pipelines[side].motion)
                                    for side in SIDES})


def build_bimanual_driver(rig: Rig, models: str | Path | None = None,
                          session_format: int = FORMAT_VERSION) -> BimanualDriver:
    pipelines = build_side_pipelines(rig, models, session_format)
    return BimanualDriver({side: (build_driver(pipelines[side], side_inputs(rig, side).topics, session_format),
                                  side_inputs(rig, side)) for side in SIDES}, build_guard(rig, pipelines))
