"""The record screen of a live sim session shows its camera: the loop keeps the first camera's latest
frame in its snapshot, and the preview passes it to the dashboard."""

import io

from rich.console import Console

from teleprev.live.record.run import _frame, make_dashboard
from teleprev.live.record.session import LiveSession, RecordOptions
from teleprev.messages import ImageSample
from tests.helpers.wait import wait_until


def test_a_live_sessions_screen_shows_its_camera(tmp_path):
    rec = LiveSession(RecordOptions(out=tmp_path / "s.mcap"))
    rec.start()
    try:
        camera = wait_until(lambda: rec.loop.snapshot.camera, 20, what="a camera frame in the preview's snapshot")
        assert isinstance(camera, ImageSample)
        console = Console(file=io.StringIO(), width=80, height=24, color_system="truecolor", force_terminal=True)
        console.print(_frame(make_dashboard(rec, "side"), rec, console))
        lines = console.file.getvalue().splitlines()
    finally:
        rec.stop()
    assert any("camera" in line for line in lines[:12]), "\n".join(lines)
    assert sum(line.count("▀") for line in lines) >= 18 * 6  # the picture, in colour blocks
