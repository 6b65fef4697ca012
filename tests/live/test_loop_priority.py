"""The session loop's thread runs at nice -10 where the machine lets it (root here, as in CI), so that busy
processes beside a session delay its steps less; the session says which it got. The threads that read the
inputs take the same (tests/devices/test_input_priority.py); the recorder's writer takes less (WRITER_NICE, -5):
above busy processes, so that what is in memory reaches the disk first, below the loop (issue 37 item 2)."""

import os
import time
from pathlib import Path

from teleprev.live.record.session import LiveSession, RecordOptions
from teleprev.session.reader import SessionReader
from teleprev.thread_priority import LOOP_NICE, WRITER_NICE


def _nice(tid: int) -> int:
    stat = Path(f"/proc/self/task/{tid}/stat").read_text()
    return int(stat.rsplit(")", 1)[1].split()[16])  # field 19 of proc(5), counted after the command name


def test_the_loop_thread_takes_its_nice_value_and_the_session_records_it(tmp_path):
    assert os.geteuid() == 0, "this test checks the raised priority, which needs root (CI runs as root)"
    rec = LiveSession(RecordOptions(out=tmp_path / "s.mcap"))
    rec.start()
    try:
        while not rec.loop.priority:
            time.sleep(0.01)
        assert _nice(rec.loop._thread.native_id) == LOOP_NICE
        assert _nice(rec.recorder._thread.native_id) == WRITER_NICE > LOOP_NICE
    finally:
        rec.stop()
    with SessionReader(tmp_path / "s.mcap") as reader:
        assert reader.metadata["loop"]["priority"] == f"nice {LOOP_NICE}"
