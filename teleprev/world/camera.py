"""A camera of the physics world: colour and depth images from one of its named viewpoints.

MuJoCo renders offscreen through whatever GL it is given: set MUJOCO_GL=egl before the first render on a
machine without a display (Mesa's EGL renders in software). Depth comes back in metres along the
camera's axis, as a depth camera reports it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Self

import mujoco
import numpy as np

from teleprev.world.build import MAX_IMAGE, VIEWS
from teleprev.world.world import PhysicsWorld


@dataclass(frozen=True)
class Frame:
    time_ns: int
    rgb: np.ndarray  # (height, width, 3) uint8, RGB
    depth: np.ndarray | None  # (height, width) float32 metres, 0 where nothing is in range; None: not asked for


class WorldCamera:
    def __init__(self, world: PhysicsWorld, camera: str = "front", width: int = 640, height: int = 480):
        if camera not in VIEWS:
            raise ValueError(f"unknown camera {camera!r} (the world has {', '.join(VIEWS)})")
        if not (16 <= width <= MAX_IMAGE[0] and 16 <= height <= MAX_IMAGE[1]):
            raise ValueError(f"image size must be 16..{MAX_IMAGE[0]} x 16..{MAX_IMAGE[1]}, got {width}x{height}")
        self.world, self.camera = world, camera
        self._renderer = mujoco.Renderer(world.model, height, width)
        self._option = mujoco.MjvOption()
        self._far = float(world.model.vis.map.zfar * world.model.stat.extent)

    def render(self, depth: bool = False) -> Frame:
        """The picture now (the world's lock is held only while the scene is copied out)."""
        with self.world.lock:
            self._renderer.update_scene(self.world.data, self.camera, self._option)
            t = self.world.time_ns
        rgb = self._renderer.render().copy()
        d = None
        if depth:
            self._renderer.enable_depth_rendering()
            try:
                d = self._renderer.render().astype(np.float32)
                d[d >= self._far * 0.999] = 0.0  # nothing in range: 0, as a depth camera reports no return
            finally:
                self._renderer.disable_depth_rendering()
        return Frame(t, rgb, d)

    def close(self) -> None:
        self._renderer.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
