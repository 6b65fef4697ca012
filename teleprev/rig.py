"""Rig files (TOML): which devices make up a setup, their settings, the robot, and the pipeline.

    [rig]                        # what is being driven, and who operates
    robot = "xarm6_leap_hand"
    end_effector = "leap_hand"   # leap_hand | parallel_gripper | vacuum

    [pipeline]                   # see teleprev/pipeline/config.py
    wrist_scale = 1.0

    [session]                    # how a recording behaves, whatever the devices
    input_loss_to_preview_s = 1.0

    [devices.glove]              # one table per device: a plugin and that plugin's settings
    plugin = "sim.glove"

    [sides.left]                 # a bimanual rig: each side's devices, robot, mount and limits (teleprev/sides.py)
    arm = "arm_left"

Everything is checked when the file is loaded, before any device opens: unknown keys, wrong types,
unknown plugins and missing devices are ConfigErrors that name the file, the table and the key.
The default rig (rigs/sim.toml) is all simulated devices.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

from teleprev.clock import SessionClock
from teleprev.config import from_table, read_toml
from teleprev.devices.contract import KINDS, DeviceContext
from teleprev.devices.physics import PhysicsAccess
from teleprev.devices.registry import load_plugin
from teleprev.errors import ConfigError
from teleprev.paths import data_dir, inside
from teleprev.pipeline.config import PipelineConfig
from teleprev.robot.effectors import EffectorName, EndEffector, end_effector
from teleprev.robot.limits import arm_limits, effector_limits
from teleprev.robot.model import load_robot, resolve_urdf

FRAME_REACH_M = 100.0  # a sensor further than this from its parent is a typo (a lab is smaller)

@dataclass(frozen=True)
class RigSection:
    name: str = "sim"
    robot: str = "xarm6_leap_hand"  # URDF (name in urdf/ or path) of arm + end effector
    end_effector: EffectorName = "leap_hand"  # a row of teleprev/robot/effectors.py
    calibration: str = ""  # calibration TOML (teleprev calibrate writes one); empty: defaults
    models: str = ""  # folder with CPN/CCN weights; empty: the shipped models/
    operator: str = ""
    task: str = "pick_place"  # default task label of episodes
    participant: str = ""  # user-study metadata
    condition: str = ""


@dataclass(frozen=True)
class SimSection:
    """[sim]: the world the sim devices live in. "kinematic": the arm and hand follow their commands
    exactly and objects move only when a grasp carries them; "physics": a MuJoCo world (teleprev/world)
    stepped at rate_hz on the session clock in a process of its own, which sim.arm and sim.hand measure
    from and command into, sim.camera renders, and which marks each episode's outcome."""

    world: Literal["kinematic", "physics"] = "kinematic"
    rate_hz: float = 500.0  # physics steps per second of session time

    def __post_init__(self):
        if not 500.0 <= self.rate_hz <= 10000.0:
            raise ValueError(f"rate_hz must be 500..10000 (the world steps at 500 Hz or more), got {self.rate_hz:g}")


@dataclass(frozen=True)
class SessionSection:
    # Input lost (missing, stale, invalid) or the process frozen for longer than this while executing: back to
    # PREVIEW, and the operator engages again. A shorter loss resumes at the engage speed (live/core/input_watch.py).
    input_loss_to_preview_s: float = 1.0

    def __post_init__(self):
        if not 0.2 <= self.input_loss_to_preview_s <= 10.0:
            raise ValueError("input_loss_to_preview_s must be in [0.2, 10] seconds (longer than the pipeline's stale "
                             "limit, short enough that nobody has looked away), got "
                             f"{self.input_loss_to_preview_s!r}")


@dataclass(frozen=True)
class SensorFrame:
    """Where a sensor's frame sits in the robot's tree (its calibrated extrinsics): [frames.<name>], name a
    camera device (its images' frame) or "suit" (the suit's world frame, in which wrist poses are given)."""

    parent: str = ""  # a link of the robot; "": its root (the arm's base)
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)  # metres, in the parent frame
    rpy: tuple[float, float, float] | None = None  # radians (fixed-axis roll, pitch, yaw) ...
    look_at: tuple[float, float, float] | None = None  # ... or a camera's optical frame (z forward, y down) aimed here

    def __post_init__(self):
        if self.rpy is not None and self.look_at is not None:
            raise ValueError("give rpy or look_at, not both")
        for key in ("xyz", "look_at"):
            value = getattr(self, key)
            if value is not None and not all(abs(v) <= FRAME_REACH_M for v in value):
                raise ValueError(
                    f"{key} must be within ±{FRAME_REACH_M:g} m of the parent frame (metres), got {list(value)}"
                )
        if self.rpy is not None and not all(abs(v) <= 2 * math.pi for v in self.rpy):
            raise ValueError(f"rpy is in radians, each within ±2π; got {list(self.rpy)} (degrees?)")
        if self.look_at is not None and tuple(self.look_at) == tuple(self.xyz):
            raise ValueError("look_at is the frame's own position: a camera cannot look at itself")


@dataclass(frozen=True)
class DeviceEntry:
    name: str
    plugin: str
    kind: str
    cls: type
    settings: Any


@dataclass(frozen=True)
class Rig:
    path: Path | None
    rig: RigSection
    pipeline: PipelineConfig
    devices: dict[str, DeviceEntry]
    raw: dict = field(default_factory=dict)  # the file's content, recorded as session metadata
    frames: dict[str, SensorFrame] = field(default_factory=dict)  # [frames.<name>]: sensors in the robot's tree
    tasks: dict[str, str] = field(default_factory=dict)  # [tasks]: task id -> the instruction in words
    text: str | None = None  # the TOML, for a rig read from text (a session's recorded rig has no file)
    sim: SimSection = field(default_factory=SimSection)  # [sim]: the world the sim devices live in
    session: SessionSection = field(default_factory=SessionSection)  # [session]
    sides: dict = field(default_factory=dict)  # [sides.left], [sides.right] (teleprev/sides.py); {}: single-arm

    @property
    def bimanual(self) -> bool:
        return bool(self.sides)

    def check_task(self, task: str, where: str) -> None:
        """Refuse a task label that a device of this rig has to act out and does not know (a simulated
        operator knows five; a device whose settings have `episode_tasks()` names what it knows)."""
        import difflib

        for d in self.devices.values():
            known = d.settings.episode_tasks() if hasattr(d.settings, "episode_tasks") else ()
            if known and task not in known:
                close = difflib.get_close_matches(task, known, 1)
                hint = f"; did you mean {close[0]!r}?" if close else ""
                raise ConfigError(f"task {task!r} is not one device {d.name!r} ({d.plugin}) performs: "
                                  f"{', '.join(known)}{hint}", where)

    def task_text(self, task: str) -> str:
        """The natural-language instruction of a task id ([tasks]); the id itself when the rig has none."""
        return self.tasks.get(task, task)

    @property
    def dir(self) -> Path:
        return self.path.parent if self.path else Path(".")

    def of_kind(self, kind: str) -> list[DeviceEntry]:
        return [d for d in self.devices.values() if d.kind == kind]

    def require(self, *kinds: str) -> None:
        """Fail clearly unless the rig has at least one device of each kind."""
        missing = [k for k in kinds if not self.of_kind(k)]
        if missing:
            where = str(self.path) if self.path else "rig"
            raise ConfigError(f"the rig has no {' and no '.join(missing)} device (add a [devices.<name>] table)", where)

    @property
    def effector(self) -> EndEffector:
        return end_effector(self.rig.end_effector)

    def with_device_settings(self, plugin_family: str, option: str, **changes) -> Rig:
        """This rig with `changes` made to the settings of every device of a plugin family: a command-line
        `option` (e.g. record --webxr-host, family "webxr") over the rig file. A ConfigError naming the option
        when no device is of the family or the settings refuse the value."""
        family = {name: d for name, d in self.devices.items() if d.plugin.split(".")[0] == plugin_family}
        if not family:
            raise ConfigError(f"{option}: the rig has no {plugin_family}.* device", str(self.path or "rig"))
        devices = dict(self.devices)
        for name, d in family.items():
            try:
                devices[name] = replace(d, settings=replace(d.settings, **changes))
            except (ValueError, TypeError) as exc:
                raise ConfigError(f"{option}: {exc}") from None
        return replace(self, devices=devices)

    def device_context(self, clock: SessionClock) -> DeviceContext:
        """What every device of this rig is opened with: the clock, the rig's folder, robot and end effector,
        and the physics world when [sim] asks for one (started when a device first uses it)."""
        physics = None
        if self.sim.world == "physics":
            physics = PhysicsAccess(clock, self.rig.end_effector, self.sim.rate_hz, self.rig.task)
        return DeviceContext(clock, self.dir, {}, self.rig.robot, self.rig.end_effector, physics=physics)

    def device_sides(self) -> dict[str, str]:
        """A bimanual rig's devices that belong to a side: device name -> "left" | "right"."""
        return {name: side for side, s in self.sides.items() for name in s.device_names}

    def side_contexts(self, context: DeviceContext) -> dict[str, DeviceContext]:
        """A bimanual rig's device context per side, for the devices of that side: its robot and end effector,
        its own `shared` (its own sim world), and `context`'s clock, operator link and network sockets."""
        return {side: DeviceContext(context.clock, self.dir, {}, s.robot, s.section.end_effector,
                                    operator=context.operator, receivers=context.receivers)
                for side, s in self.sides.items()}

    def open_devices(self, names, context: DeviceContext, contexts: dict[str, DeviceContext]) -> dict:
        """The named devices (name -> plugin instance), each opened with its side's context, else `context`."""
        sides = self.device_sides()
        return {name: self.devices[name].cls(name, self.devices[name].settings,
                                             contexts[sides[name]] if name in sides else context) for name in names}

    def resolve(self, relative: str) -> Path:
        """A path from the rig file, relative to the rig file's folder."""
        p = Path(relative)
        return p if p.is_absolute() else self.dir / p


@dataclass(frozen=True)
class SideRig(Rig):
    """One side of a bimanual rig seen as a single-arm rig (teleprev/sides.py: side_rig)."""

    side: Any = None  # teleprev.sides.Side

    @property
    def effector(self) -> EndEffector:
        return self.side.effector


def side_rig(rig: Rig, side: str) -> SideRig:
    """One side of a bimanual rig as a single-arm rig: its robot, end effector, [pipeline] and calibration,
    the devices of this side and those of no side (cameras). What build_pipeline, motion_limits and the
    checks of a single-arm rig take."""
    s = rig.sides[side]
    other = set().union(*(o.device_names for n, o in rig.sides.items() if n != side))
    mine = s.device_names
    devices = {n: d for n, d in rig.devices.items() if n in mine or n not in other}
    section = replace(rig.rig, robot=s.robot, end_effector=s.section.end_effector,
                      calibration=s.section.calibration or rig.rig.calibration)
    out = SideRig(rig.path, section, s.pipeline, devices, rig.raw, rig.frames, rig.tasks, rig.text, rig.sim,
                  rig.session, side=s)
    check_single_arm(out, f"{rig.path or 'rig'} [sides.{side}]")
    return out


def check_single_arm(rig: Rig, where: str) -> None:
    """The checks parse_rig makes of a single-arm rig's robot and motion limits (a side of a bimanual one)."""
    _check_robot(rig.rig, rig.pipeline, where)
    _check_motion_limits(rig.rig, rig.pipeline, where)
    _check_device_motion_limits({n: d for n, d in rig.devices.items()}, rig.rig, where)


def default_rig_path() -> Path:
    return data_dir("rigs") / "sim.toml"


def load_rig(path: str | Path | None = None) -> Rig:
    """A rig file, every key and value checked, the files it names included."""
    path = Path(path) if path else default_rig_path()
    rig = parse_rig(read_toml(path), path)
    for key, what, exists in (("calibration", "file", Path.is_file), ("models", "folder", Path.is_dir)):
        value = getattr(rig.rig, key)
        if value and not exists(rig.resolve(value)):
            raise ConfigError(f"no such {what} {str(rig.resolve(value))!r}", f"{path} [rig].{key}")
    for name, side in rig.sides.items():
        value = side.section.calibration
        if value and not rig.resolve(value).is_file():
            raise ConfigError(f"no such file {str(rig.resolve(value))!r}", f"{path} [sides.{name}].calibration")
    return rig


def load_rig_text(text: str, where: str, path: Path | None = None) -> Rig:
    """A rig from TOML text (e.g. the copy a session keeps in its metadata); `path` anchors relative paths.

    Rigs recorded before `[pipeline] trigger` was removed carry it; it never had an effect, so it is dropped.
    """
    import tomllib

    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"not valid TOML ({exc})", where) from None
    if isinstance(data.get("pipeline"), dict):
        data["pipeline"].pop("trigger", None)
    return replace(parse_rig(data, path, where), text=text)


def load_recorded_rig(metadata: dict, session: Path) -> Rig | None:
    """The rig a session carries in its metadata (None without one). Its contents are the session's, not
    the user's: the rig is anchored at the session's own folder (never at the path the metadata names),
    its calibration and models paths are refused if they lead out of that folder, and its robot must be
    the name of a URDF in urdf/."""
    text = metadata.get("rig", {}).get("toml")
    if not text:
        return None
    import tomllib

    session = Path(session)
    where = f"{session}: recorded rig"
    try:  # the robot is checked before the rig is loaded: loading opens the URDF it names
        robot = tomllib.loads(text).get("rig", {}).get("robot", "")
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"not valid TOML ({e})", where) from None
    if not isinstance(robot, str) or Path(robot).name != robot or robot in (".", ".."):
        raise ConfigError(f"[rig] robot {robot!r} is a path; a recorded rig may only name a URDF in urdf/ "
                          "(pass --config RIG to use another)", where)
    rig = load_rig_text(text, where, session.parent / f"{session.stem}.recorded-rig.toml")
    for key in ("calibration", "models"):
        value = getattr(rig.rig, key)
        if value:
            inside(session.parent, value, f"[rig] {key}", where)
    return rig


def parse_rig(data: dict, path: Path | None, where: str | None = None) -> Rig:
    where = where or str(path)
    unknown = sorted(set(data) - {"rig", "session", "pipeline", "devices", "frames", "tasks", "sim", "sides"})
    if unknown:
        raise ConfigError(f"unknown table [{unknown[0]}] (expected [rig], [session], [pipeline], [devices.<name>], "
                          "[frames.<name>], [tasks], [sim] and [sides.<left|right>])", where)
    rig = from_table(RigSection, data.get("rig", {}), f"{where} [rig]")
    session = from_table(SessionSection, data.get("session", {}), f"{where} [session]")
    sim = from_table(SimSection, data.get("sim", {}), f"{where} [sim]")
    if isinstance(data.get("pipeline"), dict) and "trigger" in data["pipeline"]:
        raise ConfigError("unknown key 'trigger': it was removed (a pipeline step runs on every glove sample); "
                          "delete the line", f"{where} [pipeline]")
    pipeline = from_table(PipelineConfig, data.get("pipeline", {}), f"{where} [pipeline]")
    _check_robot(rig, pipeline, where)
    _check_motion_limits(rig, pipeline, where)
    devices_table = data.get("devices", {})
    if not isinstance(devices_table, dict) or not devices_table:
        raise ConfigError("no devices: add at least one [devices.<name>] table", where)
    devices = {}
    for name, table in devices_table.items():
        dwhere = f"{where} [devices.{name}]"
        if not isinstance(table, dict):
            raise ConfigError("expected a table", dwhere)
        if "plugin" not in table:
            raise ConfigError("missing required key 'plugin' (e.g. plugin = \"sim.glove\")", dwhere)
        settings_table = {k: v for k, v in table.items() if k != "plugin"}
        cls = load_plugin(table["plugin"], dwhere)
        if getattr(cls, "kind", None) not in KINDS:
            raise ConfigError(f"plugin {table['plugin']!r} declares no valid kind", dwhere)
        settings = from_table(cls.Settings, settings_table, dwhere)
        devices[name] = DeviceEntry(name, table["plugin"], cls.kind, cls, settings)
    _check_device_motion_limits(devices, rig, where)
    frames_table = data.get("frames", {})
    if not isinstance(frames_table, dict):
        raise ConfigError("expected [frames.<name>] tables", f"{where} [frames]")
    frames = {name: from_table(SensorFrame, table, f"{where} [frames.{name}]") for name, table in frames_table.items()}
    tasks = from_table(_Tasks, {"tasks": data.get("tasks", {})}, f"{where}").tasks
    for name in frames:
        if name != "suit" and (name not in devices or devices[name].kind != "camera"):
            raise ConfigError("names no camera of this rig (a [frames] table is a camera device's name, or suit)",
                              f"{where} [frames.{name}]")
    from teleprev.sides import parse_sides

    sides = parse_sides(data.get("sides"), data.get("pipeline", {}), devices, where)
    out = Rig(path.resolve() if path else None, rig, pipeline, devices, data, frames, tasks, session=session,
              sim=sim, sides=sides)
    for name in sides:
        side_rig(out, name)  # each side's robot and limits checked as a single-arm rig's
    out.check_task(rig.task, f"{where} [rig].task")
    return out


@dataclass(frozen=True)
class _Tasks:
    tasks: dict[str, str] = field(default_factory=dict)


def _check_robot(rig: RigSection, pipeline: PipelineConfig, where: str) -> None:
    """The robot's URDF exists and has the link the wrist drives."""
    urdf = resolve_urdf(rig.robot)
    if not urdf.is_file():
        raise ConfigError(
            f"no such robot {rig.robot!r} (a URDF path, or the name of one in urdf/)", f"{where} [rig].robot"
        )
    if pipeline.tcp_link and pipeline.tcp_link not in load_robot(urdf).links:
        raise ConfigError(f"the robot {rig.robot!r} has no link {pipeline.tcp_link!r}", f"{where} [pipeline].tcp_link")


# Motion limits of a robot that teleprev/robot/limits.py does not know: no arm or hand goes past these.
MAX_ARM_ACCELERATION, MAX_ARM_JERK, MAX_HAND_ACCELERATION = 100.0, 10_000.0, 2000.0
MAX_ARM_TCP_SPEED = 5.0  # m/s


def _check_motion_limits(rig: RigSection, pipeline: PipelineConfig, where: str) -> None:
    """A motion limit may tighten the robot's own (teleprev/robot/limits.py), never loosen it: a looser one
    sends commands the controller faults on. For a robot the table lacks, a bound no robot goes past."""
    arm, effector = arm_limits(rig.robot), effector_limits(rig.end_effector)
    for key, row, bound, unit in (
        ("arm_acceleration", arm.acceleration if arm else None, MAX_ARM_ACCELERATION, "rad/s²"),
        ("arm_jerk", arm.jerk if arm else None, MAX_ARM_JERK, "rad/s³"),
        ("arm_tcp_speed", arm.tcp_speed if arm else None, MAX_ARM_TCP_SPEED, "m/s"),
        (
            "hand_acceleration",
            effector.acceleration if effector else None,
            MAX_HAND_ACCELERATION,
            "rad/s² (m/s² for a gripper)",
        ),
    ):
        value = getattr(pipeline, key)
        if value is None:
            continue
        if row is not None and value > row:
            raise ConfigError(f"{value:g} {unit} is looser than the robot's own limit ({row:g}, "
                              "teleprev/robot/limits.py); a rig may only tighten it", f"{where} [pipeline].{key}")
        if value > bound:
            raise ConfigError(
                f"{value:g} {unit} is more than any robot takes (at most {bound:g})", f"{where} [pipeline].{key}"
            )


# A device's own motion-limit settings (what its controller runs at, or faults past), by the names plugins
# give them: each is checked against the robot's physical number, as [pipeline]'s are.
DEVICE_MOTION_KEYS = {"max_velocity": "speed", "max_speed": "speed", "max_acceleration": "acceleration",
                      "max_accel": "acceleration", "max_jerk": "jerk"}


@dataclass(frozen=True)
class _Bound:
    value: float
    unit: str
    source: str  # where the number comes from
    zero_means_default: bool = False  # 0 is allowed: "the robot's own"


def _device_bound(kind: str, quantity: str, rig: RigSection) -> _Bound | None:
    """The robot's physical limit for a device of `kind` (arm, hand); None where it has none (a switch)."""
    effector = end_effector(rig.end_effector)
    if kind == "hand" and effector.is_switch:
        return None
    if quantity == "speed":
        model = load_robot(rig.robot)
        joints = [n for n in model.joint_names if (n in effector.joints) == (kind == "hand")]
        if not joints:
            return None
        unit = "m/s" if kind == "hand" and rig.end_effector == "parallel_gripper" else "rad/s"
        return _Bound(float(model.velocity_limit[model.indices(joints)].min()), unit,
                      f"the URDF's velocity limit of {rig.robot}", zero_means_default=True)
    if kind == "arm":
        row = arm_limits(rig.robot)
        number = (row.acceleration if row else MAX_ARM_ACCELERATION) if quantity == "acceleration" else \
            (row.jerk if row else MAX_ARM_JERK)
        unit = "rad/s²" if quantity == "acceleration" else "rad/s³"
    elif quantity == "acceleration":
        row = effector_limits(rig.end_effector)
        if row is not None and row.acceleration is None:
            return None
        number, unit = (row.acceleration if row else MAX_HAND_ACCELERATION), "rad/s² (m/s² for a gripper)"
    else:
        return None  # no hand has a jerk number
    source = f"{rig.robot}'s limit, teleprev/robot/limits.py" if row is not None else "more than any robot takes"
    return _Bound(number, unit, source)


def _check_device_motion_limits(devices: dict[str, DeviceEntry], rig: RigSection, where: str) -> None:
    """An arm's or hand's own speed, acceleration and jerk settings within the robot's physical numbers: a
    looser one would let the device run, or stop faulting, past what the robot takes (max_jerk = 1e308)."""
    for name, entry in devices.items():
        if entry.kind not in ("arm", "hand"):
            continue
        for key, quantity in DEVICE_MOTION_KEYS.items():
            value = getattr(entry.settings, key, None)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                continue
            bound = _device_bound(entry.kind, quantity, rig)
            if bound is None:
                continue
            low = 0 <= value if bound.zero_means_default else 0 < value
            if not (low and value <= bound.value):
                span = f"{'[0' if bound.zero_means_default else '(0'}, {bound.value:g}] {bound.unit}"
                default = " (0: the URDF's)" if bound.zero_means_default else ""
                raise ConfigError(f"{value:g} is outside the robot's range: {key} must be in {span}{default}, "
                                  f"from {bound.source}", f"{where} [devices.{name}].{key}")
