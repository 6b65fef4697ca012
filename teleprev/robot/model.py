"""A robot loaded once from its URDF: joints and links by name, limits, and forward kinematics.

Forward kinematics walks the tree level by level (all joints at the same depth in one vectorised step),
so one configuration costs a handful of numpy operations and a batch of configurations costs the same
number of operations on bigger arrays. Joint values are always float64 radians (metres for prismatic).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from teleprev.errors import UrdfError
from teleprev.robot.urdf import Joint, Link, UrdfDescription, parse_urdf


def _skew(a: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


@dataclass(frozen=True)
class LinkPoses:
    """Link frames in the robot's root frame as 4x4 transforms (..., L, 4, 4), looked up by link name."""

    world: np.ndarray
    index: Mapping[str, int]

    @property
    def rotations(self) -> np.ndarray:
        return self.world[..., :3, :3]

    @property
    def positions(self) -> np.ndarray:
        return self.world[..., :3, 3]

    def matrix(self, link: str) -> np.ndarray:
        return self.world[..., self.index[link], :, :]

    def position(self, link: str) -> np.ndarray:
        return self.world[..., self.index[link], :3, 3]


@dataclass(frozen=True)
class _Level:
    child: slice | int  # link indices (an int where the level has one link); also rows of the joint tables
    parent: np.ndarray | int


class RobotModel:
    def __init__(self, desc: UrdfDescription):
        self.desc = desc
        self.name = desc.name
        self.urdf_path = desc.path
        self.urdf_sha256 = desc.sha256
        self.links: dict[str, Link] = desc.links

        joint_of_child = {j.child: j for j in desc.joints}
        children: dict[str, list[Joint]] = {}
        for j in desc.joints:
            children.setdefault(j.parent, []).append(j)

        # Breadth-first link order: a parent always comes before its children.
        order, depth = [desc.root], {desc.root: 0}
        for name in order:
            for j in children.get(name, []):
                depth[j.child] = depth[name] + 1
                order.append(j.child)
        if len(order) != len(desc.links):
            unreachable = sorted(set(desc.links) - set(order))
            raise UrdfError(f"links not connected to the root {desc.root!r}: {unreachable}", str(desc.path))
        self.link_names: tuple[str, ...] = tuple(order)
        self.link_index = {n: i for i, n in enumerate(order)}
        self.parent_joint: dict[str, Joint] = joint_of_child

        self.joints: tuple[Joint, ...] = tuple(j for j in desc.joints if j.actuated)
        self.joint_names: tuple[str, ...] = tuple(j.name for j in self.joints)
        self.joint_index = {n: i for i, n in enumerate(self.joint_names)}
        self.lower = np.array([j.lower for j in self.joints], dtype=float)
        self.upper = np.array([j.upper for j in self.joints], dtype=float)
        self.velocity_limit = np.array([j.velocity for j in self.joints], dtype=float)

        # Per-link local transform terms (row = child link; the root's row stays identity):
        # local(q) = origin + sin(a) * k1 + (1 - cos(a)) * k2 + d * slide, with a (revolute) or d (prismatic)
        # the joint's value, so all local transforms of a configuration are one vectorised expression.
        n = len(order)
        self._origin = np.tile(np.eye(4), (n, 1, 1))
        k1 = np.zeros((n, 4, 4))
        k2 = np.zeros((n, 4, 4))
        slide = np.zeros((n, 4, 4))
        self._q_source = np.zeros(n, dtype=int)  # fixed joints read joint 0 with multiplier 0
        self._q_mult = np.zeros(n)
        self._q_offset = np.zeros(n)
        self._revolute = np.zeros(n)
        self._prismatic = np.zeros(n)
        for name in order[1:]:
            i = self.link_index[name]
            j = joint_of_child[name]
            ro = j.origin[:3, :3]
            self._origin[i] = j.origin
            if j.type == "fixed":
                continue
            k = _skew(j.axis)
            if j.type == "prismatic":
                self._prismatic[i] = 1.0
                slide[i, :3, 3] = ro @ j.axis
            else:
                self._revolute[i] = 1.0
                k1[i, :3, :3] = ro @ k
                k2[i, :3, :3] = ro @ k @ k
            if j.mimic is None:
                self._q_source[i], self._q_mult[i] = self.joint_index[j.name], 1.0
            else:
                self._q_source[i] = self.joint_index[j.mimic.joint]
                self._q_mult[i], self._q_offset[i] = j.mimic.multiplier, j.mimic.offset

        # (n, 3, 16): the three terms stacked so that one matmul with [sin a, 1 - cos a, d] adds them.
        self._terms = np.stack([k1, k2, slide], axis=1).reshape(n, 3, 16)
        levels = []
        for d in range(1, max(depth.values()) + 1):
            kids = [self.link_index[name] for name in order if depth[name] == d]
            parents = np.array([self.link_index[joint_of_child[order[k]].parent] for k in kids])
            # Breadth-first order keeps each level contiguous, so children are a plain slice; a level with
            # one link (a serial arm) indexes with ints, which numpy does fastest.
            if len(kids) == 1:
                levels.append(_Level(kids[0], int(parents[0])))
            else:
                levels.append(_Level(slice(kids[0], kids[-1] + 1), parents))
        self._levels = tuple(levels)

    # ---- names ---------------------------------------------------------------------------------
    def indices(self, names: Sequence[str]) -> np.ndarray:
        """Positions of the named actuated joints in this model's joint vector."""
        try:
            return np.array([self.joint_index[n] for n in names], dtype=int)
        except KeyError as exc:
            raise UrdfError(
                f"unknown joint name {exc.args[0]!r} (joints: {', '.join(self.joint_names)})", str(self.urdf_path)
            ) from None

    def vector(self, values: Mapping[str, float], default: np.ndarray | None = None) -> np.ndarray:
        """A joint vector from a name -> value mapping; joints not named keep `default` (zeros)."""
        q = np.zeros(len(self.joints)) if default is None else np.array(default, dtype=float)
        if values:
            q[self.indices(list(values))] = list(values.values())
        return q

    def as_dict(self, q: np.ndarray) -> dict[str, float]:
        return dict(zip(self.joint_names, (float(v) for v in q)))

    def link(self, name: str) -> Link:
        if name not in self.links:
            raise UrdfError(f"unknown link {name!r}", str(self.urdf_path))
        return self.links[name]

    # ---- limits --------------------------------------------------------------------------------
    def clip(self, q: np.ndarray) -> np.ndarray:
        return np.minimum(np.maximum(q, self.lower), self.upper)  # np.clip's wrapper costs more than the work

    def within_limits(self, q: np.ndarray, tol: float = 0.0) -> bool:
        return bool(np.all(q >= self.lower - tol) and np.all(q <= self.upper + tol))

    def neutral(self) -> np.ndarray:
        """Zero where zero is within limits, else the nearest limit."""
        return self.clip(np.zeros(len(self.joints)))

    def sample_uniform(self, n: int, rng: np.random.Generator) -> np.ndarray:
        return rng.uniform(self.lower, self.upper, size=(n, len(self.joints)))

    # ---- kinematics ----------------------------------------------------------------------------
    def fk(self, q: np.ndarray) -> LinkPoses:
        """Forward kinematics for one configuration (n,) or a batch (..., n)."""
        q = np.asarray(q, dtype=float)
        qj = q[..., self._q_source] * self._q_mult + self._q_offset
        angle = qj * self._revolute
        coeffs = np.empty(qj.shape + (3,))  # [sin a, 1 - cos a, d], filled in place (np.stack is slow here)
        np.sin(angle, out=coeffs[..., 0])
        np.subtract(1.0, np.cos(angle), out=coeffs[..., 1])
        np.multiply(qj, self._prismatic, out=coeffs[..., 2])
        local = self._origin + (coeffs[..., None, :] @ self._terms).reshape(q.shape[:-1] + self._origin.shape)
        world = local  # the root's row is the identity, and each level overwrites its children's rows
        for lv in self._levels:
            world[..., lv.child, :, :] = world[..., lv.parent, :, :] @ local[..., lv.child, :, :]
        return LinkPoses(world, self.link_index)

    def chain_to(self, tip: str) -> RobotModel:
        """The serial chain from the root to `tip` as a model of its own (e.g. the arm of arm + hand)."""
        self.link(tip)
        keep, link = [], tip
        while link in self.parent_joint:
            j = self.parent_joint[link]
            keep.append(j)
            link = j.parent
        keep.reverse()
        names = {self.desc.root} | {j.child for j in keep}
        desc = UrdfDescription(
            f"{self.name}[{self.desc.root}->{tip}]", self.urdf_path, self.urdf_sha256,
            {n: link for n, link in self.links.items() if n in names}, tuple(keep), self.desc.root,
        )
        return RobotModel(desc)


def _repo_dir(name: str) -> Path:
    from teleprev.paths import data_dir

    return data_dir(name)


def resolve_urdf(name_or_path: str | Path) -> Path:
    """A URDF path, or the name of one shipped in urdf/ (with or without .urdf)."""
    p = Path(name_or_path)
    if p.suffix == ".urdf" and (p.exists() or p.parent != Path(".")):
        return p
    shipped = _repo_dir("urdf") / (p.name if p.suffix == ".urdf" else f"{p.name}.urdf")
    return shipped if shipped.exists() else p


@functools.lru_cache(maxsize=32)
def _load(path: str, mtime_ns: int) -> RobotModel:
    return RobotModel(parse_urdf(path))


def load_robot(name_or_path: str | Path) -> RobotModel:
    """Load a URDF once per process (cached by path and modification time)."""
    path = resolve_urdf(name_or_path)
    if not path.is_file():
        raise UrdfError("no such URDF file (give a path or the name of one in urdf/)", str(name_or_path))
    return _load(str(path.resolve()), path.stat().st_mtime_ns)
