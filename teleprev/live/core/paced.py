"""What the session's paced processes (the command sender, the actuator hosts) share: how they are forked
from the session, and how each makes itself a real-time process that only the session can stop.

    pipe_r, pipe_w = paced_pipe()            # the session's ends are held: every other child closes them
    pid = fork_paced(keep={pipe_r})          # in the child: every held end but `keep` closed
    status = become_paced(priority)          # in the child (teleprev/thread_priority.py): SCHED_FIFO where
                                             # permitted, says whether it got it

A child keeps only its own pipe ends: an end another child inherited would keep that pipe open after its
owner closed it, and its reader would never see the end of it.
"""

from __future__ import annotations

import gc
import os
import signal

_held: set[int] = set()  # pipe ends the session holds for its paced children


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
