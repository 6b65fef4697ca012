"""A cheap renderer for the sim camera: the robot's URDF primitives and the scene's objects, projected
through a pinhole camera and painted back to front with flat-shaded OpenCV polygons.

Boxes show their camera-facing faces, cylinders their silhouette plus the cap facing the camera,
spheres a disc; each face is shaded by one directional light. The static part of the picture (backdrop
and table) is drawn once. A few milliseconds per 640x480 frame.
"""

from __future__ import annotations

import cv2
import numpy as np

from teleprev.devices import RobotModel, robot_geometry, world_places
from teleprev_devices.sim.world import TABLE, PlacedObject, yaw_pose

_SHIFT = 4  # sub-pixel bits for cv2 polygon coordinates
_SCALE = 1 << _SHIFT
_NEAR = 0.05
_LIGHT = np.array([0.35, -0.45, 0.82]) / np.linalg.norm([0.35, -0.45, 0.82])
_AMBIENT, _DIFFUSE = 0.45, 0.55
_CIRCLE = np.linspace(0.0, 2 * np.pi, 14, endpoint=False)

ARM_COLOUR = (222, 222, 218)  # BGR
HAND_COLOUR = (48, 48, 52)
TIP_COLOUR = (225, 225, 225)
TOOL_COLOUR = (128, 120, 118)
_EDGE = (60, 60, 60)
_FACES = np.array(robot_geometry.BOX_FACES)
_CORNER_SIGNS = robot_geometry.BOX_CORNER_SIGNS
_FACE_NORMALS = robot_geometry.BOX_FACE_NORMALS
_TABLE_POSE = yaw_pose(TABLE.yaw, TABLE.centre)


VIEWS = world_places.VIEWS  # the physics world's cameras see from the same places


class Pinhole:
    def __init__(self, width: int, height: int, fov_deg: float, view: world_places.View):
        self.width, self.height = width, height
        self.f = (width / 2) / np.tan(np.deg2rad(fov_deg) / 2)
        self.cx, self.cy = width / 2, height / 2
        eye, target, up = (np.array(v, dtype=float) for v in (view.eye, view.target, view.up))
        forward = (target - eye) / np.linalg.norm(target - eye)
        right = np.cross(forward, up)
        right /= np.linalg.norm(right)
        down = np.cross(forward, right)
        self.rotation = np.stack([right, down, forward])  # world -> camera
        self.eye = eye

    def to_camera(self, points: np.ndarray) -> np.ndarray:
        return (points - self.eye) @ self.rotation.T

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates (..., 2) and depth (...) of world points (..., 3)."""
        pc = self.to_camera(points)
        z = pc[..., 2]
        safe = np.maximum(z, _NEAR)
        uv = np.stack([self.f * pc[..., 0] / safe + self.cx, self.f * pc[..., 1] / safe + self.cy], axis=-1)
        return uv, z


def _shade(colour, normals: np.ndarray) -> np.ndarray:
    """Colours (..., 3) of faces with unit normals (..., 3) under the light."""
    k = _AMBIENT + _DIFFUSE * np.clip(normals @ _LIGHT, 0.0, 1.0)
    return np.clip(np.asarray(colour, dtype=float) * k[..., None], 0, 255)


def _perpendiculars(axes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.where(np.abs(axes[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    u = np.cross(axes, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return u, np.cross(axes, u)


class FrameFinish:
    """What every sim camera frame gets last: the label in a corner and pixel noise, so that frames differ."""

    def __init__(self, width: int, height: int, noise: float, seed: int):
        self.height = height
        rng = np.random.default_rng(seed)
        self._noise = []
        if noise > 0:
            for _ in range(4):
                n = rng.normal(0.0, noise, (height, width, 3))
                self._noise.append((np.clip(n, 0, 255).astype(np.uint8), np.clip(-n, 0, 255).astype(np.uint8)))
        self._frame = 0

    def __call__(self, img: np.ndarray, label: str = "") -> np.ndarray:
        if label:
            cv2.putText(img, label, (8, self.height - 10), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (30, 30, 30), 1, cv2.LINE_AA)
        if self._noise:
            pos, neg = self._noise[self._frame % len(self._noise)]
            cv2.add(img, pos, dst=img)
            cv2.subtract(img, neg, dst=img)
        self._frame += 1
        return img


class SceneRenderer:
    """Draws one robot (its visual primitives) and the scene objects from one viewpoint."""

    def __init__(self, model: RobotModel, width: int = 640, height: int = 480, view: str = "front",
                 fov_deg: float = 60.0, noise: float = 2.0, seed: int = 0):
        self.camera = Pinhole(width, height, fov_deg, VIEWS[view])
        self.shapes = robot_geometry.RobotShapes(model, "visual")
        self.width, self.height = width, height
        arm = {j.child for j in model.joints if j.name.startswith("joint")} | {model.desc.root}
        colours = []
        for name in self.shapes.link_names:
            if name in arm:
                colours.append(ARM_COLOUR)
            elif "fingertip" in name:
                colours.append(TIP_COLOUR)
            elif name.startswith(("gripper", "jaw", "vacuum")):
                colours.append(TOOL_COLOUR)
            else:
                colours.append(HAND_COLOUR)
        self._link_colour = np.array(colours, dtype=float)
        self._background = self._draw_background()
        self.finish = FrameFinish(width, height, noise, seed)

    # ---- static ----------------------------------------------------------------------------------
    def _draw_background(self) -> np.ndarray:
        h, w = self.height, self.width
        ramp = np.linspace(0.0, 1.0, h)[:, None, None]
        top, bottom = np.array([205, 200, 192.0]), np.array([150, 146, 140.0])
        img = np.ascontiguousarray(np.broadcast_to(top + (bottom - top) * ramp, (h, w, 3)).astype(np.uint8))
        items: list = []
        self._box_items(items, np.array([_TABLE_POSE]), np.array([TABLE.size]), np.array([TABLE.colour], float))
        self._paint(img, items)
        return img

    # ---- primitives to paint items -------------------------------------------------------------------
    def _box_items(self, items: list, poses: np.ndarray, sizes: np.ndarray, colours: np.ndarray) -> None:
        if len(poses) == 0:
            return
        rot = poses[:, :3, :3]
        centres = poses[:, :3, 3]
        corners = centres[:, None, :] + (sizes[:, None, :] / 2 * _CORNER_SIGNS) @ np.swapaxes(rot, -1, -2)
        uv, z = self.camera.project(corners)
        normals = _FACE_NORMALS @ np.swapaxes(rot, -1, -2)  # (B, 6, 3)
        face_centres = centres[:, None, :] + normals * (sizes[:, None, :] / 2 * np.abs(_FACE_NORMALS)).sum(
            -1, keepdims=True
        )
        facing = np.einsum("bfi,bfi->bf", normals, self.camera.eye - face_centres) > 0
        shades = _shade(colours[:, None, :], normals)
        depth = np.linalg.norm(centres - self.camera.eye, axis=1).tolist()
        pts = np.round(uv * _SCALE).astype(np.int32)
        bs, fs = np.nonzero(facing & (z.min(axis=1) > _NEAR)[:, None])  # row-major: grouped by box
        polys = pts[bs[:, None], _FACES[fs]]  # (K, 4, 2)
        colours_k = shades[bs, fs].tolist()
        ops: list = []
        boxes = bs.tolist()
        for k, b in enumerate(boxes):
            if k and b != boxes[k - 1]:
                items.append((depth[boxes[k - 1]], ops))
                ops = []
            ops.append(("poly", polys[k], tuple(colours_k[k])))
        if ops:
            items.append((depth[boxes[-1]], ops))

    def _cylinder_items(self, items: list, ends: np.ndarray, radius: np.ndarray, colours: np.ndarray) -> None:
        if len(ends) == 0:
            return
        axis = ends[:, 1] - ends[:, 0]
        length = np.linalg.norm(axis, axis=1, keepdims=True)
        axis = axis / np.maximum(length, 1e-9)
        u, v = _perpendiculars(axis)
        ring = np.cos(_CIRCLE)[None, :, None] * u[:, None, :] + np.sin(_CIRCLE)[None, :, None] * v[:, None, :]
        rim = ends[:, :, None, :] + radius[:, None, None, None] * ring[:, None, :, :]  # (C, 2, K, 3)
        uv, z = self.camera.project(rim)
        pts = np.round(uv * _SCALE).astype(np.int32)
        centres = ends.mean(axis=1)
        depth = np.linalg.norm(centres - self.camera.eye, axis=1)
        to_eye = self.camera.eye - centres
        # The cap whose outward normal faces the camera is the one drawn.
        top_visible = np.einsum("ci,ci->c", axis, to_eye) > 0
        cap_normal = np.where(top_visible[:, None], axis, -axis)
        cap_shade = _shade(colours, cap_normal)
        side_normal = to_eye - np.einsum("ci,ci->c", to_eye, axis)[:, None] * axis
        side_normal /= np.maximum(np.linalg.norm(side_normal, axis=1, keepdims=True), 1e-9)
        side_shade = _shade(colours, 0.5 * side_normal + 0.5 * _perp_light(axis))
        for c in np.flatnonzero(z.reshape(len(ends), -1).min(axis=1) > _NEAR):
            hull = cv2.convexHull(pts[c].reshape(-1, 2))
            cap = pts[c, 1 if top_visible[c] else 0]
            items.append((depth[c], [("poly", hull, tuple(side_shade[c].tolist())), ("outline", hull, _EDGE),
                                     ("poly", cap, tuple(cap_shade[c].tolist()))]))

    def _sphere_items(self, items: list, centres: np.ndarray, radius: np.ndarray, colours: np.ndarray) -> None:
        if len(centres) == 0:
            return
        uv, z = self.camera.project(centres)
        depth = np.linalg.norm(centres - self.camera.eye, axis=1)
        for s in np.flatnonzero(z > _NEAR):
            r = self.camera.f * radius[s] / z[s]
            centre = (int(uv[s, 0] * _SCALE), int(uv[s, 1] * _SCALE))
            items.append((depth[s], [("circle", centre, int(r * _SCALE), tuple(_shade(colours[s], _LIGHT).tolist()))]))

    @staticmethod
    def _paint(img: np.ndarray, items: list) -> None:
        """Paint items (depth, ops) farthest first; an op is ("poly", points, colour),
        ("outline", points, colour) or ("circle", centre, radius, colour) in sub-pixel units."""
        items.sort(key=lambda it: -it[0])
        for _, ops in items:
            for op in ops:
                if op[0] == "poly":
                    cv2.fillConvexPoly(img, op[1], op[2], cv2.LINE_8, _SHIFT)
                elif op[0] == "outline":
                    cv2.polylines(img, [op[1]], True, op[2], 1, cv2.LINE_8, _SHIFT)
                else:
                    cv2.circle(img, op[1], op[2], op[3], -1, cv2.LINE_8, _SHIFT)

    def _robot_items(self, items: list, q: np.ndarray) -> None:
        geo = self.shapes.at(q)
        self._box_items(items, geo.box_pose, geo.box_size, self._link_colour[geo.box_link])
        cyl_colour = self._link_colour[geo.cyl_link]
        self._cylinder_items(items, geo.cyl_ends, geo.cyl_radius, cyl_colour)
        caps = geo.cyl_capsule
        if caps.any():
            self._sphere_items(items, geo.cyl_ends[caps].reshape(-1, 3), np.repeat(geo.cyl_radius[caps], 2),
                               np.repeat(cyl_colour[caps], 2, axis=0))
        self._sphere_items(items, geo.sphere_centre, geo.sphere_radius, self._link_colour[geo.sphere_link])

    # ---- a frame ---------------------------------------------------------------------------------------
    def render(self, q: np.ndarray | None, objects: list[PlacedObject], label: str = "") -> np.ndarray:
        """A BGR frame of the robot at joints q (None: the scene without the robot) among the objects."""
        img = self._background.copy()
        items: list = []
        if q is not None:
            self._robot_items(items, q)
        boxes = [o for o in objects if o.spec.kind == "box"]
        cylinders = [o for o in objects if o.spec.kind == "cylinder"]
        if boxes:
            self._box_items(items, np.array([o.pose for o in boxes]), np.array([o.spec.size for o in boxes]),
                            np.array([o.spec.colour for o in boxes], dtype=float))
        if cylinders:
            poses = np.array([o.pose for o in cylinders])
            half = np.array([o.spec.size[1] / 2 for o in cylinders])
            ends = poses[:, None, :3, 3] + np.stack([-half, half], axis=1)[:, :, None] * poses[:, None, :3, 2]
            self._cylinder_items(items, ends, np.array([o.spec.size[0] for o in cylinders]),
                                 np.array([o.spec.colour for o in cylinders], dtype=float))
        self._paint(img, items)
        return self.finish(img, label)


def _perp_light(axis: np.ndarray) -> np.ndarray:
    """The direction across a cylinder's axis that faces the light most (for its side shade)."""
    p = _LIGHT - (axis @ _LIGHT)[:, None] * axis
    return p / np.maximum(np.linalg.norm(p, axis=1, keepdims=True), 1e-9)
