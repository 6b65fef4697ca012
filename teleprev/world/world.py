"""The physics world one rig runs in: step it on the session clock, command and read joints by name.

    world = PhysicsWorld("leap_hand", task_layout("pour", seed=7), start_ns=clock.start_ns)
    world.set_targets({"joint2": -0.3, "1": 1.2})   # drives' targets, by joint name
    world.advance_to(now_ns)                          # steps of 1/rate_hz up to the session time
    world.joint_positions(("joint1", "joint2"))       # measured, by name
    world.state()                                     # object poses and velocities: what success reads

Every method takes the world's lock, so device threads (an arm, a hand, a camera) may share one world.
The state is a function of the layout, the commands and the times they arrived: nothing is random after
the layout is drawn.
"""

from __future__ import annotations

import threading
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import mujoco
import numpy as np

from teleprev.robot.effectors import end_effector
from teleprev.world.build import Compiled, compile_world
from teleprev.world.layout import Layout
from teleprev.world.places import ARM_HOME

DEFAULT_RATE_HZ = 500.0


@dataclass(frozen=True)
class ObjectState:
    name: str
    position: tuple[float, float, float]  # of the body frame, robot base frame (m)
    quaternion: tuple[float, float, float, float]  # w x y z
    linear_velocity: tuple[float, float, float]  # m/s
    angular_velocity: tuple[float, float, float]  # rad/s, in the body frame (MuJoCo's free joint)
    touching_robot: bool  # any contact with the robot (held, pushed)

    @property
    def rotation(self) -> np.ndarray:
        m = np.zeros(9)
        mujoco.mju_quat2Mat(m, np.asarray(self.quaternion, dtype=float))
        return m.reshape(3, 3)

    @property
    def speed(self) -> float:
        return float(np.linalg.norm(self.linear_velocity))

    @property
    def spin(self) -> float:
        return float(np.linalg.norm(self.angular_velocity))


@dataclass(frozen=True)
class WorldState:
    """The free objects at one instant of the session clock."""

    time_ns: int
    objects: Mapping[str, ObjectState]

    def to_record(self) -> dict:
        """A JSON-ready dict (what a session would store)."""
        return {"time_ns": self.time_ns, "objects": {
            n: {"position": list(o.position), "quaternion": list(o.quaternion),
                "linear_velocity": list(o.linear_velocity), "angular_velocity": list(o.angular_velocity),
                "touching_robot": o.touching_robot} for n, o in self.objects.items()}}


class PhysicsWorld:
    def __init__(self, effector: str, layout: Layout, rate_hz: float = DEFAULT_RATE_HZ, start_ns: int = 0,
                 arm_home: Iterable[float] = ARM_HOME, effector_home: Mapping[str, float] | None = None):
        if not 500.0 <= rate_hz <= 10000.0:
            raise ValueError(f"rate_hz must be 500..10000 (the world steps at 500 Hz or more), got {rate_hz:g}")
        self.effector = end_effector(effector)
        self.layout = layout
        self.step_ns = round(1e9 / rate_hz)
        self.compiled: Compiled = compile_world(self.effector, layout, self.step_ns / 1e9)
        self.model = self.compiled.model
        self.data = mujoco.MjData(self.model)
        self.lock = threading.RLock()  # held by every method; a renderer copying the scene out holds it too
        m = self.model
        self.joint_names = self.compiled.arm_joints + self.compiled.effector_joints
        self._actuator = {n: m.actuator(n).id for n in self.joint_names}
        self._qpos = {n: m.jnt_qposadr[m.joint(n).id] for n in self.joint_names if n != "vacuum"}
        self._dof = {n: m.jnt_dofadr[m.joint(n).id] for n in self.joint_names if n != "vacuum"}
        self._objects = {o.name: m.body(o.name).id for o in layout.free}
        self._object_qpos = {o.name: m.jnt_qposadr[m.joint(o.name).id] for o in layout.free}
        self._object_dof = {o.name: m.jnt_dofadr[m.joint(o.name).id] for o in layout.free}
        self._robot = np.zeros(m.nbody, dtype=bool)
        self._robot[list(self.compiled.robot_bodies)] = True
        home = dict(zip(self.compiled.arm_joints, arm_home))
        home.update(self._effector_default_home())
        home.update(effector_home or {})
        self.time_ns = int(start_ns)
        self.place_robot(home)

    # ---- robot ---------------------------------------------------------------------------------
    def _effector_default_home(self) -> dict[str, float]:
        """Open: the LEAP Hand flat, the gripper's jaws wide apart, suction off."""
        if self.effector.name == "parallel_gripper":
            return {"gripper": float(self.model.jnt_range[self.model.joint("gripper").id][1])}
        return {n: 0.0 for n in self.compiled.effector_joints}

    def _check_names(self, names: Iterable[str]) -> None:
        unknown = [n for n in names if n not in self._actuator]
        if unknown:
            raise KeyError(f"unknown joints {unknown} (the world has {', '.join(self.joint_names)})")

    def place_robot(self, positions: Mapping[str, float]) -> None:
        """Put joints at these positions at rest, with the drives holding them there (a reset, not a motion)."""
        self._check_names(positions)
        with self.lock:
            for name, value in positions.items():
                if name in self._qpos:
                    self.data.qpos[self._qpos[name]] = value
                    self.data.qvel[self._dof[name]] = 0.0
            self._set_ctrl(positions)
            self._sync_mimics()
            mujoco.mj_forward(self.model, self.data)

    def _sync_mimics(self) -> None:
        # The gripper's jaws follow its driver through equalities; a reset puts them there at once.
        m = self.model
        for i in range(m.neq):
            if m.eq_type[i] == mujoco.mjtEq.mjEQ_JOINT:
                a, b = m.eq_obj1id[i], m.eq_obj2id[i]
                c = m.eq_data[i]
                self.data.qpos[m.jnt_qposadr[a]] = c[0] + c[1] * self.data.qpos[m.jnt_qposadr[b]]

    def _set_ctrl(self, targets: Mapping[str, float]) -> None:
        for name, value in targets.items():
            lo, hi = self.model.actuator_ctrlrange[self._actuator[name]]
            self.data.ctrl[self._actuator[name]] = min(max(float(value), lo), hi)

    def set_targets(self, targets: Mapping[str, float]) -> None:
        """The drives' position targets by joint name ("vacuum": 0 off, 1 on), clipped to the joint range."""
        self._check_names(targets)
        values = np.asarray(list(targets.values()), dtype=float)
        if not np.all(np.isfinite(values)):
            raise ValueError(f"joint targets must be finite, got {dict(targets)}")
        with self.lock:
            self._set_ctrl(targets)

    def targets(self, names: Iterable[str] | None = None) -> dict[str, float]:
        names = self.joint_names if names is None else tuple(names)
        self._check_names(names)
        with self.lock:
            return {n: float(self.data.ctrl[self._actuator[n]]) for n in names}

    def joint_positions(self, names: Iterable[str] | None = None) -> dict[str, float]:
        """Measured positions by name (rad, m; "vacuum": the suction command, 0 or 1)."""
        names = self.joint_names if names is None else tuple(names)
        self._check_names(names)
        with self.lock:
            return {n: float(self.data.qpos[self._qpos[n]]) if n in self._qpos
                    else float(self.data.ctrl[self._actuator[n]]) for n in names}

    def joint_velocities(self, names: Iterable[str] | None = None) -> dict[str, float]:
        names = self.joint_names if names is None else tuple(names)
        self._check_names(names)
        with self.lock:
            return {n: float(self.data.qvel[self._dof[n]]) if n in self._dof else 0.0 for n in names}

    def tcp(self) -> np.ndarray:
        """The TCP's 4x4 pose in the robot base frame."""
        with self.lock:
            site = self.data.site("tcp")
            pose = np.eye(4)
            pose[:3, :3], pose[:3, 3] = site.xmat.reshape(3, 3), site.xpos
            return pose

    # ---- time ----------------------------------------------------------------------------------
    def step(self, n: int = 1) -> None:
        with self.lock:
            for _ in range(n):
                mujoco.mj_step(self.model, self.data)
            self.time_ns += n * self.step_ns

    def advance_to(self, t_ns: int) -> int:
        """Step up to session time t_ns (the whole steps that fit); returns how many were taken."""
        with self.lock:
            n = max(0, (int(t_ns) - self.time_ns) // self.step_ns)
            self.step(n)
            return n

    # ---- objects -------------------------------------------------------------------------------
    def place_object(self, name: str, position, quaternion=(1.0, 0.0, 0.0, 0.0)) -> None:
        """Put a free object at a pose, at rest (a test's teleport, a recorded layout's restore)."""
        if name not in self._objects:
            raise KeyError(f"no free object {name!r} (the world has {', '.join(self._objects)})")
        with self.lock:
            a, d = self._object_qpos[name], self._object_dof[name]
            self.data.qpos[a:a + 3] = position
            q = np.asarray(quaternion, dtype=float)
            self.data.qpos[a + 3:a + 7] = q / np.linalg.norm(q)
            self.data.qvel[d:d + 6] = 0.0
            mujoco.mj_forward(self.model, self.data)

    def _touching_robot(self) -> set[int]:
        touching = set()
        body = self.model.geom_bodyid
        for c in self.data.contact[:self.data.ncon]:
            b1, b2 = body[c.geom1], body[c.geom2]
            if self._robot[b1] != self._robot[b2]:
                touching.add(int(b2 if self._robot[b1] else b1))
        return touching

    def seen(self, anchor) -> dict[str, tuple[float, ...]]:
        """What a person watching the scene sees: every free object's position and yaw, and the robot hand's
        (its TCP, as "hand"), in the task frame (metres from `anchor`, the TCP at the arm's home), then how
        it leans (its own x and z axes: where a part of it is, e.g. a held mug's handle):
        (x, y, z, yaw, x axis (3), z axis (3))."""
        ax, ay, az = (float(v) for v in anchor)

        def pose(p, r) -> tuple[float, ...]:
            return (float(p[0]) - ax, float(p[1]) - ay, float(p[2]) - az, float(np.arctan2(r[1, 0], r[0, 0])),
                    *(float(v) for v in r[:, 0]), *(float(v) for v in r[:, 2]))

        tcp = self.tcp()
        out = {"hand": pose(tcp[:3, 3], tcp[:3, :3])}
        for name, o in self.state().objects.items():
            out[name] = pose(o.position, o.rotation)
        return out

    def state(self) -> WorldState:
        with self.lock:
            touching = self._touching_robot()
            objects = {}
            for name, body in self._objects.items():
                a, d = self._object_qpos[name], self._object_dof[name]
                qpos, qvel = self.data.qpos, self.data.qvel
                objects[name] = ObjectState(
                    name, tuple(map(float, qpos[a:a + 3])), tuple(map(float, qpos[a + 3:a + 7])),
                    tuple(map(float, qvel[d:d + 3])), tuple(map(float, qvel[d + 3:d + 6])), body in touching)
            return WorldState(self.time_ns, objects)
