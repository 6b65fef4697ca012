"""An XR page driving a recorded session on the simulated robot (the page played by tests/helpers/xr_page.py
over real TLS): the operator's actions come from the page, what the page sent is what the file holds, and a
hand that leaves the view makes the commands brake and hold."""

from __future__ import annotations

import threading
import time

import numpy as np

from teleprev import topics
from teleprev.live.record.session import LiveSession, RecordOptions
from teleprev.session.reader import SessionReader
from tests.helpers.sessions import engage_until_accepted, wait_opened
from tests.helpers.wait import wait_until
from tests.helpers.xr_page import PageClient, open_hand, webxr_rig


class Player(threading.Thread):
    """Plays a right hand whose wrist sways 4 cm and whose fingers curl, at 72 Hz; `hidden` takes it out of view."""

    def __init__(self, page: PageClient):
        super().__init__(daemon=True)
        self.page, self.hidden, self.stop, self.sent = page, threading.Event(), threading.Event(), []

    def run(self):
        start = time.monotonic()
        k = 0
        while not self.stop.is_set():
            t = time.monotonic() - start
            right = open_hand()
            right[:, 0] += 0.04 * np.sin(1.5 * t)
            right[:, 1] += 1.1
            shown = None if self.hidden.is_set() else right
            self.page.frame(right=shown)
            self.sent.append((time.monotonic(), shown))
            k += 1
            time.sleep(max(0.0, start + k / 72.0 - time.monotonic()))


def test_the_page_engages_records_what_it_sent_and_a_lost_hand_holds_the_robot(tmp_path):
    # a hand lost for 1.2 s brakes and holds; the [session] bound is raised past it, so that the session
    # stays in execute (tests/live/test_input_loss.py: past the bound it goes back to preview)
    rig = webxr_rig(tmp_path, input_loss_to_preview_s=3.0)
    rec = LiveSession(RecordOptions(out=tmp_path / "s.mcap", rig=rig))
    rec.start()
    page = player = None
    try:
        urls = wait_until(rec.devices["glove"].operator_urls, what="the page's URL")
        page = PageClient(int(urls[0].split(":")[2].strip("/")))
        player = Player(page)
        player.start()
        wait_opened(rec)
        time.sleep(0.5)
        assert page.action("start")["refused"] == ""

        def toggle():
            assert page.action("toggle_mode")["refused"] == ""

        engage_until_accepted(rec, ask=toggle)  # the page's toggle, again where the loop refused it
        time.sleep(1.5)  # the arm follows the swaying wrist
        hidden_at = rec.clock.now_ns()
        player.hidden.set()
        time.sleep(1.2)
        shown_at = rec.clock.now_ns()
        player.hidden.clear()
        time.sleep(0.5)
        assert page.action("stop")["refused"] == ""
        assert page.action("toggle_mode")["refused"] == ""
        wait_until(lambda: rec.loop.snapshot.mode == "preview", what="preview")
    finally:
        if player is not None:
            player.stop.set()
            player.join()
        if page is not None:
            page.close()
        rec.stop()
    reader = SessionReader(tmp_path / "s.mcap")
    raw = [m.payload.positions for m in reader.messages(["/glove/glove/xr_right"])]
    sent = [s for _, s in player.sent if s is not None]
    assert len(raw) == len(sent)  # every frame the page sent with a hand in it, nothing more
    np.testing.assert_array_equal(np.array(raw), np.array(sent, dtype=np.float32).reshape(len(sent), -1))
    modes = [m.payload.data["mode"] for m in reader.messages([topics.MODE])]
    assert modes == ["execute", "preview"]
    episodes = [m.payload.data["event"] for m in reader.messages([topics.EPISODE])]
    assert episodes[:2] == ["start", "stop"]
    arm = [(m.log_time_ns, m.payload.positions) for m in reader.messages([topics.COMMAND_ARM])]
    moving = [q for t, q in arm if t < hidden_at]
    assert np.ptp(np.array(moving[-40:]), axis=0).max() > 1e-3  # the arm followed the swaying wrist
    held = np.array([q for t, q in arm if hidden_at + 0.7e9 < t < shown_at])
    assert len(held) > 20 and np.ptp(held, axis=0).max() < 1e-9  # braked, then held where it stopped


def test_the_preview_shows_the_pages_url_until_the_page_streams(tmp_path):
    rec = LiveSession(RecordOptions(out=tmp_path / "s.mcap", rig=webxr_rig(tmp_path)))
    rec.start()
    try:
        url = wait_until(rec.devices["glove"].operator_urls, what="the page's URL")[0]

        def hints_show_the_url():  # each device's row, once that device serves the page
            hints = {r.name: r.hint for r in rec.device_rows()}
            return hints if hints["glove"] == hints["suit"] == f"XR page: {url}" else None

        assert not wait_until(hints_show_the_url, what="the page's URL in the glove's and suit's rows")["arm"]
        page = PageClient(int(url.split(":")[2].strip("/")))

        def streamed():  # the page streams until the hints are gone
            page.frame(right=open_hand())
            return not any(r.hint for r in rec.device_rows())

        wait_until(streamed, what="the hints gone", poll_s=0.02)
        page.close()
    finally:
        rec.stop()
