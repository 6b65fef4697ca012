"""The sensors' frames in the robot's tree, for /tf: every camera (its images' frame_id is its device
name) and the suit's world frame ("suit", in which wrist poses are given), placed by the rig's
[frames.<name>] tables (calibrated extrinsics), so that images, the wrist and the robot share one scene
in Foxglove. The suit's rotation defaults to the calibration's suit-to-robot yaw; a camera without a
[frames] table hangs at the robot's root until it is calibrated."""

from __future__ import annotations

import numpy as np

from teleprev.errors import ConfigError
from teleprev.messages import JointSample, Transform, TransformsSample
from teleprev.retarget.calibration import Calibration
from teleprev.rig import Rig, SensorFrame
from teleprev.robot.frames import FramePublisher
from teleprev.robot.model import RobotModel
from teleprev.transforms import matrix_to_quat, rpy_to_matrix

SUIT_FRAME = "suit"


def sensor_frames(rig: Rig, robot: RobotModel, calibration: Calibration) -> tuple[Transform, ...]:
    out = []
    names = [d.name for d in rig.of_kind("camera")] + ([SUIT_FRAME] if rig.of_kind("suit") else [])
    for name in names:
        frame = rig.frames.get(name, SensorFrame())
        parent = frame.parent or robot.desc.root
        if parent not in robot.links:
            raise ConfigError(f"parent {parent!r} is not a link of {robot.name}", f"{rig.path} [frames.{name}]")
        if frame.rpy is not None:
            rotation = rpy_to_matrix(*frame.rpy)
        elif frame.look_at is not None:
            rotation = optical_look_at(
                np.asarray(frame.xyz, float), np.asarray(frame.look_at, float), f"{rig.path} [frames.{name}]"
            )
        elif name == SUIT_FRAME:
            rotation = calibration.suit_to_robot()
        else:
            rotation = np.eye(3)
        out.append(Transform(parent, name, np.asarray(frame.xyz, dtype=float), matrix_to_quat(rotation)))
    return tuple(out)


def optical_look_at(eye: np.ndarray, target: np.ndarray, where: str) -> np.ndarray:
    """The rotation of a camera's optical frame (x right, y down, z forward) at `eye` looking at `target`,
    with the world's z up."""
    forward = target - eye
    if np.linalg.norm(forward) < 1e-9:
        raise ConfigError("look_at is the camera's own position", where)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    if np.linalg.norm(right) < 1e-9:  # looking straight up or down: x of the parent is "up" in the image
        right = np.cross(forward, [1.0, 0.0, 0.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    return np.stack([right, down, forward], axis=1)


class RobotFrames:
    """The robot's /tf from its measured joints, for the session loop: one sample per arm state sample (at
    most one per `period_ns`), stamped with its acquisition time so that the robot lines up with the
    images; the end effector at its latest measured state."""

    def __init__(self, publisher: FramePublisher, period_ns: int = 0):
        self.publisher = publisher
        self.period_ns = period_ns
        self._last_ns = 0

    def sample(self, driver, arm_state) -> TransformsSample | None:
        """The frames for this arm state sample of a PipelineDriver's arm, or None (none due, or no state)."""
        if arm_state.stamp_ns - self._last_ns < self.period_ns:
            return None
        pipeline, model = driver.pipeline, self.publisher.model
        arm = pipeline.measured(arm_state, pipeline.arm_names) if isinstance(arm_state, JointSample) else None
        if arm is None:
            return None
        self._last_ns = arm_state.stamp_ns
        joints = dict(zip(pipeline.arm_names, arm))
        eff = pipeline.measured(driver.latest.get(driver.topics.effector), pipeline.effector_names)
        if eff is not None and pipeline.effector_names[0] in model.joint_index:
            joints.update(zip(pipeline.effector_names, eff))
        return self.publisher.sample(model.vector(joints), arm_state.stamp_ns)
