"""The session loop: where every sample of a recording passes, in one order.

Device reader threads (devices/runner.py) hand samples to a bounded queue; one loop thread takes them in
arrival order, gives each a strictly increasing log time on the session clock (its host receive time),
records it, feeds the pipeline driver, passes the step's targets and every accepted mode switch to the
paced command sender (teleprev/live/sender.py), publishes the robot's frames on /tf, and carries out the
operator's controls (mode switches, episodes). Because the loop is the only place where order is
decided, replaying a session's raw streams in log-time order meets the pipeline with exactly the inputs
it met live.

The commands do not wait for this loop: the sender samples them on its own clock, in its own process. A
relay thread here takes each tick it reports, passes its commands to the arm and the end effector (the
actuators' `send`), and queues the tick for the loop to record (/command/arm, /command/hand and
/command/tick, stamped with the instant the sender sent them).

After a device fails, nothing engages by itself: the session goes back to preview (an actuator that
failed: nothing more is sent at once, its controller has stopped it; another device: the commands brake to
rest), records why, and refuses an unattended engage until the operator engages with a key.

The terminal preview reads `snapshot`, which the loop replaces (never mutates) after every change.
"""

from __future__ import annotations

import queue
import threading
import time
import traceback
from collections import Counter
from dataclasses import dataclass, field, replace
from typing import Any, Callable

import numpy as np

from teleprev.devices.contract import Actuator
from teleprev.messages import Event, ImageSample, JointSample, Logged, PoseSample, Sample
from teleprev.pipeline.driver import PipelineDriver
from teleprev.pipeline.planner import ModeUpdate
from teleprev import topics
from teleprev.clock import SessionClock
from teleprev.live.episodes import EpisodeTracker
from teleprev.live.thread_priority import raise_this_thread

_STOP = object()


@dataclass(frozen=True)
class LoopSnapshot:
    """What the terminal preview shows; replaced as a whole by the loop thread."""

    mode: str = "preview"
    episode: int = -1
    episode_active: bool = False
    task: str = ""
    episode_started_ns: int = 0
    session_started_ns: int = 0
    step: Any = None  # the last StepResult
    measured_arm: np.ndarray | None = None
    measured_effector: np.ndarray | None = None
    message: str = ""  # the last refusal or warning, for the operator
    commands_sent: int = 0
    dropped: int = 0
    fault: str = ""  # why the session stays in preview until the operator engages
    camera: Any = None  # the latest ImageSample of the first camera heard from, for the preview


@dataclass
class StreamCounter:
    count: int = 0
    first_ns: int = 0
    last_ns: int = 0
    latency_ns: int = 0  # receive - acquisition of the last sample

    def rate_hz(self) -> float:
        return (self.count - 1) * 1e9 / (self.last_ns - self.first_ns) if self.count > 1 and self.last_ns > self.first_ns else 0.0


@dataclass
class LoopStats:
    streams: dict[str, StreamCounter] = field(default_factory=dict)
    dropped: Counter = field(default_factory=Counter)  # samples the loop queue had no room for, per topic
    commands_sent: Counter = field(default_factory=Counter)
    command_errors: Counter = field(default_factory=Counter)
    step_ns: list[int] = field(default_factory=list)  # pipeline step durations (bounded)
    device_failures: Counter = field(default_factory=Counter)  # "error" device events, per device
    late_ns: list[int] = field(default_factory=list)  # how late each of the sender's ticks woke (bounded)
    ticks: int = 0
    engages: int = 0  # accepted switches to execute


class SessionLoop:
    def __init__(
        self,
        clock: SessionClock,
        log: Callable[[Logged], Any],
        driver: PipelineDriver | None = None,
        actuators: dict[str, Actuator] | None = None,
        frames=None,
        tf_period_ns: int = 0,
        queue_size: int = 4096,
        on_episode_start: Callable[[str], None] | None = None,
        sender=None,
    ):
        """`log` receives every message to record (Recorder.log); `actuators` maps "arm" and "hand" to the
        ActuatorPorts that pass commands on; `frames` (a FramePublisher) turns measured joints into /tf;
        `sender` (a started CommandSender) makes the commands of a format 4 pipeline."""
        self.clock = clock
        self._log = log
        self.driver = driver
        self.actuators = actuators or {}
        self.frames = frames
        self.tf_period_ns = tf_period_ns
        self.on_episode_start = on_episode_start
        self.stats = LoopStats()
        self.episodes = EpisodeTracker()
        self.snapshot = LoopSnapshot(session_started_ns=clock.now_ns())
        self._camera_topic: str | None = None
        self._queue: queue.Queue = queue.Queue(maxsize=queue_size)
        self._last_ns = 0
        self._last_tf_ns = 0
        self._thread: threading.Thread | None = None
        self.halted = ""  # why the session may no longer execute (e.g. the recording failed)
        self.failure = ""  # why the loop no longer runs the pipeline (it raised), or ""
        self.sender = sender
        self.sender_active = False  # the sender is commanding (executing, or braking to rest)
        self._mode_seq = 0  # the last mode switch passed to the sender
        self._relay_thread: threading.Thread | None = None
        self._stopping = False
        self.fault = ""  # why the session stays in preview until the operator engages (a device failed)
        self._fault_told = False
        self.priority = ""  # the loop thread's nice value once it runs, or why it could not be raised
        self.holds: dict[str, str] = {}  # why execute is refused for now, by who asked (a timed episodes' reset)
        self.taps: list[Callable[[Logged], Any]] = []  # each sample as logged, on this thread (e.g. a policy's observations)

    # ---- producers (any thread) ----------------------------------------------------------------
    def sink(self, sample: Sample, receive_ns: int) -> None:
        """For device threads: never blocks; a full queue drops the sample and counts it."""
        try:
            self._queue.put_nowait((receive_ns, sample))
        except queue.Full:
            self.stats.dropped[sample.topic] += 1

    def control(self, action: str, **data) -> None:
        """For the operator (keys) and scripts: 'mode' (mode=), 'start' (task=), 'stop', 'discard',
        'outcome' (success=), 'operator' (event=, detail=), 'halt' (why=: back to preview, which brakes
        the robot to rest, and execute is refused from then on), 'hold' (why=, source=: the same until a
        'hold' from that source with why="" lifts it; execute is refused while any source holds: timed
        episodes' resets, a policy that has not acted yet in its episode). 'start', 'stop' and 'discard' take at_ns=: the
        session-clock instant the episode event is stamped with (when a schedule or a key asked for it,
        however late the loop gets to it; default: when the loop does). Controls are never dropped."""
        self._queue.put((None, (action, data)))

    def backlog(self) -> int:
        """Samples and controls waiting for the loop thread (it is behind when this grows)."""
        return self._queue.qsize()

    # ---- lifecycle -----------------------------------------------------------------------------
    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="session-loop", daemon=True)
        self._thread.start()
        if self.sender is not None:
            self._relay_thread = threading.Thread(target=self._relay, name="command-relay", daemon=True)
            self._relay_thread.start()

    def stop(self, timeout: float = 5.0) -> None:
        """Stop the sender, process everything queued so far (its last ticks too), then stop."""
        self._stopping = True
        if self.sender is not None:
            self.sender.stop()
            if self._relay_thread:
                self._relay_thread.join(timeout)
        self._queue.put((None, _STOP))
        if self._thread:
            self._thread.join(timeout)

    # ---- the relay thread ------------------------------------------------------------------------
    def _relay(self) -> None:
        """The sender's ticks: their commands to the actuators at once, then to the loop to record."""
        from teleprev.live.sender import SentTick

        while True:
            items = self.sender.receive(0.2)
            if items is None:  # the sender has gone
                self.sender_active = False
                if not self._stopping:
                    self.control("halt", why="the command sender stopped")
                return
            for item in items:
                if not isinstance(item, SentTick):
                    continue
                tick = item.tick
                if tick.seq >= self._mode_seq:  # (a tick from before the last mode switch says nothing now)
                    self.sender_active = tick.active
                received = self.clock.now_ns()
                for kind, names, q, v in (("arm", self._arm_names, tick.arm, tick.arm_v),
                                          ("hand", self._effector_names, tick.hand, tick.hand_v)):
                    if q is not None:
                        self._send(kind, JointSample(tick.t_ns, names, q, v))
                self._queue.put((received, item))

    def _run(self) -> None:
        self.priority = raise_this_thread()
        while True:
            receive_ns, item = self._queue.get()
            if item is _STOP:
                return
            try:
                if receive_ns is None:
                    self._control(*item)
                elif isinstance(item, Sample):
                    self._sample(item, receive_ns)
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
            self._control("halt", {"why": self.failure})
        except Exception:
            if self.sender is not None:  # the halt itself failed: stop sending at once
                self.sender.stop()

    # ---- the loop thread -------------------------------------------------------------------------
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
        t = self._stamp(receive_ns)
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
        counter = self.stats.streams.get(sample.topic)
        if counter is None:
            counter = self.stats.streams[sample.topic] = StreamCounter(first_ns=t)
        counter.count += 1
        counter.last_ns = t
        counter.latency_ns = t - getattr(payload, "stamp_ns", t)
        if sample.topic == topics.DEVICE_EVENT and payload.data.get("event") == "error":
            self._device_failed(payload.data)
        if isinstance(payload, ImageSample) and self._camera_topic in (None, sample.topic):
            self._camera_topic = sample.topic
            self.snapshot = replace(self.snapshot, camera=payload)
        if self.driver is None or self.failure:
            return
        started = time.perf_counter_ns()
        out = self.driver.feed(msg)
        if sample.topic == self.driver.topics.arm:
            self._publish_frames(payload)
        if out.result is None:
            return
        if len(self.stats.step_ns) < 100_000:
            self.stats.step_ns.append(time.perf_counter_ns() - started)
        self._pass_updates()
        for topic, payload in out.logged:
            self._log(Logged(topic, self._stamp(), payload))
        self._send("arm", out.arm_command)
        self._send("hand", out.effector_command)
        pipeline, latest = self.driver.pipeline, self.driver.latest
        self.snapshot = replace(
            self.snapshot, mode=self.driver.mode, step=out.result,
            measured_arm=pipeline.measured(latest.get(self.driver.topics.arm), pipeline.arm_names),
            measured_effector=pipeline.measured(latest.get(self.driver.topics.effector), pipeline.effector_names),
            commands_sent=sum(self.stats.commands_sent.values()), dropped=sum(self.stats.dropped.values()),
        )

    def _pass_updates(self) -> None:
        """The planner's updates the driver made (format 4), to the sender."""
        if self.driver is not None and self.sender is not None:
            for update in self.driver.take_updates():
                if isinstance(update, ModeUpdate):
                    self._mode_seq = update.seq
                    if update.mode == "halt":
                        self.sender_active = False  # the planner sends nothing more from its next tick
                    elif update.mode == "execute":
                        self.sender_active = True
                self.sender.send(update)

    def _tick(self, item, receive_ns: int) -> None:
        """Record one of the sender's ticks: its commands and which updates it had (CommandTick)."""
        tick = item.tick
        stats = self.stats
        stats.ticks += 1
        if len(stats.late_ns) < 1_000_000:
            stats.late_ns.append(item.late_ns)
        for topic, names, q, v in ((topics.COMMAND_ARM, self._arm_names, tick.arm, tick.arm_v),
                                   (topics.COMMAND_HAND, self._effector_names, tick.hand, tick.hand_v)):
            if q is not None:
                self._log(Logged(topic, self._stamp(receive_ns), JointSample(tick.t_ns, names, q, v)))
        data = {"seq": tick.seq, "late_ms": item.late_ns / 1e6, "flags": list(tick.flags), "active": tick.active}
        self._log(Logged(topics.COMMAND_TICK, self._stamp(), Event(tick.t_ns, "teleprev.CommandTick", data)))
        self.snapshot = replace(self.snapshot, commands_sent=sum(stats.commands_sent.values()))

    @property
    def _arm_names(self) -> tuple[str, ...]:
        return self.driver.pipeline.arm_names

    @property
    def _effector_names(self) -> tuple[str, ...]:
        return self.driver.pipeline.effector_names

    def _device_failed(self, data: dict) -> None:
        """A device failed: count it, tell the operator, go back to preview (a recorded mode switch, so a
        replay does the same) and stay there until the operator engages. An actuator that failed has been
        stopped by its controller: nothing more is sent (halt). Another device: the commands brake to rest
        within their limits."""
        name = str(data.get("device", ""))
        self.stats.device_failures[name] += 1
        message = f"device {name} failed: {data.get('message', '')}"
        actuator = name in {getattr(p, "name", None) for p in self.actuators.values()}
        self.fault, self._fault_told = message, False
        if self.driver is not None and (self.driver.mode == "execute" or (actuator and self.sender_active)):
            switch = {"mode": "preview", "reason": f"device {name} failed"}
            if actuator:
                switch["halt"] = True
            self._control("mode", switch)
            message += ("; nothing more is sent to the robot" if actuator else "; the robot brakes to rest") + \
                ", back in PREVIEW (press space to engage again)"
        self.snapshot = replace(self.snapshot, message=message, fault=self.fault)

    def _send(self, kind: str, command: JointSample | None) -> None:
        """Through an ActuatorPort: never raises; a device that is down or refuses is counted, not retried."""
        if command is None:
            return
        port = self.actuators.get(kind)
        if port is None:
            return
        if port.send(command):
            self.stats.commands_sent[kind] += 1
        else:
            self.stats.command_errors[kind] += 1

    def _publish_frames(self, arm_state) -> None:
        """/tf for every arm state sample (at most one per tf_period_ns), stamped with its acquisition time
        so that the robot lines up with the images; the end effector at its latest measured state."""
        if self.frames is None or arm_state.stamp_ns - self._last_tf_ns < self.tf_period_ns:
            return
        pipeline, model = self.driver.pipeline, self.frames.model
        arm = pipeline.measured(arm_state, pipeline.arm_names) if isinstance(arm_state, JointSample) else None
        if arm is None:
            return
        self._last_tf_ns = arm_state.stamp_ns
        joints = dict(zip(pipeline.arm_names, arm))
        eff = pipeline.measured(self.driver.latest.get(self.driver.topics.effector), pipeline.effector_names)
        if eff is not None and pipeline.effector_names[0] in model.joint_index:
            joints.update(zip(pipeline.effector_names, eff))
        self._log(Logged(topics.TF, self._stamp(), self.frames.sample(model.vector(joints), arm_state.stamp_ns)))

    def _control(self, action: str, data: dict) -> None:
        now = self.clock.now_ns()
        message = ""
        if action == "halt":
            self.halted = data["why"]
            action, data, message = "mode", {"mode": "preview", "reason": "halt"}, f"{self.halted}: robot stopped"
        elif action == "hold":
            source, why = data.get("source", "schedule"), data.get("why", "")
            if why:
                self.holds[source] = why
            else:
                self.holds.pop(source, None)
            action, data = ("mode", {"mode": "preview", "reason": data.get("reason", "hold")}) if why else ("", {})
        if action == "mode":
            mode = data["mode"]
            t = self._stamp(now)
            if self.driver is not None and mode == self.driver.mode and not data.get("halt") and not self.halted:
                return  # already in it (a retried engage accepted meanwhile): nothing to switch or record
            if self.halted and mode == "execute":
                refused = self.halted
            elif self.holds and mode == "execute":
                refused = "; ".join(self.holds.values())
            elif self.fault and mode == "execute" and data.get("reason") == "script":
                refused = f"{self.fault} (an unattended session does not engage again after a fault)"
                if not self._fault_told:  # why it stays in preview, once per fault
                    self._fault_told = True
                    self._event(topics.OPERATOR, "teleprev.OperatorEvent", {"event": "engage_refused", "detail": refused}, now)
            else:
                halt = bool(data.get("halt"))
                refused = self.driver.request_mode("estop" if halt else mode, t) if self.driver else "no pipeline"
            if refused:
                message = f"cannot switch to {mode}: {refused}"
            else:
                # An e-stop is recorded as a switch to preview for the reason "estop" (a replay repeats it).
                switch = {"mode": "preview", "reason": "estop"} if mode == "estop" else {"mode": mode, "reason": data.get("reason", "key")}
                if data.get("halt"):
                    switch["halt"] = True
                self._log(Logged(topics.MODE, t, Event(t, "teleprev.ModeSwitch", switch)))
                self._pass_updates()
                if mode == "execute":
                    self.stats.engages += 1
                    self.fault = ""  # the operator engaged again
        elif action in ("start", "stop", "discard", "outcome"):
            tracker = self.episodes
            at = data.get("at_ns")
            at = now if at is None else int(at)
            if action == "start":
                task = data.get("task") or tracker.task or ""
                events = tracker.start(task, at)
                if self.on_episode_start:
                    self.on_episode_start(task)
            elif action == "stop":
                events = tracker.stop(at)
            elif action == "discard":
                events = tracker.discard(at)
            else:
                events = tracker.outcome(bool(data.get("success", True)))
            for e in events:
                self._event(topics.EPISODE, "teleprev.EpisodeEvent", e, now, stamp_ns=at)
        elif action == "operator":
            self._event(topics.OPERATOR, "teleprev.OperatorEvent", {"event": data.get("event", ""), "detail": data.get("detail", "")}, now)
        self.snapshot = replace(
            self.snapshot, mode=self.driver.mode if self.driver else "preview", episode=self.episodes.index,
            episode_active=self.episodes.active, task=self.episodes.task, episode_started_ns=self.episodes.started_ns,
            message=message or self.snapshot.message, fault=self.fault,
        )
