"""`teleprev record` stopped by SIGTERM (systemd, docker), SIGHUP (a closed SSH session) or Ctrl-C pressed
twice in quick succession: the session file is finalized every time."""

from __future__ import annotations

import signal
import time

import pytest

from teleprev.session.reader import SessionReader
from teleprev.session.recorder import RECORDER_RECORD
from tests.helpers.faults import has_traceback, start_cli, wait_for_file


@pytest.mark.parametrize("signals, gap_s", [
    ((signal.SIGTERM,), 0.0),
    ((signal.SIGHUP,), 0.0),
    ((signal.SIGINT, signal.SIGINT), 0.02),  # a second Ctrl-C 20 ms after the first
    ((signal.SIGTERM, signal.SIGINT, signal.SIGHUP), 0.0),  # a burst
], ids=["sigterm", "sighup", "double-ctrl-c", "burst"])
def test_a_signal_finalizes_the_session(tmp_path, signals, gap_s):
    out = tmp_path / "s.mcap"
    proc = start_cli(["record", "--duration", "60", "--no-preview", "--engage-after", "0.3", "-o", out])
    try:
        wait_for_file(out, 150_000, timeout=60)  # the recording started
        for k, sig in enumerate(signals):
            if k:
                time.sleep(gap_s)
            proc.send_signal(sig)
        stdout, stderr = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    if gap_s == 0.0 and len(signals) > 1:
        # sent back to back, they may all be pending at once, and Python runs pending handlers by number
        assert proc.returncode in {128 + s for s in signals}, stderr
    else:
        assert proc.returncode == 128 + signals[0], stderr
    assert not has_traceback(stdout + stderr)
    assert "is complete" in stdout
    with SessionReader(out, verify_crc=True) as reader:  # a complete file: footer, summary, counters
        assert RECORDER_RECORD in reader.metadata
        assert reader.topics["/glove/glove/hand"].message_count > 10
        assert (
            sum(1 for _ in reader.messages(["/glove/glove/hand"])) == reader.topics["/glove/glove/hand"].message_count
        )
