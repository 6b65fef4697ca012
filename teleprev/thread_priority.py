"""The session loop's priority: a nice value below the default, for the thread that orders the inputs and
steps the pipeline, so that busy processes beside the session (cameras, encoders, a browser) delay its
steps less. Busy processes at nice 0 on every core put 4.2 ms into the step's p99 at nice 0, and 0.29 ms at
nice -10 (bench/pipeline.py --busy 2). The command sender has SCHED_FIFO of its own (live/core/sender.py);
the loop is not given real-time priority, so that a bug spinning in it cannot freeze the machine."""

from __future__ import annotations

import os
import threading

LOOP_NICE = -10


def raise_this_thread(nice: int = LOOP_NICE) -> str:
    """Give the calling thread `nice` (Linux sets it per thread). Its priority as the session records it:
    "nice -10" when done, else why not: without root, CAP_SYS_NICE or an RLIMIT_NICE that allows it, the
    thread stays at its nice value."""
    try:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), nice)
        return f"nice {nice}"
    except (OSError, AttributeError) as exc:
        why = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        return (f"the session loop stays at nice {os.getpriority(os.PRIO_PROCESS, 0)} ({why}): run as root, or grant "
                f"CAP_SYS_NICE or a nice limit (limits.conf) to let it take {nice}")
