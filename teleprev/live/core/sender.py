"""The paced command sender: the process that makes the robot's commands, at their rate, on time.

A recording's other work (the session loop, the preview, the recorder, cameras and their encoders) shares
the interpreter lock and the CPU; a command that waits for either arrives late, and a late command
followed by the next one on time is a jump that a servo-mode arm runs at once. So the commands leave from a
process of their own, forked from the session before its threads start, which does nothing else:

    every 1 / command_rate_hz, on the session clock (missed ticks are skipped, never sent in a burst):
        adopt the updates the session loop has sent since the last tick (targets, mode switches)
        sample the commands at the tick's instant on the grid (teleprev/pipeline/planner.py:
        CommandPlanner.tick), the last grid instant the tick woke at or after
        hand them back, stamped with that instant and with how late the tick woke

The commands are sampled on the grid, not at the instant the tick wakes, because a servo-mode arm runs its
targets on a fixed cycle of its own (UFactory's 4 ms; teleprev/emulators/xarm_servo.py): positions sampled
at wake instants 0.04-0.08 ms off the grid (p99, SCHED_FIFO) read there as 17 % more acceleration and twice
the jerk of a stream at its limits (bench/hardware.py's recorded sessions).

The process asks for SCHED_FIFO (real-time priority, above every ordinary process on the machine) where it
is permitted (root, CAP_SYS_NICE or an rtprio limit); `realtime` says whether it got it. Measured on a
2-core machine carrying 8 busy processes, a 15 ms-per-40 ms rendering thread and a 30 fps camera thread
(bench/realtime.py, mechanisms): a sender thread in the session process woke up to 91 ms late (p99 53 ms;
SCHED_FIFO does not help a thread that waits for the interpreter lock), a process without real-time
priority up to 147 ms, this process with SCHED_FIFO at most 1.6 ms (p99 0.15 ms).

The commands leave on the wire from paced processes too: an actuator whose plugin allows it runs in a
process of its own, one priority step below this one (teleprev/live/core/actuator_host.py), and the sender hands it
each tick's command the moment the tick is sampled (`outlets`: a pipe per such actuator; its process writes
the command at once with the plugin's SDK call). The other actuators (the simulated ones, which share the
simulated world with the session's other devices) are passed their commands by the session process.

Every direction is a pipe of length-prefixed JSON messages of known types (teleprev/live/core/pipe_codec.py:
nothing is unpickled). The session process reads the ticks back on a thread of its own (the CommandRelay's),
passes the commands of the actuators that have no process of their own to them, and records every tick. The
sender dies with the session (PR_SET_PDEATHSIG), ignores the terminal's signals (the session stops it after
braking), and a sender that dies is seen at once (its pipe closes): the session then halts.
"""

from __future__ import annotations

import os
import select
import threading
import time
from dataclasses import dataclass

import numpy as np

from teleprev.clock import SessionClock
from teleprev.live.core.paced import (
    close_held,
    fork_paced,
    paced_pipe,
    reap,
)
from teleprev.live.core.pipe_codec import frame, types_by_name, unframe, write_what_fits
from teleprev.messages import JointSample
from teleprev.pipeline.planner import CommandPlanner, ModeUpdate, TargetUpdate, Tick
from teleprev.thread_priority import DEFAULT_PRIORITY, PacedStatus, become_paced

_STOP = "stop"


@dataclass(frozen=True)
class SentTick:
    """One tick as the sender reports it: what the planner sent, and how late the tick woke (ns)."""

    tick: Tick
    late_ns: int


@dataclass(frozen=True)
class WireCommand:
    """One tick's command for an actuator in a process of its own (the sender to that process)."""

    seq: int  # the tick's
    command: JointSample  # stamped with the tick's instant


@dataclass(frozen=True)
class Outlet:
    """Where the sender hands one actuator's commands: the write end of its process's command pipe."""

    kind: str  # "arm" or "hand"
    fd: int
    names: tuple[str, ...]  # the actuator's joints, as the planner's commands name them


_TO_SENDER = types_by_name(TargetUpdate, ModeUpdate)  # and _STOP, a string
_FROM_SENDER = types_by_name(SentTick, Tick, PacedStatus)


class CommandSender:
    """The session process's handle on the sender process (see the module docstring)."""

    def __init__(self, planner: CommandPlanner, clock: SessionClock, rate_hz: float,
                 priority: int = DEFAULT_PRIORITY, outlets: tuple[Outlet, ...] = (),
                 warm_pose: tuple[np.ndarray, np.ndarray] | None = None):
        """`outlets`: the actuators in processes of their own (actuator_host.py), handed their commands
        by the sender itself; `warm_pose`: arm and end-effector joints inside their limits, where the sender
        runs its planner through an engage before its first tick (see _warm)."""
        if not 0 < rate_hz <= 1000:
            raise ValueError(f"command_rate_hz must be in (0, 1000], got {rate_hz}")
        self.planner = planner
        self.clock = clock
        self.period_ns = int(round(1e9 / rate_hz))
        self.priority = priority
        self.outlets = outlets
        self.warm_pose = warm_pose
        self.pid: int | None = None
        self.status: PacedStatus | None = None
        self._to_sender: int | None = None  # write end of the updates pipe
        self._from_sender: int | None = None  # read end of the ticks pipe
        self._buffer = b""
        self.dropped_updates = 0
        # send() (the session loop) and stop() (the session's end) share the updates pipe: a send that met
        # the closed descriptor raised EBADF, and a reused descriptor number could take an update's bytes
        # into another file.
        self._send_lock = threading.Lock()

    # ---- the session process ---------------------------------------------------------------------
    def start(self) -> CommandSender:
        """Fork the sender. Call before the session starts its threads (paced.fork_paced), after the
        actuator processes whose outlets it writes to have been forked."""
        updates_r, updates_w = paced_pipe()
        ticks_r, ticks_w = paced_pipe()
        pid = fork_paced(keep={updates_r, ticks_w, *(o.fd for o in self.outlets)})
        if pid == 0:  # the sender
            try:
                if self.warm_pose is not None:
                    _warm(self.planner, *self.warm_pose)
                _Sender(self.planner, self.clock, self.period_ns, self.priority, updates_r, ticks_w, self.outlets).run()
            finally:
                os._exit(0)
        close_held(updates_r)
        close_held(ticks_w)
        for outlet in self.outlets:  # the sender's alone now: its actuator's process sees it close with the sender
            close_held(outlet.fd)
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

    def receive(self, timeout_s: float) -> list[SentTick | PacedStatus] | None:
        """What the sender reported within timeout_s (ticks, its status); None once it has gone (its pipe
        closed: it stopped, or died)."""
        if self._from_sender is None:
            return None
        ready, _, _ = select.select([self._from_sender], [], [], timeout_s)
        if not ready:
            return []
        chunk = os.read(self._from_sender, 1 << 16)
        if not chunk:
            close_held(self._from_sender)
            self._from_sender = None
            return None
        out, self._buffer = unframe(self._buffer + chunk, _FROM_SENDER)
        for item in out:
            if isinstance(item, PacedStatus):
                self.status = item
        return out

    def stop(self, timeout_s: float = 2.0) -> None:
        """Ask the sender to end (it finishes its tick) and reap it; kill it if it does not end in time."""
        if self.pid is None:
            return
        self.send(_STOP)
        with self._send_lock:
            if self._to_sender is not None:
                close_held(self._to_sender)
                self._to_sender = None
        reap(self.pid, timeout_s)
        self.pid = None


def _warm(planner: CommandPlanner, arm: np.ndarray, hand: np.ndarray) -> None:
    """Run the planner through an engage, a move and a stop from `arm`, `hand`, then give it back its state
    untouched. Its compiled kernels load on their first call (milliseconds each): without this, the first
    commands of the session's first engage left up to 9 ms after their tick."""
    original = planner.state
    planner.state = type(original)()
    try:
        t, period = 0, 8_333_333
        planner.adopt(ModeUpdate(1, t, "execute", arm, hand))
        planner.adopt(TargetUpdate(2, t, arm + 0.01, np.zeros_like(arm), t, hand + 0.01, np.zeros_like(hand)))
        for k in range(6):
            planner.tick(t + k * period)
        planner.adopt(ModeUpdate(3, t + 6 * period, "preview", arm, hand))
        for k in range(6, 12):
            planner.tick(t + k * period)
    except Exception:  # warming is an optimisation: the ticks then pay for what did not load
        pass
    finally:
        planner.state = original


class _Sender:
    """The sender process's loop."""

    def __init__(self, planner: CommandPlanner, clock: SessionClock, period_ns: int, priority: int, updates: int,
                 ticks: int, outlets: tuple[Outlet, ...]):
        self.planner, self.clock, self.period_ns = planner, clock, period_ns
        self.priority = priority
        self.updates, self.ticks = updates, ticks
        self.outlets = list(outlets)
        self.inbox = b""
        self.outbox = b""

    def _setup(self) -> PacedStatus:
        status = become_paced(self.priority)
        for fd in (self.updates, self.ticks, *(o.fd for o in self.outlets)):
            os.set_blocking(fd, False)
        return status

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
            tick = self.planner.tick(t0 + (t - t0) // period * period)  # the grid instant it woke at or after
            if tick is not None:
                self._hand_out(tick)  # on the wire first: recording can wait
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

    def _hand_out(self, tick: Tick) -> None:
        """Each outlet's command of this tick, to its actuator's process. A command is a few hundred bytes
        in a pipe of 1 MiB that its process empties at once: a full pipe is a process that hangs (its
        commands are dropped; the device's runner reports it), a closed one a process that has ended."""
        for outlet in list(self.outlets):
            q, v = (tick.arm, tick.arm_v) if outlet.kind == "arm" else (tick.hand, tick.hand_v)
            if q is None:
                continue
            try:
                os.write(outlet.fd, frame(WireCommand(tick.seq, JointSample(tick.t_ns, outlet.names, q, v))))
            except BlockingIOError:
                pass
            except BrokenPipeError:
                self.outlets.remove(outlet)

    def _write(self, item) -> None:
        self.outbox += frame(item)
        self._flush()

    def _flush(self) -> None:
        """As much of the outbox as the pipe takes now; the rest at the next tick (never block)."""
        self.outbox = write_what_fits(self.ticks, self.outbox)
