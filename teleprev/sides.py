"""A bimanual rig's sides: `[sides.left]` and `[sides.right]`, each an arm with its end effector.

    [sides.left]
    arm = "arm_left"                  # device names ([devices.<name>] tables) this side reads and drives
    hand = "hand_left"
    glove = "glove_left"              # the operator's left hand ...
    suit = "suit_left"                # ... and left wrist
    robot = "xarm6_leap_hand_left"    # arm + end effector URDF (default: the end effector's, mirrored on the left)
    end_effector = "leap_hand"        # leap_hand | parallel_gripper | vacuum
    mount_xyz = [0.0, 0.35, 0.0]      # the arm's base in the world (metres) ...
    mount_yaw = 0.0                   # ... and its turn about the world's z (radians)
    calibration = ""                  # this side's calibration file; "": the rig's
    cameras = ["cam_left"]            # cameras that belong to this side (a wrist camera; a sim camera shows its robot)
    [sides.left.pipeline]             # this side's [pipeline] keys over the rig's (limits, workspace, ...)
    arm_acceleration = 8.0

A rig without [sides] is a single-arm rig, read exactly as before. A side is a single-arm rig of its own
(teleprev.rig.side_rig): the pipeline, the motion limits and `teleprev audit` take it unchanged, so each side has its
own retargeting, Corrector, limits and planner. The world frame is the one the suit's yaw calibration turns
into: a side's arm base is turned by mount_yaw in it, so its pipeline sees the suit turned by suit_yaw -
mount_yaw (the wrist's relative motion, which is what drives the arm, needs no translation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Literal

from teleprev.config import from_table
from teleprev.errors import ConfigError
from teleprev.pipeline.config import PipelineConfig
from teleprev.robot.effectors import EffectorName, EndEffector, end_effector

if TYPE_CHECKING:
    from teleprev.rig import DeviceEntry

SideName = Literal["left", "right"]
SIDES: tuple[SideName, ...] = ("left", "right")  # the order of a bimanual dataset's vectors (LeRobot's bi_* rigs)
LEFT_HAND_URDF = {"leap_hand": "leap_hand_left"}  # end effectors with a handed description: the left one
LEFT_ROBOT = {"leap_hand": "xarm6_leap_hand_left"}
SIDE_DEVICE_KINDS = {"arm": "arm", "hand": "hand", "glove": "glove", "suit": "suit"}


@dataclass(frozen=True)
class SideSection:
    arm: str
    hand: str
    glove: str = ""
    suit: str = ""
    robot: str = ""
    end_effector: EffectorName = "leap_hand"
    hand_urdf: str = ""  # the end effector alone (self-collision, Corrector); "": the table's, mirrored on the left
    mount_xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    mount_yaw: float = 0.0
    calibration: str = ""
    cameras: tuple[str, ...] = ()  # camera devices of this side: they see (a sim camera renders) this side's robot
    pipeline: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        if not all(abs(v) <= 10.0 for v in self.mount_xyz):
            raise ValueError(f"mount_xyz must be within ±10 m of the world's origin, got {list(self.mount_xyz)}")
        if not abs(self.mount_yaw) <= 2 * math.pi:
            raise ValueError(f"mount_yaw is in radians, within ±2π; got {self.mount_yaw!r} (degrees?)")


@dataclass(frozen=True)
class Side:
    """One side as the rig has it, its defaults filled in: what the pipeline and the session need."""

    name: SideName
    section: SideSection
    robot: str
    effector: EndEffector  # the table's row, with this side's robot and hand description
    pipeline: PipelineConfig

    @property
    def devices(self) -> dict[str, str]:
        """role (arm, hand, glove, suit) -> device name, for the roles this side has."""
        return {role: getattr(self.section, role) for role in SIDE_DEVICE_KINDS if getattr(self.section, role)}

    @property
    def device_names(self) -> set[str]:
        """Every device of this side: its arm, hand, glove, suit and cameras."""
        return set(self.devices.values()) | set(self.section.cameras)

    def prefixed(self, name: str) -> str:
        """A joint or feature name of this side, as LeRobot's bimanual robots name theirs: "left_" + name."""
        return f"{self.name}_{name}"


def parse_sides(data: Any, pipeline_table: dict, devices: dict[str, DeviceEntry], where: str) -> dict[str, Side]:
    """The [sides] table: {} when absent (a single-arm rig); else both sides, every key and device checked."""
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError("expected [sides.left] and [sides.right] tables", f"{where} [sides]")
    unknown = sorted(set(data) - set(SIDES))
    if unknown:
        raise ConfigError(f"unknown side {unknown[0]!r} (a rig's sides are left and right)", f"{where} [sides]")
    missing = [s for s in SIDES if s not in data]
    if missing:
        raise ConfigError(f"a bimanual rig needs both sides: add [sides.{missing[0]}]", f"{where} [sides]")
    sides = {name: _side(name, data[name], pipeline_table, devices, f"{where} [sides.{name}]") for name in SIDES}
    shared = sorted(set(sides["left"].section.cameras) & set(sides["right"].section.cameras))
    if shared:
        raise ConfigError(f"both sides name camera {shared[0]!r}: a camera belongs to one side, or to none",
                          f"{where} [sides.right].cameras")
    for role in ("arm", "hand"):
        if sides["left"].devices[role] == sides["right"].devices[role]:
            raise ConfigError(f"both sides name {role} device {sides['left'].devices[role]!r}: each side drives its "
                              "own", f"{where} [sides.right].{role}")
    return sides


def _side(name: SideName, table: Any, pipeline_table: dict, devices: dict[str, DeviceEntry], where: str) -> Side:
    section = from_table(SideSection, table, where)
    for role, kind in SIDE_DEVICE_KINDS.items():
        device = getattr(section, role)
        if not device:
            continue
        if device not in devices:
            raise ConfigError(f"no device {device!r} in this rig (add [devices.{device}])", f"{where}.{role}")
        if devices[device].kind != kind:
            raise ConfigError(f"device {device!r} is a {devices[device].kind}, not a {kind}", f"{where}.{role}")
    for k, camera in enumerate(section.cameras):
        if camera not in devices or devices[camera].kind != "camera":
            raise ConfigError(f"{camera!r} is not a camera device of this rig", f"{where}.cameras[{k}]")
    row = end_effector(section.end_effector, f"{where}.end_effector")
    left = name == "left"
    robot = section.robot or (LEFT_ROBOT.get(row.name, row.robot) if left else row.robot)
    hand_urdf = section.hand_urdf or (LEFT_HAND_URDF.get(row.name, row.hand_urdf) if left else row.hand_urdf)
    if bool(hand_urdf) != bool(row.hand_urdf):
        raise ConfigError(f"hand_urdf is for an end effector with self-collision; {row.name} has none",
                          f"{where}.hand_urdf")
    merged = {**(pipeline_table if isinstance(pipeline_table, dict) else {}), **section.pipeline}
    pipeline = from_table(PipelineConfig, merged, f"{where}.pipeline")
    return Side(name, section, robot, replace(row, robot=robot, hand_urdf=hand_urdf), pipeline)
