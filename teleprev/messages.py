"""The messages that flow through teleprev: from devices into the session loop, the recorder and the
pipeline, and back out of recorded sessions.

Every message carries `stamp_ns`, the time its data was acquired, on the session clock (integer
nanoseconds). The time a message reached the host (MCAP log_time) is not part of the message: the
session loop assigns it. Values are float64, so a session read back gives bit-identical inputs.

Recorded as (see teleprev/session/topics.py):
    JointSample  -> foxglove.JointStates     PoseSample -> foxglove.PoseInFrame
    ImageSample  -> foxglove.CompressedImage TransformsSample -> foxglove.FrameTransforms
    DepthSample  -> foxglove.RawImage 16UC1 (or CompressedImage 16-bit PNG), its scale in the channel's metadata
    CameraInfo   -> foxglove.CameraCalibration
    Event        -> JSON with a titled schema (one schema per event type)
    RobotDescription -> std_msgs/msg/String (ROS 2 CDR)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from teleprev.transforms import pose_matrix


@dataclass(frozen=True, slots=True)
class JointSample:
    """Named joint values: radians (metres for prismatic joints); a glove's SMPL-X hand pose is 45
    axis-angle components named "<joint>.x|y|z" (see teleprev/human/smplx.py)."""

    stamp_ns: int
    names: tuple[str, ...]
    positions: np.ndarray
    velocities: np.ndarray | None = None

    def value(self, name: str) -> float:
        return float(self.positions[self.names.index(name)])

    def as_dict(self) -> dict[str, float]:
        return dict(zip(self.names, self.positions.tolist()))


@dataclass(frozen=True, slots=True)
class PoseSample:
    """A pose of `frame_id`'s child in `frame_id`: position (3,) metres, orientation (4,) x y z w."""

    stamp_ns: int
    frame_id: str
    position: np.ndarray
    orientation: np.ndarray

    def matrix(self) -> np.ndarray:
        return pose_matrix(self.position, self.orientation)


@dataclass(frozen=True, slots=True)
class ImageSample:
    """An encoded image (`format` "jpeg" or "png"), as a camera produced it."""

    stamp_ns: int
    frame_id: str
    data: bytes
    format: str = "jpeg"


@dataclass(frozen=True, slots=True)
class DepthSample:
    """A depth image: `depth` (H, W) uint16 in the camera's units, `scale_m` metres per unit (a D435's unit is
    1 mm, a D405's 0.1 mm; 0 is "no depth"). `format` is how it is recorded: "raw" (foxglove.RawImage 16UC1,
    compressed by the file's zstd chunks) or "png" (a 16-bit PNG in foxglove.CompressedImage)."""

    stamp_ns: int
    frame_id: str
    depth: np.ndarray
    scale_m: float
    format: str = "raw"

    def metres(self) -> np.ndarray:
        """The depth in metres (float32; 0 where the camera saw nothing)."""
        return self.depth.astype(np.float32) * np.float32(self.scale_m)


@dataclass(frozen=True, slots=True)
class CameraInfo:
    """A pinhole camera's calibration for the images of `frame_id` (foxglove.CameraCalibration): `k` the 3x3
    intrinsic matrix row-major, `d` the distortion coefficients of `distortion_model` ("plumb_bob": k1 k2 p1
    p2 k3)."""

    stamp_ns: int
    frame_id: str
    width: int
    height: int
    k: tuple[float, ...]
    d: tuple[float, ...] = ()
    distortion_model: str = "plumb_bob"


@dataclass(frozen=True, slots=True)
class Transform:
    parent: str
    child: str
    translation: np.ndarray  # (3,)
    rotation: np.ndarray  # (4,) x y z w


@dataclass(frozen=True, slots=True)
class TransformsSample:
    """Link frames of a robot at one instant (recorded on /tf so Foxglove's URDF panel animates)."""

    stamp_ns: int
    transforms: tuple[Transform, ...]


@dataclass(frozen=True, slots=True)
class Event:
    """A JSON message: `schema` is its schema title (an entry of topics.EVENT_SCHEMAS), `data` its fields."""

    stamp_ns: int
    schema: str
    data: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class RobotDescription:
    """The robot's URDF text, recorded on /robot_description as ROS 2 std_msgs/msg/String (the one schema
    Foxglove's URDF layer reads from a topic). std_msgs/String has no stamp: it reads back as 0."""

    stamp_ns: int
    urdf: str


Payload = (JointSample | PoseSample | ImageSample | DepthSample | CameraInfo | TransformsSample | Event
           | RobotDescription)


@dataclass(frozen=True, slots=True)
class Sample:
    """A payload on its topic, as a device or the pipeline hands it to the session loop."""

    topic: str
    payload: Payload


@dataclass(frozen=True, slots=True)
class Logged:
    """A message as recorded: topic, host receive time (MCAP log_time) and payload."""

    topic: str
    log_time_ns: int
    payload: Payload
