"""The world's cameras render through EGL: colour that shows the scene, depth in metres."""

from __future__ import annotations

import numpy as np
import pytest

from teleprev.world.build import VIEWS
from teleprev.world.camera import WorldCamera
from teleprev.world.layout import task_layout
from teleprev.world.world import PhysicsWorld
from tests.world.helpers import run


@pytest.fixture
def world():
    w = PhysicsWorld("leap_hand", task_layout("pick_place", 1))
    w.place_robot({"joint1": 1.6})  # the arm swung aside: the top camera sees the table under it
    run(w, 0.1)
    return w


def test_the_top_camera_sees_the_table_at_its_distance(world):
    with WorldCamera(world, "top", 320, 240) as cam:
        frame = cam.render(depth=True)
    assert frame.rgb.shape == (240, 320, 3) and frame.rgb.dtype == np.uint8
    assert frame.depth.shape == (240, 320) and frame.depth.dtype == np.float32
    assert frame.time_ns == world.time_ns
    # The camera looks straight down from 1.45 m onto the table top (z = 0) at its centre pixel.
    assert frame.depth[120, 160] == pytest.approx(VIEWS["top"].eye[2], abs=0.005)
    r, g, b = frame.rgb[120, 160].astype(int)
    assert r > g > b  # the table's brown
    # Beyond the table's sides nothing is in range: no return, 0, and black.
    assert frame.depth[120, 2] == 0.0 and frame.rgb[120, 2].max() < 10


def test_depth_shows_an_object_nearer_than_the_table(world):
    with WorldCamera(world, "top", 320, 240) as cam:
        before = cam.render(depth=True).depth
        # Lift the cup to 0.5 m above the table under the camera's centre: the centre pixel sees it there.
        world.place_object("cup", (VIEWS["top"].eye[0], 0.0, 0.5))
        after = cam.render(depth=True).depth
    assert after[120, 160] == pytest.approx(VIEWS["top"].eye[2] - 0.5 - 0.004, abs=0.01)  # its floor's top
    assert before[120, 160] == pytest.approx(VIEWS["top"].eye[2], abs=0.005)


def test_the_front_camera_at_640x480_shows_the_scene_changing(world):
    with WorldCamera(world, "front") as cam:
        first = cam.render().rgb
        world.place_robot({"joint1": 0.0, "joint2": -0.8})
        second = cam.render().rgb
    assert first.shape == (480, 640, 3)
    assert np.count_nonzero(np.any(first != second, axis=2)) > 1000  # the arm moved in the picture


def test_unknown_cameras_and_sizes_are_refused(world):
    with pytest.raises(ValueError, match="unknown camera 'back'.*front"):
        WorldCamera(world, "back")
    with pytest.raises(ValueError, match="image size"):
        WorldCamera(world, "front", 4000, 3000)
