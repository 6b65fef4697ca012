"""The paced command sender: the process that makes the robot's commands, at their rate, on time.

A recording's other work (the session loop, the preview, the recorder, cameras and their encoders) shares
the interpreter lock and the CPU; a command that waits for either arrives late, and a late command
followed by the next one on time is a jump that a servo-mode arm runs at once. So the commands leave from a
process of their own, forked from the session before its threads start, which does nothing else:

    every 1 / command_rate_hz, on the session clock (a tick that wakes late is taken at the instant it
    wakes; missed ticks are skipped, never sent in a burst):
        adopt the updates the session loop has sent since the last tick (targets, mode switches)
        sample the commands at this instant (teleprev/pipeline/planner.py: CommandPlanner.tick)
        hand them back, stamped with this instant and with the tick's lateness

The process asks for SCHED_FIFO (real-time priority, above every ordinary process on the machine) where it
is permitted (root, CAP_SYS_NICE or an rtprio limit); `realtime` says whether it got it. Measured on a
2-core machine carrying 8 busy processes, a 15 ms-per-40 ms rendering thread and a 30 fps camera thread
(bench/realtime.py, mechanisms): a sender thread in the session process woke up to 91 ms late (p99 53 ms;
SCHED_FIFO does not help a thread that waits for the interpreter lock), a process without real-time
priority up to 147 ms, this process with SCHED_FIFO at most 1.6 ms (p99 0.15 ms).

Both directions are pipes of length-prefixed JSON messages of known types (teleprev/live/core/pipe_codec.py:
nothing is unpickled). The session process reads the ticks back on a thread of its own (`outputs`), passes
the commands to the actuators and records them. The sender dies with the session (PR_SET_PDEATHSIG), ignores
the terminal's signals (the session stops it after braking), and a sender that dies is seen at once (its
pipe closes): the session then halts.
"""

from __future__ import annotations

import ctypes
import gc
import os
import select
import signal
import threading
import time
from dataclasses import dataclass

from teleprev.clock import SessionClock
from teleprev.live.core.pipe_codec import frame, types_by_name, unframe
from teleprev.pipeline.planner import CommandPlanner, ModeUpdate, TargetUpdate, Tick

DEFAULT_PRIORITY = 50  # SCHED_FIFO priority: above ordinary processes, below the kernel's own threads (99)
_STOP = "stop"


@dataclass(frozen=True)
class SentTick:
    """One tick as the sender reports it: what the planner sent, and how late the tick woke (ns)."""

    tick: Tick
    late_ns: int


@dataclass(frozen=True)
class SenderStatus:
    """The sender's first report: whether it got real-time priority, and why not."""

    realtime: bool
    detail: str


_TO_SENDER = types_by_name(TargetUpdate, ModeUpdate)  # and _STOP, a string
_FROM_SENDER = types_by_name(SentTick, Tick, SenderStatus)


class CommandSender:
    """The session process's handle on the sender process (see the module docstring)."""

    def __init__(self, planner: CommandPlanner, clock: SessionClock, rate_hz: float,
                 priority: int = DEFAULT_PRIORITY):
        if not 0 < rate_hz <= 1000:
            raise ValueError(f"command_rate_hz must be in (0, 1000], got {rate_hz}")
        self.planner = planner
        self.clock = clock
        self.period_ns = int(round(1e9 / rate_hz))
        self.priority = priority
        self.pid: int | None = None
        self.status: SenderStatus | None = None
        self._to_sender: int | None = None  # write end of the updates pipe
        self._from_sender: int | None = None  # read end of the ticks pipe
        self._buffer = b""
        self.dropped_updates = 0
        # send() (the session loop) and stop() (the session's end) share the updates pipe: a send that met
        # the closed descriptor raised EBADF, and a reused descriptor number could take an update's bytes
        # into another file.
        self._send_lock = threading.Lock()

    # ---- the session process ---------------------------------------------------------------------
    def start(self) -> "CommandSender":
        """Fork the sender. Call before the session starts its threads: a fork copies only the calling
        thread, so no lock another thread holds can be copied held."""
        updates_r, updates_w = os.pipe()
        ticks_r, ticks_w = os.pipe()
        for fd in (updates_w, ticks_w):
            _enlarge(fd)
        gc.freeze()  # the objects made so far stay out of the sender's collections: no copy-on-write storm
        pid = os.fork()
        if pid == 0:  # the sender
            try:
                os.close(updates_w)
                os.close(ticks_r)
                _Sender(self.planner, self.clock, self.period_ns, self.priority, updates_r, ticks_w).run()
            finally:
                os._exit(0)
        gc.unfreeze()
        os.close(updates_r)
        os.close(ticks_w)
        os.set_blocking(updates_w, False)
        self.pid, self._to_sender, self._from_sender = pid, updates_w, ticks_r
        return self

    @property
    def alive(self) -> bool:
        return self._from_sender is not None

    def send(self, update: TargetUpdate | ModeUpdate | str) -> bool:
        """Pass an update on; never blocks (a full pipe, which a living sender never lets happen, drops it
        and counts it)."""
        data = frame(update)
        with self._send_lock:
            if self._to_sender is None:
                return False
            try:
                os.write(self._to_sender, data)
            except (BlockingIOError, BrokenPipeError):
                self.dropped_updates += 1
                return False
        return True

    def receive(self, timeout_s: float) -> list[SentTick | SenderStatus] | None:
        """What the sender reported within timeout_s (ticks, its status); None once it has gone (its pipe
        closed: it stopped, or died)."""
        if self._from_sender is None:
            return None
        ready, _, _ = select.select([self._from_sender], [], [], timeout_s)
        if not ready:
            return []
        chunk = os.read(self._from_sender, 1 << 16)
        if not chunk:
            os.close(self._from_sender)
            self._from_sender = None
            return None
        out, self._buffer = unframe(self._buffer + chunk, _FROM_SENDER)
        for item in out:
            if isinstance(item, SenderStatus):
                self.status = item
        return out

    def stop(self, timeout_s: float = 2.0) -> None:
        """Ask the sender to end (it finishes its tick) and reap it; kill it if it does not end in time."""
        if self.pid is None:
            return
        self.send(_STOP)
        with self._send_lock:
            if self._to_sender is not None:
                os.close(self._to_sender)
                self._to_sender = None
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if os.waitpid(self.pid, os.WNOHANG)[0]:
                break
            time.sleep(0.01)
        else:
            os.kill(self.pid, signal.SIGKILL)
            os.waitpid(self.pid, 0)
        self.pid = None


def _enlarge(fd: int) -> None:
    """A pipe of 1 MiB where Linux allows (F_SETPIPE_SZ): seconds of ticks if the reader is held up."""
    try:
        import fcntl

        fcntl.fcntl(fd, 1031, 1 << 20)  # F_SETPIPE_SZ
    except (OSError, AttributeError):
        pass


class _Sender:
    """The sender process's loop."""

    def __init__(self, planner: CommandPlanner, clock: SessionClock, period_ns: int, priority: int, updates: int,
                 ticks: int):
        self.planner, self.clock, self.period_ns = planner, clock, period_ns
        self.priority = priority
        self.updates, self.ticks = updates, ticks
        self.inbox = b""
        self.outbox = b""

    def _setup(self) -> SenderStatus:
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT):
            signal.signal(sig, signal.SIG_IGN)  # the session stops the sender, after braking
        try:
            ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG: die with the session
        except (OSError, AttributeError):
            pass
        os.set_blocking(self.updates, False)
        os.set_blocking(self.ticks, False)
        try:
            from threadpoolctl import threadpool_limits

            threadpool_limits(1)  # vectors of 6 to 16: BLAS threads would only wake up other cores
        except Exception:
            pass
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(self.priority))
            return SenderStatus(True, f"SCHED_FIFO priority {self.priority}")
        except (PermissionError, OSError, AttributeError) as exc:
            return SenderStatus(False, f"no real-time priority ({exc}): run as root, or grant CAP_SYS_NICE or an "
                                       "rtprio limit (limits.conf) to let the command sender use SCHED_FIFO")

    def run(self) -> None:
        self._write(self._setup())
        clock, period = self.clock, self.period_ns
        t0 = clock.now_ns() + period
        due = t0
        while True:
            wait = due - clock.now_ns()
            if wait > 0:
                time.sleep(wait / 1e9)
            t = clock.now_ns()
            if not self._adopt():
                return
            tick = self.planner.tick(t)
            if tick is not None:
                self._write(SentTick(tick, t - due))
            self._flush()
            due = t0 + ((t - t0) // period + 1) * period  # the next tick after now: no catch-up burst

    def _adopt(self) -> bool:
        """Adopt every update that has arrived, in order; False when the session asks to stop (or has
        gone)."""
        while True:
            try:
                chunk = os.read(self.updates, 1 << 16)
            except BlockingIOError:
                break
            if not chunk:
                return False
            self.inbox += chunk
        updates, self.inbox = unframe(self.inbox, _TO_SENDER)
        for update in updates:
            if update == _STOP:
                return False
            self.planner.adopt(update)
        return True

    def _write(self, item) -> None:
        self.outbox += frame(item)
        self._flush()

    def _flush(self) -> None:
        """As much of the outbox as the pipe takes now; the rest at the next tick (never block)."""
        while self.outbox:
            try:
                n = os.write(self.ticks, self.outbox)
            except BlockingIOError:
                return
            except BrokenPipeError:
                self.outbox = b""
                return
            self.outbox = self.outbox[n:]
