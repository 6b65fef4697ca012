"""The record screen at 80x24 and 120x45: every key shows, the robot, the hand and the camera each get room
to be read, and nothing runs past the terminal; in a smaller one the status stays."""

from __future__ import annotations

import io
from dataclasses import replace
from types import SimpleNamespace

import cv2
import numpy as np
import pytest
from rich.console import Console

from teleprev.live.record.run import ROBOT_BOUNDS
from teleprev.messages import ImageSample
from teleprev.preview.camera_view import picture
from teleprev.preview.dashboard import KEYS, Dashboard
from teleprev.preview.robot_view import RobotView
from teleprev.robot.model import load_robot
from teleprev.status import DeviceRow, LoopSnapshot

ARM = tuple(f"joint{i}" for i in range(1, 7))


@pytest.fixture(scope="module")
def dashboard():
    robot, hand = load_robot("xarm6_leap_hand"), load_robot("leap_hand_right")
    return Dashboard(
        RobotView(robot, "side", ROBOT_BOUNDS["side"]), RobotView(hand, "side"), ARM, hand.joint_names, robot
    )


def snapshot(hand_joints: int) -> LoopSnapshot:
    arm = np.array([0.0, -0.3, -0.6, 0.0, 0.9, 0.0])
    flexed = np.full(hand_joints, 0.6)
    step = SimpleNamespace(state=SimpleNamespace(arm_q=arm, effector_q=flexed), corrected=flexed, retargeted=flexed,
                           report={"corrector": "untouched"})
    return LoopSnapshot(mode="execute", episode=0, episode_active=True, task="pour", step=step,
                        measured_arm=arm, measured_effector=flexed)


DEVICES = [DeviceRow(name, kind, "ok", 100.0, 100.0, 2.0, dropped=0, lost=0, errors=0) for name, kind in
           (("glove", "glove"), ("suit", "suit"), ("cam_front", "camera"), ("arm", "arm"), ("hand", "hand"))]


def camera_frame() -> ImageSample:
    image = np.zeros((480, 640, 3), np.uint8)
    image[:, :320] = (0, 0, 255)  # BGR: the left half red
    image[:, 320:] = (0, 255, 0)  # the right half green
    return ImageSample(7, "cam_front", cv2.imencode(".jpg", image)[1].tobytes(), "jpeg")


def screen(dashboard, width: int, height: int, camera=None, countdown=None) -> list[str]:
    console = Console(file=io.StringIO(), width=width, height=height, record=True, color_system="truecolor")
    console.print(dashboard.render(snapshot(16), DEVICES, width, height, 0, camera=camera, countdown=countdown))
    return console.export_text().rstrip("\n").splitlines()


def panel_width(lines: list[str], title: str) -> int:
    top = next(line for line in lines if title in line)
    start = top.index(title)
    return top.index("╮", start) - top.rindex("╭", 0, start) + 1


@pytest.mark.parametrize("width, height", [(80, 24), (120, 45)])
def test_every_key_and_every_picture_fits(dashboard, width, height):
    lines = screen(dashboard, width, height, camera_frame())
    assert len(lines) <= height and max(len(line) for line in lines) <= width
    text = " ".join(" ".join(lines).split())
    for key, what in KEYS:
        assert f"{key} {what}" in text, key  # q, y/f and r included
    assert "EXECUTE" in text and "episode 0" in text and "cam_front" in text
    for title in ("robot (side)", "hand", "camera"):
        assert panel_width(lines, title) >= 20, title
    assert panel_width(lines, "robot (side)") >= width // 2 - 2  # the robot keeps the larger share
    braille = sum(0x2801 <= ord(c) <= 0x28FF for c in "".join(lines))
    assert braille > 150  # robot and hand drawn, not a blob
    assert sum(line.count("▀") for line in lines) >= 18 * 6  # the camera, in colour blocks


@pytest.mark.parametrize("width, height", [(80, 24), (120, 45)])
def test_the_countdown_of_timed_episodes_fits(dashboard, width, height):
    lines = screen(dashboard, width, height, camera_frame(), countdown=("episode 2/4", 1.25))
    assert len(lines) <= height and max(len(line) for line in lines) <= width
    text = " ".join(" ".join(lines).split())
    assert "episode 2/4: 1.2 s left" in text and all(f"{key} {what}" in text for key, what in KEYS)
    for title in ("robot (side)", "hand", "camera"):
        assert panel_width(lines, title) >= 20, title
    assert sum(0x2801 <= ord(c) <= 0x28FF for c in "".join(lines)) > 150
    small = " ".join(" ".join(screen(dashboard, 50, 14, countdown=("reset", 0.5))).split())
    assert "reset: 0.5 s left" in small  # a small terminal keeps the countdown with the status


def test_without_a_camera_the_robot_and_hand_share_the_width(dashboard):
    lines = screen(dashboard, 80, 24)
    assert not any("─ camera ─" in line for line in lines) and panel_width(lines, "hand") >= 20


def test_a_small_terminal_keeps_the_status_and_every_key(dashboard):
    lines = screen(dashboard, 50, 14, camera_frame())
    text = " ".join(" ".join(lines).split())
    assert "EXECUTE" in text and all(f"{key} {what}" in text for key, what in KEYS)
    assert sum(0x2801 <= ord(c) <= 0x28FF for c in text) == 0  # no room for pictures


def test_the_camera_picture_keeps_its_colours_and_aspect():
    rgb = np.zeros((480, 640, 3), np.uint8)
    rgb[:, :320] = (255, 0, 0)
    rgb[:, 320:] = (0, 255, 0)
    pic = picture(rgb, 20, 10)
    assert pic.top.shape[:2] == (7, 20)  # 4:3 in 20 columns: 15 pixel rows, two to a cell
    assert (pic.top[:, :9] == (248, 0, 0)).all() and (pic.bottom[:, 11:] == (0, 248, 0)).all()


def test_the_xr_pages_url_shows_until_the_page_streams_and_the_screen_still_fits(dashboard):
    url = "https://192.168.1.7:8443/?token=Zq3vR8xWb2LkP0mN4tYs1A"
    waiting = [
        replace(d, state="connecting", hint=f"XR page: {url}") if d.kind in ("glove", "suit") else d for d in DEVICES
    ]
    console = Console(file=io.StringIO(), width=80, height=24, record=True, color_system="truecolor")
    console.print(dashboard.render(snapshot(16), waiting, 80, 24, 0, camera=camera_frame()))
    lines = console.export_text().rstrip("\n").splitlines()
    assert len(lines) <= 24 and max(len(line) for line in lines) <= 80
    assert sum(f"XR page: {url}" in line for line in lines) == 1  # once for the glove and the suit it serves
    assert not any("XR page" in line for line in screen(dashboard, 80, 24, camera_frame()))
