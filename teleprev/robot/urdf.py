"""Parse the subset of URDF that teleprev's robot descriptions use.

Geometry is primitives only (box, cylinder, sphere, capsule): meshes are refused, because the exact
self-collision check must stay well under a millisecond. Errors name the file and the element.
"""

from __future__ import annotations

import hashlib
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from teleprev.errors import UrdfError
from teleprev.transforms import make_transform, rpy_to_matrix

ACTUATED_TYPES = ("revolute", "continuous", "prismatic")
JOINT_TYPES = ACTUATED_TYPES + ("fixed",)


@dataclass(frozen=True)
class Shape:
    """A primitive in its link's frame. `size` is (x, y, z) for a box, (radius,) for a sphere and
    (radius, length) along z for a cylinder or capsule."""

    kind: str
    size: tuple[float, ...]
    origin: np.ndarray  # 4x4, in the link frame


@dataclass(frozen=True)
class Link:
    name: str
    collisions: tuple[Shape, ...]
    visuals: tuple[Shape, ...]


@dataclass(frozen=True)
class Mimic:
    joint: str
    multiplier: float
    offset: float


@dataclass(frozen=True)
class Joint:
    name: str
    type: str
    parent: str
    child: str
    origin: np.ndarray  # 4x4, child frame at q = 0 in the parent frame
    axis: np.ndarray  # unit vector in the child frame
    lower: float
    upper: float
    velocity: float
    effort: float
    mimic: Mimic | None

    @property
    def actuated(self) -> bool:
        return self.type in ACTUATED_TYPES and self.mimic is None


@dataclass(frozen=True)
class UrdfDescription:
    name: str
    path: Path
    sha256: str
    links: dict[str, Link]
    joints: tuple[Joint, ...]  # in document order
    root: str


def _floats(text: str | None, count: int, where: str, attr: str, default: str | None = None) -> tuple[float, ...]:
    if text is None:
        if default is None:
            raise UrdfError(f"missing attribute '{attr}'", where)
        text = default
    try:
        values = tuple(float(v) for v in text.split())
    except ValueError:
        raise UrdfError(f"attribute '{attr}' is not numeric: {text!r}", where) from None
    if len(values) != count:
        raise UrdfError(f"attribute '{attr}' needs {count} numbers, got {len(values)}: {text!r}", where)
    if not all(np.isfinite(values)):
        raise UrdfError(f"attribute '{attr}' is not finite: {text!r}", where)
    return values


def _origin(elem: ET.Element | None, where: str) -> np.ndarray:
    if elem is None:
        return np.eye(4)
    xyz = _floats(elem.get("xyz"), 3, f"{where} <origin>", "xyz", "0 0 0")
    rpy = _floats(elem.get("rpy"), 3, f"{where} <origin>", "rpy", "0 0 0")
    return make_transform(rpy_to_matrix(*rpy), xyz)


def _shape(elem: ET.Element, where: str) -> Shape:
    geom = elem.find("geometry")
    if geom is None or len(geom) != 1:
        raise UrdfError("needs exactly one primitive inside <geometry>", where)
    prim = geom[0]
    pwhere = f"{where} <{prim.tag}>"
    if prim.tag == "box":
        size = _floats(prim.get("size"), 3, pwhere, "size")
    elif prim.tag == "sphere":
        size = _floats(prim.get("radius"), 1, pwhere, "radius")
    elif prim.tag in ("cylinder", "capsule"):
        size = _floats(prim.get("radius"), 1, pwhere, "radius") + _floats(prim.get("length"), 1, pwhere, "length")
    elif prim.tag == "mesh":
        raise UrdfError(
            "meshes are not supported; describe the link with boxes, cylinders, capsules or spheres", pwhere
        )
    else:
        raise UrdfError(f"unknown geometry <{prim.tag}>", pwhere)
    if any(s <= 0 for s in size):
        raise UrdfError(f"sizes must be positive, got {size}", pwhere)
    return Shape(prim.tag, size, _origin(elem.find("origin"), where))


def _link(elem: ET.Element, file: str) -> Link:
    name = elem.get("name")
    if not name:
        raise UrdfError("a <link> has no name", file)
    where = f"{file}: <link name=\"{name}\">"
    collisions = tuple(_shape(c, f"{where} <collision>") for c in elem.findall("collision"))
    visuals = tuple(_shape(v, f"{where} <visual>") for v in elem.findall("visual"))
    return Link(name, collisions, visuals)


def _joint(elem: ET.Element, file: str) -> Joint:
    name = elem.get("name")
    if not name:
        raise UrdfError("a <joint> has no name", file)
    where = f"{file}: <joint name=\"{name}\">"
    jtype = elem.get("type")
    if jtype not in JOINT_TYPES:
        raise UrdfError(f"unsupported joint type {jtype!r} (expected one of {', '.join(JOINT_TYPES)})", where)
    parent, child = elem.find("parent"), elem.find("child")
    if parent is None or parent.get("link") is None:
        raise UrdfError("missing <parent link=...>", where)
    if child is None or child.get("link") is None:
        raise UrdfError("missing <child link=...>", where)
    axis_elem = elem.find("axis")
    axis = np.array(
        _floats(axis_elem.get("xyz") if axis_elem is not None else None, 3, f"{where} <axis>", "xyz", "1 0 0")
    )
    if jtype != "fixed":
        norm = np.linalg.norm(axis)
        if norm < 1e-9:
            raise UrdfError("axis has zero length", f"{where} <axis>")
        axis = axis / norm
    lower = upper = 0.0
    velocity = effort = float("inf")
    limit = elem.find("limit")
    if jtype in ("revolute", "prismatic"):
        if limit is None:
            raise UrdfError(f"a {jtype} joint needs <limit lower upper velocity effort>", where)
        lwhere = f"{where} <limit>"
        lower = _floats(limit.get("lower"), 1, lwhere, "lower")[0]
        upper = _floats(limit.get("upper"), 1, lwhere, "upper")[0]
        velocity = _floats(limit.get("velocity"), 1, lwhere, "velocity")[0]
        effort = _floats(limit.get("effort"), 1, lwhere, "effort")[0]
        if lower > upper:
            raise UrdfError(f"lower limit {lower} is above upper limit {upper}", lwhere)
        if velocity <= 0:
            raise UrdfError(f"velocity limit must be positive, got {velocity}", lwhere)
    elif jtype == "continuous":
        lower, upper = -np.pi, np.pi
        if limit is not None and limit.get("velocity") is not None:
            velocity = _floats(limit.get("velocity"), 1, f"{where} <limit>", "velocity")[0]
    mimic = None
    mimic_elem = elem.find("mimic")
    if mimic_elem is not None:
        target = mimic_elem.get("joint")
        if not target:
            raise UrdfError("<mimic> needs a joint attribute", where)
        mult = _floats(mimic_elem.get("multiplier"), 1, f"{where} <mimic>", "multiplier", "1")[0]
        off = _floats(mimic_elem.get("offset"), 1, f"{where} <mimic>", "offset", "0")[0]
        mimic = Mimic(target, mult, off)
    return Joint(
        name, jtype, parent.get("link"), child.get("link"), _origin(elem.find("origin"), where),
        axis, lower, upper, velocity, effort, mimic,
    )


def parse_urdf(path: str | Path) -> UrdfDescription:
    path = Path(path)
    if not path.is_file():
        raise UrdfError("no such URDF file", str(path))
    raw = path.read_bytes()
    try:
        root = ET.fromstring(raw)
    except ET.ParseError as exc:
        raise UrdfError(f"not well-formed XML ({exc})", str(path)) from None
    if root.tag != "robot":
        raise UrdfError(f"the root element is <{root.tag}>, expected <robot>", str(path))
    file = str(path)
    links: dict[str, Link] = {}
    for elem in root.findall("link"):
        link = _link(elem, file)
        if link.name in links:
            raise UrdfError(f"link {link.name!r} is defined twice", file)
        links[link.name] = link
    joints = tuple(_joint(e, file) for e in root.findall("joint"))
    seen: set[str] = set()
    children: set[str] = set()
    for j in joints:
        where = f"{file}: <joint name=\"{j.name}\">"
        if j.name in seen:
            raise UrdfError("joint is defined twice", where)
        seen.add(j.name)
        for role, link_name in (("parent", j.parent), ("child", j.child)):
            if link_name not in links:
                raise UrdfError(f"{role} link {link_name!r} is not defined", where)
        if j.child in children:
            raise UrdfError(f"link {j.child!r} has two parent joints", where)
        children.add(j.child)
    by_name = {j.name: j for j in joints}
    for j in joints:
        if j.mimic is not None:
            target = by_name.get(j.mimic.joint)
            if target is None or not target.actuated:
                raise UrdfError(
                    f"mimics {j.mimic.joint!r}, which is not an actuated joint", f'{file}: <joint name="{j.name}">'
                )
    roots = [name for name in links if name not in children]
    if len(roots) != 1:
        raise UrdfError(f"expected one root link, found {len(roots)}: {roots}", file)
    return UrdfDescription(root.get("name", path.stem), path, hashlib.sha256(raw).hexdigest(), links, joints, roots[0])
