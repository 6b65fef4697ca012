"""The XR page drives a bimanual rig: its right hand the right side, its left hand the left side, four devices
(a webxr.glove and a webxr.suit per side) on one page's server over a real WebSocket on loopback. The left hand
now drives a robot, so its pinches are no controls: the status tells the page (gestures: false), and a pinch
that still arrives is refused with where the controls went; the page's buttons still switch the mode."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from teleprev.live.record.bimanual_session import GESTURE_REFUSED, open_session
from teleprev.live.record.session import RecordOptions
from teleprev.session.reader import SessionReader
from teleprev.transforms import axis_angle_to_matrix
from tests.helpers.wait import wait_until
from tests.helpers.xr_hands import local_rotations, mirror_in_xr, xr_hand
from tests.helpers.xr_page import PageClient, bimanual_webxr_rig


@pytest.fixture
def session(tmp_path):
    out = tmp_path / "s.mcap"
    rec = open_session(RecordOptions(rig=bimanual_webxr_rig(tmp_path), out=out))
    rec.start()
    stop = threading.Event()
    try:
        names = ("glove_left", "glove_right", "suit_left", "suit_right")
        wait_until(lambda: all(rec.devices[n]._receiver for n in names), 20, what="the four devices connected")
        server = rec.devices["glove_left"]._receiver
        assert all(rec.devices[n]._receiver is server for n in names)  # one page, one server
        page = PageClient(server.port)
        flexion = np.linspace(0.2, 0.9, 15)
        # a right hand in front of the operator, palm down, fingers forward; the left hand its mirror image
        wrist = axis_angle_to_matrix(np.array([0.0, 1.0, 0.0]) * (-np.pi / 2)) @ np.diag([-1.0, 1.0, -1.0])
        right = xr_hand(local_rotations(flexion, np.zeros(15)), wrist, [0.2, 1.1, -0.35])
        left = mirror_in_xr(right)
        sender = threading.Thread(target=lambda: [page.frame(right=right, left=left) for _ in iter(
            lambda: stop.wait(1 / 60), True)], daemon=True)
        sender.start()

        def finish():  # the page stops sending and closes, then the recording ends
            stop.set()
            sender.join(5)
            page.close()
            rec.stop()
        yield rec, page, out, finish
    finally:
        stop.set()
        rec.stop()


def test_both_hands_drive_their_sides_and_pinches_are_no_controls(session):
    rec, page, out, finish = session

    def stepped():
        views = rec.loop.snapshot.sides
        return len(views) == 2 and all(v.step is not None and v.step.corrected is not None
                                       and v.step.report.get("step", 0) >= 20 for v in views)
    wait_until(stepped, 30, what="both sides stepped from the page's hands")
    assert rec.context.operator.status()["gestures"] is False
    ack = page.action("toggle_mode", via="gesture")  # a pinch of the left hand: a grasp now, not a control
    assert ack["refused"] == GESTURE_REFUSED
    assert rec.loop.snapshot.mode == "preview"
    assert page.action("toggle_mode")["refused"] == ""  # the page's button
    wait_until(lambda: rec.loop.snapshot.mode == "execute", 10, what="execute from the page's button")
    finish()
    with SessionReader(out) as r:
        corrected = {side: [m.payload for m in r.messages(topics=[f"/pipeline/{side}/corrected"])]
                     for side in ("left", "right")}
        modes = [m.payload.data["mode"] for m in r.messages(topics=["/events/mode"])]
    assert len(corrected["left"]) >= 20 and len(corrected["right"]) >= 20
    left, right = corrected["left"][-1], corrected["right"][-1]
    assert np.abs(np.asarray(right.positions)).max() > 0.2
    np.testing.assert_allclose(left.positions, right.positions, atol=0.05)  # the mirrored hand: the same joints
    assert modes.count("execute") == 1
