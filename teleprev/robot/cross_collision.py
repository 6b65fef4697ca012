"""Contact between two robots placed in one world: every link of one against every link of the other.

A bimanual rig's two arms, each with its hand, stand at their mounts; `CrossCollisionChecker.contacts` says
which link pairs (one of each robot) are closer than the clearance, for whole configurations of both. FCL
decides every pair that bounding spheres (grown by the clearance) do not rule out; a pair within the
clearance but not touching is found with FCL's distance query. Arm against arm, hand against hand and hand
against arm are all among the pairs: no pair of the two robots is left out (they are not joined by
anything, so none touches by construction).
"""

from __future__ import annotations

from dataclasses import dataclass

import fcl
import numpy as np

from teleprev.robot.collision import _bounding_radius, _fcl_geometry
from teleprev.robot.model import RobotModel


@dataclass
class _Placed:
    """One robot's collision shapes, for placing them at its configurations."""

    model: RobotModel
    base: np.ndarray  # 4x4: the robot's root in the world
    shape_link: np.ndarray  # per shape, its link's index in the model
    local: np.ndarray  # (S, 4, 4) per shape, its origin in its link
    radius: np.ndarray  # (S,) bounding sphere of each shape
    link_of: list[str]  # per shape, its link's name
    objects: list

    @classmethod
    def of(cls, model: RobotModel, base: np.ndarray) -> _Placed:
        shape_link, local, radius, link_of, objects = [], [], [], [], []
        for name in model.link_names:
            for shape in model.links[name].collisions:
                shape_link.append(model.link_index[name])
                local.append(shape.origin)
                radius.append(_bounding_radius(shape.kind, shape.size))
                link_of.append(name)
                objects.append(fcl.CollisionObject(_fcl_geometry(shape.kind, shape.size), fcl.Transform()))
        return cls(model, np.asarray(base, float), np.array(shape_link), np.array(local), np.array(radius), link_of,
                   objects)

    def shapes(self, q: np.ndarray) -> np.ndarray:
        """(S, 4, 4): the shapes in the world at the robot's configuration q (all its joints)."""
        return self.base @ self.model.fk(q).world[self.shape_link] @ self.local


class CrossCollisionChecker:
    def __init__(self, a: RobotModel, base_a: np.ndarray, b: RobotModel, base_b: np.ndarray,
                 clearance_m: float = 0.0):
        self.robots = (_Placed.of(a, base_a), _Placed.of(b, base_b))
        self.clearance_m = float(clearance_m)
        ra, rb = self.robots[0].radius, self.robots[1].radius
        self._reach2 = (ra[:, None] + rb[None, :] + self.clearance_m) ** 2  # (Sa, Sb)
        self._last: list[tuple[bytes, np.ndarray] | None] = [None, None]  # per robot: its last q and shapes
        self._request = fcl.CollisionRequest()
        self._distance = fcl.DistanceRequest()

    def contacts(self, q_a: np.ndarray, q_b: np.ndarray) -> list[tuple[str, str]]:
        """The link pairs (robot a's link, robot b's link) closer than the clearance, at these configurations."""
        sa, sb = self._shapes(0, q_a), self._shapes(1, q_b)
        diff = sa[:, None, :3, 3] - sb[None, :, :3, 3]
        near = np.argwhere(np.einsum("ijk,ijk->ij", diff, diff) < self._reach2)
        found: list[tuple[str, str]] = []
        for i, j in near.tolist():
            pair = (self.robots[0].link_of[i], self.robots[1].link_of[j])
            if pair in found:
                continue
            oa, ob = self.robots[0].objects[i], self.robots[1].objects[j]
            oa.setRotation(sa[i, :3, :3])
            oa.setTranslation(sa[i, :3, 3])
            ob.setRotation(sb[j, :3, :3])
            ob.setTranslation(sb[j, :3, 3])
            if fcl.collide(oa, ob, self._request, fcl.CollisionResult()):
                found.append(pair)
            elif self.clearance_m > 0 and fcl.distance(oa, ob, self._distance, fcl.DistanceResult()) < self.clearance_m:
                found.append(pair)
        return found

    def _shapes(self, k: int, q: np.ndarray) -> np.ndarray:
        """Robot k's shapes at q (the last configuration's kept: one side stands still while the other moves)."""
        key = np.asarray(q, dtype=float).tobytes()
        last = self._last[k]
        if last is None or last[0] != key:
            last = self._last[k] = (key, self.robots[k].shapes(q))
        return last[1]

    def collides(self, q_a: np.ndarray, q_b: np.ndarray) -> bool:
        return bool(self.contacts(q_a, q_b))
