"""A write failure during a recording (a full disk): the robot brakes to rest, the preview says why,
what was flushed stays readable, and `teleprev record` exits non-zero with one line."""

from __future__ import annotations

import os
import threading
import time

import numpy as np
import pytest

from teleprev.errors import SessionError
from teleprev.session.recover import recover
from tests.helpers.faults import has_traceback, run_cli, small_disk
from tests.helpers.sessions import engage_until_accepted, record_what_is_sent
from tests.helpers.wait import wait_until


def fill_after_flush(writer, timeout_s: float = 5.0) -> None:
    """Swap the session file for /dev/full right after the writer's next flush, on its own thread."""
    swapped, flush = threading.Event(), writer.flush

    def flush_then_fill():
        flush()
        if not swapped.is_set():
            full = os.open("/dev/full", os.O_WRONLY)
            os.dup2(full, writer._file.fileno())
            os.close(full)
            swapped.set()

    writer.flush = flush_then_fill
    assert swapped.wait(timeout_s), "the recorder did not flush"


def test_a_full_disk_stops_the_robot_and_the_preview_says_why(tmp_path):
    from teleprev.live.record.session import LiveSession, RecordOptions

    rec = LiveSession(RecordOptions(out=tmp_path / "full.mcap"))
    doubles = record_what_is_sent(rec)
    rec.start()
    try:
        rec.loop.start_episode("pick_place")
        time.sleep(1.0)
        engage_until_accepted(rec)
        time.sleep(0.5)
        assert rec.loop.snapshot.mode == "execute", rec.loop.snapshot.message
        # From here every write the recorder makes fails with ENOSPC, as on a disk that just filled up. The
        # swap lands right after a flush: between a flush's write and its fsync, fsync on /dev/full gives
        # EINVAL (a character device cannot sync), which no full disk gives.
        fill_after_flush(rec.recorder._writer)
        failed_at = time.monotonic()
        wait_until(
            lambda: rec.loop.snapshot.mode == "preview", 10, what="preview (the write failure reaching the loop)"
        )
        reached_s = time.monotonic() - failed_at
        snap = rec.loop.snapshot
        assert reached_s < 3 * rec.recorder.flush_interval_s + 1.0  # the next flush fails, the loop hears at once
        assert "no space left" in snap.message and "robot stopped" in snap.message
        time.sleep(1.5)  # braking to rest takes well under this
        rec.loop.engage()  # the operator tries to go on: refused
        wait_until(lambda: "cannot switch to execute" in rec.loop.snapshot.message, what="the refusal")
        assert rec.loop.snapshot.mode == "preview"
    finally:
        with pytest.raises(SessionError, match="no space left.*teleprev recover"):
            rec.stop()
    arm = doubles["arm"].sent
    after = [(t, c) for t, c in arm if t > failed_at + reached_s]
    assert after, "the arm should brake under control, not be dropped"
    last_t = arm[-1][0]
    assert last_t < failed_at + reached_s + 1.5  # then nothing more is sent
    (_, a), (_, b) = after[-2:]
    speed = np.abs(np.asarray(b.positions) - np.asarray(a.positions)) / ((b.stamp_ns - a.stamp_ns) / 1e9)
    assert speed.max() < 0.05  # at rest when the commands stop
    saved = recover(tmp_path / "full.mcap")
    assert saved.messages.get("/glove/glove/hand", 0) > 50  # what was flushed before the failure


def test_record_on_a_full_disk_exits_non_zero_with_one_line(tmp_path):
    with small_disk(tmp_path, 700_000) as (folder, preexec):
        out = folder / "x.mcap"
        run = run_cli(["record", "--duration", "30", "--no-preview", "--engage-after", "0.5", "-o", out],
                      preexec_fn=preexec, timeout=90)
        assert run.returncode == 2, run.stderr
        assert not has_traceback(run.stdout + run.stderr)
        lines = [line for line in run.stderr.splitlines() if line.strip()]
        assert len(lines) == 1, run.stderr
        assert ("no space left" in lines[0] or "size limit" in lines[0]) and "teleprev recover" in lines[0]
        saved = recover(out, tmp_path / "saved.mcap")
    assert saved.messages.get("/glove/glove/hand", 0) > 20 and saved.span_s > 0.2
