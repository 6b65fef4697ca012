"""An actuator in a process of its own, beside the paced command sender: where its commands go on the wire.

A command written on a thread of the session process waits for the interpreter lock and the CPU like
everything else there: with 8 busy processes on 2 cores, targets reached the emulated xArm controller up
to 172 ms apart, 14 in one 8.33 ms period. So an actuator whose plugin allows it (`Actuator.own_process`)
runs whole (connect, read, send) in a process forked from the session before its threads start, with
real-time priority one below the sender's (teleprev/live/core/paced.py):

    main thread     waits for the sender's commands (a pipe: sender.WireCommand) and writes each at once; in a
                    replay, which has no sender, the player hands its commands over (`send`) ahead of their
                    stamps, and each is written at its stamp, so the player's thread sets no command's timing
                    through an ActuatorPort, the plugin's SDK call; says what went out and when (WireRecord)
    runner thread   the device's DeviceRunner: connects, reconnects, polls the state, reports gaps and faults

One device, one process: a bus shared by reads and writes (the LEAP Hand's serial port) stays in one
process, and a write that waits for its device's reply (the xArm SDK waits for each) delays nobody else's.

Samples and events, wire records and the runner's stats go back to the session over one pipe as typed
messages (pipe_codec); there a thread hands samples and events to the session loop's inbox as a runner of
its own would, so a fault reaches the loop as before. `ActuatorHost` has the runner's interface (start,
stop, stats, connected, is_alive). The process dies with the session (PR_SET_PDEATHSIG); a process that
ends on its own is the device's `error` event, which sends the session back to preview.
"""

from __future__ import annotations

import dataclasses
import os
import select
import threading
from dataclasses import dataclass

from teleprev import topics
from teleprev.clock import SessionClock
from teleprev.devices.contract import Actuator
from teleprev.devices.runner import ActuatorPort, DeviceRunner, RunnerStats, Sink
from teleprev.errors import DeviceError
from teleprev.live.core.paced import (
    close_held,
    fork_paced,
    paced_pipe,
    reap,
)
from teleprev.live.core.pipe_codec import frame, types_by_name, unframe, write_what_fits
from teleprev.live.core.sender import Outlet, WireCommand
from teleprev.messages import Event, JointSample, PoseSample, Sample
from teleprev.thread_priority import ACTUATOR_PRIORITY, PacedStatus, become_paced

_STATS_EVERY_NS = 100_000_000  # how often the process sends its runner's stats (the preview's device rows)
SUPERSEDED = "superseded"  # a WireRecord's error when a later command was written instead


@dataclass(frozen=True)
class WireRecord:
    """One command as its actuator's process wrote it: which tick's, when the write began and how long the
    plugin's send took (session clock, ns), and whether the device took it (else why not)."""

    kind: str
    seq: int
    t_ns: int  # the command's stamp: the instant its tick was sampled
    wire_ns: int
    call_ns: int
    sent: bool
    error: str = ""

    def event_data(self) -> dict:
        """As a recording's /command/wire event carries it (stamped with `wire_ns`)."""
        data = {"kind": self.kind, "seq": self.seq, "t_ns": self.t_ns, "call_ms": self.call_ns / 1e6, "sent": self.sent}
        if self.error:
            data["error"] = self.error
        return data


@dataclass(frozen=True)
class Forwarded:
    """A sample or device event from the process's runner, with its receive time there."""

    sample: Sample
    receive_ns: int


_TO_HOST = types_by_name(WireCommand, JointSample)
_FROM_HOST = types_by_name(Forwarded, Sample, JointSample, PoseSample, Event, WireRecord, RunnerStats, PacedStatus)


class ActuatorHost:
    """The session's handle on one actuator's process (see the module docstring)."""

    def __init__(self, kind: str, device: Actuator, sink: Sink, clock: SessionClock, names: tuple[str, ...],
                 priority: int = ACTUATOR_PRIORITY, commands_from_session: bool = False):
        """`sink` is the session loop's (samples and events arrive as from a DeviceRunner); `names` the
        actuator's joints as the planner's commands name them. `on_wire(WireRecord)` is called for every
        command written (set it before `start`). `commands_from_session`: no paced sender writes the
        commands pipe (a replay): the session hands each command over with `send`."""
        self.kind, self.device, self.sink, self.clock = kind, device, sink, clock
        self.priority = priority
        self.commands_from_session = commands_from_session
        self.on_wire = lambda record: None
        self.refusal = ""  # why the device did not take a command the session sent (send raises it after)
        self._seq = 0
        self.status: PacedStatus | None = None
        self.pid: int | None = None
        self._commands_r, commands_w = paced_pipe()
        self.outlet = Outlet(kind, commands_w, names)  # for the sender, forked after this process
        self._control_w: int | None = None  # closed: the process stops
        self._reports_r: int | None = None
        self._thread: threading.Thread | None = None
        self._stopping = False
        self._stats = RunnerStats(name=device.name, kind=device.kind, state="connecting", received=0, errors=0,
                                  rate_hz=0.0, nominal_hz=0.0, latency_ms=0.0, latency_max_ms=0.0, last_receive_ns=None,
                                  last_error="", connects=0, gaps=0, sink_errors=0)

    @property
    def name(self) -> str:
        return self.device.name

    @property
    def connected(self) -> bool:
        return self._stats.state in ("ok", "gap")

    # ---- the session process ---------------------------------------------------------------------
    def fork(self) -> None:
        """Fork the actuator's process: before the session starts any thread, and before the sender."""
        control_r, self._control_w = paced_pipe()
        self._reports_r, reports_w = paced_pipe()
        pid = fork_paced(keep={self._commands_r, control_r, reports_w})
        if pid == 0:
            try:
                _Host(self, control_r, reports_w).run()
            finally:
                os._exit(0)
        for fd in (self._commands_r, control_r, reports_w):
            close_held(fd)
        self.pid = pid

    def start(self) -> ActuatorHost:
        """Start handing on what the process reports (a thread: after every fork)."""
        self._thread = threading.Thread(target=self._read, name=f"device-{self.name}-host", daemon=True)
        self._thread.start()
        return self

    def send(self, command: JointSample) -> None:
        """From the session (`commands_from_session`): hand one command to the process, which writes it at
        its stamp (at once if that has passed). DeviceError when the process is gone, or when the device did
        not take an earlier command."""
        if self.refusal:
            raise DeviceError(f"command dropped: the device did not take an earlier one ({self.refusal})",
                              self.device.name)
        self._seq += 1
        try:
            os.write(self.outlet.fd, frame(WireCommand(self._seq, command)))  # one frame: an atomic pipe write
        except OSError as exc:
            raise DeviceError(f"the actuator's process is gone ({exc}): command dropped", self.device.name) from None

    def stop(self, timeout: float = 5.0) -> None:
        """Stop the device (its runner closes it) and the process; wait for its last reports."""
        self._stopping = True
        if self.commands_from_session:
            close_held(self.outlet.fd)
        close_held(self._control_w)
        self._control_w = None
        if self._thread is not None:
            self._thread.join(timeout)
        if self.pid is not None:
            reap(self.pid, 1.0)
            self.pid = None

    def is_alive(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def stats(self) -> RunnerStats:
        return self._stats

    def _read(self) -> None:
        buffer = b""
        while True:
            ready, _, _ = select.select([self._reports_r], [], [], 0.5)
            if not ready:
                continue
            chunk = os.read(self._reports_r, 1 << 16)
            if not chunk:
                break
            items, buffer = unframe(buffer + chunk, _FROM_HOST)
            for item in items:
                if isinstance(item, Forwarded):
                    self.sink(item.sample, item.receive_ns)
                elif isinstance(item, WireRecord):
                    if not item.sent and not item.error.startswith(SUPERSEDED):
                        self.refusal = self.refusal or item.error or "not taken"
                    self.on_wire(item)
                elif isinstance(item, RunnerStats):
                    self._stats = item
                elif isinstance(item, PacedStatus):
                    self.status = item
        close_held(self._reports_r)
        if not self._stopping:  # it ended on its own: the device is gone for this session
            code = reap(self.pid, 1.0) if self.pid is not None else None
            self.pid = None
            message = f"the actuator's process ended (exit status {code}): nothing more is sent to it"
            now = self.clock.now_ns()
            self._stats = dataclasses.replace(self._stats, state="error", errors=self._stats.errors + 1, rate_hz=0.0,
                                              last_error=message)
            event = Event(now, "teleprev.DeviceEvent", {"device": self.name, "event": "error", "message": message})
            self.sink(Sample(topics.DEVICE_EVENT, event), now)


class _Host:
    """The actuator's process."""

    def __init__(self, handle: ActuatorHost, control: int, reports: int):
        self.handle = handle
        self.control, self.reports = control, reports
        self.commands: int | None = handle._commands_r
        self._lock = threading.Lock()  # the runner's thread and the main thread share the reports pipe
        self._outbox = b""

    def run(self) -> None:
        h = self.handle
        os.set_blocking(self.reports, False)
        self._report(become_paced(h.priority))  # before the runner's thread: it inherits the priority
        clock = h.clock
        runner = DeviceRunner(h.device, self._forward, clock).start()
        port = ActuatorPort(h.device, runner)
        inbox = b""
        next_stats = 0
        pending: list[WireCommand] = []  # handed over ahead of their stamps (a replay's player), written at them
        while True:
            watched = [self.control] + ([self.commands] if self.commands is not None else [])
            wait_s = 0.05
            if pending:
                wait_s = min(wait_s, max(0.0, (min(c.command.stamp_ns for c in pending) - clock.now_ns()) / 1e9))
            ready, _, _ = select.select(watched, [], [], wait_s)
            if self.control in ready:
                break  # the session closed it (it never writes): stop
            if self.commands in ready:
                chunk = os.read(self.commands, 1 << 16)
                if not chunk:  # the sender has ended: no more commands (the session halts)
                    os.close(self.commands)
                    self.commands = None
                commands, inbox = unframe(inbox + chunk, _TO_HOST)
                pending += commands
            now = clock.now_ns()
            due = [c for c in pending if c.command.stamp_ns <= now]  # a command goes out at its stamp, not before
            if due:
                pending = [c for c in pending if c.command.stamp_ns > now]
                # The latest command wins (Actuator.send): commands that queued up while a write waited (a
                # hand's write waits for a read in progress on its bus) are not written after it in a burst.
                for c in due[:-1]:
                    self._report(WireRecord(h.kind, c.seq, c.command.stamp_ns, clock.now_ns(), 0, False,
                                            f"{SUPERSEDED}: a later command was due before this one could be written"))
                for c in due[-1:]:
                    down = port.dropped_down
                    wire = clock.now_ns()
                    sent = port.send(c.command)
                    done = clock.now_ns()
                    why = "" if sent else "the device was down" if port.dropped_down > down else port.last_error
                    self._report(WireRecord(h.kind, c.seq, c.command.stamp_ns, wire, done - wire, sent, why))
            now = clock.now_ns()
            if now >= next_stats:
                self._report(runner.stats())
                next_stats = now + _STATS_EVERY_NS
            self._flush()
        runner.stop()
        self._report(runner.stats())
        os.set_blocking(self.reports, True)  # the last reports: the session reads until the pipe closes
        self._flush()

    def _forward(self, sample: Sample, receive_ns: int) -> None:
        self._report(Forwarded(sample, receive_ns))

    def _report(self, item) -> None:
        data = frame(item)
        with self._lock:
            self._outbox += data
        self._flush()

    def _flush(self) -> None:
        """As much of the outbox as the pipe takes now (never block: the rest goes with the next report)."""
        with self._lock:
            self._outbox = write_what_fits(self.reports, self._outbox)
