"""The session loop: where every sample of a recording passes, in one order.

Device reader threads (devices/runner.py) hand samples to a bounded queue; one loop thread takes them in
arrival order, gives each a strictly increasing log time on the session clock (its host receive time),
records it, feeds the pipeline driver (a glove sample with a newer one queued behind it is recorded but
steps nothing, and /events/superseded says so: a loop that fell behind steps the newest input, not its
backlog), passes the step's targets and every accepted mode switch to the
paced command sender (teleprev/live/core/sender.py), publishes the robot's frames on /tf, and carries out the
operator's controls (mode switches, episodes). Because the loop is the only place where order is
decided, replaying a session's raw streams in log-time order meets the pipeline with exactly the inputs
it met live.

The loop thread only orders and dispatches: the controls are typed messages (teleprev/live/core/controls.py)
queued among the samples; whether execute may be engaged is the ExecuteGate's to say
(teleprev/live/core/gate.py); the commands do not wait for this loop: the sender samples them on its own clock,
in its own process, and hands them at once to the actuators that run in paced processes of their own
(teleprev/live/core/actuator_host.py: the real arm and hand, whose SDK calls put the bytes on the wire there);
the CommandRelay's thread (teleprev/live/core/relay.py) passes each tick's commands to the actuators that
run here (the simulated ones), then queues the tick for the loop to record (/command/arm, /command/hand and
/command/tick, stamped with the instant the sender sampled them, which is when it handed them on). The
actuators' processes say what they wrote and when, recorded on /command/wire.

Input lost while executing (missing, stale or invalid samples, a frozen process) holds the robot; past the
rig's bound the session goes back to preview (teleprev/live/core/input_watch.py).

After a device fails, nothing engages by itself: the session goes back to preview (an actuator that
failed: nothing more is sent at once, its controller has stopped it; another device: the commands brake to
rest), records why, and the gate refuses an unattended engage until the operator engages with a key.

The terminal preview reads `snapshot`, which the loop replaces (never mutates) after every change.
"""

from __future__ import annotations

import queue
import threading
import time
import traceback
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from teleprev import topics
from teleprev.clock import SessionClock
from teleprev.devices.contract import Actuator
from teleprev.live.core.actuator_host import WireRecord
from teleprev.live.core.controls import (
    Control,
    DiscardEpisode,
    Engage,
    EStop,
    Halt,
    Hold,
    LoopControls,
    MarkOutcome,
    OperatorNote,
    Release,
    StartEpisode,
    StopEpisode,
    ToPreview,
    WorldLayout,
)
from teleprev.live.core.episodes import EpisodeTracker
from teleprev.live.core.gate import ExecuteGate, GateState
from teleprev.live.core.input_watch import InputEvent, InputWatch
from teleprev.live.core.relay import CommandRelay, tick_records
from teleprev.messages import DepthSample, Event, ImageSample, Logged, PoseSample, Sample
from teleprev.pipeline.driver import PipelineDriver
from teleprev.status import LoopSnapshot
from teleprev.thread_priority import raise_this_thread

_STOP = object()
IDLE_CHECK_S = 0.1  # the loop wakes at least this often to see whether the input has been lost


@dataclass
class StreamCounter:
    count: int = 0
    first_ns: int = 0
    last_ns: int = 0
    latency_ns: int = 0  # receive - acquisition of the last sample

    def rate_hz(self) -> float:
        return (
            (self.count - 1) * 1e9 / (self.last_ns - self.first_ns)
            if self.count > 1 and self.last_ns > self.first_ns
            else 0.0
        )


@dataclass
class LoopStats:
    streams: dict[str, StreamCounter] = field(default_factory=dict)
    dropped: Counter = field(default_factory=Counter)  # samples the loop queue had no room for, per topic
    commands_sent: Counter = field(default_factory=Counter)
    command_errors: Counter = field(default_factory=Counter)
    step_ns: list[int] = field(default_factory=list)  # pipeline step durations (bounded)
    device_failures: Counter = field(default_factory=Counter)  # "error" device events, per device
    late_ns: list[int] = field(default_factory=list)  # how late each of the sender's ticks woke (bounded)
    superseded: int = 0  # glove samples recorded but not stepped: a newer one was queued already
    ticks: int = 0
    engages: int = 0  # accepted switches to execute

    def count(self, topic: str, t_ns: int, payload) -> None:
        """One sample of `topic` logged at t_ns."""
        counter = self.streams.get(topic)
        if counter is None:
            counter = self.streams[topic] = StreamCounter(first_ns=t_ns)
        counter.count += 1
        counter.last_ns = t_ns
        counter.latency_ns = t_ns - getattr(payload, "stamp_ns", t_ns)


class LoopInbox:
    """The one queue the session loop takes everything from, in arrival order: samples from the device
    threads (never blocking: a full queue drops the sample and counts it), controls (never dropped), the
    sender's ticks. Made before the loop, so that the device runners (whose ports the loop sends through)
    can be given its `sink`."""

    def __init__(self, size: int = 4096):
        self.queue: queue.Queue = queue.Queue(maxsize=size)
        self.dropped: Counter = Counter()  # samples there was no room for, per topic
        self.queued: Counter = Counter()  # samples put on the queue so far, per topic (one writer each)

    def sink(self, sample: Sample, receive_ns: int) -> None:
        try:
            self.queue.put_nowait((receive_ns, sample))
        except queue.Full:
            self.dropped[sample.topic] += 1
            return
        self.queued[sample.topic] += 1

    def put(self, receive_ns: int | None, item) -> None:
        self.queue.put((receive_ns, item))

    def backlog(self) -> int:
        return self.queue.qsize()


class SessionLoop(LoopControls):
    """The one thread that orders every input, records it and feeds the pipeline; the controls any thread
    may call are LoopControls' (typed messages queued here)."""

    def __init__(
        self,
        clock: SessionClock,
        log: Callable[[Logged], Any],
        driver: PipelineDriver | None = None,
        *,
        inbox: LoopInbox | None = None,
        actuators: dict[str, Actuator] | None = None,
        hosted: frozenset[str] = frozenset(),
        sender=None,
        frames=None,
        on_episode_start: Callable[[str], None] | None = None,
        judge: Callable[[], tuple[str, str] | None] | None = None,
        input_loss_to_preview_s: float = 1.0,
    ):
        """`log` receives every message to record (Recorder.log); `inbox` the queue the device runners were
        given the `sink` of (default: a new one); `actuators` maps "arm" and "hand" to the ActuatorPorts
        that pass commands on; `sender` (a CommandSender, started before this loop) makes the commands from the
        pipeline's updates; `frames` (teleprev/live/record/frames.py: RobotFrames) turns measured joints into /tf;
        `judge` (a physics rig) gives the outcome of the task now, as (mark, reason), or None when it cannot say:
        each episode that stops is marked with it, beside the operator's y/f;
        `input_loss_to_preview_s`: the rig's [session] bound on a loss of the operator's input while executing
        (a policy's actions are not watched: no person looks away)."""
        self.clock = clock
        self._log = log
        self.driver = driver
        self.inbox = inbox or LoopInbox()
        self.sink = self.inbox.sink  # for device threads (any thread): never blocks
        self.backlog = self.inbox.backlog  # samples and controls waiting (the loop is behind when this grows)
        names = (driver.pipeline.arm_names, driver.pipeline.effector_names) if driver is not None else ((), ())
        self.relay = CommandRelay(clock, actuators if actuators is not None else {}, sender, names,
                                  on_tick=self.inbox.put, on_gone=lambda: self.halt("the command sender stopped"),
                                  hosted=hosted)
        self.frames = frames
        self.on_episode_start = on_episode_start
        self.judge = judge
        self.stats = LoopStats(dropped=self.inbox.dropped, commands_sent=self.relay.sent,
                               command_errors=self.relay.errors)
        self.episodes = EpisodeTracker()
        self.gate = ExecuteGate()
        self._planner_holds = False  # the planner keeps commands it engaged with (no halt since): see _device_failed
        watched = driver is not None and not driver.topics.action
        self.input_watch = InputWatch(int(input_loss_to_preview_s * 1e9), int(driver.pipeline.cfg.stale_ms * 1e6)) \
            if watched else None
        self.snapshot = LoopSnapshot(session_started_ns=clock.now_ns(),
                                     stale_ms=driver.pipeline.cfg.stale_ms if driver is not None else 0.0)
        self._camera_topic: str | None = None
        self._depth_topic: str | None = None
        self._taken: Counter = Counter()  # trigger samples taken off the queue so far, per topic
        self._last_ns = 0
        self._thread: threading.Thread | None = None
        self.failure = ""  # why the loop no longer runs the pipeline (it raised), or ""
        self.priority = ""  # the loop thread's nice value once it runs, or why it could not be raised
        # each sample as logged, on this thread (e.g. a policy's observations)
        self.taps: list[Callable[[Logged], Any]] = []
        self._handlers: dict[type, Callable[[Any, int], str | None]] = {
            Engage: self._engage, ToPreview: self._to_preview, EStop: self._estop, Halt: self._halt,
            Hold: self._hold, Release: self._release, StartEpisode: self._episode, StopEpisode: self._episode,
            DiscardEpisode: self._episode, MarkOutcome: self._episode, OperatorNote: self._note,
            WorldLayout: self._world_layout,
        }

    # ---- lifecycle -----------------------------------------------------------------------------
    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="session-loop", daemon=True)
        self._thread.start()
        self.relay.start()

    def stop(self, timeout: float = 5.0) -> None:
        """Stop the sender, process everything queued so far (its last ticks too), then stop."""
        self.relay.stop(timeout)
        self.inbox.put(None, _STOP)
        if self._thread:
            self._thread.join(timeout)

    # ---- the loop thread -------------------------------------------------------------------------
    def _run(self) -> None:
        self.priority = raise_this_thread()
        get = self.inbox.queue.get
        woke, stalled_s = time.monotonic(), 0.0
        while True:
            try:
                receive_ns, item = get(timeout=IDLE_CHECK_S)
            except queue.Empty:
                receive_ns, item = None, None
            if item is _STOP:
                return
            stalled_s = max(stalled_s, time.monotonic() - woke)  # longer than IDLE_CHECK_S: frozen
            woke = time.monotonic()
            try:
                if self.input_watch is not None and (item is None or isinstance(item, Sample)):
                    now = self.clock.now_ns() if item is None else receive_ns
                    self._input_event(self.input_watch.check(now, stalled_s))
                    stalled_s = 0.0
                if item is None:
                    continue
                if receive_ns is None:
                    self._apply(item)
                elif isinstance(item, Sample):
                    self._sample(item, receive_ns)
                elif isinstance(item, WireRecord):
                    self._wire(item, receive_ns)
                else:
                    self._tick(item, receive_ns)
            except Exception as exc:  # a bug must neither leave the arm moving nor end the recording
                self._failed(exc)

    def _failed(self, exc: Exception) -> None:
        """The pipeline raised: brake the robot to rest and refuse execute (halt), keep recording the
        devices without the pipeline, and say why (`failure`; the traceback is in the file)."""
        if self.failure:
            return
        self.failure = f"the session loop failed: {type(exc).__name__}: {exc}"
        try:
            self._event(topics.OPERATOR, "teleprev.OperatorEvent",
                        {"event": "loop_failed", "detail": "".join(traceback.format_exception(exc))})
            self._apply(Halt(self.failure))
        except Exception:
            if self.relay.sender is not None:  # the halt itself failed: stop sending at once
                self.relay.sender.stop()

    def _stamp(self, receive_ns: int | None = None) -> int:
        t = self.clock.now_ns() if receive_ns is None else receive_ns
        self._last_ns = max(t, self._last_ns + 1)
        return self._last_ns

    def _event(self, topic: str, schema: str, data: dict, t_ns: int | None = None, stamp_ns: int | None = None) -> int:
        """Log an event at t_ns (made strictly increasing), stamped stamp_ns (default: its log time)."""
        t = self._stamp(t_ns)
        self._log(Logged(topic, t, Event(t if stamp_ns is None else stamp_ns, schema, data)))
        return t

    def _sample(self, sample: Sample, receive_ns: int) -> None:
        superseded = self._superseded(sample.topic)
        marked = self._stamp(receive_ns) if superseded else 0
        t = self._stamp(receive_ns)
        if superseded:  # recorded before the sample, so that a re-run knows when it meets the sample
            marker = Logged(topics.SUPERSEDED, marked,
                            Event(marked, "teleprev.Superseded", {"topic": sample.topic, "log_time_ns": t}))
            self._log(marker)
            self.driver.feed(marker)
            self.stats.superseded += 1
        msg = self._record(sample, t)
        payload = msg.payload
        if self.driver is None or self.failure:
            return
        started = time.perf_counter_ns()
        age_ns = self.clock.now_ns() - getattr(payload, "stamp_ns", t)  # when the step takes it
        out = self.driver.feed(msg)
        if self.frames is not None and sample.topic == self.driver.topics.arm:
            tf = self.frames.sample(self.driver, payload)
            if tf is not None:
                self._log(Logged(topics.TF, self._stamp(), tf))
        if out.result is None:
            return
        if len(self.stats.step_ns) < 100_000:
            self.stats.step_ns.append(time.perf_counter_ns() - started)
        if self.input_watch is not None:
            update = out.result.update
            usable = out.result.arm_target is not None if update is None else \
                update.arm is not None and update.hand is not None
            self._input_event(self.input_watch.stepped(t, usable, out.result.report.get("flags", [])))
        self._pass_updates()
        for topic, payload in out.logged:
            self._log(Logged(topic, self._stamp(), payload))
        pipeline, latest = self.driver.pipeline, self.driver.latest
        self.snapshot = replace(
            self.snapshot, mode=self.driver.mode, step=out.result,
            measured_arm=pipeline.measured(latest.get(self.driver.topics.arm), pipeline.arm_names),
            measured_effector=pipeline.measured(latest.get(self.driver.topics.effector), pipeline.effector_names),
            commands_sent=sum(self.stats.commands_sent.values()), dropped=sum(self.stats.dropped.values()),
            input_age_ms=age_ns / 1e6,
        )

    def _record(self, sample: Sample, t: int) -> Logged:
        """Record a device's sample at log time t, pass it to the taps and the counters, and keep what the
        screen shows of it (a failure, the camera, the depth); the recorded message."""
        payload = sample.payload
        if isinstance(payload, PoseSample):
            # Foxglove's pose schema cannot store -0.0 (it reads back as +0.0); adding +0.0 turns -0.0
            # into +0.0 and leaves every other value alone, so the pipeline sees what a replay will.
            payload = replace(payload, position=np.asarray(payload.position, float) + 0.0,
                              orientation=np.asarray(payload.orientation, float) + 0.0)
        msg = Logged(sample.topic, t, payload)
        self._log(msg)
        for tap in self.taps:
            tap(msg)
        self.stats.count(sample.topic, t, payload)
        if sample.topic == topics.DEVICE_EVENT and payload.data.get("event") == "error":
            self._device_failed(payload.data)
        if isinstance(payload, ImageSample) and self._camera_topic in (None, sample.topic):
            self._camera_topic = sample.topic
            self.snapshot = replace(self.snapshot, camera=payload)
        elif isinstance(payload, DepthSample) and self._depth_topic in (None, sample.topic):
            self._depth_topic = sample.topic
            self.snapshot = replace(self.snapshot, depth=payload)
        return msg

    def _superseded(self, topic: str) -> bool:
        """Whether this glove sample (the step's trigger) is to be recorded but not stepped: a newer one is
        queued already, so the loop is behind, and stepping this one would only make the newer one wait
        longer (its age when stepped is the input's age at the robot). Every sample is still recorded; a
        re-run skips the same steps (/events/superseded)."""
        if self.driver is None or self.failure or self.driver.topics.action or topic != self.driver.topics.hand:
            return False
        self._taken[topic] += 1
        return self.inbox.queued[topic] > self._taken[topic]

    def _pass_updates(self) -> None:
        """The planner's updates the driver made, to the sender."""
        if self.relay.sender is not None:
            self.relay.pass_updates(self.driver.take_updates())

    def _tick(self, item, receive_ns: int) -> None:
        """Record one of the sender's ticks: its commands and which updates it had (CommandTick)."""
        self.stats.ticks += 1
        if len(self.stats.late_ns) < 1_000_000:
            self.stats.late_ns.append(item.late_ns)
        for msg in tick_records(item, self.relay, self._stamp, receive_ns):
            self._log(msg)
        self.snapshot = replace(self.snapshot, commands_sent=sum(self.stats.commands_sent.values()))

    def _wire(self, r: WireRecord, receive_ns: int) -> None:
        """Record one command as its actuator's process wrote it (/command/wire, stamped when the write began)."""
        self.relay.wire(r.kind, r.sent)
        self._event(topics.COMMAND_WIRE, "teleprev.CommandWire", r.event_data(), receive_ns, stamp_ns=r.wire_ns)

    def _device_failed(self, data: dict) -> None:
        """A device failed: count it, tell the operator, go back to preview (a recorded mode switch, so a
        replay does the same) and stay there until the operator engages. An actuator that failed has been
        stopped by its controller: nothing more is sent (halt). Another device: the commands brake to rest
        within their limits. An actuator that fails at rest in preview is halted too (once), while the
        planner still keeps a command for it: its controller let go of that command, so the next engage
        starts from where the arm is measured (teleprev/pipeline/planner.py)."""
        name = str(data.get("device", ""))
        self.stats.device_failures[name] += 1
        message = f"device {name} failed: {data.get('message', '')}"
        actuator = name in {getattr(p, "name", None) for p in self.relay.actuators.values()}
        self.gate.faulted(message)
        moving = self.driver is not None and (self.driver.mode == "execute" or (actuator and self.relay.active))
        if moving or (actuator and self._planner_holds):
            self._apply(ToPreview(f"device {name} failed", halt=actuator))
            message += ("; nothing more is sent to the robot" if actuator else "; the robot brakes to rest") + \
                ", back in PREVIEW (press space to engage again)"
        self.snapshot = replace(self.snapshot, message=message, fault=self.gate.fault)

    def _input_event(self, event: InputEvent | None) -> None:
        """Record a transition of the operator's input; past the bound, back to preview until the operator engages."""
        if event is None:
            return
        self._event(topics.OPERATOR, "teleprev.OperatorEvent", {"event": event.event, "detail": event.detail})
        if event.to_preview:
            self.gate.faulted(event.detail)
            self._apply(ToPreview("input_lost"))
        self.snapshot = replace(self.snapshot, message=event.detail, fault=self.gate.fault)

    # ---- controls, on the loop thread ------------------------------------------------------------
    def _apply(self, control: Control) -> None:
        """Carry out one control; each handler returns the operator's message ("": none new), or None
        when nothing changed (the preview's snapshot then stays as it is)."""
        message = self._handlers[type(control)](control, self.clock.now_ns())
        if message is None:
            return
        self.snapshot = replace(
            self.snapshot, mode=self.driver.mode if self.driver else "preview", episode=self.episodes.index,
            episode_active=self.episodes.active, task=self.episodes.task, episode_started_ns=self.episodes.started_ns,
            message=message or self.snapshot.message, fault=self.gate.fault,
        )

    def _engage(self, c: Engage, now: int) -> str | None:
        return self._switch("execute", c.reason, now, unattended=c.unattended)

    def _to_preview(self, c: ToPreview, now: int) -> str | None:
        return self._switch("preview", c.reason, now, halt=c.halt)

    def _estop(self, c: EStop, now: int) -> str | None:
        return self._switch("estop", "estop", now)

    def _halt(self, c: Halt, now: int) -> str | None:
        self.gate.halt(c.why)
        refused = self._switch("preview", "halt", now)
        return refused or f"{c.why}: robot stopped"

    def _hold(self, c: Hold, now: int) -> str | None:
        self.gate.hold(c.source, c.why)
        return self._switch("preview", c.reason, now)

    def _release(self, c: Release, now: int) -> str:
        self.gate.release(c.source)
        return ""

    def _switch(self, mode: str, reason: str, now: int, halt: bool = False, unattended: bool = False) -> str | None:
        """A mode switch through the gate and the pipeline, recorded (so that a replay makes it too) and
        passed to the sender; returns why it was refused, "" when made, None when already in that mode."""
        t = self._stamp(now)
        halted = self.gate.state is GateState.HALTED
        if self.driver is not None and mode == self.driver.mode and not halt and not halted:
            return None  # already in it (a retried engage accepted meanwhile): nothing to switch or record
        refusal = self.gate.refusal(unattended) if mode == "execute" else None
        if refusal is not None:
            if refusal.tell:  # why it stays in preview, once per fault
                self._event(topics.OPERATOR, "teleprev.OperatorEvent",
                            {"event": "engage_refused", "detail": refusal.why}, now)
            refused = refusal.why
        else:
            refused = self.driver.request_mode("estop" if halt else mode, t) if self.driver else "no pipeline"
        if refused:
            return f"cannot switch to {mode}: {refused}"
        # An e-stop is recorded as a switch to preview for the reason "estop" (a replay repeats it).
        switch = {"mode": "preview", "reason": "estop"} if mode == "estop" else {"mode": mode, "reason": reason}
        if halt:
            switch["halt"] = True
        self._log(Logged(topics.MODE, t, Event(t, "teleprev.ModeSwitch", switch)))
        self._pass_updates()
        if halt or mode == "estop":
            self._planner_holds = False
        if mode == "execute":
            self._planner_holds = True
            self.stats.engages += 1
            self.gate.engaged()  # the operator engaged again
        if self.input_watch is not None:
            self.input_watch.engaged(t) if mode == "execute" else self.input_watch.left_execute()
        return ""

    def _episode(self, c: StartEpisode | StopEpisode | DiscardEpisode | MarkOutcome, now: int) -> str:
        at = now if getattr(c, "at_ns", None) is None else int(c.at_ns)
        events, message = self.episodes.apply_judged(c, at, self.judge)
        if isinstance(c, StartEpisode) and self.on_episode_start:
            self.on_episode_start(self.episodes.task)
        for e in events:
            self._event(topics.EPISODE, "teleprev.EpisodeEvent", e, now, stamp_ns=at)
        return message

    def _world_layout(self, c: WorldLayout, now: int) -> None:
        self._event(topics.WORLD, "teleprev.WorldLayout", c.event, now, stamp_ns=c.at_ns)

    def _note(self, c: OperatorNote, now: int) -> str:
        self._event(topics.OPERATOR, "teleprev.OperatorEvent", {"event": c.event, "detail": c.detail}, now)
        return c.detail if c.show else ""
