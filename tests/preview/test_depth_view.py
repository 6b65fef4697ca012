"""The preview's camera panel shows depth, colour-mapped (near red, far blue, no return black): `c` switches
colour, depth and both; the key shows only with a depth camera, and the screen still fits 80x24."""

from __future__ import annotations

import io
from types import SimpleNamespace

import numpy as np
import pytest
from rich.console import Console

from teleprev.live.record.run import ROBOT_BOUNDS, _frame, make_dashboard, with_camera_key
from teleprev.live.record.session import LiveSession, RecordOptions
from teleprev.messages import DepthSample
from teleprev.preview.camera_view import depth_rgb
from teleprev.preview.dashboard import CAMERA_KEY, Dashboard
from teleprev.preview.robot_view import RobotView
from teleprev.robot.model import load_robot
from teleprev.session.reader import SessionReader
from teleprev.status import DeviceRow, LoopSnapshot
from teleprev_devices.realsense_software import SoftwareRealSense
from tests.helpers.depth_session import depth_physics_rig, record_depth_session
from tests.helpers.wait import wait_until

W, H = 160, 120


@pytest.fixture(scope="module")
def recorded_depth(tmp_path_factory) -> list[DepthSample]:
    """Depth frames of a session recorded live from a (software_device) D435: a tilted table, 0.3..0.9 m."""
    path = tmp_path_factory.mktemp("depth") / "session.mcap"
    record_depth_session(path, SoftwareRealSense(serial="000000000435", model="D435", width=W, height=H), 1.0)
    with SessionReader(path) as reader:
        return [m.payload for m in reader.messages(["/camera/wrist/depth"])]


def test_a_recorded_depth_frame_maps_near_to_red_far_to_blue_and_holes_to_black(recorded_depth):
    sample = recorded_depth[len(recorded_depth) // 2]
    metres = sample.metres()
    rgb = depth_rgb(metres, step=1).astype(int)
    seen = metres > 0
    assert (~seen).any() and not rgb[~seen].any()  # the camera's holes are black
    near = metres <= np.percentile(metres[seen], 5)
    far = (metres >= np.percentile(metres[seen], 95)) & seen
    near_rgb, far_rgb = rgb[near & seen].mean(axis=0), rgb[far].mean(axis=0)
    assert near_rgb[0] > near_rgb[2] + 100, near_rgb  # red
    assert far_rgb[2] > far_rgb[0] + 100, far_rgb  # blue
    # the colours follow the depth: along the depth, red goes down and blue up
    order = np.argsort(metres[seen])
    red, blue = rgb[seen][order][:, 0], rgb[seen][order][:, 2]
    thirds = np.array_split(np.arange(len(order)), 3)
    assert red[thirds[0]].mean() > red[thirds[2]].mean() and blue[thirds[0]].mean() < blue[thirds[2]].mean()


def test_a_gradient_gives_a_different_colour_at_near_and_far():
    counts = np.repeat(np.linspace(300, 900, H, dtype=np.uint16)[:, None], W, axis=1)  # 0.3 m top, 0.9 m bottom
    rgb = depth_rgb(DepthSample(1, "cam", counts, 0.001).metres())
    assert rgb.shape == (H // 4, W // 4, 3)
    top, bottom = rgb[0].mean(axis=0), rgb[-1].mean(axis=0)
    assert top[0] > top[2] + 100 and bottom[2] > bottom[0] + 100, (top, bottom)


@pytest.fixture(scope="module")
def dashboard():
    robot, hand = load_robot("xarm6_leap_hand"), load_robot("leap_hand_right")
    return Dashboard(RobotView(robot, "side", ROBOT_BOUNDS["side"]), RobotView(hand, "side"),
                     tuple(f"joint{i}" for i in range(1, 7)), hand.joint_names, robot)


def _screen(dashboard, width, height, camera, depth) -> list[str]:
    arm, flexed = np.array([0.0, -0.3, -0.6, 0.0, 0.9, 0.0]), np.full(16, 0.6)
    step = SimpleNamespace(state=SimpleNamespace(arm_q=arm, effector_q=flexed), corrected=flexed, retargeted=flexed,
                           report={"corrector": "untouched"})
    snap = LoopSnapshot(mode="preview", step=step, measured_arm=arm, measured_effector=flexed)
    rows = [DeviceRow(n, k, "ok", 30.0, 30.0, 2.0, 0, 0, 0) for n, k in (("glove", "glove"), ("wrist", "camera"))]
    console = Console(file=io.StringIO(), width=width, height=height, record=True, color_system="truecolor")
    console.print(dashboard.render(snap, rows, width, height, 0, camera=camera, depth=depth))
    return console.export_text().rstrip("\n").splitlines()


def _titles(lines: list[str]) -> set[str]:
    return {t for t in ("camera", "depth") if any(f"─ {t} ─" in line for line in lines)}


def test_c_switches_the_camera_panel_between_colour_depth_and_both_within_80x24(dashboard, recorded_depth):
    from tests.preview.test_layout import camera_frame

    camera, depth = camera_frame(), recorded_depth[-1]
    assert dashboard.camera_mode == "colour"
    without = _screen(dashboard, 80, 24, camera, None)
    assert not any("colour/depth" in line for line in without)  # no depth camera: no key for it
    shown = []
    press = with_camera_key(dashboard, lambda key: pytest.fail(f"{key!r} reached the recording"))
    for _ in range(4):
        for size in ((80, 24), (120, 45)):
            lines = _screen(dashboard, *size, camera, depth)
            assert len(lines) <= size[1] and all(len(line) <= size[0] for line in lines), "\n".join(lines)
            assert any(f"{CAMERA_KEY[0]} {CAMERA_KEY[1]}" in line for line in lines), "\n".join(lines)
            assert sum(line.count("▀") for line in lines) >= 18 * 6
            shown.append((dashboard.camera_mode, size, _titles(lines)))
        press(CAMERA_KEY[0])
    assert shown == [("colour", (80, 24), {"camera"}), ("colour", (120, 45), {"camera"}),
                     ("depth", (80, 24), {"depth"}), ("depth", (120, 45), {"depth"}),
                     # both: side by side where they fit; at 80x24 the depth (the robot and hand keep their room)
                     ("both", (80, 24), {"depth"}), ("both", (120, 45), {"camera", "depth"}),
                     ("colour", (80, 24), {"camera"}), ("colour", (120, 45), {"camera"})]


def test_a_live_physics_sessions_screen_shows_its_cameras_depth(tmp_path):
    rec = LiveSession(RecordOptions(out=tmp_path / "s.mcap", rig=depth_physics_rig(tmp_path)))
    rec.start()
    try:
        depth = wait_until(lambda: rec.loop.snapshot.depth, 60, what="a depth frame in the preview's snapshot")
        assert isinstance(depth, DepthSample) and depth.depth.shape == (H, W)
        dashboard = make_dashboard(rec, "side")
        dashboard.next_camera_mode()
        console = Console(file=io.StringIO(), width=80, height=24, record=True, color_system="truecolor")
        console.print(_frame(dashboard, rec, console))
        lines = console.export_text().rstrip("\n").splitlines()
    finally:
        rec.stop()
    assert "depth" in _titles(lines) and all(len(line) <= 80 for line in lines), "\n".join(lines)
