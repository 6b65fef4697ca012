"""The sim camera's picture and the robot geometry it is drawn from."""

import cv2
import numpy as np
import pytest

from teleprev.clock import SessionClock
from teleprev.devices.contract import DeviceContext
from teleprev.robot.geometry import BOX_EDGES, BOX_FACES, RobotShapes, robot_geometry
from teleprev.robot.model import load_robot
from teleprev_devices.sim.camera import CameraSettings, SimCamera
from teleprev_devices.sim.world import shared_world

ARM = tuple(f"joint{i}" for i in range(1, 7))
HOME = np.array([0.0, -0.27, -0.11, 0.0, -0.85, -1.571])


def grab(cam, n=1):
    frames = []
    while len(frames) < n:
        frames += [s.payload for s in cam.read(0.5)]
    return [cv2.imdecode(np.frombuffer(f.data, np.uint8), cv2.IMREAD_COLOR) for f in frames[:n]]


@pytest.fixture
def camera():
    ctx = DeviceContext(clock=SessionClock())
    cam = SimCamera("cam", CameraSettings(width=320, height=240, noise=0.0, label=False, latency_ms=5.0), ctx)
    world = shared_world(ctx)
    world.set_joints(ARM, HOME)
    cam.connect()
    yield cam, world
    cam.disconnect()


def test_frames_change_when_the_robot_moves_and_only_then(camera):
    cam, world = camera
    a, b = grab(cam, 2)
    assert a.shape == (240, 320, 3)
    assert np.array_equal(a, b)  # same world, no noise: the same picture
    world.set_joints(ARM, HOME + np.array([0.6, 0.3, -0.3, 0.0, 0.3, 0.0]))
    world.set_joints(tuple(str(i) for i in range(16)), np.r_[[0.0, 1.5, 1.5, 1.5] * 3, [1.2, 0.5, 0.5, 0.5]])
    (c,) = grab(cam)
    changed = np.abs(c.astype(int) - a.astype(int)).max(axis=2) > 40
    assert changed.sum() > 500, f"only {changed.sum()} pixels changed"
    assert changed.sum() < 0.5 * changed.size  # the table and the backdrop stayed


def test_noise_makes_frames_differ_a_little():
    ctx = DeviceContext(clock=SessionClock())
    cam = SimCamera("cam", CameraSettings(width=160, height=120, noise=2.0, latency_ms=5.0), ctx)
    cam.connect()
    a, b = grab(cam, 2)
    cam.disconnect()
    diff = np.abs(a.astype(int) - b.astype(int))
    assert 0.2 < diff.mean() < 6.0


@pytest.mark.parametrize("view", ["front", "side", "top"])
def test_views_show_the_robot_on_the_table(view):
    """The robot's pixels differ from the empty scene's, and the table fills part of every view."""
    ctx = DeviceContext(clock=SessionClock())
    cam = SimCamera("cam", CameraSettings(width=320, height=240, noise=0.0, label=False, view=view), ctx)
    cam.connect()
    renderer = cam.renderer
    world = shared_world(ctx)
    world.set_joints(ARM, HOME)
    q = world.joints()
    with_robot = renderer.render(q, world.scene(0, q))
    without = renderer.render(None, world.scene(0, q))
    cam.disconnect()
    robot_pixels = (np.abs(with_robot.astype(int) - without.astype(int)).max(axis=2) > 20).sum()
    assert robot_pixels > 0.01 * 320 * 240
    table = np.abs(without.astype(int) - np.array([95, 120, 150])).max(axis=2) < 50
    assert table.sum() > 0.1 * 320 * 240


def test_camera_settings_are_checked():
    from teleprev.config import from_table
    from teleprev.errors import ConfigError

    with pytest.raises(ConfigError, match=r"\[devices.cam\].view.*'front'"):
        from_table(CameraSettings, {"view": "back"}, "[devices.cam]")
    with pytest.raises(ConfigError, match="jpeg_quality"):
        from_table(CameraSettings, {"jpeg_quality": 0}, "[devices.cam]")


def test_geometry_is_the_urdf_primitives_at_the_configuration():
    model = load_robot("xarm6_leap_hand")
    rng = np.random.default_rng(0)
    q = model.sample_uniform(1, rng)[0]
    base = np.eye(4)
    base[:3, 3] = [0.1, -0.2, 0.3]
    geo = RobotShapes(model).at(q, base)
    world = base @ model.fk(q).world
    boxes = [(n, s) for n in geo.link_names for s in model.links[n].visuals if s.kind == "box"]
    cylinders = [(n, s) for n in geo.link_names for s in model.links[n].visuals if s.kind == "cylinder"]
    assert len(geo.box_pose) == len(boxes) and len(geo.cyl_ends) == len(cylinders)
    for i, (name, shape) in enumerate(boxes):
        pose = world[model.link_index[name]] @ shape.origin
        assert geo.link_names[geo.box_link[i]] == name
        assert np.allclose(geo.box_pose[i], pose)
        assert np.allclose(geo.box_corners[i].mean(axis=0), pose[:3, 3])
        local = (geo.box_corners[i] - pose[:3, 3]) @ pose[:3, :3]
        assert np.allclose(np.abs(local), np.array(shape.size) / 2)
        edges = np.linalg.norm(
            geo.box_corners[i][[a for a, _ in BOX_EDGES]] - geo.box_corners[i][[b for _, b in BOX_EDGES]], axis=1
        )
        assert np.allclose(np.sort(edges), np.sort(np.repeat(shape.size, 4)))
        for face in BOX_FACES:  # each face loop is a planar quad, counter-clockwise seen from outside
            c = geo.box_corners[i][list(face)]
            n = np.cross(c[1] - c[0], c[2] - c[0])
            assert abs(np.dot(n, c[3] - c[0])) < 1e-12
            assert np.dot(n, c.mean(axis=0) - pose[:3, 3]) > 0
    for i, (name, shape) in enumerate(cylinders):
        pose = world[model.link_index[name]] @ shape.origin
        assert np.allclose(geo.cyl_ends[i].mean(axis=0), pose[:3, 3])
        assert np.linalg.norm(geo.cyl_ends[i][1] - geo.cyl_ends[i][0]) == pytest.approx(shape.size[1])
        assert np.allclose(np.cross(geo.cyl_ends[i][1] - geo.cyl_ends[i][0], pose[:3, 2]), 0, atol=1e-12)
        assert geo.cyl_radius[i] == shape.size[0]
    # The one-off helper gives the same; collision geometry is available too.
    assert np.allclose(robot_geometry(model, q, base).box_corners, geo.box_corners)
    assert len(RobotShapes(model, "collision").at(q).box_pose) == sum(
        s.kind == "box" for link in model.links.values() for s in link.collisions)


def test_an_object_the_hand_closes_on_moves_with_it_and_drops_when_released():
    from teleprev.robot.effectors import EFFECTORS
    from teleprev.robot.ik import ArmIK
    from teleprev.transforms import make_transform
    from teleprev_devices.sim.world import SimWorld

    world = SimWorld("xarm6_leap_hand", "leap_hand")
    world.set_home(dict(zip(ARM, HOME)))
    model = world.model
    (cup,) = [o for o in world.scene(0) if o.spec.name == "cup"]
    link, offset = EFFECTORS["leap_hand"].grasp_link, np.array(EFFECTORS["leap_hand"].grasp_offset)
    ik = ArmIK(model, link, tcp=make_transform(translation=offset))
    home_pose = ik.pose(HOME)
    result = ik.solve(make_transform(home_pose[:3, :3], cup.pose[:3, 3]), HOME)
    assert result.converged
    open_hand = np.zeros(16)
    closed = np.r_[[0.0, 1.0, 1.0, 0.8] * 3, [0.5, 0.5, 0.5, 0.5]]
    world.set_joints(ARM + tuple(str(i) for i in range(16)), np.r_[result.q, open_hand])
    assert world.scene(0)[0].held is None  # an open hand holds nothing
    world.set_joints(tuple(str(i) for i in range(16)), closed)
    (held,) = world.scene(0)
    assert held.held is not None
    lifted = ik.solve(make_transform(home_pose[:3, :3], cup.pose[:3, 3] + [0.0, 0.1, 0.15]), result.q)
    world.set_joints(ARM, lifted.q)
    (moved,) = world.scene(0)
    assert np.allclose(moved.pose[:3, 3], cup.pose[:3, 3] + [0.0, 0.1, 0.15], atol=2e-3)
    world.set_joints(tuple(str(i) for i in range(16)), open_hand)
    (dropped,) = world.scene(0)
    assert dropped.held is None
    assert dropped.pose[2, 3] == pytest.approx(cup.pose[2, 3]) and dropped.pose[1, 3] == pytest.approx(
        cup.pose[1, 3] + 0.1, abs=2e-3
    )


class _Physics:
    """What follow_operator needs of the physics world: its scene requests, recorded."""

    closed = False

    def __init__(self):
        self.loaded: list[str] = []

    def seen(self, anchor):
        return None

    def load_layout(self, task, seed, anchor, spots, reason):
        self.loaded.append(reason)


def test_the_physics_scene_only_moves_forward_whichever_actuator_asks_late():
    # The arm and the hand each ask at their own acquisition time; a thread that ran late asks about a
    # moment before the operator's new episode, and must not bring the last episode's scene back.
    from teleprev_devices.sim.operator import SimOperator
    from teleprev_devices.sim.world import SimWorld

    op = SimOperator(seed=0, task="pick_place", mode="fixed")
    world = SimWorld("xarm6_leap_hand", "leap_hand", {"sim.operator": op})
    physics = _Physics()
    start_1, _ = op.episode_span(1)
    ns = lambda t: int(t * 1e9)  # noqa: E731
    world.follow_operator(physics, ns(start_1 - 1.0))  # episode 0's scene
    world.follow_operator(physics, ns(start_1 + 0.01))  # the arm: episode 1 began
    world.follow_operator(physics, ns(start_1 - 0.01))  # the hand, late: still episode 0 by its clock
    world.follow_operator(physics, ns(start_1 + 0.02))
    assert physics.loaded == ["operator episode 0 (seed 0): pick_place", "operator episode 1 (seed 0): pick_place"]
