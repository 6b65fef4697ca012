"""The simulated world shared by the sim devices of one rig (context.shared["sim.world"]).

It holds the robot's current joint state (SimArm and SimHand write it, SimCamera draws it), the table
and the objects of the operator's current task. Objects are laid out per episode from the operator's
script, mapped from the task frame into the robot's base frame through `anchor`: the robot point that
the operator's resting wrist corresponds to (the TCP at the arm's home pose). The robot base stands on
the table top (z = 0). An object the end effector closes on moves with it until it lets go, then
drops upright onto the table (or the cup below it), or hangs from the peg it was let go at, so the
camera shows a grasp that worked.

On a physics rig (DeviceContext.physics) the objects are the physics world's instead: `follow_operator`
loads each new operator episode's scene into it, its objects where the episode's script put them, and
has the operator watch the world (SimOperator.watch): its aimed phases go where it sees the objects.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from teleprev.devices import EFFECTORS, RobotModel, load_robot, transforms, world_places
from teleprev_devices.sim.shared import get_or_create
from teleprev_devices.sim.tasks import SCRIPTS, TABLE_Z, SceneObject

TABLE = SceneObject("table", "box", (1.2, 1.3, 0.04), (0.30, 0.0, -0.02), 0.0, (95, 120, 150), False)

EYES_PERIOD_S = 0.05  # how often the watching operator looks (a person's visual feedback takes ~0.1 s)
_GRASP_REACH = 0.09  # metres between the grasp point and an object's centre for a grasp to hold it


def yaw_pose(yaw: float, centre) -> np.ndarray:
    """A 4x4 pose standing upright at `centre`, turned `yaw` about z."""
    return transforms.make_transform(transforms.rpy_to_matrix(0.0, 0.0, yaw), centre)


@dataclass
class PlacedObject:
    spec: SceneObject
    pose: np.ndarray  # 4x4 in the robot base frame
    held: np.ndarray | None = None  # pose relative to the grasp point while held


class SimWorld:
    def __init__(self, robot: str, end_effector: str, shared: dict | None = None):
        self.model: RobotModel = load_robot(robot)
        self.end_effector = end_effector
        self._shared = shared if shared is not None else {}
        self._lock = threading.Lock()
        # Until an arm reports, the robot stands at the sim arm's default home.
        self._q = self.model.clip(
            self.model.vector(
                {
                    f"joint{i + 1}": v
                    for i, v in enumerate(world_places.ARM_HOME)
                    if f"joint{i + 1}" in self.model.joint_index
                },
                self.model.neutral(),
            )
        )
        self.vacuum_on = False
        self.anchor = np.array(world_places.DEFAULT_ANCHOR)
        # The point that closes on objects (the end-effector table's grasp point); for the LEAP Hand also,
        # in _reach_points, the pinch between the thumb and index tips.
        effector = EFFECTORS.get(end_effector)
        self._tcp_link = effector.tcp_link if effector else None
        self._grasp_link = effector.grasp_link if effector else None
        self._grasp_offset = np.array(effector.grasp_offset) if effector else None
        if self._grasp_link not in self.model.link_index:
            self._grasp_link = None
        self._episode: tuple | None = None
        self._objects: list[PlacedObject] = []
        self._physics_episode: tuple | None = None
        self._watching = False

    # ---- robot state ---------------------------------------------------------------------------
    def set_joints(self, names: tuple[str, ...], values: np.ndarray) -> None:
        idx = [self.model.joint_index[n] for n in names if n in self.model.joint_index]
        vals = [v for n, v in zip(names, values) if n in self.model.joint_index]
        with self._lock:
            if idx:
                self._q[idx] = vals
            if "vacuum" in names:
                self.vacuum_on = bool(values[names.index("vacuum")] >= 0.5)

    def joints(self) -> np.ndarray:
        with self._lock:
            return self._q.copy()

    def set_home(self, q_arm: dict[str, float]) -> None:
        """Place the task scene relative to the TCP at the arm's home pose."""
        tcp = self._tcp_link
        if tcp in self.model.link_index:
            q = self.model.vector(q_arm, self.model.neutral())
            with self._lock:
                self.anchor = self.model.fk(q).position(tcp).copy()
                self._episode = None  # lay the scene out again

    def grasp_point(self, q: np.ndarray) -> np.ndarray | None:
        """The pose that carries a held object (the palm, the jaws' centre, the suction cup)."""
        if self._grasp_link is None:
            return None
        m = self.model.fk(q).matrix(self._grasp_link)
        return m @ transforms.make_transform(translation=self._grasp_offset)

    def _reach_points(self, q: np.ndarray, grip: np.ndarray) -> list[np.ndarray]:
        points = [grip[:3, 3]]
        if self.end_effector == "leap_hand" and "thumb_tip_head" in self.model.link_index:
            poses = self.model.fk(q)
            points.append(0.5 * (poses.position("thumb_tip_head") + poses.position("index_tip_head")))
        return points

    def closed(self, q: np.ndarray) -> bool:
        """Whether the end effector is holding on (fingers curled, jaws shut, suction on)."""
        if self.end_effector == "leap_hand":
            flex = [q[self.model.joint_index[j]] for j in ("1", "5", "9") if j in self.model.joint_index]
            return bool(flex) and float(np.mean(flex)) > 0.6
        if self.end_effector == "parallel_gripper" and "gripper" in self.model.joint_index:
            return float(q[self.model.joint_index["gripper"]]) < 0.07
        return self.vacuum_on

    # ---- scene ---------------------------------------------------------------------------------
    def _layout(self, objects: tuple[SceneObject, ...]) -> list[PlacedObject]:
        placed = []
        for o in objects:
            centre = np.array([self.anchor[0] + o.centre[0], self.anchor[1] + o.centre[1], o.centre[2] - TABLE_Z])
            placed.append(PlacedObject(o, yaw_pose(o.yaw, centre)))
        return placed

    def _scene_source(self, now_ns: int) -> tuple[tuple, tuple[SceneObject, ...]]:
        op = self._shared.get("sim.operator")
        if op is None:
            return ("default",), SCRIPTS["pick_place"](np.random.default_rng(0), np.zeros(3)).objects
        t = op.time_s(now_ns)
        index, task = op.episode(t)
        return (index, task), op.objects(t)

    def scene(self, now_ns: int, q: np.ndarray | None = None) -> list[PlacedObject]:
        """The objects now (robot base frame), after letting the end effector pick up or drop them."""
        q = self.joints() if q is None else q
        key, objects = self._scene_source(now_ns)
        grip = self.grasp_point(q)
        closed = self.closed(q)
        with self._lock:
            if key != self._episode:
                self._episode = key
                self._objects = self._layout(objects)
            for obj in self._objects:
                if obj.held is not None:
                    if closed and grip is not None:
                        obj.pose = grip @ obj.held
                    else:
                        obj.held = None
                        self._drop(obj)
            if closed and grip is not None and not any(o.held is not None for o in self._objects):
                points = self._reach_points(q, grip)

                def distance(o: PlacedObject) -> float:
                    return min(float(np.linalg.norm(o.pose[:3, 3] - p)) for p in points)

                near = [o for o in self._objects if o.spec.graspable and distance(o) < _GRASP_REACH]
                if near:
                    obj = min(near, key=distance)
                    obj.held = np.linalg.inv(grip) @ obj.pose
            return [PlacedObject(o.spec, o.pose.copy(), o.held) for o in self._objects]

    def _drop(self, obj: PlacedObject) -> None:
        height = obj.spec.size[2] if obj.spec.kind == "box" else obj.spec.size[1]
        x_axis = obj.pose[:3, 0]
        yaw = float(np.arctan2(x_axis[1], x_axis[0]))
        for peg in (o for o in self._objects if o.spec.name == "peg"):
            if np.linalg.norm(peg.pose[:3, 3] - obj.pose[:3, 3]) < _GRASP_REACH:
                # Let go next to the peg: it hangs from it upright, its handle's hole round the peg and the
                # hole's top bar on it (as the physics world's mug comes to hang).
                out, up = world_places.MUG_HANDLE
                hole = np.array([out * np.cos(yaw), out * np.sin(yaw), up - height / 2])
                hang = peg.pose[:3, 3] - hole - [0.0, 0.0, 0.011]
                obj.pose = yaw_pose(yaw, hang)
                return
        # Onto whatever it is above (a stacked cup rests on the one below), else the table.
        floor = 0.0
        for other in self._objects:
            if other is obj or other.spec.kind != "cylinder" or obj.spec.kind != "cylinder":
                continue
            if np.linalg.norm(other.pose[:2, 3] - obj.pose[:2, 3]) < other.spec.size[0]:
                floor = max(floor, other.pose[2, 3] + other.spec.size[1] / 2 - 0.07)
        obj.pose = yaw_pose(yaw, [obj.pose[0, 3], obj.pose[1, 3], floor + height / 2])


    # ---- the physics world's scene ---------------------------------------------------------------
    def follow_operator(self, physics, now_ns: int) -> None:
        """Physics: when the operator has begun another episode, run its scene (once per episode, whichever
        device notices first). Only forward: each actuator asks at its own acquisition time, and one whose
        thread ran late may ask about a moment before the episode the other has already begun."""
        op = self._shared.get("sim.operator")
        if op is None:
            return
        if not self._watching:  # the operator watches the world it acts in, as a person at the table does
            self._watching = True
            op.watch(Eyes(lambda: physics.seen(self.anchor), alive=lambda: not physics.closed))
        t = op.time_s(now_ns)
        key = op.episode(t)
        with self._lock:
            if self._physics_episode is not None and key[0] <= self._physics_episode[0]:
                return
            self._physics_episode = key
        index, task = key
        physics.load_layout(task, op.seed, self.anchor, op.spots(t),
                            reason=f"operator episode {index} (seed {op.seed}): {task}")


class Eyes:
    """What the operator sees, looked at every EYES_PERIOD_S by a thread of its own: reading the physics
    world (a mirror of it, rebuilt whenever the scene changes) must not hold up the glove and suit
    threads that ask. Calling gives the latest look (None before the first); it stops looking when
    `alive()` turns false (the world closed with the session)."""

    def __init__(self, look, alive=lambda: True, period_s: float = EYES_PERIOD_S):
        self._look, self._alive, self._period_s = look, alive, period_s
        self._seen = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="sim-operator-eyes", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set() and self._alive():
            try:
                self._seen = self._look()
            except Exception:  # the world not (or no longer) running: the operator acts on what it saw
                pass
            self._stop.wait(self._period_s)

    def __call__(self):
        return self._seen

    def close(self) -> None:
        self._stop.set()


def shared_world(context) -> SimWorld:
    """The rig's world (created by the first sim device that needs it)."""
    return get_or_create(context.shared, "sim.world",
                         lambda: SimWorld(context.robot, context.end_effector, context.shared))
