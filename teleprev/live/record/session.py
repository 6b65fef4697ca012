"""A recording in progress: the rig's devices, the pipeline, the session loop and the recorder, wired.

    with LiveSession(options) as rec:      # opens devices, starts threads
        rec.loop.start_episode("pour")
        ...
    rec.summary                          # counts, drops, where the file is

`teleprev record` drives one from the keyboard and the terminal preview, or from a script (--duration,
--episodes; timed episodes: --episode-time, --reset-time); tests and benchmarks drive it directly.
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime as _dt
import json
import time
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from teleprev import topics
from teleprev.assembly import build_pipeline, rig_calibration
from teleprev.clock import SessionClock
from teleprev.errors import ConfigError
from teleprev.live.core.loop import LoopInbox, SessionLoop
from teleprev.live.record.frames import RobotFrames, sensor_frames
from teleprev.live.record.metadata import session_metadata
from teleprev.live.record.operator_actions import ACTION_KEYS, handle_key, operator_status
from teleprev.live.record.schedule import EpisodeTimes
from teleprev.messages import Logged, RobotDescription
from teleprev.pipeline.driver import InputTopics, PipelineDriver
from teleprev.rig import Rig, load_rig
from teleprev.robot.frames import FramePublisher
from teleprev.robot.model import RobotModel, load_robot
from teleprev.status import DeviceRow

if TYPE_CHECKING:
    from teleprev.live.core.sender import CommandSender

URDF_MEDIA_TYPE = "application/xml"  # the rig's URDF, attached to the session as <name>.urdf
# What a switch to preview may wait for before it reaches the sender: a busy session loop (its queue)
PREVIEW_SLACK_S = 0.1


@dataclass
class RecordOptions:
    out: Path
    rig: Path | None = None  # None: the default all-sim rig
    models: Path | None = None  # None: the rig's, else the shipped models/
    task: str = ""  # default task label (else the rig's)
    task_text: str = ""  # the task as an instruction in words (else the rig's [tasks] entry for it)
    operator: str = ""
    participant: str = ""
    condition: str = ""
    practice: bool = False
    queue_size: int = 8192
    connect_timeout_s: float = 5.0  # unattended: every device must have sent something by then
    foxglove: int | None = None  # a live Foxglove view on this port of 127.0.0.1 (0: any free port)
    episode_plan: EpisodeTimes | None = None  # timed episodes (run.run_timed): kept in the file's metadata
    policy: dict[str, str] | None = None  # a policy drives the pipeline (teleprev rollout): its metadata record
    webxr_host: str = ""  # the XR page's address to listen on, over the rig's (record --webxr-host)


def inside_limits(robot: RobotModel, *joint_sets: tuple[str, ...]) -> tuple[np.ndarray, ...]:
    """Per set of the robot's joints, zero clipped into their limits (a sender warms its planner there)."""
    return tuple(np.clip(np.zeros(len(names)), robot.lower[robot.indices(names)], robot.upper[robot.indices(names)])
                 for names in joint_sets)


def default_session_path(task: str) -> Path:
    stamp = _dt.datetime.now().strftime("%Y%m%d_%H%M%S")
    return Path("sessions") / f"{stamp}_{task or 'session'}.mcap"


class LiveSession:
    def __init__(self, options: RecordOptions):
        from teleprev.devices.runner import ActuatorPort, DeviceRunner
        from teleprev.session.recorder import LAG_BUDGET_S, Recorder

        self.options = options
        self.rig: Rig = load_rig(options.rig)
        if options.webxr_host:
            self.rig = self.rig.with_device_settings("webxr", "--webxr-host", host=options.webxr_host)
        rig = self.rig
        rig.require("glove", "suit", "arm", "hand")
        self.task = options.task or rig.rig.task
        out = Path(options.out)
        if out.exists():
            raise ConfigError("a session with this name exists already; choose another --out", str(out))
        self.clock = SessionClock()
        self.context = rig.device_context(self.clock)
        self.physics = self.context.physics
        if self.physics is not None:
            # Started before the sender forks, so that an actuator reaches the world from either process.
            self.physics.host()
        self.devices = {name: entry.cls(name, entry.settings, self.context) for name, entry in rig.devices.items()}
        first = {kind: rig.of_kind(kind)[0].name for kind in ("glove", "suit", "arm", "hand")}
        self.pipeline = build_pipeline(rig, options.models)
        inputs = InputTopics.for_devices(first["glove"], first["suit"], first["arm"], first["hand"])
        if options.policy is not None:  # the policy's actions step the pipeline (Pipeline.joint_step)
            inputs = dataclasses.replace(inputs, action=topics.POLICY_ACTION)
        self.driver = PipelineDriver(self.pipeline, inputs)
        self.robot = load_robot(rig.rig.robot)
        out.parent.mkdir(parents=True, exist_ok=True)
        urdf = Path(self.robot.urdf_path)
        self.view = None
        if options.foxglove is not None:
            from teleprev.live.view.foxglove_view import FoxgloveView, session_channels

            # every channel declared before the server starts: a client that connects at once sees them all
            self.view = FoxgloveView(
                options.foxglove, session_channels([s for dev in self.devices.values() for s in dev.streams()])
            )
        try:
            self.recorder = Recorder(
                out,
                session_metadata(self),
                attachments={urdf.name: (URDF_MEDIA_TYPE, urdf.read_bytes())},
                on_failure=self._recording_failed,
                lag_budget_s=LAG_BUDGET_S,
                on_behind=self._recording_behind,
            )
        except BaseException:
            if self.view is not None:
                self.view.close()
            raise
        from teleprev.live.core.actuator_host import ActuatorHost
        from teleprev.live.core.sender import CommandSender
        from teleprev.pipeline.planner import CommandPlanner

        inbox = LoopInbox(options.queue_size)  # the device runners' sink, and the actuators' ports, before the loop
        # The actuators whose plugins allow it run in paced processes of their own, where their commands
        # leave on the wire (live/core/actuator_host.py); every other device has a runner thread here.
        names = {"arm": self.pipeline.arm_names, "hand": self.pipeline.effector_names}
        self.hosts = {kind: ActuatorHost(kind, self.devices[first[kind]], inbox.sink, self.clock, names[kind])
                      for kind in ("arm", "hand") if self.devices[first[kind]].own_process}
        hosted = {host.name: host for host in self.hosts.values()}
        self.runners = {name: hosted.get(name) or DeviceRunner(dev, inbox.sink, self.clock)
                        for name, dev in self.devices.items()}
        self.actuators = {
            kind: self.hosts.get(kind) or ActuatorPort(self.devices[first[kind]], self.runners[first[kind]])
            for kind in ("arm", "hand")
        }
        self.sender = CommandSender(CommandPlanner.for_pipeline(self.pipeline), self.clock,
                                    rig.pipeline.command_rate_hz, outlets=tuple(h.outlet for h in self.hosts.values()),
                                    warm_pose=inside_limits(self.robot, names["arm"], names["hand"]))
        frames = FramePublisher(self.robot, sensor_frames(rig, self.robot, rig_calibration(rig)))
        tf_period_ns = int(1e9 / rig.pipeline.tf_rate_hz) if rig.pipeline.tf_rate_hz > 0 else 0
        self.loop = SessionLoop(self.clock, self._log, self.driver, inbox=inbox, actuators=self.actuators,
                                hosted=frozenset(self.hosts), sender=self.sender,
                                frames=RobotFrames(frames, tf_period_ns), on_episode_start=self._episode_started,
                                judge=self._judge if self.physics is not None else None,
                                input_loss_to_preview_s=rig.session.input_loss_to_preview_s)
        for host in self.hosts.values():
            host.on_wire = self.loop.wired
        if self.physics is not None:  # every scene the world runs, recorded (those begun so far first)
            for entry in self.physics.layouts:
                self._world_layout(entry)
            self.physics.listeners.append(self._world_layout)
        self.summary = None
        self.cannot_start = False  # a device could not start at all (wait_connected said which, at once)
        self._press = self._press_unattended
        # A device carrying the operator's controls (the XR page) acts on this recording and shows its status.
        self.context.operator.act = self.act
        self.context.operator.status = lambda: operator_status(self.loop.snapshot)

    @property
    def preview_lead_s(self) -> float:
        """How long before a timed episode's end to switch to preview so that the robot is at rest by then:
        the commands' braking bound, plus two of the sender's ticks and PREVIEW_SLACK_S for the switch to
        reach it."""
        return self.pipeline.motion.stop_time_bound() + 2.0 / self.rig.pipeline.command_rate_hz + PREVIEW_SLACK_S

    def act(self, action: str, via: str = "") -> str:
        """An operator action by name (operator_actions.ACTION_KEYS), from a control other than the keyboard:
        it presses the action's key on whatever reads the keys now. "" when pressed, "unknown" for no such action.
        `via`: how it was asked (contract.OperatorLink); a one-arm session takes a gesture as any other."""
        key = ACTION_KEYS.get(action)
        if key is None:
            return "unknown"
        self._press(key)
        return ""

    @contextlib.contextmanager
    def pressing(self, press):
        """While the block runs, `act` presses keys with `press` (an interactive run's or a timed run's)."""
        self._press = press
        try:
            yield
        finally:
            self._press = self._press_unattended

    def _press_unattended(self, key: str) -> None:
        handle_key(self, key, [])

    def _recording_failed(self, exc: OSError) -> None:
        """On the recorder's writer thread, the moment a write fails (the recorder has noted it, so
        `failure` says why): the robot brakes to rest and the preview says why; the session then ends
        with a non-zero exit."""
        self.loop.halt(self.failure)

    def _recording_behind(self, behind: bool, lag_s: float, shed: dict[str, int]) -> None:
        """On the recorder's writer thread: it fell behind (new work is shed, the least valuable first, so that
        what is in memory reaches the disk first), or caught up; recorded, and shown in the preview."""
        counts = ", ".join(f"{n} {topic}" for topic, n in sorted(shed.items())) or "nothing yet"
        if behind:
            self.loop.note("recording_behind", f"the recording is {lag_s:.2f} s behind: camera frames (then all but "
                                               f"commands and events) are not recorded until it catches up", show=True)
        else:
            self.loop.note("recording_caught_up", f"the recording caught up; not recorded meanwhile: {counts}",
                           show=True)

    @property
    def failure(self) -> str:
        """Why this session cannot go on (the recording or the session loop failed), or ""."""
        exc = self.recorder.failure
        if exc is None:
            return self.loop.failure
        from teleprev.errors import describe_os_error

        return f"recording failed ({describe_os_error(exc)})"

    def settle(self, timeout_s: float = 3.0) -> bool:
        """Back to preview (if not there) and wait until the commands have braked to rest, so that
        stopping the devices never cuts a motion short; False if it did not settle in time."""
        start = time.monotonic()
        asked = False
        while time.monotonic() < start + timeout_s:
            if self.driver.state.mode == "preview" and not self.loop.relay.active:
                return True
            if not asked and self.driver.state.mode != "preview" and time.monotonic() > start + 0.25:
                # no switch to preview was on its way (the caller's would have arrived by now): ask for one
                self.loop.to_preview("stop")
                asked = True
            time.sleep(0.01)
        return False

    def _log(self, msg: Logged) -> bool:
        """Every message to the file, and to the live Foxglove view when there is one."""
        if self.view is not None:
            self.view.log(msg)
        return self.recorder.log(msg)

    def _world_layout(self, entry) -> None:
        self.loop.world_layout(entry.to_event(), entry.time_ns)

    def _judge(self) -> tuple[str, str] | None:
        """The physics world's outcome of its task now, as the loop marks a stopping episode with it."""
        outcome = self.physics.outcome()
        return None if outcome is None else (outcome.mark, outcome.reason)

    def _episode_started(self, task: str) -> None:
        for listener in self.context.task_listeners:
            listener(task)

    def start(self) -> LiveSession:
        return self._start((self.sender,), {topics.ROBOT_DESCRIPTION: self.robot})

    def _start(self, senders: Iterable[CommandSender], descriptions: dict[str, RobotModel]) -> LiveSession:
        """Start everything in its order; `descriptions`: topic -> the robot whose URDF is logged on it (a
        bimanual session's: one a side)."""
        for host in self.hosts.values():  # forked first, before this session starts any thread
            host.fork()
        for sender in senders:  # after the actuators' processes, whose command pipes they write
            sender.start()
        self.recorder.start()
        t = self.clock.now_ns()  # first in the file, so that Foxglove's URDF layer has the robot from the start
        for topic, robot in descriptions.items():
            self._log(Logged(topic, t, RobotDescription(t, robot.urdf_path.read_text())))
        self.loop.start()
        for runner in self.runners.values():
            runner.start()
        if self.options.practice:
            self.loop.note("practice_start")
        return self

    def stop(self):
        """Brake to rest, stop the devices, let the loop finish what is queued, close the file; returns
        its summary (raises SessionError if the recording failed: what was flushed stays recoverable)."""
        self.settle()
        for runner in self.runners.values():
            runner.stop()
        self.loop.stop_episode()
        self.loop.stop()
        stats = self.loop.stats
        status = self.sender.status
        extra = {
            "loop": {
                "dropped": json.dumps(dict(stats.dropped)),
                "commands_sent": json.dumps(dict(stats.commands_sent)),
                "command_errors": json.dumps(dict(stats.command_errors)),
                "device_failures": json.dumps(dict(stats.device_failures)),
                "failure": self.loop.failure,
                "priority": self.loop.priority,
            },
            "sender": {
                "rate_hz": f"{1e9 / self.sender.period_ns:g}",
                "ticks": str(stats.ticks),
                "realtime": "true" if status and status.realtime else "false",
                "detail": status.detail if status else "",
                "dropped_updates": str(self.sender.dropped_updates),
            },
            "devices": {name: json.dumps(counts) for name, counts in self.device_counts().items()},
        }
        if self.physics is not None:
            stats = self.physics.link().stats()
            extra["world_run"] = {"steps": str(stats.steps), "late_max_ms": f"{stats.late_max_ms:.3f}",
                                  "late_batches": str(stats.late_batches),
                                  "realtime": "true" if stats.realtime else "false"}
        if self.hosts:  # where the real actuators' commands were written: their own paced processes
            extra["actuator_processes"] = {kind: host.status.detail if host.status else "did not start"
                                           for kind, host in self.hosts.items()}
        try:
            self.summary = self.recorder.close(extra)
        finally:
            if self.view is not None:
                self.view.close()
            if self.physics is not None:
                self.physics.close()
        return self.summary

    def __enter__(self) -> LiveSession:
        return self.start()

    def __exit__(self, *exc) -> None:
        if self.summary is None:
            self.stop()

    def wait_connected(self, timeout_s: float | None = None) -> list[str]:
        """Wait until every device has sent something; what is wrong with each that has not, after timeout_s
        (default: the options' connect_timeout_s), naming the device, what was tried and what happened."""
        timeout_s = self.options.connect_timeout_s if timeout_s is None else timeout_s
        deadline = time.monotonic() + timeout_s
        while True:
            silent = {name: r.stats() for name, r in self.runners.items() if r.stats().last_receive_ns is None}
            if not silent or time.monotonic() >= deadline:
                break
            failures = self.start_failures()
            if failures:  # no wait makes it start: say it at once
                return failures
            time.sleep(0.02)
        problems = []
        for name, s in silent.items():
            device, plugin = self.devices[name], self.rig.devices[name].plugin
            tried = f"tried {device.endpoint()}, " if device.endpoint() else ""
            what = ("no packets" if s.connects else f"connect failed: {s.last_error}" if s.last_error else
                    f"still connecting: its connect() had not returned after {timeout_s:g} s (a busy machine? "
                    "raise --connect-timeout)")
            problems.append(f"device {name!r} ({plugin}) sent nothing within {timeout_s:g} s: {tried}{what}")
        return problems

    def start_failures(self) -> list[str]:
        """One line per reason that devices cannot start at all (a port taken, a folder not writable), or []
        while none has failed so: no wait makes such a device start, so the session ends at once."""
        from teleprev.devices.runner import cannot_start_lines

        lines = cannot_start_lines({name: r.stats() for name, r in self.runners.items()},
                                   {name: entry.plugin for name, entry in self.rig.devices.items()})
        self.cannot_start = self.cannot_start or bool(lines)
        return lines

    def device_rows(self) -> list[DeviceRow]:
        rows = []
        for name, runner in self.runners.items():
            s = runner.stats()
            urls = self.devices[name].operator_urls() if s.last_receive_ns is None else []
            hint = f"XR page: {urls[0]}" if urls else ""
            rows.append(DeviceRow(name, self.devices[name].kind, s.state, s.rate_hz, s.nominal_hz, s.latency_ms,
                                  self._loop_dropped(name), s.sink_errors, s.errors, s.lost_input, hint))
        return rows

    def _loop_dropped(self, name: str) -> int:
        """Samples of this device the session loop's queue had no room for."""
        prefix = f"/{self.devices[name].kind}/{name}/"
        return sum(n for topic, n in self.loop.stats.dropped.items() if topic.startswith(prefix))

    def device_counts(self) -> dict[str, dict[str, int]]:
        """Per device, what it delivered and every count of what it lost or skipped (for the file's metadata)."""
        out = {}
        for name, runner in self.runners.items():
            s = runner.stats()
            out[name] = {"received": s.received, **s.skipped, "lost_input": s.lost_input,
                         "loop_dropped": self._loop_dropped(name), "sink_errors": s.sink_errors,
                         "failures": self.loop.stats.device_failures.get(name, 0)}
        return out
