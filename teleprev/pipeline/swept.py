"""The hand's motion, not just its end point, free of self-collision, with a clearance margin.

A command is a straight joint-space segment from the last command. Two facts make checking it exact:

* clearance by inflation: every collision shape grown by c/2 (boxes by c in each dimension, spheres and
  capsules by c/2 in radius). If no two grown shapes touch, no two original shapes are closer than c
  (a point within c of both would put their midpoint inside both grown shapes).
* a bound on how far any link moves: a point of link L at most r from joint j's origin moves at most
  r |dq_j| when joint j turns by dq_j, so along the segment it moves at most sum_j R[L, j] |dq_j| (R from
  the link lengths of the URDF, independent of the configuration).

Checking the grown shapes at n = ceil(2 M / c) evenly spaced points (M: the largest link motion on the
segment) then proves every configuration on the segment keeps at least c/2 between links: any point of
the segment is within half a spacing of a checked one, where two links moved at most M/n <= c/2 towards
each other. The end point itself keeps the full c.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from teleprev.robot.collision import SelfCollisionChecker
from teleprev.robot.model import RobotModel
from teleprev.robot.urdf import Shape

START_STEP_M = 0.0005  # from a start already inside the margin: plain shapes, link motion <= this between checks


def _grow(shape: Shape, by: float) -> Shape:
    if shape.kind == "box":
        return dataclasses.replace(shape, size=tuple(s + 2 * by for s in shape.size))
    if shape.kind == "sphere":
        return dataclasses.replace(shape, size=(shape.size[0] + by,))
    if shape.kind == "cylinder":  # radius, length
        return dataclasses.replace(shape, size=(shape.size[0] + by, shape.size[1] + 2 * by))
    return dataclasses.replace(shape, size=(shape.size[0] + by, shape.size[1]))  # capsule: radius, length


def inflated_model(model: RobotModel, by: float) -> RobotModel:
    """The same robot with every collision shape grown by `by` metres on every side."""
    links = {name: dataclasses.replace(link, collisions=tuple(_grow(s, by) for s in link.collisions))
             for name, link in model.desc.links.items()}
    return RobotModel(dataclasses.replace(model.desc, links=links))


def _shape_reach(shape: Shape) -> float:
    """Farthest distance from the link frame's origin to a point of the shape."""
    centre = float(np.linalg.norm(shape.origin[:3, 3]))
    size = shape.size
    if shape.kind == "box":
        return centre + 0.5 * float(np.linalg.norm(size))
    if shape.kind == "sphere":
        return centre + size[0]
    if shape.kind == "cylinder":
        return centre + float(np.hypot(size[0], 0.5 * size[1]))
    return centre + size[0] + 0.5 * size[1]


def reach_table(model: RobotModel, link_names: tuple[str, ...]) -> np.ndarray:
    """(links, joints): R[L, j] bounds the distance from joint j's origin to any point of link L."""
    reach = np.zeros((len(link_names), len(model.joint_names)))
    for row, name in enumerate(link_names):
        acc = max((_shape_reach(s) for s in model.links[name].collisions), default=0.0)
        current = name
        while current in model.parent_joint:
            joint = model.parent_joint[current]
            if joint.type != "fixed":
                source = joint.mimic.joint if joint.mimic is not None else joint.name
                weight = abs(joint.mimic.multiplier) if joint.mimic is not None else 1.0
                reach[row, model.joint_index[source]] += (acc if joint.type != "prismatic" else 1.0) * weight
            acc += float(np.linalg.norm(joint.origin[:3, 3]))
            current = joint.parent
    return reach


class SweptCheck:
    def __init__(self, model: RobotModel, checker: SelfCollisionChecker, clearance_m: float, compiled: bool = False):
        self.model = model
        self.compiled = compiled  # the compiled segment check (sessions of format 3 on); False: the numpy one
        self.checker = checker
        self.clearance = float(clearance_m)
        self.grown = (SelfCollisionChecker(inflated_model(model, self.clearance / 2), checker.exclusions)
                      if self.clearance > 0 else checker)
        self.reach = reach_table(model, checker.link_names)
        self._clear_cache: tuple[bytes, bool] = (b"", False)  # the last end point checked (pure: a cache)

    def motion_bound(self, q0: np.ndarray, q1: np.ndarray) -> float:
        """Metres: no point of any link moves further than this on the segment q0 -> q1."""
        return float((self.reach @ np.abs(np.asarray(q1) - np.asarray(q0))).max())

    def clear(self, q: np.ndarray) -> bool:
        """At least the clearance between every checked pair of links."""
        key = np.asarray(q, dtype=float).tobytes()
        if self._clear_cache[0] == key:
            return self._clear_cache[1]
        free = not self.grown.collides(q)
        self._clear_cache = (key, free)
        return free

    def _points(self, q0: np.ndarray, q1: np.ndarray, spacing_m: float) -> np.ndarray:
        n = max(1, math.ceil(self.motion_bound(q0, q1) / spacing_m))
        return q0 + (np.arange(1, n + 1) / n)[:, None] * (q1 - q0)

    def segment_free(self, q0: np.ndarray, q1: np.ndarray) -> bool:
        """The segment from command q0 (itself checked) to q1 keeps the clearance (half of it between the
        checked points). From a start already inside the margin (a measured state at engage), the plain
        shapes are checked every START_STEP_M of link motion instead, so the hand can move out."""
        if np.array_equal(q0, q1):
            return True
        if self.clearance > 0 and self.clear(q0):
            points = self._points(q0, q1, self.clearance / 2)
            return self.grown.first_collision(points[:-1]) is None and self.clear(points[-1])
        return self.checker.first_collision(self._points(q0, q1, START_STEP_M)) is None

    def last_free_on_segment(self, q0: np.ndarray, q1: np.ndarray, steps: int = 10) -> np.ndarray:
        """A point of the segment q0 -> q1 whose own segment from q0 passes (q0 itself at worst), by bisection."""
        lo, hi = 0.0, 1.0
        for _ in range(steps):
            mid = 0.5 * (lo + hi)
            if self.segment_free(q0, q0 + mid * (q1 - q0)):
                lo = mid
            else:
                hi = mid
        return q0 + lo * (q1 - q0)
