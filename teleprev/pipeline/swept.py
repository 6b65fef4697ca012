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

A command that is not free need not stop the whole hand (SweptCheck.slide, compiled only): a candidate
command whose every joint lies between that joint's braking step and its capped step towards the target
keeps the hand's limits (each limit is an interval both ends keep), so the search may hold back the fingers
(kinematic chains from the palm) of the colliding link pairs and let the others take their step, then
slide each held finger as far towards its step as some subset of its joints and a bisection of the rest
allow. Each candidate is checked as a command is (its segment and the way on to its stop point) and
taken only where the compiled test shows it free, so the judges are the same (kernels/swept.py:
swept_slide). Two interleaved fingers, each in the other's way, cannot get out between braking and
tracking: there the one nearer its target gives way, its joints taking the limiter's capped step away
from their targets (a command the limiter itself gives, so within every limit), checked the same way.

SweptCheck runs a segment in one numba kernel (teleprev/kernels/swept.py, swept_*) where the geometry is
all boxes: the bound, the points, the checks in order, the end point's, and last_free_on_segment's
bisection; otherwise, and for the older sessions re-run with numpy's arithmetic
(teleprev/pipeline/older_formats), the numpy check. Per configuration it decides as SelfCollisionChecker
does (the compiled box test with its margin turned either way) and hands the ones within the margin back
to FCL here, so its answers are the numpy check's (tests/pipeline/test_swept.py); only the bound's last bit
may differ (a summation order), which can change the number of points only at an exact tie.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from teleprev.kernels import swept as swept_kernels
from teleprev.robot.collision import FclSelfCollisionChecker, SelfCollisionChecker
from teleprev.robot.model import RobotModel
from teleprev.robot.urdf import Shape

START_STEP_M = 0.0005  # from a start already inside the margin: plain shapes, link motion <= this between checks
SLIDE_STEPS = 5  # halvings of a held finger's remaining step (its last 1/32 of a step may be left untried)
# Configurations one slide may test (a count, so that a re-run finds the same command): about 2 ms of a
# planner tick (8.3 ms at 120 Hz) with the LEAP Hand's fingers crowded; one blocked finger needs about 100.
SLIDE_BUDGET = 400


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


def finger_table(model: RobotModel, link_names: tuple[str, ...]) -> swept_kernels.Fingers:
    """The kinematic chains from the palm: each starts at a moving joint with no moving joint above it
    (a finger's root), numbered in the model's joint order; a link or joint above every such joint is
    the palm's (-1)."""
    def root(link: str) -> str | None:
        found = None
        while link in model.parent_joint:
            joint = model.parent_joint[link]
            if joint.type != "fixed":
                found = joint.mimic.joint if joint.mimic is not None else joint.name
            link = joint.parent
        return found

    child = {j.mimic.joint if j.mimic is not None else j.name: link for link, j in model.parent_joint.items()
             if j.type != "fixed"}
    joint_root = [root(child[name]) if name in child else None for name in model.joint_names]
    roots = [name for name in model.joint_names if name in set(joint_root)]
    number = {name: k for k, name in enumerate(roots)}
    return swept_kernels.Fingers(np.array([number.get(r, -1) for r in joint_root], dtype=np.int64),
                                 np.array([number.get(root(name), -1) for name in link_names], dtype=np.int64),
                                 len(roots))


class SweptCheck:
    slides = True  # a command that is not free holds back only the fingers it must (slide); older formats: False
    # Where the whole hand brakes and that segment is not free with the clearance, it brakes keeping its
    # direction, else into the margin where no link collides on the way (segment_collision_free), rather
    # than stopping short (Motion._avoid); formats up to 8: False.
    brakes_in_margin = True

    def __init__(self, model: RobotModel, checker: SelfCollisionChecker, clearance_m: float):
        self.model = model
        self.checker = checker
        self.clearance = float(clearance_m)
        self.grown = (SelfCollisionChecker(inflated_model(model, self.clearance / 2), checker.exclusions)
                      if self.clearance > 0 else checker)
        self.reach = reach_table(model, checker.link_names)
        self._clear_cache: tuple[bytes, bool] = (b"", False)  # the last end point checked (pure: a cache)
        # The last command's end point, whose clearance its check found: the next command starts there, and
        # the check of its way to the stop point has taken _clear_cache by then (command_free).
        self._command_end: tuple[bytes, bool] = (b"", False)
        self._kernel_args = self._compiled_tables()
        if self._kernel_args is not None:  # load the kernels from numba's cache now, not in a live loop's first steps
            q = model.neutral()
            self._segment_free_compiled(q, q + 1e-3)
            self._last_free_compiled(q, q + 1e-3, 1)
            self.command_free(q, q + 1e-3, q, q + 1.0, q - 1.0, q + 1.0)
            self.slide(q, q + 1e-3, q, np.stack([q, q]), q + 1e-3, 0.01, q + 1.0, q - 1.0, q + 1.0)
            self._clear_cache = self._command_end = (b"", False)

    def _compiled_tables(self) -> tuple | None:
        """The swept kernels' arguments after their own (teleprev/kernels/swept.py: SweptTable, FkTable,
        SweptShapes, Margins, the scratch point), or None where the checkers are not the compiled ones
        (geometry other than boxes): then the numpy check runs."""
        if self.checker.kernel_tables is None or self.grown.kernel_tables is None:
            return None
        fk, p, margins = self.checker.kernel_tables
        g = self.grown.kernel_tables[1]
        if not all(np.array_equal(a, b) for a, b in ((g.shape_link, p.shape_link), (g.links, p.links),
                                                       (g.pairs, p.pairs))):  # same links, boxes per link and pairs
            return None
        self._point = np.empty(len(self.model.joint_names))
        self._fingers = finger_table(self.model, self.checker.link_names)
        table = swept_kernels.SweptTable(np.ascontiguousarray(self.reach, dtype=np.float64),
                                         self.clearance / 2 if self.clearance > 0 else 0.0, START_STEP_M)
        shapes = swept_kernels.SweptShapes(
            p.shape_link, np.ascontiguousarray(np.stack([g.shape_local, p.shape_local])),
            np.ascontiguousarray(np.stack([g.shape_size, p.shape_size])), p.links,
            np.ascontiguousarray(np.stack([g.spheres, p.spheres])), p.pairs)
        return (*table, *fk, *shapes, *margins, self._point)

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
        if self._kernel_args is not None:
            return self._segment_free_compiled(q0, q1)
        return self._segment_free_numpy(q0, q1)

    def _segment_free_numpy(self, q0: np.ndarray, q1: np.ndarray) -> bool:
        if np.array_equal(q0, q1):
            return True
        if self.clearance > 0 and self.clear(q0):
            points = self._points(q0, q1, self.clearance / 2)
            return self.grown.first_collision(points[:-1]) is None and self.clear(points[-1])
        return self.segment_collision_free(q0, q1)

    def segment_collision_free(self, q0: np.ndarray, q1: np.ndarray) -> bool:
        """No two links collide on the segment q0 -> q1: the plain shapes every START_STEP_M of link motion
        (as `teleprev audit` checks a command segment), without the clearance."""
        return self.checker.first_collision(self._points(q0, q1, START_STEP_M)) is None

    def last_free_on_segment(self, q0: np.ndarray, q1: np.ndarray, steps: int = 10) -> np.ndarray:
        """A point of the segment q0 -> q1 whose own segment from q0 passes (q0 itself at worst), by bisection."""
        if self._kernel_args is not None:
            lo = self._last_free_compiled(q0, q1, steps)
            if lo is not None:
                return q0 + lo * (q1 - q0)
        lo, hi = 0.0, 1.0
        for _ in range(steps):
            mid = 0.5 * (lo + hi)
            if self.segment_free(q0, q0 + mid * (q1 - q0)):
                lo = mid
            else:
                hi = mid
        return q0 + lo * (q1 - q0)

    # ---- compiled (teleprev/kernels/swept.py: swept_segment, swept_last_free) -----------------------
    # The kernels check every configuration with the compiled test of the checkers (one pass with the
    # loose and the tight margin: SelfCollisionChecker's decision, collision_kernels.self_collision_margins_into)
    # and hand back the ones within the margin, which FCL decides here, as SelfCollisionChecker does. So
    # the answers are the checker's.
    def _segment_free_compiled(self, q0, q1) -> bool:
        q0 = np.ascontiguousarray(q0, dtype=np.float64)
        q1 = np.ascontiguousarray(q1, dtype=np.float64)
        key = q0.tobytes()
        cached = self._clear_cache
        q0_clear = int(cached[1]) if cached[0] == key else -1
        start = 1
        while True:
            answer, k, known, end_clear = swept_kernels.swept_segment(q0, q1, q0_clear, start, *self._kernel_args)
            if known != q0_clear:  # the kernel checked q0's clearance: clear(q0) caches it
                self._clear_cache = (key, bool(known))
                q0_clear = known
            if answer == swept_kernels.SWEPT_FREE or answer == swept_kernels.SWEPT_COLLIDES:
                if end_clear >= 0:
                    self._clear_cache = (self._point.tobytes(), bool(end_clear))
                return answer == swept_kernels.SWEPT_FREE
            if answer == swept_kernels.SWEPT_UNSURE_START:
                q0_clear = int(not FclSelfCollisionChecker.collides(self.grown, self._point))
                self._clear_cache = (key, bool(q0_clear))
                start = 1
            elif answer == swept_kernels.SWEPT_UNSURE_GROWN or answer == swept_kernels.SWEPT_UNSURE_PLAIN:
                checker = self.grown if answer == swept_kernels.SWEPT_UNSURE_GROWN else self.checker
                if FclSelfCollisionChecker.collides(checker, self._point):
                    return False
                start = k + 1
            elif answer == swept_kernels.SWEPT_UNSURE_END:
                free = not FclSelfCollisionChecker.collides(self.grown, self._point)
                self._clear_cache = (self._point.tobytes(), free)
                return free
            else:  # not finite, or too many points
                return self._segment_free_numpy(q0, q1)

    def command_free(self, q0, q1, v1, acceleration, lower, upper) -> bool | None:
        """Compiled only: segment_free(q0, q1) and segment_free(q1, stop) in one kernel call, stop being
        where braking at `acceleration` from q1 at v1 ends within [lower, upper] (Motion._stop_point's
        arithmetic, in the kernel). None where the kernel cannot answer alone (a configuration within the
        margin, inputs it does not take, or no compiled check): then the caller makes the two calls."""
        if self._kernel_args is None:
            return None
        q0 = np.ascontiguousarray(q0, dtype=np.float64)
        q1 = np.ascontiguousarray(q1, dtype=np.float64)
        key0, key1 = q0.tobytes(), q1.tobytes()
        cached, end = self._clear_cache, self._command_end
        q0_clear = int(cached[1]) if cached[0] == key0 else int(end[1]) if end[0] == key0 else -1
        answer, cache, clear, q1_clear = swept_kernels.swept_command(
            q0, q1, np.ascontiguousarray(v1, dtype=np.float64), acceleration, lower, upper,
            q0_clear, int(cached[1]) if cached[0] == key1 else -1, *self._kernel_args)
        if answer != swept_kernels.SWEPT_FREE and answer != swept_kernels.SWEPT_COLLIDES:
            return None
        if cache:
            self._clear_cache = ((key0, key1, self._point.tobytes())[cache - 1], bool(clear))
        if q1_clear >= 0:
            self._command_end = (key1, bool(q1_clear))
        return answer == swept_kernels.SWEPT_FREE

    def slide(self, q0, track, stop, away, target, dt, acceleration, lower,
              upper) -> tuple[np.ndarray, np.ndarray, int] | None:
        """A command from q0 that holds back only the fingers whose motion would collide (swept_slide):
        (command, its velocity, held: bit f for each finger left short of its step), every joint between
        its braking step `stop` and its capped step `track`, the command and the way on to where braking
        at `acceleration` from it stops within [lower, upper] shown free. None where no finger-wise command
        is found (the colliding fingers brake already), where q0 is within the margin, or where the check
        is not compiled (or not this format's): then the caller brakes the whole hand. Two fingers stuck in each
        other's way: the one nearer its `target` gives way, a joint at a time, to `away` (row 0: each joint's
        capped step towards its lower limit, row 1 its upper; the limiter's own commands, so within every
        limit), checked the same way (swept_slide's step 3)."""
        if not self.slides or self._kernel_args is None or not dt > 0:
            return None
        q0 = np.ascontiguousarray(q0, dtype=np.float64)
        key = q0.tobytes()
        cached, end = self._clear_cache, self._command_end
        q0_clear = int(cached[1]) if cached[0] == key else int(end[1]) if end[0] == key else -1
        out = np.empty((2, len(q0)))
        answer, held, _ = swept_kernels.swept_slide(
            q0, q0_clear, np.ascontiguousarray(track, dtype=np.float64), np.ascontiguousarray(stop, dtype=np.float64),
            np.ascontiguousarray(away, dtype=np.float64), np.ascontiguousarray(target, dtype=np.float64), float(dt),
            acceleration, lower, upper, SLIDE_STEPS, SLIDE_BUDGET, *self._fingers, *self._kernel_args, out)
        if answer != swept_kernels.SWEPT_FREE:
            return None
        return out[0], out[1], int(held)

    def _last_free_compiled(self, q0, q1, steps: int) -> float | None:
        """The bisection's fraction of the segment, or None where a configuration on the way is within the
        margin (then the caller bisects, each segment checked by _segment_free_compiled)."""
        q0 = np.ascontiguousarray(q0, dtype=np.float64)
        q1 = np.ascontiguousarray(q1, dtype=np.float64)
        key = q0.tobytes()
        cached = self._clear_cache
        q0_clear = int(cached[1]) if cached[0] == key else -1
        end = np.empty_like(q0)
        answer, lo, q0_clear, cache = swept_kernels.swept_last_free(q0, q1, int(steps), q0_clear, *self._kernel_args,
                                                                    end)
        if answer != swept_kernels.SWEPT_FREE:
            return None
        if cache == 1:
            self._clear_cache = (key, bool(q0_clear))
        elif cache >= 2:
            self._clear_cache = (end.tobytes(), cache == 3)
        return float(lo)
