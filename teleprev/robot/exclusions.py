"""The link pairs a robot's self-collision check leaves out, kept in a TOML file next to its URDF.

Two kinds: `adjacent` (joined by a joint, so their shapes touch by construction) and `always` (in
contact in every configuration sampled when the file was written). Keeping the list in a file, not in
code, lets a reader see exactly what the checker ignores. `teleprev robot exclusions URDF` writes it.
"""

from __future__ import annotations

import datetime as _dt
import tomllib
from dataclasses import dataclass
from pathlib import Path

from teleprev.errors import UrdfError
from teleprev.robot.model import RobotModel


@dataclass(frozen=True)
class ExcludedPair:
    links: tuple[str, str]
    reason: str  # "adjacent" or "always"


@dataclass(frozen=True)
class Exclusions:
    pairs: tuple[ExcludedPair, ...]
    urdf_sha256: str | None = None
    samples: int = 0

    def pair_set(self) -> set[frozenset[str]]:
        return {frozenset(p.links) for p in self.pairs}

    def checked_pairs(self, link_names: tuple[str, ...]) -> tuple[tuple[str, str], ...]:
        """The link pairs a self-collision check tests, in the one order every checker reports them in: each
        pair of `link_names` (in their order) that is not excluded."""
        excluded = self.pair_set()
        return tuple((a, b) for i, a in enumerate(link_names) for b in link_names[i + 1:]
                     if frozenset((a, b)) not in excluded)


def exclusions_path(urdf_path: Path) -> Path:
    return urdf_path.with_suffix(".collision.toml")


def adjacent_pairs(model: RobotModel) -> list[tuple[str, str]]:
    """Pairs of links with geometry joined by one joint, looking through links without geometry."""
    def geometric_parent(link: str) -> str | None:
        while link in model.parent_joint:
            link = model.parent_joint[link].parent
            if model.links[link].collisions:
                return link
        return None

    pairs = []
    for name in model.link_names:
        if model.links[name].collisions:
            parent = geometric_parent(name)
            if parent is not None:
                pairs.append((parent, name))
    return pairs


def load_exclusions(model: RobotModel) -> Exclusions:
    path = exclusions_path(model.urdf_path)
    if not path.is_file():
        raise UrdfError(
            f"no self-collision exclusion list; write one with `teleprev robot exclusions {model.urdf_path}`", str(path)
        )
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise UrdfError(f"not valid TOML ({exc})", str(path)) from None
    if data.get("urdf_sha256") not in (None, model.urdf_sha256):
        raise UrdfError(
            f"written for a different version of {model.urdf_path.name}; rerun `teleprev robot exclusions "
            f"{model.urdf_path}`",
            str(path),
        )
    pairs = []
    for k, entry in enumerate(data.get("pair", [])):
        links = entry.get("links")
        where = f"{path}: pair #{k + 1}"
        if not (isinstance(links, list) and len(links) == 2 and all(isinstance(name, str) for name in links)):
            raise UrdfError("'links' must be a list of two link names", where)
        for link in links:
            if link not in model.links:
                raise UrdfError(f"unknown link {link!r}", where)
        pairs.append(ExcludedPair((links[0], links[1]), str(entry.get("reason", ""))))
    return Exclusions(tuple(pairs), data.get("urdf_sha256"), int(data.get("samples", 0)))


def write_exclusions(model: RobotModel, exclusions: Exclusions) -> Path:
    path = exclusions_path(model.urdf_path)
    today = _dt.date.today().isoformat()
    lines = [
        f"# Link pairs that teleprev's self-collision check of {model.urdf_path.name} leaves out.",
        "#   adjacent: joined by a joint, so their shapes touch by construction",
        f"#   always:   in contact in every one of the {exclusions.samples} uniform samples drawn when this file "
        "was written",
        f"# Written by `teleprev robot exclusions {model.urdf_path.name} --samples {exclusions.samples}` on {today}.",
        f'urdf_sha256 = "{model.urdf_sha256}"',
        f"samples = {exclusions.samples}",
        "",
    ]
    for p in exclusions.pairs:
        lines += ["[[pair]]", f'links = ["{p.links[0]}", "{p.links[1]}"]', f'reason = "{p.reason}"', ""]
    path.write_text("\n".join(lines))
    return path
