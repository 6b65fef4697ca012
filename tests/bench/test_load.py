"""bench/common.py's Load: busy processes that a loaded figure runs beside, and that a bench can stop while
it does what the figure does not measure (bench/faults.py: a command's start-up, the checks after it)."""

from __future__ import annotations

import sys
from pathlib import Path

from tests.helpers.wait import wait_until

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))
import common  # noqa: E402


def _states(load: common.Load) -> set[str]:
    return {Path(f"/proc/{p.pid}/stat").read_text().rsplit(")", 1)[1].split()[0] for p in load.procs}


def test_paused_stops_the_busy_processes_and_resumes_them():
    with common.Load(2) as load:
        wait_until(lambda: _states(load) == {"R"}, 10, what="the busy processes running")
        with load.paused():
            wait_until(lambda: _states(load) == {"T"}, 10, what="the busy processes stopped")
        wait_until(lambda: _states(load) == {"R"}, 10, what="the busy processes running again")
        load.pause()  # left stopped: the end still ends them (a stopped process does not act on SIGTERM)
    assert all(p.exitcode is not None for p in load.procs)
