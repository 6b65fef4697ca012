"""bench/common.py's Load: busy processes that a loaded figure runs beside, and that a bench can stop while
it does what the figure does not measure (bench/faults.py: a command's start-up, the checks after it).
They are ordinary processes (SCHED_OTHER, nice 0), even when the thread that makes them runs at real-time
priority or a raised nice value, as the benches' own paced threads do: a spinner that kept SCHED_FIFO
would hold a core against the command sender it is meant to load."""

from __future__ import annotations

import os
import sys
import threading
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


def _scheduling(pid: int) -> tuple[int, int]:
    return os.sched_getscheduler(pid), os.getpriority(os.PRIO_PROCESS, pid)


def test_busy_processes_are_ordinary_whoever_forks_them():
    seen: dict = {}

    def from_a_paced_thread():
        try:
            os.sched_setscheduler(threading.get_native_id(), os.SCHED_FIFO, os.sched_param(1))
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), -5)
        except PermissionError:
            seen["denied"] = True
            return
        with common.Load(2) as load:
            pids = [p.pid for p in load.procs]
            # (a spinner sets itself ordinary as it starts: wait for that, or for the deadline)
            wait_until(lambda: all(_scheduling(pid) == (os.SCHED_OTHER, 0) for pid in pids), 5.0,
                       what="the busy processes at SCHED_OTHER, nice 0")
            seen["spinners"] = [_scheduling(pid) for pid in pids]

    thread = threading.Thread(target=from_a_paced_thread)
    thread.start()
    thread.join(30)
    assert not seen.get("denied"), "real-time priority is not permitted here: the tests need it (run as root)"
    assert seen["spinners"] == [(os.SCHED_OTHER, 0)] * 2
