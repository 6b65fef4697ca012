"""Export recipes (TOML, in datasets/recipes/): which recorded streams become which LeRobot features.

    [export]
    fps = 0                       # frames per second; 0: the reference camera's rate (30 without camera)
    reference_camera = ""         # the camera whose frames set the frame times; "": the first camera
    max_gap_ms = 100.0            # a stream silent for longer than this around a frame makes a gap
    on_gap = "split"              # split the episode at a gap | drop the episode | fail the export
    min_episode_s = 0.5           # shorter pieces (after trimming and splitting) are left out

    [video]                       # see teleprev/export/video.py: codec, crf, preset, gop, ...
    codec = "h264"

    [[feature]]
    name = "observation.state"
    streams = ["arm_state", "effector_state"]    # values concatenated in this order

    [[feature]]
    name = "action"
    streams = ["arm_command", "effector_command"]

    [[feature]]
    name = "observation.images.{camera}"          # one video feature per camera
    streams = ["camera:*"]

    [[feature]]
    name = "observation.images.{camera}_depth"    # LeRobot's name for a camera's depth map
    streams = ["depth:*"]                         # or "depth:wrist": the cameras whose depth is exported

A depth stream (a depth camera's /camera/<name>/depth, teleprev/topics.py) becomes a LeRobot depth-map video:
shape (H, W, 1), info is_depth_map, in metres (the session's unit times its scale), quantised and encoded by
lerobot's own depth encoder (12-bit log quantisation, lossless HEVC), so LeRobotDataset reads it back in
metres to within the quantisation step.

Streams are named by role, so one recipe fits any rig: the role is looked up among the session's topics
(device names come from the topic layout, teleprev/session/topics.py). A role names the device when the
rig has several of its kind ("arm_state:left"), otherwise the one device (or the one the pipeline used)
is taken. A stream may also be given by its topic ("/arm/left/state").

In a bimanual session (its "sides" metadata record), a joint or wrist role named without a device is taken
once per side, all of the left side's streams first, its joints named "left_<prefix>.<joint>" as LeRobot's
bimanual robots name theirs: the default recipe gives one `action` of left_arm.joint1 .. right_hand.15.

A feature's `timing` is "action" for features named action / action.*, "observation" otherwise:
observations use the latest sample at or before the frame's time, actions the commanded trajectory at
the frame's time (the commands sampled where the frames are, see timeline.py), so a dataset's actions
keep the robot's motion limits at the dataset's fps. `timing = "sent"` takes instead the first command
sent in the frame (the raw command stream, as recorded), and `timing = "next"` derives an action from a
state stream: the value the stream has at the next frame's time (where the robot went), for recordings
without commands.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from teleprev import topics as T
from teleprev.config import from_table, read_toml
from teleprev.errors import ConfigError, SessionError
from teleprev.export.video import VideoSettings
from teleprev.paths import data_dir
from teleprev.session.summary import PREVIEW_ONLY, is_preview_only

JOINTS, POSE, IMAGE = "foxglove.JointStates", "foxglove.PoseInFrame", "foxglove.CompressedImage"
DEPTH = "depth"  # a Source's schema for a depth stream (recorded as foxglove.RawImage, or a PNG CompressedImage)
DEPTH_SCHEMAS = ("foxglove.RawImage", IMAGE)
POSE_NAMES = ("x", "y", "z", "qx", "qy", "qz", "qw")  # a pose as 7 values: position, quaternion x y z w
LEROBOT_RESERVED = ("timestamp", "frame_index", "episode_index", "index", "task_index", "task")


@dataclass(frozen=True)
class Role:
    """A kind of recorded stream: a device stream (kind, stream) or a fixed pipeline topic."""

    schema: str
    prefix: str  # joint names in the feature become "<prefix>.<joint>"
    kind: str = ""
    stream: str = ""
    topic: str = ""
    pipeline_input: str = ""  # key of the "pipeline" metadata's inputs naming the device the pipeline used


ROLES: dict[str, Role] = {
    "arm_state": Role(JOINTS, "arm", kind="arm", stream="state", pipeline_input="arm"),
    "effector_state": Role(JOINTS, "hand", kind="hand", stream="state", pipeline_input="effector"),
    "glove": Role(JOINTS, "glove", kind="glove", stream="hand", pipeline_input="hand"),
    "wrist": Role(POSE, "wrist", kind="suit", stream="wrist", pipeline_input="wrist"),
    "body": Role(JOINTS, "body", kind="suit", stream="body"),
    "camera": Role(IMAGE, "", kind="camera", stream="image"),
    "depth": Role(DEPTH, "", kind="camera", stream="depth"),
    "arm_command": Role(JOINTS, "arm", topic=T.COMMAND_ARM),
    "effector_command": Role(JOINTS, "hand", topic=T.COMMAND_HAND),
    "arm_target": Role(JOINTS, "arm_target", topic=T.ARM_TARGET),
    "retargeted": Role(JOINTS, "retargeted", topic=T.RETARGETED),
    "corrected": Role(JOINTS, "corrected", topic=T.CORRECTED),
}


@dataclass(frozen=True)
class ExportSection:
    fps: int = 0
    reference_camera: str = ""
    max_gap_ms: float = 100.0
    on_gap: Literal["split", "drop", "fail"] = "split"
    min_episode_s: float = 0.5

    def __post_init__(self):
        if not 0 <= self.fps <= 1000:
            raise ValueError(f"fps must be 1..1000 (0: the camera's rate), got {self.fps}")
        if not (math.isfinite(self.max_gap_ms) and self.max_gap_ms > 0):  # NaN fails every comparison
            raise ValueError(f"max_gap_ms must be a finite number > 0, got {self.max_gap_ms:g}")
        if not (math.isfinite(self.min_episode_s) and self.min_episode_s >= 0):
            raise ValueError(f"min_episode_s must be a finite number >= 0, got {self.min_episode_s:g}")


@dataclass(frozen=True)
class FeatureSpec:
    name: str
    streams: tuple[str, ...]
    timing: Literal["", "observation", "action", "sent", "next"] = ""  # "": by the name (see the module doc)

    def __post_init__(self):
        if not self.name or not self.streams:
            raise ValueError("a feature needs a name and at least one stream")

    @property
    def is_action(self) -> bool:
        if self.timing:
            return self.timing in ("action", "sent", "next")
        return self.name == "action" or self.name.startswith("action.")


@dataclass(frozen=True)
class Recipe:
    feature: tuple[FeatureSpec, ...]
    export: ExportSection = field(default_factory=ExportSection)
    video: VideoSettings = field(default_factory=VideoSettings)
    description: str = ""
    path: str = ""  # where it was read from (not a TOML key)


def recipes_dir() -> Path:
    return data_dir("datasets") / "recipes"


def load_recipe(which: str | Path | None = None) -> Recipe:
    """A recipe file, or the name of one in datasets/recipes/ ("default", "with_glove"); None: the default."""
    path = Path(which) if which else recipes_dir() / "default.toml"
    if not path.is_file() and which and path.suffix == "" and len(path.parts) == 1:
        path = recipes_dir() / f"{which}.toml"
    if not path.is_file():
        known = ", ".join(sorted(p.stem for p in recipes_dir().glob("*.toml"))) or "none"
        raise ConfigError(f"no such recipe file (recipes in {recipes_dir()}: {known})", str(which))
    return recipe_from_table(read_toml(path), path)


def recipe_from_table(data: dict, path: str | Path) -> Recipe:
    """A recipe from its TOML table (checked as load_recipe checks a file); `path` names it in errors."""
    if "path" in data:
        raise ConfigError("unknown key 'path'", str(path))
    if "import" in data:
        raise ConfigError("an import recipe (it has an [import] table): use it with `teleprev import`", str(path))
    recipe = from_table(Recipe, data, str(path))
    names = [f.name for f in recipe.feature]
    for f in recipe.feature:
        where = f"{path} [[feature]] {f.name!r}"
        if names.count(f.name) > 1:
            raise ConfigError("feature defined twice", where)
        if f.name in LEROBOT_RESERVED or "/" in f.name:
            raise ConfigError(
                f"not a usable feature name (reserved by LeRobot: {', '.join(LEROBOT_RESERVED)}; no '/')", where
            )
        for s in f.streams:
            _parse_stream(s, where)
    return Recipe(recipe.feature, recipe.export, recipe.video, recipe.description, str(path))


def _parse_stream(text: str, where: str) -> tuple[str, str]:
    """(role, device) of a stream entry, or ("", topic) for a topic."""
    if text.startswith("/"):
        return "", text
    role, _, device = text.partition(":")
    if role not in ROLES:
        raise ConfigError(
            f"unknown stream {text!r} (roles: {', '.join(ROLES)}; or a topic such as /arm/arm/state)", where
        )
    if device and ROLES[role].topic:
        raise ConfigError(f"{role!r} is a pipeline stream, not a device's: write it without ':{device}'", where)
    return role, device


# --- resolution against a session -------------------------------------------------------------------


@dataclass(frozen=True)
class Source:
    """One recorded stream feeding (part of) a feature."""

    entry: str  # as the recipe wrote it
    topic: str
    schema: str
    prefix: str


@dataclass(frozen=True)
class ResolvedFeature:
    name: str
    is_action: bool
    sources: tuple[Source, ...]
    next_frame: bool = False  # timing "next": the stream's value at the next frame (an action derived from states)
    sent: bool = False  # timing "sent": the first command sent in the frame (the raw command stream)

    @property
    def is_image(self) -> bool:
        """A colour camera's video."""
        return self.sources[0].schema == IMAGE

    @property
    def is_depth(self) -> bool:
        """A depth camera's depth-map video."""
        return self.sources[0].schema == DEPTH

    @property
    def is_video(self) -> bool:
        return self.sources[0].schema in (IMAGE, DEPTH)


def resolve(
    recipe: Recipe, session_topics: dict, metadata: dict[str, dict[str, str]], where: str
) -> list[ResolvedFeature]:
    """The recipe's features with their topics in this session. `session_topics` maps topic -> info with
    a `.schema` (SessionReader.topics). Raises SessionError naming what the session lacks."""
    schemas = {t: info.schema for t, info in session_topics.items()}
    devices: dict[str, list[str]] = {}
    for topic in schemas:
        parsed = T.parse_device_topic(topic)
        if parsed:
            devices.setdefault(f"{parsed[0]}/{parsed[2]}", []).append(parsed[1])
    try:
        inputs = json.loads(metadata.get("pipeline", {}).get("inputs", "{}"))
    except json.JSONDecodeError:
        inputs = {}
    out: list[ResolvedFeature] = []
    what = "file" if "import" in metadata else "session"  # a recording teleprev did not make is no session
    sides = recorded_sides(metadata, where)
    for spec in recipe.feature:
        fwhere = f"{where}: feature {spec.name!r}"
        sources: list[Source] = []
        per_side = [e for e in spec.streams if _is_side_role(e)] if sides else []
        for side in sides if per_side else ():  # all of the left side's values first, as LeRobot's bi_* robots
            sources.extend(side_source(entry, side, sides[side], schemas, fwhere, what) for entry in per_side)
        for entry in spec.streams:
            if entry not in per_side:
                sources.extend(_sources(entry, schemas, devices, inputs, fwhere, what))
        images = [s for s in sources if s.schema in (IMAGE, DEPTH)]
        if images and len(images) != len(sources):
            raise ConfigError(
                f"mixes camera and joint streams ({', '.join(spec.streams)}); give cameras their own feature",
                f"{recipe.path} [[feature]] {spec.name!r}",
            )
        if images:
            if len(images) > 1 and "{camera}" not in spec.name:
                raise ConfigError("takes several cameras: put {camera} in its name, e.g. observation.images.{camera}",
                                  f"{recipe.path} [[feature]] {spec.name!r}")
            for s in images:
                out.append(ResolvedFeature(spec.name.replace("{camera}", s.prefix), False, (s,)))
        elif sources:
            out.append(ResolvedFeature(spec.name, spec.is_action, tuple(sources), spec.timing == "next",
                                       spec.timing == "sent"))
    names = [f.name for f in out]
    dup = next((n for n in names if names.count(n) > 1), None)
    if dup:
        raise ConfigError(f"two features are named {dup!r}", recipe.path)
    if not any(not f.is_video for f in out):
        raise ConfigError("the recipe gives no joint feature (a LeRobot dataset needs at least one)", recipe.path)
    return out


def _sources(entry: str, schemas: dict[str, str], devices: dict[str, list[str]], inputs: dict, where: str,
             what: str = "session") -> list[Source]:
    role_name, device = _parse_stream(entry, where)
    if not role_name:  # a topic
        topic = device
        if topic not in schemas:
            has = ", ".join(sorted(schemas)) if schemas else "none"
            raise SessionError(f"no topic {topic} in this {what} (its topics: {has})", where)
        parsed = T.parse_device_topic(topic)
        prefix = parsed[1] if parsed else topic.strip("/").split("/")[-1]
        if (parsed and parsed[0] == "camera" and parsed[2] == "depth") or schemas[topic] == DEPTH_SCHEMAS[0]:
            return [_checked(entry, topic, schemas, DEPTH, prefix, where)]
        if schemas[topic] not in (JOINTS, POSE, IMAGE):
            raise SessionError(f"{topic} holds {schemas[topic]} messages, expected {JOINTS}, {POSE} or {IMAGE}"
                               f"{_import_hint(schemas[topic])}", where)
        return [Source(entry, topic, schemas[topic], prefix)]
    role = ROLES[role_name]
    if role.topic:
        if role.topic not in schemas:
            hint = ""
            if role.topic.startswith("/command/"):
                hint = (
                    f": {PREVIEW_ONLY}" if is_preview_only(schemas) else " (commands are recorded only in execute mode)"
                )
            raise SessionError(f"stream {entry!r} ({role.topic}) is not in this session{hint}", where)
        return [_checked(entry, role.topic, schemas, role.schema, role.prefix, where)]
    found = sorted(devices.get(f"{role.kind}/{role.stream}", []))
    if device == "*":
        if role_name not in ("camera", "depth"):
            raise ConfigError(f"'{entry}': only cameras can be taken all at once", where)
        return [_checked(f"{role_name}:{d}", T.device_topic("camera", d, role.stream), schemas, role.schema, d, where)
                for d in found]
    if device:
        if device not in found:
            raise SessionError(f"stream {entry!r}: no {role.kind} device {device!r} with a {role.stream} stream "
                               f"in this session (found: {', '.join(found) or 'none'})", where)
        return [_checked(entry, T.device_topic(role.kind, device, role.stream), schemas, role.schema, device, where)]
    if not found:
        raise SessionError(f"stream {entry!r}: this session has no {role.kind} device with a {role.stream} stream "
                           f"(topics: {', '.join(sorted(schemas))})", where)
    if len(found) > 1:
        used = inputs.get(role.pipeline_input) if role.pipeline_input else None
        parsed = T.parse_device_topic(used) if isinstance(used, str) else None
        if not parsed or parsed[1] not in found:
            raise SessionError(f"stream {entry!r}: the session has {len(found)} {role.kind} devices "
                               f"({', '.join(found)}); name one, e.g. '{role_name}:{found[0]}'", where)
        found = [parsed[1]]
    prefix = found[0] if role_name in ("camera", "depth") else role.prefix
    return [_checked(entry, T.device_topic(role.kind, found[0], role.stream), schemas, role.schema, prefix, where)]


def recorded_sides(metadata: dict[str, dict[str, str]], where: str) -> dict[str, dict[str, str]]:
    """A bimanual session's sides (its "sides" record: side -> role -> device), left first; {} for one arm."""
    from teleprev.sides import SIDES

    record = metadata.get("sides") or {}
    try:
        return {side: json.loads(record[side]) for side in SIDES if side in record}
    except json.JSONDecodeError as exc:
        raise SessionError(f"the sides record is not JSON ({exc})", where) from None


# A side's device for each per-device role: the role's pipeline input -> the side's device role
_SIDE_DEVICE = {"arm": "arm", "effector": "hand", "hand": "glove", "wrist": "suit"}


def _is_side_role(entry: str) -> bool:
    """A recipe stream that a bimanual session has once per side: a joint or wrist role named without a device."""
    role = ROLES.get(entry)
    return role is not None and role.schema in (JOINTS, POSE) and (bool(role.topic) or role.pipeline_input != "")


def side_source(entry: str, side: str, devices: dict[str, str], schemas: dict[str, str], where: str,
                what: str = "session") -> Source:
    """A role's stream on one side of a bimanual session, its joints named as LeRobot's bimanual robots name
    theirs: "left_arm.joint1", ..., "right_hand.15" (the side's prefix before the role's)."""
    from teleprev.pipeline.bimanual import side_topic

    role = ROLES[entry]
    if role.topic:
        topic = side_topic(role.topic, side)
    else:
        topic = T.device_topic(role.kind, devices.get(_SIDE_DEVICE[role.pipeline_input], ""), role.stream)
    if topic not in schemas:
        hint = f": {PREVIEW_ONLY}" if role.topic.startswith("/command/") and is_preview_only(schemas) else ""
        raise SessionError(f"stream {entry!r} of the {side} side ({topic}) is not in this {what}{hint}", where)
    return _checked(f"{entry}:{side}", topic, schemas, role.schema, f"{side}_{role.prefix}", where)


def _checked(entry: str, topic: str, schemas: dict[str, str], schema: str, prefix: str, where: str) -> Source:
    if schema == DEPTH and schemas[topic] in DEPTH_SCHEMAS:
        return Source(entry, topic, DEPTH, prefix)
    if schema == DEPTH:
        raise SessionError(f"stream {entry!r} ({topic}) holds {schemas[topic]} messages, expected a depth image "
                           f"({' or '.join(DEPTH_SCHEMAS)}){_import_hint(schemas[topic])}", where)
    if schemas[topic] != schema:
        raise SessionError(f"stream {entry!r} ({topic}) holds {schemas[topic]} messages, expected {schema}"
                           f"{_import_hint(schemas[topic])}", where)
    return Source(entry, topic, schema, prefix)


def _import_hint(schema: str) -> str:
    return " (a ROS recording: bring it in with `teleprev import`)" if "/msg/" in schema else ""
