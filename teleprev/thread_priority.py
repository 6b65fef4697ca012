"""The session loop's priority: a nice value below the default, for the thread that orders the inputs and
steps the pipeline, so that busy processes beside the session (cameras, encoders, a browser) delay its
steps less. The threads that read the inputs (each device's runner, a receiver's socket thread) take the
same: beside 4 busy processes a 120 Hz glove's samples reached the step 181 and 422 ms old (p95, two runs)
with those threads at nice 0, most of it waiting in the socket for the receiving thread, and 57 and 40 ms
old at nice -10 (bench/input_age.py). A nice value counts only inside the process's autogroup (one per
terminal session, Linux's default): busy processes of other sessions share the CPUs with this one by
group, whatever the nice values in it. Busy processes at nice 0 on every core put 4.2 ms into the step's
p99 at nice 0, and 0.29 ms at nice -10 (bench/pipeline.py --busy 2). The command sender has SCHED_FIFO of
its own (live/core/sender.py); the loop is not given real-time priority, so that a bug spinning in it cannot
freeze the machine."""

from __future__ import annotations

import os
import threading

LOOP_NICE = -10
# The recorder's writer: above busy processes beside the session (what is in memory reaches the disk first, so
# that a full disk loses at most a second), below the loop, whose steps the commands wait for.
WRITER_NICE = -5


def raise_this_thread(nice: int = LOOP_NICE, thread: str = "the session loop") -> str:
    """Give the calling thread `nice` (Linux sets it per thread). Its priority as the session records it:
    "nice -10" when done, else why not (naming `thread`): without root, CAP_SYS_NICE or an RLIMIT_NICE that
    allows it, the thread stays at its nice value."""
    try:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), nice)
        return f"nice {nice}"
    except (OSError, AttributeError) as exc:
        why = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        return (f"{thread} stays at nice {os.getpriority(os.PRIO_PROCESS, 0)} ({why}): run as root, or grant "
                f"CAP_SYS_NICE or a nice limit (limits.conf) to let it take {nice}")
