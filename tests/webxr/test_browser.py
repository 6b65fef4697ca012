"""teleprev's XR page in a real browser: Debian's Chromium, driven by playwright, is a Meta Quest 3 with hand
tracking (Meta's IWER) playing a recorded operator's hand into the page. What teleprev records is what the
browser produced, joint for joint; the left hand's pinches engage the robot and start an episode; and `teleprev
devices check`
finds the page that stayed open."""

from __future__ import annotations

import time

import numpy as np

from teleprev import topics
from teleprev.human.smplx import angles_from_hand_pose
from teleprev.live.record.session import LiveSession, RecordOptions
from teleprev.session.reader import SessionReader
from teleprev_devices.webxr import hands
from tests.helpers.cli import teleprev
from tests.helpers.ports import free_tcp_port
from tests.helpers.wait import wait_until
from tests.helpers.xr_browser import Quest3Browser, recorded_motion
from tests.helpers.xr_hands import RADIUS_M, local_rotations, matrices, xr_hand
from tests.helpers.xr_page import webxr_rig

FRAMES = 180  # 3 s at the headless browser's 60 frames a second


def _url(rec: LiveSession) -> str:
    return wait_until(rec.devices["glove"].operator_urls, what="the XR page served")[0]


def test_a_quest3_streams_a_recorded_hand_that_teleprev_records_joint_for_joint(tmp_path):
    motion = recorded_motion(FRAMES)
    rec = LiveSession(RecordOptions(out=tmp_path / "s.mcap", rig=webxr_rig(tmp_path)))
    rec.start()
    try:
        with Quest3Browser(_url(rec)) as quest:
            quest.play(motion)  # queued before XR starts (pushing it is heavy work for this process)
            quest.enter("immersive-ar")
            time.sleep(0.5)
            quest.now({"left": {"pinch": 1.0}})  # thumb to index: PREVIEW -> EXECUTE
            time.sleep(0.3)
            quest.now({"left": {"pinch": 0.0}})
            quest.now({"left": left_hand(pinch_middle=True)})  # thumb to middle finger: start an episode
            time.sleep(0.3)
            quest.now({"left": left_hand(pinch_middle=False)})
            quest.wait_played()
            time.sleep(0.3)
            shown = quest.state()["status"]
            quest.page.evaluate("window.teleprev.state.session.end()")
            time.sleep(0.3)
            sent = quest.sent()
            assert not quest.errors, quest.errors
    finally:
        rec.stop()
    assert shown["recording"] and shown["mode"] == "execute" and shown["episode_active"]
    assert "corrected_links" in shown and shown["commands_sent"] > 0  # what the headset's panel shows

    reader = SessionReader(tmp_path / "s.mcap")
    right = np.array([m.payload.positions for m in reader.messages(["/glove/glove/xr_right"])])
    left = np.array([m.payload.positions for m in reader.messages(["/glove/glove/xr_left"])])
    heads = np.array([m.payload.position for m in reader.messages(["/suit/suit/head"])])
    wrists = np.array([m.payload.position for m in reader.messages(["/suit/suit/wrist"])])
    assert len(sent.seq) >= FRAMES and (sent.present == 7).all()
    assert len(right) == len(left) == len(heads) == len(sent.seq)  # every frame, nothing lost or added
    np.testing.assert_array_equal(right, sent.values[:, 207:].astype(float))  # joint for joint, bit for bit
    np.testing.assert_array_equal(left, sent.values[:, 7:207].astype(float))
    page_wrist = sent.values[:, 207:210].astype(float)
    assert np.abs(wrists @ hands.A - page_wrist).max() < 1e-9  # the wrist in the suit frame: A p
    assert np.abs(heads @ hands.A - sent.values[:, :3].astype(float)).max() < 1e-9

    # The hand IWER played is the recorded glove's: its fingers' angles come back through the browser.
    poses = np.array([m.payload.positions for m in reader.messages(["/glove/glove/hand"])])
    at = _played_frames(motion, sent.values[:, 207:])
    assert len(at) == FRAMES
    got = np.array(angles_from_hand_pose(poses[at].reshape(-1, 15, 3)))
    want = np.array(angles_from_hand_pose(np.array([e["source"] for e in motion]).reshape(-1, 15, 3)))
    assert np.abs(got - want).max() < 1e-4
    assert np.ptp(want[0], axis=0).max() > 0.3  # (the fingers did move)

    modes = [m.payload.data for m in reader.messages([topics.MODE])]
    assert modes[0]["mode"] == "execute" and modes[0]["reason"] == "key"  # the pinch pressed the space bar
    assert [m.payload.data["event"] for m in reader.messages([topics.EPISODE])][0] == "start"
    assert reader.topics[topics.COMMAND_ARM].message_count > 50
    reader.close()

    # ... and the session is one like any other: it evaluates, audits and exports.
    session = str(tmp_path / "s.mcap")
    evaluated = teleprev("eval", session)
    assert evaluated.returncode == 0 and "reproduces the recorded commands bit for bit" in evaluated.stdout, (
        evaluated.stdout
    )
    assert teleprev("audit", session).returncode == 0
    root = tmp_path / "ds"
    exported = teleprev("export", session, "--repo-id", "lab/xr", "--root", str(root))
    assert exported.returncode == 0, exported.stdout + exported.stderr
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    dataset = LeRobotDataset("lab/xr", root=root, video_backend="pyav")
    assert dataset.num_episodes >= 1 and dataset.num_frames > 50  # (a camera gap on a loaded machine splits one)


def test_devices_check_finds_the_page_left_open_across_a_restart(tmp_path):
    port = free_tcp_port()
    rig = webxr_rig(tmp_path, port=port)
    rec = LiveSession(RecordOptions(out=tmp_path / "s.mcap", rig=rig))
    rec.start()
    try:
        quest = Quest3Browser(_url(rec))
        quest.enter("immersive-vr")
    finally:
        rec.stop()  # teleprev goes away; the page stays in its XR session and tries again
    try:
        result = teleprev("devices", "check", str(rig), "--seconds", "3")
        assert result.returncode == 0, result.stdout + result.stderr
        assert f"XR page: open https://127.0.0.1:{port}/" in result.stdout
        assert "all 5 devices streaming" in result.stdout
    finally:
        quest.close()


def test_on_a_bimanual_rig_the_pages_pinches_are_no_controls_and_its_button_is(tmp_path):
    """Both hands drive robots: the status says gestures: false, and the page sends nothing for a left pinch
    (the robots stay in preview); its preview/execute button still switches both sides."""
    from teleprev.live.record.bimanual_session import open_session
    from tests.helpers.xr_page import bimanual_webxr_rig

    rec = open_session(RecordOptions(out=tmp_path / "s.mcap", rig=bimanual_webxr_rig(tmp_path)))
    rec.start()
    try:
        url = wait_until(rec.devices["glove_left"].operator_urls, what="the XR page served")[0]
        with Quest3Browser(url) as quest:
            quest.enter("immersive-ar")
            wait_until(lambda: (quest.state()["status"] or {}).get("gestures") is False, 10,
                       what="the status telling the page that pinches are off")
            wait_until(lambda: all(v.step is not None for v in rec.loop.snapshot.sides) and
                       len(rec.loop.snapshot.sides) == 2, 20, what="both sides stepped from the page's hands")
            quest.now({"left": {"pinch": 1.0}})  # thumb to index: was PREVIEW -> EXECUTE
            time.sleep(0.5)
            quest.now({"left": {"pinch": 0.0}})
            assert quest.state()["actions"] == [] and rec.loop.snapshot.mode == "preview"
            quest.page.evaluate("document.getElementById('toggle-mode').click()")  # (IWER's overlay is on top)
            wait_until(lambda: rec.loop.snapshot.mode == "execute", 10, what="execute from the page's button")
            assert not quest.errors, quest.errors
    finally:
        rec.stop()


def left_hand(pinch_middle: bool) -> dict:
    """A left hand for IWER to show (only its fingertips matter to the page's gestures): open, or with the
    thumb's tip 5 mm from the middle finger's and 2 cm from the index's."""
    joints = xr_hand(local_rotations(np.zeros(15), np.zeros(15)), np.eye(3), [-0.2, 1.1, -0.4])
    tip = hands.JOINT_INDEX
    if pinch_middle:
        joints[tip["thumb-tip"], :3] = joints[tip["middle-finger-tip"], :3] + [0.0, 0.0, -0.005]
    return {"joints": matrices(joints).tolist(), "radii": [RADIUS_M] * 25}


def _played_frames(motion: list[dict], right: np.ndarray) -> list[int]:
    """The index of the frame the page sent for each entry of the motion (matched on the wrist's place:
    before the playback the hand was IWER's own, after it the last entry's)."""
    out, i = [], 0
    for entry in motion:
        wrist = np.array(entry["right"]["joints"][12:15], dtype=np.float32)
        while i < len(right) and not np.array_equal(right[i, :3], wrist):
            i += 1
        out.append(i)
        i += 1
    return [k for k in out if k < len(right)]
