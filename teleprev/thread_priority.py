"""The session's priorities. The session loop's: a nice value below the default, for the thread that orders
the inputs and steps the pipeline, so that busy processes beside the session (cameras, encoders, a browser)
delay its steps less. The threads that read the inputs (each device's runner, a receiver's socket thread)
take the same: beside 4 busy processes a 120 Hz glove's samples reached the step 181 and 422 ms old (p95, two runs)
with those threads at nice 0, most of it waiting in the socket for the receiving thread, and 57 and 40 ms
old at nice -10 (bench/input_age.py). A nice value counts only inside the process's autogroup (one per
terminal session, Linux's default): busy processes of other sessions share the CPUs with this one by
group, whatever the nice values in it. Busy processes at nice 0 on every core put 4.2 ms into the step's
p99 at nice 0, and 0.29 ms at nice -10 (bench/pipeline.py --busy 2). The command sender has SCHED_FIFO of
its own (live/core/sender.py), and so do the actuator hosts (`become_paced`: a paced process's real-time
priority); the loop is not given real-time priority, so that a bug spinning in it cannot freeze the
machine."""

from __future__ import annotations

import ctypes
import os
import signal
import threading
from dataclasses import dataclass

LOOP_NICE = -10
# The recorder's writer: above busy processes beside the session (what is in memory reaches the disk first, so
# that a full disk loses at most a second), below the loop, whose steps the commands wait for.
WRITER_NICE = -5
DEFAULT_PRIORITY = 50  # SCHED_FIFO priority: above ordinary processes, below the kernel's own threads (99)
# The actuators' processes, one below the sender: a hand's process busy reading its bus never holds up the
# sender's tick, and a write waits at most for the rest of a tick (a fraction of a millisecond).
ACTUATOR_PRIORITY = DEFAULT_PRIORITY - 1
# The physics world's process (teleprev/world/process.py): above every ordinary process (an ordinary one fell
# up to 150 ms behind the clock on a loaded 2-core machine), below the command path, whose ticks and writes
# never wait for a world step.
WORLD_PRIORITY = 40
# A receiver's decoding process (devices/vmc/decoding_process.py): above every ordinary process, below every
# other real-time one (the command path, the physics world at 40, an emulated motor bus at 10): it decodes the
# operator's input and moves nothing. Any real-time priority puts it before ordinary processes, which is all
# the input needs.
INPUT_PRIORITY = 5
# How long a thread of a paced process that wants the interpreter lock waits before the running thread is
# asked for it (Python's default is 5 ms): an actuator's process writes commands on its main thread while
# its runner and SDK threads poll; at 5 ms, writes began up to 8.3 ms after their tick (bench/hardware.py).
SWITCH_INTERVAL_S = 0.0002


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


@dataclass(frozen=True)
class PacedStatus:
    """A paced process's first report: whether it got real-time priority, and why not."""

    realtime: bool
    detail: str


def become_paced(priority: int = DEFAULT_PRIORITY, die_with_parent_thread: bool = True) -> PacedStatus:
    """In a paced child: ignore the terminal's signals (the session stops it, after braking), die with the
    session (PR_SET_PDEATHSIG), one BLAS thread, the interpreter lock handed over within SWITCH_INTERVAL_S,
    and SCHED_FIFO `priority` where permitted (root, CAP_SYS_NICE or an rtprio limit); threads started after
    this inherit the priority. PR_SET_PDEATHSIG fires when the thread that started the child ends: a child
    started from another thread than the session's main one (`die_with_parent_thread` False) watches for
    its parent's end itself."""
    import sys

    sys.setswitchinterval(SWITCH_INTERVAL_S)
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT):
        signal.signal(sig, signal.SIG_IGN)
    if die_with_parent_thread:
        try:
            ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG: die with the session
        except (OSError, AttributeError):
            pass
    try:
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)  # vectors of 6 to 16: BLAS threads would only wake up other cores
    except Exception:
        pass
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        return PacedStatus(True, f"SCHED_FIFO priority {priority}")
    except (PermissionError, OSError, AttributeError) as exc:
        return PacedStatus(False, f"no real-time priority ({exc}): run as root, or grant CAP_SYS_NICE or an "
                                  "rtprio limit (limits.conf) to let this process use SCHED_FIFO")
