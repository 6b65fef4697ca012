"""A robot's geometric primitives at one configuration, in the world frame, for drawing it.

The simulated camera renders the robot from this, and the terminal preview draws the same robot from
it. Each URDF primitive becomes plain world-frame geometry: a box its pose and eight corners (edges and
faces index them through BOX_EDGES and BOX_FACES), a cylinder or capsule its two end points and radius,
a sphere its centre and radius. `RobotShapes` gathers a model's primitives once, so a configuration
costs one forward kinematics and a few numpy operations.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from teleprev.robot.model import RobotModel

# Corner i of a box is at (±x, ±y, ±z) / 2 in its frame, with the signs of the bits of i (x: bit 0).
BOX_CORNER_SIGNS = np.array(
    [[1 if i & 1 else -1, 1 if i & 2 else -1, 1 if i & 4 else -1] for i in range(8)], dtype=float
)
BOX_EDGES: tuple[tuple[int, int], ...] = (
    (0, 1), (2, 3), (4, 5), (6, 7), (0, 2), (1, 3), (4, 6), (5, 7), (0, 4), (1, 5), (2, 6), (3, 7),
)
# Faces as corner loops, counter-clockwise seen from outside, with their outward normals in the box frame.
BOX_FACES: tuple[tuple[int, int, int, int], ...] = (
    (0, 4, 6, 2), (1, 3, 7, 5), (0, 1, 5, 4), (2, 6, 7, 3), (0, 2, 3, 1), (4, 5, 7, 6),
)
BOX_FACE_NORMALS = np.array([[-1, 0, 0], [1, 0, 0], [0, -1, 0], [0, 1, 0], [0, 0, -1], [0, 0, 1]], dtype=float)


@dataclass(frozen=True)
class RobotGeometry:
    """World-frame primitives; `*_link` index `link_names`."""

    link_names: tuple[str, ...]
    box_link: np.ndarray  # (B,)
    box_pose: np.ndarray  # (B, 4, 4) box centre and axes
    box_size: np.ndarray  # (B, 3) full edge lengths
    box_corners: np.ndarray  # (B, 8, 3)
    cyl_link: np.ndarray  # (C,)
    cyl_ends: np.ndarray  # (C, 2, 3) centres of the two end faces (capsules: of the two end spheres)
    cyl_radius: np.ndarray  # (C,)
    cyl_capsule: np.ndarray  # (C,) bool
    sphere_link: np.ndarray  # (S,)
    sphere_centre: np.ndarray  # (S, 3)
    sphere_radius: np.ndarray  # (S,)


class RobotShapes:
    """The primitives of one model (`source`: "visual", or "collision"; a link without visuals falls back
    to its collision shapes, so nothing with geometry goes missing)."""

    def __init__(self, model: RobotModel, source: Literal["visual", "collision"] = "visual"):
        if source not in ("visual", "collision"):
            raise ValueError(f"source must be 'visual' or 'collision', got {source!r}")
        self.model = model
        self.link_names = tuple(n for n in model.link_names if model.links[n].visuals or model.links[n].collisions)
        groups: dict[str, list] = {"box": [], "cyl": [], "sphere": []}
        for li, name in enumerate(self.link_names):
            link = model.links[name]
            shapes = link.visuals if source == "visual" and link.visuals else link.collisions
            for s in shapes:
                kind = "cyl" if s.kind in ("cylinder", "capsule") else s.kind
                groups[kind].append((li, model.link_index[name], s))

        def table(rows):
            return (np.array([r[0] for r in rows], dtype=int), np.array([r[1] for r in rows], dtype=int),
                    np.array([r[2].origin for r in rows]).reshape(-1, 4, 4))

        self._box_link, self._box_model_link, self._box_local = table(groups["box"])
        self._box_size = np.array([r[2].size for r in groups["box"]], dtype=float).reshape(-1, 3)
        self._cyl_link, self._cyl_model_link, self._cyl_local = table(groups["cyl"])
        self._cyl_radius = np.array([r[2].size[0] for r in groups["cyl"]], dtype=float)
        half = np.array([r[2].size[1] / 2 for r in groups["cyl"]], dtype=float)
        # End points in the shape frame, homogeneous: (C, 2, 4).
        self._cyl_ends_local = np.zeros((len(half), 2, 4))
        self._cyl_ends_local[:, 0, 2], self._cyl_ends_local[:, 1, 2] = -half, half
        self._cyl_ends_local[:, :, 3] = 1.0
        self._cyl_capsule = np.array([r[2].kind == "capsule" for r in groups["cyl"]], dtype=bool)
        self._sph_link, self._sph_model_link, self._sph_local = table(groups["sphere"])
        self._sph_radius = np.array([r[2].size[0] for r in groups["sphere"]], dtype=float)
        self._corner_offsets = self._box_size[:, None, :] / 2 * BOX_CORNER_SIGNS  # (B, 8, 3)

    def at(self, q: np.ndarray, base: np.ndarray | None = None) -> RobotGeometry:
        """The primitives at joint vector q (the model's joint order); `base` places the robot's root."""
        world = self.model.fk(np.asarray(q, dtype=float)).world
        if base is not None:
            world = np.asarray(base, dtype=float) @ world
        box_pose = world[self._box_model_link] @ self._box_local
        corners = box_pose[:, None, :3, 3] + self._corner_offsets @ np.swapaxes(box_pose[:, :3, :3], -1, -2)
        cyl_pose = world[self._cyl_model_link] @ self._cyl_local
        ends = (cyl_pose[:, None] @ self._cyl_ends_local[..., None])[..., :3, 0]
        sph = (world[self._sph_model_link] @ self._sph_local)[:, :3, 3]
        return RobotGeometry(
            self.link_names, self._box_link, box_pose, self._box_size, corners,
            self._cyl_link, ends, self._cyl_radius, self._cyl_capsule,
            self._sph_link, sph, self._sph_radius,
        )


def robot_geometry(model: RobotModel, q: np.ndarray, base: np.ndarray | None = None,
                   source: Literal["visual", "collision"] = "visual") -> RobotGeometry:
    """One-off convenience: RobotShapes(model, source).at(q, base). Keep a RobotShapes to draw repeatedly."""
    return RobotShapes(model, source).at(q, base)
