"""Exact self-collision, with per-link labels and the colliding link pairs.

    SelfCollisionChecker     what everything calls: for all-box geometry the compiled check decides
                             (teleprev/robot/compiled_collision.py, microseconds), FCL only where the
                             compiled answer is within its margin of touching; FCL alone otherwise
    FclSelfCollisionChecker  FCL decides every contact (also the tests' independent reference)

The compiled check brackets FCL's answer (tests/robot/test_compiled_collision.py): every pair FCL finds
in contact, it reports with its margin (1 nm) on the "colliding" side; every pair it reports with the
margin turned the other way (overlapping by more than 1 nm), FCL finds. Where the two agree they are
FCL's answer; where they differ (a pair within a nanometre of touching) FCL is asked. So the answers
are FCL's, bit for bit: sessions recorded with the FCL checker re-run identically.

In FclSelfCollisionChecker fcl decides every contact. Two vectorised numpy filters only decide which shape pairs fcl
needs to
look at: bounding spheres, then, for box pairs, the face axes of the separating-axis test (a pair they
let through may still be apart, and fcl decides; a pair they drop is apart for sure).
Link pairs that are never checked (parent and child, and pairs that touch in every sampled
configuration) come from the exclusion file next to the URDF (see exclusions.py).
"""

from __future__ import annotations

import fcl
import numpy as np

from teleprev.kernels import boxes as boxes_kernels
from teleprev.kernels import collision as collision_kernels
from teleprev.robot.collision_report import CollisionReport, link_labels
from teleprev.robot.compiled_collision import CompiledSelfCollisionChecker
from teleprev.robot.exclusions import Exclusions, load_exclusions
from teleprev.robot.model import RobotModel

_SAT_GAP = 1e-9  # a box pair counts as separated only when some axis separates it by more than this


def _fcl_geometry(kind: str, size: tuple[float, ...]):
    if kind == "box":
        return fcl.Box(*size)
    if kind == "sphere":
        return fcl.Sphere(size[0])
    if kind == "cylinder":
        return fcl.Cylinder(size[0], size[1])
    return fcl.Capsule(size[0], size[1])


def _bounding_radius(kind: str, size: tuple[float, ...]) -> float:
    if kind == "box":
        return 0.5 * float(np.linalg.norm(size))
    if kind == "sphere":
        return size[0]
    if kind == "cylinder":
        return float(np.hypot(size[0], 0.5 * size[1]))
    return size[0] + 0.5 * size[1]


def boxes_separated(ta: np.ndarray, tb: np.ndarray, half_a: np.ndarray, half_b: np.ndarray) -> np.ndarray:
    """Face-axis separation test for k pairs of oriented boxes (world transforms (k, 4, 4), half extents
    (k, 3)): True where one of the six face normals separates the pair, so it certainly does not touch.

    The nine edge-edge axes of the full separating-axis test are left to fcl: on collision-free hand
    configurations the face axes already clear all but about 0.4 pairs per configuration.
    """
    rat = np.swapaxes(ta[:, :3, :3], -1, -2)
    r = rat @ tb[:, :3, :3]
    t = (rat @ (tb[:, :3, 3] - ta[:, :3, 3])[..., None])[..., 0]
    ar = np.abs(r)
    face_a = np.abs(t) - half_a - (ar @ half_b[..., None])[..., 0]
    face_b = np.abs((t[:, None, :] @ r)[:, 0, :]) - (half_a[:, None, :] @ ar)[:, 0, :] - half_b
    return np.maximum(face_a.max(axis=1), face_b.max(axis=1)) > _SAT_GAP


def _distance2(centres: np.ndarray) -> np.ndarray:
    """Squared distances between all shape centres, (..., S, 3) -> (..., S, S)."""
    sq = np.einsum("...i,...i->...", centres, centres)
    return sq[..., :, None] + sq[..., None, :] - 2.0 * (centres @ np.swapaxes(centres, -1, -2))


class FclSelfCollisionChecker:
    """Self-collision of one robot model, every contact decided by FCL.

    `link_names` are the links with collision geometry (the m labels of a configuration), in model order.
    """

    def __init__(self, model: RobotModel, exclusions: Exclusions | None = None):
        self.model = model
        self.exclusions = exclusions if exclusions is not None else load_exclusions(model)
        self.link_names = tuple(n for n in model.link_names if model.links[n].collisions)
        link_pos = {n: i for i, n in enumerate(self.link_names)}

        shape_link, local, kinds, half, radius, objects = [], [], [], [], [], []
        for name in self.link_names:
            for shape in model.links[name].collisions:
                shape_link.append(link_pos[name])
                local.append(shape.origin)
                kinds.append(shape.kind)
                half.append(np.array(shape.size) / 2 if shape.kind == "box" else np.zeros(3))
                radius.append(_bounding_radius(shape.kind, shape.size))
                objects.append(fcl.CollisionObject(_fcl_geometry(shape.kind, shape.size), fcl.Transform()))
        self._shape_link = np.array(shape_link)
        self._shape_model_link = np.array([model.link_index[self.link_names[i]] for i in shape_link])
        self._local = np.array(local)
        self._half = np.array(half)
        self._objects = objects

        # Link pairs that are checked, and the shape pairs under each.
        self.link_pairs: tuple[tuple[str, str], ...] = self.exclusions.checked_pairs(self.link_names)
        pair_of = np.full((len(self.link_names),) * 2, -1)  # link positions -> checked pair (-1: not checked)
        for k, (a, b) in enumerate(self.link_pairs):
            pair_of[link_pos[a], link_pos[b]] = pair_of[link_pos[b], link_pos[a]] = k
        si, sj = np.triu_indices(len(shape_link), 1)  # every shape pair i < j, in order
        links = np.asarray(shape_link, dtype=np.int64)
        lp = pair_of[links[si], links[sj]]
        under = lp >= 0  # (a link is never paired with itself)
        self._si, self._sj, self._lp = si[under], sj[under], lp[under]
        self._flat_pair = self._si * len(shape_link) + self._sj  # into the (S, S) distance matrix
        rad = np.array(radius)
        self._reach2 = (rad[self._si] + rad[self._sj]) ** 2
        is_box = np.array([k == "box" for k in kinds])
        self._both_boxes = is_box[self._si] & is_box[self._sj]
        # Pair -> (link a, link b) positions, to turn colliding pairs into per-link labels.
        self._pair_links = np.array([(link_pos[a], link_pos[b]) for a, b in self.link_pairs], dtype=int).reshape(-1, 2)
        self._request = fcl.CollisionRequest()

    # ---- internals -----------------------------------------------------------------------------
    def _shape_world(self, world: np.ndarray) -> np.ndarray:
        """Shape transforms (..., S, 4, 4) from link transforms (..., L, 4, 4)."""
        return world[..., self._shape_model_link, :, :] @ self._local

    def _candidates(self, shapes: np.ndarray) -> np.ndarray:
        """Indices into the shape-pair tables of the pairs fcl must decide, for one configuration."""
        near = np.flatnonzero(_distance2(shapes[:, :3, 3]).ravel()[self._flat_pair] < self._reach2)
        boxes = self._both_boxes[near]
        if boxes.any():
            a, b = self._si[near[boxes]], self._sj[near[boxes]]
            apart = boxes_separated(shapes[a], shapes[b], self._half[a], self._half[b])
            boxes[boxes] = ~apart
            near = near[boxes | ~self._both_boxes[near]]
        return near

    def _fcl_pairs(self, shapes: np.ndarray, candidates: np.ndarray, first_only: bool) -> list[int]:
        """Link-pair indices that fcl finds in contact, trying each link pair's shape pairs until one hits."""
        hit: list[int] = []
        seen: set[int] = set()
        placed: set[int] = set()
        objects = self._objects
        for lp, a, b in zip(
            self._lp[candidates].tolist(), self._si[candidates].tolist(), self._sj[candidates].tolist()
        ):
            if lp in seen:
                continue
            for s in (a, b):
                if s not in placed:
                    objects[s].setRotation(shapes[s, :3, :3])  # cheaper than building an fcl.Transform
                    objects[s].setTranslation(shapes[s, :3, 3])
                    placed.add(s)
            if fcl.collide(objects[a], objects[b], self._request, fcl.CollisionResult()):
                seen.add(lp)
                hit.append(lp)
                if first_only:
                    break
        return hit

    def _report(self, hits: list[int]) -> CollisionReport:
        labels = np.zeros(len(self.link_names), dtype=bool)
        if hits:
            labels[self._pair_links[hits].ravel()] = True
        return CollisionReport(labels, tuple(self.link_pairs[i] for i in sorted(hits)))

    # ---- public --------------------------------------------------------------------------------
    def check(self, q: np.ndarray) -> CollisionReport:
        """All colliding link pairs and the per-link labels of one configuration."""
        shapes = self._shape_world(self.model.fk(q).world)
        return self._report(self._fcl_pairs(shapes, self._candidates(shapes), first_only=False))

    def collides(self, q: np.ndarray) -> bool:
        """Whether one configuration is in self-collision; stops at the first contact."""
        shapes = self._shape_world(self.model.fk(q).world)
        return bool(self._fcl_pairs(shapes, self._candidates(shapes), first_only=True))

    def first_collision(self, q: np.ndarray) -> int | None:
        """Index of the first configuration of the batch q (N, n) in self-collision, or None."""
        return next((i for i, x in enumerate(q) if self.collides(x)), None)

    def pair_matrix(self, q: np.ndarray, world: np.ndarray | None = None) -> np.ndarray:
        """(N, len(link_pairs)) bool: which checked link pairs collide, for a batch of configurations.

        `world` may pass link transforms already computed (for example by the batched FK on a GPU).
        """
        q = np.atleast_2d(q)
        world = self.model.fk(q).world if world is None else world
        shapes = self._shape_world(world)  # (N, S, 4, 4)
        centres = shapes[..., :3, 3]
        d = centres[:, self._si] - centres[:, self._sj]  # gathering beats (N, S, S) matmuls for batches
        rows, cols = np.nonzero(np.einsum("npi,npi->np", d, d) < self._reach2)
        boxes = self._both_boxes[cols]
        if boxes.any():
            rb, cb = rows[boxes], cols[boxes]
            a, b = self._si[cb], self._sj[cb]
            apart = boxes_separated(shapes[rb, a], shapes[rb, b], self._half[a], self._half[b])
            keep = np.ones(len(rows), dtype=bool)
            keep[np.flatnonzero(boxes)[apart]] = False
            rows, cols = rows[keep], cols[keep]
        out = np.zeros((len(q), len(self.link_pairs)), dtype=bool)
        starts = np.flatnonzero(np.r_[True, rows[1:] != rows[:-1]]) if len(rows) else []
        for n, sel in zip(rows[starts], np.split(cols, starts[1:])):  # rows come sorted from nonzero
            out[n, self._fcl_pairs(shapes[n], sel, first_only=False)] = True
        return out

    def labels(self, q: np.ndarray, world: np.ndarray | None = None) -> np.ndarray:
        """(N, m) bool per-link labels for a batch of configurations."""
        return self.labels_from_pairs(self.pair_matrix(q, world))

    def labels_from_pairs(self, pairs: np.ndarray) -> np.ndarray:
        return link_labels(pairs, self._pair_links, len(self.link_names))


class SelfCollisionChecker(FclSelfCollisionChecker):
    """FCL's answers (see the module docstring), from compiled code wherever it is certain of them.

    The compiled test runs once per configuration with both margins (kernels.*_margins: FK, box poses
    and bounding spheres once, each axis compared with +MARGIN and -MARGIN): the answers of `_loose`
    (CompiledSelfCollisionChecker with +MARGIN: FCL's contacts and more) and of the same checker with
    -MARGIN (fewer) at once. `kernel_tables` holds the kernels' tables (the swept check takes them too).
    """

    def __init__(self, model: RobotModel, exclusions: Exclusions | None = None):
        super().__init__(model, exclusions)
        self._loose = None
        self.kernel_tables = None  # (FkTable, BoxTable, Margins) where the compiled check runs
        self._args = None
        if all(s.kind == "box" for n in self.link_names for s in model.links[n].collisions):
            self._loose = CompiledSelfCollisionChecker(model, self.exclusions)  # FCL's contacts and more
            self.kernel_tables = (self._loose.kinematics.table, self._loose.boxes,
                                  collision_kernels.Margins(self._loose.margin, -boxes_kernels.MARGIN))
            self._args = tuple(x for table in self.kernel_tables for x in table)  # the kernels' arguments after q
            self._n_labels = len(self.link_names)
            q = model.neutral()  # load the kernels from numba's cache now, not in a live loop's first steps
            self.check(q), self.collides(q), self.first_collision(q[None]), self.pair_matrix(q[None])

    def check(self, q: np.ndarray) -> CollisionReport:
        if self._args is None:
            return super().check(q)
        labels = np.zeros(self._n_labels, dtype=bool)
        index = np.empty(len(self.link_pairs), dtype=np.int64)
        n = collision_kernels.check_margins(
            np.ascontiguousarray(q, dtype=np.float64), *self._args, False, labels, index
        )
        report = self.report_of(n, labels, index)
        return report if report is not None else super().check(q)

    def report_of(self, n: int, labels: np.ndarray, index: np.ndarray) -> CollisionReport | None:
        """The report of a compiled check's answer (collision_kernels.check_margins without first_only): n
        colliding pairs, their indices in index[:n], their links in labels; None where a pair is within
        the margin of touching (n < 0): then FCL decides."""
        if n < 0:
            return None
        names = self.link_pairs
        return CollisionReport(labels, tuple([names[i] for i in index[:n].tolist()]))

    def collides(self, q: np.ndarray) -> bool:
        if self._args is None:
            return super().collides(q)
        n = collision_kernels.collides_margins(np.ascontiguousarray(q, dtype=np.float64), *self._args)
        return n > 0 if n >= 0 else super().collides(q)

    def first_collision(self, q: np.ndarray) -> int | None:
        if self._args is None:
            return super().first_collision(q)
        q = np.ascontiguousarray(q, dtype=np.float64)
        k, state = collision_kernels.first_colliding_margins(q, 0, *self._args)
        while k >= 0 and state < 0 and not super().collides(q[k]):  # within the margin and free for FCL: go on
            k, state = collision_kernels.first_colliding_margins(q, k + 1, *self._args)
        return None if k < 0 else int(k)

    def pair_matrix(self, q: np.ndarray, world: np.ndarray | None = None) -> np.ndarray:
        if self._args is None:
            return super().pair_matrix(q, world)
        q = np.atleast_2d(q)
        world = self._loose.kinematics.world(q) if world is None else world  # (one kernel fewer to compile)
        world = np.ascontiguousarray(world, dtype=np.float64).reshape(-1, *world.shape[-3:])
        _, boxes, margins = self.kernel_tables
        hits, unsure = collision_kernels.pair_matrix_margins_world(world, *boxes, *margins)
        unsure = np.flatnonzero(unsure)
        if len(unsure):
            hits[unsure] = super().pair_matrix(q[unsure])
        return hits
