"""Compile one physics world: the robot from our URDF, its drives, the table, a task's objects, cameras.

Names carry over from the URDF: joints and actuators are the robot's joint names ("joint1".., "0".."15",
"gripper"; "vacuum" is an actuator only), bodies are links, and each task object is a body (with a free
joint) of its own name. Collision groups: the robot touches the table and the objects, never itself (its
self-collision is the pipeline's guard, not the world's business); objects touch everything.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from teleprev.paths import data_dir
from teleprev.robot.effectors import EndEffector
from teleprev.world import drives
from teleprev.world.layout import HANDLE_BAR, HANDLE_DEPTH, HANDLE_HOLE, HANDLE_Z, Layout, Placed, Shape
from teleprev.world.places import VIEWS, View

_ROBOT_TYPE, _ROBOT_AFFINITY = 1, 2  # robot geoms: collide with what has bit 1 in its affinity... and not themselves
_OBJECT_TYPE, _OBJECT_AFFINITY = 2, 3
TABLE_SIZE = (1.2, 1.3, 0.04)
TABLE_CENTRE = (0.30, 0.0, -0.02)

_ARM_RGBA = (0.87, 0.87, 0.85, 1.0)
_HAND_RGBA = (0.19, 0.19, 0.2, 1.0)
_TIP_RGBA = (0.88, 0.88, 0.88, 1.0)
_TOOL_RGBA = (0.5, 0.47, 0.46, 1.0)


# The sim camera's 60 degree horizontal field at 4:3 (its viewpoints: places.VIEWS).
FOVY_DEG = math.degrees(2 * math.atan(math.tan(math.radians(30.0)) * 3 / 4))
MAX_IMAGE = (1280, 960)  # the offscreen buffer: the largest camera image the world renders
CONTACT_TIMECONST = 0.008


@dataclass(frozen=True)
class Compiled:
    model: mujoco.MjModel
    arm_joints: tuple[str, ...]
    effector_joints: tuple[str, ...]  # "vacuum" included: an actuator without a joint
    robot_bodies: frozenset[int]
    tcp_site: str = "tcp"


def _quat_yaw(yaw: float) -> list[float]:
    return [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]


def _quat_mul(a, b) -> list[float]:
    q = np.zeros(4)
    mujoco.mju_mulQuat(q, np.asarray(a, float), np.asarray(b, float))
    return q.tolist()


def _geom(body, name: str, kind, size, pos, quat=(1.0, 0.0, 0.0, 0.0), mass: float | None = None,
          shape: Shape | None = None, collides: bool = True):
    g = body.add_geom()
    g.name, g.type = name, kind
    g.size = list(size) + [0.0] * (3 - len(size))
    g.pos, g.quat = list(pos), list(quat)
    if mass is not None:
        g.mass = mass
    if shape is not None:
        g.rgba = list(shape.rgba)
        g.friction = [shape.friction, 0.005, 0.0001]
        if shape.kind == "sphere":
            # Rolling and spinning friction too (condim 6): without them a ball on a flat floor rolls for ever.
            g.condim, g.friction = 6, [shape.friction, 0.005, 0.0005]
        elif shape.rolling > 0:
            g.condim, g.friction = 6, [shape.friction, 0.005, shape.rolling]
    g.contype, g.conaffinity = (_OBJECT_TYPE, _OBJECT_AFFINITY) if collides else (0, 0)
    return g


def _cup_parts(shape: Shape) -> list[tuple]:
    """(suffix, type, half sizes, pos, quat) of a hollow tapered cup: a floor and a ring of wall plates.
    The body frame is the centre of the cup's base."""
    r_bottom, r_top, h, t = shape.size
    n = 12 if r_top < 0.05 else 16
    tilt = math.atan2(r_top - r_bottom, h)
    r_mid = (r_bottom + r_top) / 2 - t / 2
    half_width = r_mid * math.tan(math.pi / n) * 1.08  # a little overlap: no gap between plates
    parts = [("floor", mujoco.mjtGeom.mjGEOM_CYLINDER, (r_bottom, t / 2), (0.0, 0.0, t / 2), (1.0, 0.0, 0.0, 0.0))]
    for i in range(n):
        a = 2 * math.pi * i / n
        quat = _quat_mul(_quat_yaw(a), [math.cos(tilt / 2), 0.0, math.sin(tilt / 2), 0.0])
        # The walls stand on the floor (z from t to h): only the floor touches what the cup stands on.
        r_centre = r_mid + (r_top - r_bottom) * t / (2 * h)
        pos = (r_centre * math.cos(a), r_centre * math.sin(a), (h + t) / 2)
        half_length = (h - t) / 2 / math.cos(tilt)
        parts.append((f"wall{i}", mujoco.mjtGeom.mjGEOM_BOX, (t / 2, half_width, half_length), pos, quat))
    return parts


def mug_handle_hole(shape: Shape) -> tuple[float, float]:
    """The centre of a mug's handle hole (x out from its axis, z up from its base) in the mug's body frame;
    the hole (HANDLE_HOLE) spans from the wall's outside outwards, its axis along y."""
    r_bottom, r_top, h, _ = shape.size
    wall = r_bottom + (r_top - r_bottom) * HANDLE_Z / h
    return wall + HANDLE_HOLE[0] / 2, HANDLE_Z


def _mug_parts(shape: Shape) -> list[tuple]:
    """A cup and its handle: a top and a bottom bar out of the wall, and an outer bar joining them."""
    cx, cz = mug_handle_hole(shape)
    w, hh = HANDLE_HOLE[0] / 2, HANDLE_HOLE[1] / 2
    b, d = HANDLE_BAR / 2, HANDLE_DEPTH / 2
    inner = cx - w - 0.006  # the bars start inside the wall: no gap
    outer = cx + w + 2 * b
    box = mujoco.mjtGeom.mjGEOM_BOX
    q = (1.0, 0.0, 0.0, 0.0)
    bar = ((outer - inner) / 2, d, b)
    return _cup_parts(shape) + [
        ("handle_top", box, bar, ((outer + inner) / 2, 0.0, cz + hh + b), q),
        ("handle_bottom", box, bar, ((outer + inner) / 2, 0.0, cz - hh - b), q),
        ("handle_outer", box, (b, d, hh), (cx + w + b, 0.0, cz), q),
    ]


def _parts(shape: Shape) -> list[tuple]:
    if shape.kind == "cup":
        return _cup_parts(shape)
    if shape.kind == "mug":
        return _mug_parts(shape)
    q = (1.0, 0.0, 0.0, 0.0)
    if shape.kind == "box":
        return [("", mujoco.mjtGeom.mjGEOM_BOX, tuple(s / 2 for s in shape.size), (0.0, 0.0, 0.0), q)]
    return [("", mujoco.mjtGeom.mjGEOM_SPHERE, shape.size, (0.0, 0.0, 0.0), q)]


def _volume(kind, half) -> float:
    if kind == mujoco.mjtGeom.mjGEOM_BOX:
        return 8 * half[0] * half[1] * half[2]
    if kind == mujoco.mjtGeom.mjGEOM_CYLINDER:
        return math.pi * half[0] ** 2 * 2 * half[1]
    return 4 / 3 * math.pi * half[0] ** 3


def _add_object(spec: mujoco.MjSpec, o: Placed) -> None:
    parts = _parts(o.shape)
    if o.fixed:
        # Static: geoms on the world body, in world coordinates.
        for suffix, kind, half, pos, quat in parts:
            yawq = _quat_yaw(o.yaw)
            rotated = np.zeros(3)
            mujoco.mju_rotVecQuat(rotated, np.asarray(pos, float), np.asarray(yawq, float))
            _geom(spec.worldbody, o.name + (f"/{suffix}" if suffix else ""), kind, half,
                  np.asarray(o.position) + rotated, _quat_mul(yawq, quat), shape=o.shape, collides=o.collides)
        return
    body = spec.worldbody.add_body()
    body.name, body.pos, body.quat = o.name, list(o.position), _quat_yaw(o.yaw)
    joint = body.add_freejoint()
    joint.name = o.name
    volumes = [_volume(kind, half) for _, kind, half, _, _ in parts]
    for (suffix, kind, half, pos, quat), v in zip(parts, volumes):
        _geom(body, o.name + (f"/{suffix}" if suffix else ""), kind, half, pos, quat,
              mass=o.shape.mass * v / sum(volumes), shape=o.shape, collides=o.collides)


def _robot_colour(link: str, arm_links: set[str]) -> tuple[float, ...]:
    if link in arm_links:
        return _ARM_RGBA
    if "fingertip" in link:
        return _TIP_RGBA
    if link.startswith(("gripper", "jaw", "vacuum")):
        return _TOOL_RGBA
    return _HAND_RGBA


def _add_drive(spec: mujoco.MjSpec, joint: str, drive: drives.Drive) -> None:
    j = spec.joint(joint)
    j.armature, j.damping = drive.armature, [drive.damping, 0.0, 0.0]  # mujoco 4: a polynomial in the speed
    a = spec.add_actuator()
    a.name, a.target = joint, joint
    a.trntype = mujoco.mjtTrn.mjTRN_JOINT
    a.set_to_position(kp=drive.kp, kv=drive.kd)
    a.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
    a.forcerange = [-drive.force_limit, drive.force_limit]
    a.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
    a.ctrlrange = list(j.range)


def _add_camera(spec: mujoco.MjSpec, name: str, view: View) -> None:
    eye, target, up = (np.asarray(v, dtype=float) for v in (view.eye, view.target, view.up))
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    # A MuJoCo camera looks along its -z with +y up.
    rotation = np.stack([right, np.cross(right, forward), -forward], axis=1)
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, rotation.flatten())
    cam = spec.worldbody.add_camera()
    cam.name, cam.pos, cam.quat, cam.fovy = name, eye.tolist(), quat.tolist(), FOVY_DEG


def compile_world(effector: EndEffector, layout: Layout, timestep: float) -> Compiled:
    spec = mujoco.MjSpec.from_file(str(data_dir("urdf") / f"{effector.robot}.urdf"))
    spec.compiler.fusestatic = False  # keep every link (the TCP, the tip frames) a named body
    spec.option.timestep = timestep
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC  # grasps hold better than with the pyramid
    spec.option.impratio = 10.0
    spec.visual.global_.offwidth, spec.visual.global_.offheight = MAX_IMAGE
    # Software GL (Mesa's llvmpipe under EGL): shadows and multisampling cost more than the picture itself.
    spec.visual.quality.shadowsize, spec.visual.quality.offsamples = 0, 0

    arm_joints = tuple(j.name for j in spec.joints if j.name.startswith("joint"))
    arm_links = {"link_base"} | {spec.joint(n).parent.name for n in arm_joints} | {"link_eef"}
    robot_bodies = [b for b in spec.bodies if b.name != "world"]
    for b in robot_bodies:
        # The xArm controller's gravity model with the whole end effector as its payload: uncompensated
        # fingers left the arm 0.24 mrad (joint2, joint3) below its target at rest, which a new command
        # stream from there reads as a step (a jerk fault). Compensating the fingers' own joints too is
        # within the Dynamixels' noise: their links weigh grams.
        b.gravcomp = 1.0
    for g in spec.geoms:
        g.contype, g.conaffinity = _ROBOT_TYPE, _ROBOT_AFFINITY
        g.rgba = list(_robot_colour(g.parent.name, arm_links))
        g.friction = [1.0, 0.005, 0.0001]
    spec.body(effector.tcp_link).add_site(name="tcp")

    for name in arm_joints:
        _add_drive(spec, name, drives.ARM)
    effector_joints = tuple(effector.joints)
    if effector.name == "leap_hand":
        for name in effector_joints:
            _add_drive(spec, name, drives.LEAP_SIDE if name in drives.LEAP_SIDE_JOINTS else drives.LEAP)
    elif effector.name == "parallel_gripper":
        _add_drive(spec, "gripper", drives.GRIPPER)
        for eq in spec.equalities:  # the jaws' mimic: as stiff as the step allows, so they squeeze as driven
            eq.solref = [2 * timestep, 1.0]
    elif effector.is_switch:
        cup = spec.body(effector.tcp_link).parent
        for g in cup.geoms:
            g.margin, g.gap = 0.004, 0.004  # contacts appear just before touching: suction pulls from there
        a = spec.add_actuator()
        a.name = "vacuum"
        a.set_to_adhesion(gain=drives.VACUUM_FORCE_N)
        a.trntype, a.target = mujoco.mjtTrn.mjTRN_BODY, cup.name
        a.ctrllimited, a.ctrlrange = mujoco.mjtLimited.mjLIMITED_TRUE, [0.0, 1.0]

    table = spec.worldbody.add_geom()
    table.name, table.type = "table", mujoco.mjtGeom.mjGEOM_BOX
    table.size, table.pos = [s / 2 for s in TABLE_SIZE], list(TABLE_CENTRE)
    table.rgba, table.friction = [0.59, 0.47, 0.37, 1.0], [0.7, 0.005, 0.0001]
    table.contype, table.conaffinity = _OBJECT_TYPE, _OBJECT_AFFINITY
    for o in layout.objects:
        _add_object(spec, o)
    for name, view in VIEWS.items():
        _add_camera(spec, name, view)
    light = spec.worldbody.add_light()
    light.type = mujoco.mjtLightType.mjLIGHT_DIRECTIONAL
    light.pos, light.dir = [0.6, -0.8, 2.0], [-0.35, 0.45, -0.82]  # the sim renderer's light
    light.diffuse, light.ambient, light.castshadow = [0.6, 0.6, 0.6], [0.3, 0.3, 0.3], False

    for g in spec.geoms:
        # Stiffer contacts than MuJoCo's default (0.02 s lets a 30 N squeeze sink 7 mm into a cup's 4 mm
        # wall; 0.008 s, 1 mm), except the pour's balls: light, they chatter on stiff contacts.
        if g.type != mujoco.mjtGeom.mjGEOM_SPHERE:
            g.solref = [CONTACT_TIMECONST, 1.0]
    model = spec.compile()
    robot_ids = frozenset(model.body(b.name).id for b in robot_bodies)
    return Compiled(model, arm_joints, effector_joints, robot_ids)
