"""What the session's paced processes (the command sender, the actuator hosts) share: how they are forked
from the session, and how each makes itself a real-time process that only the session can stop.

    pipe_r, pipe_w = paced_pipe()            # the session's ends are held: every other child closes them
    pid = fork_paced(keep={pipe_r})          # in the child: every held end but `keep` closed
    status = become_paced(priority)          # in the child: SCHED_FIFO where permitted, says whether it got it

A child keeps only its own pipe ends: an end another child inherited would keep that pipe open after its
owner closed it, and its reader would never see the end of it.
"""

from __future__ import annotations

import ctypes
import gc
import os
import signal
from dataclasses import dataclass

DEFAULT_PRIORITY = 50  # SCHED_FIFO priority: above ordinary processes, below the kernel's own threads (99)
# The actuators' processes, one below the sender: a hand's process busy reading its bus never holds up the
# sender's tick, and a write waits at most for the rest of a tick (a fraction of a millisecond).
ACTUATOR_PRIORITY = DEFAULT_PRIORITY - 1
# How long a thread of a paced process that wants the interpreter lock waits before the running thread is
# asked for it (Python's default is 5 ms): an actuator's process writes commands on its main thread while
# its runner and SDK threads poll; at 5 ms, writes began up to 8.3 ms after their tick (bench/hardware.py).
SWITCH_INTERVAL_S = 0.0002

_held: set[int] = set()  # pipe ends the session holds for its paced children


@dataclass(frozen=True)
class PacedStatus:
    """A paced process's first report: whether it got real-time priority, and why not."""

    realtime: bool
    detail: str


def paced_pipe() -> tuple[int, int]:
    """A pipe of 1 MiB where Linux allows (F_SETPIPE_SZ: seconds of messages if the reader is held up), both
    ends held (see the module docstring)."""
    r, w = os.pipe()
    try:
        import fcntl

        fcntl.fcntl(w, 1031, 1 << 20)  # F_SETPIPE_SZ
    except (OSError, AttributeError):
        pass
    _held.update((r, w))
    return r, w


def close_held(fd: int | None) -> None:
    """Close a held pipe end (None: nothing)."""
    if fd is None:
        return
    _held.discard(fd)
    try:
        os.close(fd)
    except OSError:
        pass


def fork_paced(keep: set[int]) -> int:
    """Fork a paced child (0 in the child, its pid in the session). Call before the session starts its
    threads: a fork copies only the calling thread, so no lock another thread holds can be copied held."""
    gc.freeze()  # the objects made so far stay out of the child's collections: no copy-on-write storm
    pid = os.fork()
    if pid == 0:
        for fd in _held - keep:
            try:
                os.close(fd)
            except OSError:
                pass
        _held.clear()
        _held.update(keep)
    else:
        gc.unfreeze()
    return pid


def become_paced(priority: int = DEFAULT_PRIORITY) -> PacedStatus:
    """In a paced child: ignore the terminal's signals (the session stops it, after braking), die with the
    session (PR_SET_PDEATHSIG), one BLAS thread, the interpreter lock handed over within SWITCH_INTERVAL_S,
    and SCHED_FIFO `priority` where permitted (root, CAP_SYS_NICE or an rtprio limit); threads started after
    this inherit the priority."""
    import sys

    sys.setswitchinterval(SWITCH_INTERVAL_S)
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT):
        signal.signal(sig, signal.SIG_IGN)
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
                                  "rtprio limit (limits.conf) to let the command path use SCHED_FIFO")


def reap(pid: int, timeout_s: float) -> int | None:
    """Wait up to timeout_s for a child to end, then kill it; its exit status (None if it was killed)."""
    import time

    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            return os.waitstatus_to_exitcode(status)
        time.sleep(0.01)
    try:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
    except (ProcessLookupError, ChildProcessError):
        pass
    return None
