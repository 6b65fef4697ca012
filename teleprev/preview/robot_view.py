"""A robot drawn as wireframe in the terminal, seen from the front, the side or the top.

Views are orthographic in the robot's base frame (x forward, z up): "front" looks back at the robot
from in front of it, "side" from its right, "top" from above. Several robots (the real one, the
previewed one) share one view; links can be highlighted (the links the Corrector had to fix).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from rich.text import Text

from teleprev.preview.canvas import BrailleCanvas
from teleprev.robot.geometry import BOX_EDGES, RobotGeometry, RobotShapes
from teleprev.robot.model import RobotModel

VIEWS = ("front", "side", "top")
# (u, v) axes of each view: u to the right on screen, v up.
_AXES = {
    "front": (np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0])),
    "side": (np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])),
    "top": (np.array([0.0, -1.0, 0.0]), np.array([1.0, 0.0, 0.0])),
}
_EDGES = np.array(BOX_EDGES)


@dataclass(frozen=True)
class Layer:
    q: np.ndarray
    style: str
    highlight: frozenset[str] = frozenset()
    highlight_style: str = "bold red"


class RobotView:
    def __init__(self, model: RobotModel, view: str = "front", bounds: tuple[float, float, float, float] | None = None):
        if view not in VIEWS:
            raise ValueError(f"view must be one of {', '.join(VIEWS)}, got {view!r}")
        self.model = model
        self.view = view
        self.shapes = RobotShapes(model, "visual")
        self.bounds = bounds  # (u_min, u_max, v_min, v_max) in metres; None: fit the first frame drawn

    def _segments(self, geo: RobotGeometry, to_dots, scale: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Screen segments (n, 2) x 2 and the link index of each: box edges, and cylinder outlines (two
        sides and two caps of the cylinder's silhouette, in the view plane)."""
        corners = geo.box_corners
        starts = [to_dots(corners[:, _EDGES[:, 0]].reshape(-1, 3))]
        ends = [to_dots(corners[:, _EDGES[:, 1]].reshape(-1, 3))]
        links = [np.repeat(geo.box_link, len(_EDGES))]
        if len(geo.cyl_link):
            p0, p1 = to_dots(geo.cyl_ends[:, 0]), to_dots(geo.cyl_ends[:, 1])
            d = p1 - p0
            length = np.linalg.norm(d, axis=1, keepdims=True)
            # seen end-on, a cylinder is drawn as a square of its diameter
            d = np.where(length > 1e-6, d / np.maximum(length, 1e-6), [1.0, 0.0])
            perp = np.stack([-d[:, 1], d[:, 0]], axis=1) * (geo.cyl_radius * scale)[:, None]
            starts += [p0 + perp, p0 - perp, p0 + perp, p1 + perp]
            ends += [p1 + perp, p1 - perp, p0 - perp, p1 - perp]
            links += [geo.cyl_link] * 4
        return np.concatenate(starts), np.concatenate(ends), np.concatenate(links)

    def render(self, layers: list[Layer], cols: int, rows: int) -> Text:
        canvas = BrailleCanvas(cols, rows)
        u_axis, v_axis = _AXES[self.view]
        geos = [(layer, self.shapes.at(layer.q)) for layer in layers]
        if self.bounds is None:
            pts = np.concatenate(
                [np.concatenate([g.box_corners.reshape(-1, 3), g.cyl_ends.reshape(-1, 3)]) for _, g in geos]
            )
            u, v = pts @ u_axis, pts @ v_axis
            pad = 0.05 * max(np.ptp(u), np.ptp(v), 1e-3)
            self.bounds = (u.min() - pad, u.max() + pad, v.min() - pad, v.max() + pad)
        u0, u1, v0, v1 = self.bounds
        # Dots are about square (2 x 4 per cell of a 1:2 terminal cell): one scale for both axes.
        scale = min((canvas.width - 1) / (u1 - u0), (canvas.height - 1) / (v1 - v0))
        off_u = (canvas.width - 1 - scale * (u1 - u0)) / 2
        off_v = (canvas.height - 1 - scale * (v1 - v0)) / 2

        def to_dots(p: np.ndarray) -> np.ndarray:
            return np.stack(
                [off_u + (p @ u_axis - u0) * scale, canvas.height - 1 - off_v - (p @ v_axis - v0) * scale], axis=1
            )

        for layer, geo in geos:
            a, b, link = self._segments(geo, to_dots, scale)
            hot = np.isin(link, [i for i, n in enumerate(geo.link_names) if n in layer.highlight])
            canvas.segments(a[~hot], b[~hot], layer.style)
            if hot.any():
                canvas.segments(a[hot], b[hot], layer.highlight_style)
        return canvas.render()
