"""Import recipes: an export recipe (teleprev/export/recipe.py: [export], [video], [[feature]] naming
topics) plus an [import] table saying how to read the foreign files:

    [import]
    episodes = "file"            # file: one episode per file | events: from events_topic | gaps: split at silences
    events_topic = ""            # episodes = "events": a topic of std_msgs/String (or JSON) "start" / "stop"
    gap_s = 1.0                  # episodes = "gaps": a silence longer than this on gap_topic ends an episode
    gap_topic = ""               # "": the first joint stream of the recipe
    timestamps = "header"        # header: the messages' own stamps (log time where a stamp is 0) | log: log time
    task = "pick up the cube and place it in the bowl"   # the episodes' task (natural language)
    robot_type = ""              # "": the URDF's robot name, else "unknown"
    urdf = ""                    # a URDF path or a name in urdf/: joint streams keep its actuated joints, in its order
    [import.joints]              # or name them per topic (this order); both absent: every joint, as recorded
    "/joint_states" = ["joint1", "joint2"]
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from teleprev.config import from_table, read_toml
from teleprev.errors import ConfigError, SessionError
from teleprev.export.recipe import Recipe, recipe_from_table
from teleprev.paths import data_dir


@dataclass(frozen=True)
class ImportSection:
    episodes: Literal["file", "events", "gaps"] = "file"
    events_topic: str = ""
    gap_s: float = 1.0
    gap_topic: str = ""
    timestamps: Literal["header", "log"] = "header"
    task: str = ""
    robot_type: str = ""
    urdf: str = ""
    joints: dict[str, list[str]] = field(default_factory=dict)

    def __post_init__(self):
        if self.gap_s <= 0:
            raise ValueError(f"gap_s must be > 0, got {self.gap_s}")
        if self.episodes == "events" and not self.events_topic:
            raise ValueError('episodes = "events" needs events_topic')


@dataclass(frozen=True)
class ImportRecipe:
    recipe: Recipe
    section: ImportSection
    urdf_joints: tuple[str, ...] = ()  # the URDF's actuated joints, in its order
    urdf_robot: str = ""

    @property
    def robot_type(self) -> str:
        return self.section.robot_type or self.urdf_robot or "unknown"

    def joint_order(self, topic: str) -> tuple[str, ...]:
        """The joints a stream is given with (empty: as recorded)."""
        return tuple(self.section.joints.get(topic, ())) or self.urdf_joints

    def select_joints(self, topic: str, seen: tuple[str, ...], where: str) -> tuple[str, ...]:
        """The joints a joint stream that has `seen` (in their recorded order) is given with: the recipe's
        [import.joints] list (each must be there) or the URDF's joints it has, in that order; every joint as
        recorded when the recipe names neither."""
        wanted = self.joint_order(topic)
        if not wanted:
            return seen
        missing = [n for n in wanted if n not in seen]
        if self.section.joints.get(topic) and missing:
            raise SessionError(
                f"[import.joints] {topic}: no joints {missing} in this stream (it has {list(seen)})", where
            )
        names = tuple(n for n in wanted if n in seen)
        if not names:
            raise SessionError(f"{topic} has none of the URDF's joints (it has {list(seen)}, the URDF {list(wanted)})",
                               where)
        return names


def load_import_recipe(which: str | Path) -> ImportRecipe:
    """An import recipe file, or the name of one in datasets/imports/ (e.g. "ros2_arm")."""
    path = Path(which)
    shipped = data_dir("datasets") / "imports"
    if not path.is_file() and path.suffix == "" and len(path.parts) == 1:
        path = shipped / f"{which}.toml"
    if not path.is_file():
        known = ", ".join(sorted(p.stem for p in shipped.glob("*.toml"))) or "none"
        raise ConfigError(f"no such import recipe file (shipped ones in {shipped}: {known})", str(which))
    data = read_toml(path)
    table = data.pop("import", {})
    if not isinstance(table, dict):
        raise ConfigError("[import] must be a table", str(path))
    section = from_table(ImportSection, table, f"{path} [import]")
    recipe = recipe_from_table(data, path)
    joints, robot = (), ""
    if section.urdf:
        from teleprev.errors import UrdfError
        from teleprev.robot.model import resolve_urdf
        from teleprev.robot.urdf import parse_urdf

        urdf_path = resolve_urdf(section.urdf)
        if not urdf_path.is_file() and (path.parent / section.urdf).is_file():
            urdf_path = path.parent / section.urdf  # relative to the recipe
        try:
            desc = parse_urdf(urdf_path)
        except UrdfError as exc:
            raise ConfigError(f"[import] urdf: {exc}", str(path)) from None
        joints = tuple(j.name for j in desc.joints if j.actuated)
        robot = desc.name
    return ImportRecipe(recipe, section, joints, robot)
