"""Exact self-collision of an all-box robot in compiled code: a drop-in for SelfCollisionChecker.

Same link names, checked link pairs (and their order), exclusions, method names and return types as
the fcl-based teleprev.robot.collision.SelfCollisionChecker, so swapping one for the other is a
one-line change. The arithmetic (FK, box poses, bounding spheres, the separating-axis test) is in
teleprev.kernels (fk, boxes, collision). A pair counts as colliding unless its boxes are apart by more than `margin`
(boxes_kernels.MARGIN, 1 nm) along a separating axis or their bounding spheres are: against FCL it can only
err towards "colliding", and only for boxes within nanometres of touching.

Importing this module compiles nothing; the first call of each kernel compiles it (seconds) unless the
on-disk cache has it, which `warm()` (run by scripts/setup.sh) makes sure of.
"""

from __future__ import annotations

import itertools

import numpy as np

from teleprev.errors import UrdfError
from teleprev.kernels import boxes as boxes_kernels
from teleprev.kernels import collision as collision_kernels
from teleprev.robot.collision_report import CollisionReport, link_labels
from teleprev.robot.compiled_kinematics import CompiledKinematics
from teleprev.robot.exclusions import Exclusions, load_exclusions
from teleprev.robot.model import RobotModel

_CORNERS = np.array(list(itertools.product((-1.0, 1.0), repeat=3)))


class CompiledSelfCollisionChecker:
    """Self-collision of one robot model whose collision geometry is all boxes.

    `link_names` are the links with collision geometry (the m labels of a configuration), in model order;
    `link_pairs` the checked link pairs. A negative `margin` reports only pairs that overlap deeper than
    -margin (tests use it to bracket FCL's answer from below).
    """

    def __init__(self, model: RobotModel, exclusions: Exclusions | None = None, margin: float = boxes_kernels.MARGIN):
        self.model = model
        self.exclusions = exclusions if exclusions is not None else load_exclusions(model)
        self.margin = float(margin)
        self.kinematics = CompiledKinematics(model)
        self.link_names = tuple(n for n in model.link_names if model.links[n].collisions)
        link_pos = {n: i for i, n in enumerate(self.link_names)}

        shape_link, local, size, sphere = [], [], [], []
        for name in self.link_names:
            corners = []
            for shape in model.links[name].collisions:
                if shape.kind != "box":
                    raise UrdfError(
                        f"the compiled self-collision check handles boxes only; link {name!r} has a {shape.kind}",
                        str(model.urdf_path),
                    )
                half = np.array(shape.size, dtype=float) / 2
                shape_link.append(link_pos[name])
                local.append(shape.origin[:3])
                size.append([*half, np.linalg.norm(half)])
                corners.append(shape.origin[:3, 3] + (_CORNERS * half) @ shape.origin[:3, :3].T)
            corners = np.concatenate(corners)
            centre = (corners.min(axis=0) + corners.max(axis=0)) / 2
            sphere.append([*centre, np.linalg.norm(corners - centre, axis=1).max()])
        shape_link_rows = np.array([model.link_index[self.link_names[i]] for i in shape_link], dtype=np.int64)
        shape_local = np.ascontiguousarray(local, dtype=np.float64).reshape(-1, 3, 4)
        shape_size = np.array(size, dtype=np.float64).reshape(-1, 4)
        spheres = np.array(sphere, dtype=np.float64).reshape(-1, 4)
        # Per checked link: its model link and its run of boxes (boxes were gathered link by link).
        shape_link = np.array(shape_link, dtype=np.int64)
        links = np.array(
            [(model.link_index[n], np.searchsorted(shape_link, k), np.searchsorted(shape_link, k, side="right"))
             for k, n in enumerate(self.link_names)], dtype=np.int64,
        ).reshape(-1, 3)

        # Checked link pairs, in the order SelfCollisionChecker reports them (Exclusions.checked_pairs).
        self.link_pairs: tuple[tuple[str, str], ...] = self.exclusions.checked_pairs(self.link_names)
        self._pairs = np.array([(link_pos[a], link_pos[b]) for a, b in self.link_pairs], dtype=np.int64).reshape(-1, 2)
        self.boxes = collision_kernels.BoxTable(shape_link_rows, shape_local, shape_size, links, spheres, self._pairs)
        # SelfCollisionChecker's two-margin kernels (kernels.*_margins) with both margins `margin`: their
        # answers are then never MARGINS_UNSURE, and those of this one margin.
        self._margins = collision_kernels.Margins(self.margin, self.margin)
        self._args = (*self.kinematics.table, *self.boxes, *self._margins)

    @staticmethod
    def _q(q) -> np.ndarray:
        return np.ascontiguousarray(q, dtype=np.float64)

    # ---- public (SelfCollisionChecker's API) ---------------------------------------------------

    def check(self, q: np.ndarray) -> CollisionReport:
        """All colliding link pairs and the per-link labels of one configuration."""
        labels = np.zeros(len(self.link_names), dtype=bool)
        index = np.empty(len(self.link_pairs), dtype=np.int64)
        n = collision_kernels.check_margins(self._q(q), *self._args, False, labels, index)
        return CollisionReport(labels, tuple([self.link_pairs[i] for i in index[:n].tolist()]))

    def collides(self, q: np.ndarray) -> bool:
        """Whether one configuration is in self-collision; stops at the first contact."""
        return bool(collision_kernels.collides_margins(self._q(q), *self._args) > 0)

    def first_collision(self, q: np.ndarray, start: int = 0) -> int | None:
        """Index of the first configuration of the batch q (N, n), from `start` on, in self-collision."""
        k = collision_kernels.first_colliding_margins(self._q(q), start, *self._args)[0]
        return None if k < 0 else int(k)

    def pair_matrix(self, q: np.ndarray, world: np.ndarray | None = None) -> np.ndarray:
        """(N, len(link_pairs)) bool: which checked link pairs collide, for a batch of configurations.

        `world` may pass link transforms (N, L, 4, 4) already computed.
        """
        if world is None:
            world = self.kinematics.world(np.atleast_2d(self._q(q)))
        world = np.ascontiguousarray(world, dtype=np.float64).reshape(-1, *world.shape[-3:])
        return collision_kernels.pair_matrix_margins_world(world, *self.boxes, *self._margins)[0]

    def labels(self, q: np.ndarray, world: np.ndarray | None = None) -> np.ndarray:
        """(N, m) bool per-link labels for a batch of configurations."""
        return self.labels_from_pairs(self.pair_matrix(q, world))

    def labels_from_pairs(self, pairs: np.ndarray) -> np.ndarray:
        return link_labels(pairs, self._pairs, len(self.link_names))
