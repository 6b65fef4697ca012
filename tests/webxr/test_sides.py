"""The WebXR page's left hand drives a bimanual rig's left side: webxr.glove and webxr.suit with side = "left"
read the left hand, over the page's real WebSocket on loopback (one server for both sides' devices). A left
hand held palm down, fingers to the operator's left, gives a left wrist pointing left; a mirrored operator
gives the left side the mirror of the right (the left glove's own SMPL-X pose, the wrist as a mirrored right
wrist: teleprev/human/mirror.py), as vmc and sim devices with side = "left" do."""

from __future__ import annotations

import numpy as np
import pytest

from teleprev.clock import SessionClock
from teleprev.devices import DeviceContext
from teleprev.human.mirror import mirror_hand_pose, mirror_wrist
from teleprev.transforms import axis_angle_to_matrix, quat_to_matrix
from teleprev_devices.webxr import WebXrGlove, WebXrSuit
from teleprev_devices.webxr.plugins import WebXrSettings
from tests.helpers.wait import wait_until
from tests.helpers.xr_hands import local_rotations, mirror_in_xr, xr_hand
from tests.helpers.xr_page import PageClient


@pytest.fixture
def devices(tmp_path):
    context = DeviceContext(SessionClock())
    made = {}
    for side in ("left", "right"):
        settings = WebXrSettings(port=0, cert_dir=str(tmp_path / "cert"), side=side)
        for kind, cls in (("glove", WebXrGlove), ("suit", WebXrSuit)):
            made[f"{kind}_{side}"] = cls(f"{kind}_{side}", settings, context)
    for d in made.values():
        d.connect()
    page = PageClient(made["glove_left"]._receiver.port)
    assert all(d._receiver is made["glove_left"]._receiver for d in made.values())  # one server
    try:
        yield page, made
    finally:
        page.close()
        for d in made.values():
            d.disconnect()


def latest(device, topic_end: str):
    got = []

    def arrived():
        got.extend(s for s in device.read(0.05) if s.topic.endswith(topic_end))
        return got
    wait_until(arrived, 5, what=f"{topic_end} from {device.name}")
    return got[-1].payload


def test_a_left_hand_pointing_left_gives_a_left_wrist_pointing_left(devices):
    page, d = devices
    # a right hand palm down, fingers to the right (+x), thumb forward (-z), in SMPL-X hand axes (fingers -x,
    # back +y, thumb +z); its mirror image is a left hand palm down, fingers to the left, thumb forward
    right = xr_hand(local_rotations(np.zeros(15), np.zeros(15)), np.diag([-1.0, 1.0, -1.0]), [0.2, 1.1, -0.35])
    left = mirror_in_xr(right)
    page.frame(left=left)
    pose = latest(d["suit_left"], "/wrist")
    np.testing.assert_allclose(pose.position, [0.35, 0.2, 1.1], atol=1e-6)  # ahead, to the left, up
    r = quat_to_matrix(pose.orientation)
    # as a mirrored right wrist: fingers along its -x (the operator's left), palm (+y) down, thumb forward
    np.testing.assert_allclose(r @ [-1.0, 0, 0], [0, 1, 0], atol=1e-6)
    np.testing.assert_allclose(r @ [0, 1.0, 0], [0, 0, -1], atol=1e-6)
    np.testing.assert_allclose(r @ [0, 0, 1.0], [1, 0, 0], atol=1e-6)
    assert d["suit_right"].read(0.2) == [] or all(not s.topic.endswith("/wrist") for s in d["suit_right"].read(0.1))


def test_a_mirrored_operator_gives_the_left_side_the_mirror_of_the_right(devices, rng):
    page, d = devices
    flexion, abduction = rng.uniform(0.0, 1.2, 15), rng.uniform(-0.3, 0.3, 15)
    turn = axis_angle_to_matrix(np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8]) * 1.1)
    right = xr_hand(local_rotations(flexion, abduction), turn, [0.2, 1.1, -0.35])
    page.frame(right=right, left=mirror_in_xr(right))
    right_hand, left_hand = latest(d["glove_right"], "/hand"), latest(d["glove_left"], "/hand")
    assert np.abs(right_hand.positions).max() > 0.3
    np.testing.assert_allclose(left_hand.positions, mirror_hand_pose(right_hand.positions), atol=1e-4)
    right_wrist, left_wrist = latest(d["suit_right"], "/wrist"), latest(d["suit_left"], "/wrist")
    position, rotation = mirror_wrist(right_wrist.position, quat_to_matrix(right_wrist.orientation))
    np.testing.assert_allclose(left_wrist.position, position, atol=1e-5)
    np.testing.assert_allclose(quat_to_matrix(left_wrist.orientation), rotation, atol=1e-4)


def test_side_must_be_left_or_right(tmp_path):
    with pytest.raises(ValueError, match="side must be 'left' or 'right', got 'up'"):
        WebXrSettings(side="up")
