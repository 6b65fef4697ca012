"""`teleprev replay` run live: the player on its own thread, the robot's state read back, the screen."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
from rich.console import Console, Group
from rich.live import Live
from rich.text import Text

from teleprev.assembly import build_pipeline, rig_calibration
from teleprev.clock import SessionClock
from teleprev.errors import ConfigError, DeviceError
from teleprev.export.actions import is_dataset
from teleprev.live.no_signals import NoSignals
from teleprev.live.record.run import ROBOT_BOUNDS
from teleprev.live.replay.player import (
    ROUNDING,
    Player,
    load_dataset_playback,
    load_playback,
    safe_speed,
    smooth,
    validate,
)
from teleprev.live.replay.replay_recording import ReplayRecording
from teleprev.live.replay.state_tap import StateTap
from teleprev.preview.keys import KeyReader
from teleprev.preview.robot_view import Layer, RobotView
from teleprev.rig import load_recorded_rig, load_rig
from teleprev.robot.model import load_robot
from teleprev.session.reader import SessionReader


def _recorded_rig(session: Path):
    with SessionReader(session) as reader:
        rig = load_recorded_rig(reader.metadata, session)
    if rig is None:
        raise ConfigError("the session does not carry its rig; pass --rig", str(session))
    return rig


def build_player(session: Path, episode, speed: float, to: str, rig_path=None, smoothed: bool = False, out=None):
    """The player and what it drives; returns (player, runners, tap, rig, message, recording). `session`: a
    session file or a LeRobot dataset folder (its `action` column); `smoothed`: play the sequence as the
    pipeline's generator re-commands it (teleprev.live.replay.player.smooth); `out`: record the replay there
    (teleprev.live.replay.replay_recording)."""
    from teleprev.devices.registry import load_plugin
    from teleprev.devices.runner import DeviceRunner

    dataset = is_dataset(session)
    if to == "arm" and not rig_path:  # the hardware to drive comes from the user, never from a file's contents
        raise ConfigError("--to arm needs --rig RIG: the devices a session names are not opened from its metadata",
                          str(session))
    if dataset and not rig_path:
        raise ConfigError("a dataset does not carry its rig: pass --config RIG (the robot that plays its actions)",
                          str(session))
    if out is not None and to == "preview":
        raise ConfigError("--out records what the robot is sent: add --to sim or --to arm")
    rig = load_rig(rig_path) if rig_path else _recorded_rig(session)
    pipeline = build_pipeline(rig, calibration=rig_calibration(rig) if rig_path else None)
    eff_guard = pipeline.effector.guard
    if dataset:
        from teleprev.assembly import motion_limits

        loaded = load_dataset_playback(session, episode, motion_limits(rig))
    else:
        loaded = load_playback(session, episode)
    playback = validate(loaded, pipeline.arm_guard, eff_guard)
    if smoothed:
        if pipeline.motion is None:
            raise ConfigError("--smooth needs the rig's motion limits, and this rig has none", str(rig.path or session))
        playback, effective = smooth(playback, pipeline.motion, eff_guard, speed), speed  # generated for this speed
    else:
        effective = safe_speed(playback, pipeline.arm_guard.speed, eff_guard.speed, speed, pipeline.motion)
        if to != "preview" and pipeline.motion is not None and effective < min(speed, 1.0) - ROUNDING:
            # Slower than recorded, the recorded commands' pauses stretch past what a servo arm rides through.
            # The refusal alone: the speed that would pass is no option (it is slower than 1x).
            what = "the dataset's actions" if dataset else "the recorded commands"
            raise ConfigError(f"{what} exceed the robot's acceleration or jerk limit at {min(speed, 1.0):g}x, and "
                              "slower than 1x a servo arm would stop between them: add --smooth to re-command "
                              "them through the jerk-limited generator", str(session))
    message = "" if effective >= speed else (f"playing at {effective:.2f}x: {speed:g}x would exceed a joint's speed, "
                                             "acceleration or jerk limit")
    clock = SessionClock()
    actuators, runners, tap, recording, hosts = {}, [], StateTap(), None, {}
    if to != "preview":
        context = rig.device_context(clock)
        if to == "sim":
            entries = {"arm": load_plugin("sim.arm"), "hand": load_plugin("sim.hand")}
            devices = {kind: cls(f"replay_{kind}", cls.Settings(), context) for kind, cls in entries.items()}
        else:
            rig.require("arm", "hand")
            devices = {
                kind: rig.of_kind(kind)[0].cls(rig.of_kind(kind)[0].name, rig.of_kind(kind)[0].settings, context)
                for kind in ("arm", "hand")
            }
        sink = tap.sink  # (the recording's, once it exists: _Sink)
        hosts = _hosts(devices, _Sink(sink), clock, playback)
        try:
            recording = ReplayRecording(out, rig, session, episode, clock) if out is not None else None
        except BaseException:
            for host in hosts.values():
                host.stop()
            raise
        if recording is not None:
            sink = recording.sink(tap.sink)
            for host in hosts.values():
                host.sink.to = sink
                host.on_wire = recording.wired
        actuators = {kind: hosts.get(kind) or dev for kind, dev in devices.items()}
        actuators = recording.actuators(actuators) if recording else actuators
        runners = [hosts.get(kind) or DeviceRunner(dev, sink, clock) for kind, dev in devices.items()]
        if context.physics is not None:  # the physics world the sim devices started, closed after them
            runners.append(_WorldRun(context.physics))

    def measured():
        arm = next((s for t, s in tap.latest.items() if t.startswith("/arm/")), None)
        hand = next((s for t, s in tap.latest.items() if t.startswith("/hand/")), None)
        if arm is None or hand is None:
            return None  # not connected yet: the ramp waits

        def pick(s, names):
            return np.array([s.positions[s.names.index(n)] for n in names])
        return pick(arm, playback.arm_names), pick(hand, playback.effector_names)

    player = Player(
        playback,
        effective,
        actuators,
        pipeline.arm_guard,
        eff_guard,
        measured,
        rig.pipeline.engage_speed_frac,
        motion=pipeline.motion,
        clock=clock,
        lead_s=HANDOVER_LEAD_S if hosts else 0.0,
    )
    if recording is not None:
        recording.playing = lambda: player.state.mode == "playing"
        # the source's camera frames go in beside the commands, as their instants are played
        from teleprev.live.replay.camera_carry import CameraCarry, dataset_depth_frames, session_frames

        frames = dataset_depth_frames(session, episode) if dataset else session_frames(session)
        recording.carry = CameraCarry(frames, recording, player) if frames is not None else None
    return player, runners, tap, rig, message, recording


class _WorldRun:
    """The physics world of a replay to a physics rig's sim devices, among the replay's runners: started by the
    devices' first use, closed when the runners stop (not only at the process's exit: a replay run inside a
    longer-lived process would leave the world stepping)."""

    def __init__(self, physics):
        self.physics = physics

    def start(self) -> None:
        pass

    def stop(self) -> None:
        self.physics.close()


HANDOVER_LEAD_S = 0.05  # how far ahead of its stamp the player hands a command to its actuator's process


class _Sink:
    """A sink whose destination is set after it is handed out (an actuator's process is forked before the
    replay's recording starts its thread)."""

    def __init__(self, to):
        self.to = to

    def __call__(self, sample, receive_ns: int) -> None:
        self.to(sample, receive_ns)


def _hosts(devices: dict, sink: _Sink, clock: SessionClock, playback) -> dict:
    """The real actuators whose plugins allow it (`own_process`), each in a paced process of its own, forked
    now (before any thread of the replay's starts), where its commands go on the wire, as in a recording
    (teleprev/live/core/actuator_host.py); the player hands them their commands."""
    from teleprev.live.core.actuator_host import ActuatorHost

    names = {"arm": playback.arm_names, "hand": playback.effector_names}
    hosts = {kind: ActuatorHost(kind, dev, sink, clock, names[kind], commands_from_session=True)
             for kind, dev in devices.items() if dev.own_process}
    for host in hosts.values():
        host.fork()
    return hosts


def _start_view(port: int | None, session: Path, player: Player, console: Console):
    """The live Foxglove view of a replay: the session's topics played at the player's speed from when it
    starts playing. Returns (view, stop event, thread) or None."""
    if port is None:
        return None
    from teleprev.live.view.foxglove_view import FoxgloveView, file_channels, stream_session

    view = FoxgloveView(port, file_channels(session))
    stop = threading.Event()
    p = player.p
    lo, hi = int(p.t_ns[0]) - 1_000_000_000, int(p.t_ns[-1]) + 1_000_000_000  # the window around the played steps
    thread = threading.Thread(
        target=stream_session,
        name="foxglove-replay",
        daemon=True,
        args=(view, session, lo, hi, player.speed, lambda: player.state.mode in ("playing", "done"), stop),
    )
    thread.start()
    console.print(f"Foxglove: open connection {view.url}", highlight=False)
    return view, stop, thread


def play(session: Path, episode, speed: float, to: str, rig_path, engage_after, console: Console, view: str, show: bool,
         smoothed: bool = False, foxglove: int | None = None, out: Path | None = None, signals=None) -> None:
    """`signals` (teleprev.cli.signals.StopSignals): a stop signal while the player and its recording are
    built is raised once they are whole, and none cuts the robot's stop and the recording's close short."""
    signals = signals or NoSignals()
    rig = load_rig(rig_path) if rig_path else None if is_dataset(session) else _recorded_rig(session)
    if rig is not None and rig.bimanual:
        from teleprev.live.replay.bimanual_playback import play_bimanual

        if foxglove is not None:
            raise ConfigError("--foxglove is not built for a bimanual replay yet", str(rig.path or session))
        play_bimanual(session, episode, speed, to, rig, bool(rig_path), engage_after, console, show, smoothed, out,
                      signals)
        return
    with signals.deferred():
        built = build_player(session, episode, speed, to, rig_path, smoothed, out)
    player, runners, tap, rig, message, recording = built
    live_view, thread = None, threading.Thread(target=player.run, daemon=True)
    try:
        signals.check()
        live_view = _start_view(foxglove, session, player, console)
        for r in runners:
            r.start()
        if recording is not None and recording.carry is not None:
            recording.carry.start()
        thread.start()
        _show(session, player, thread, to, rig, engage_after, console, view, show, message)
    finally:
        with signals.finishing():
            _finish(player, thread, runners, live_view, recording, console, out)
    sent = sum(1 for phase, _, _ in player.state.sent if phase == "playing")
    p = player.p
    console.print(f"played {len(p.t_ns)} steps at {player.speed:.2f}x to {to}; {sent} commands sent"
                  + (f"; {message}" if message else ""))
    if player.state.message:  # the robot refused a command or went away: playback stopped there
        raise DeviceError(f"playback stopped: {player.state.message}")
    if recording is not None:
        recording.check()


def _show(session: Path, player: Player, thread: threading.Thread, to: str, rig, engage_after, console: Console,
          view: str, show: bool, message: str) -> None:
    """Engage (at once for the screen, after `engage_after` or on space otherwise) and show the replay until
    the player is done or stopped (q, Esc)."""
    if to == "preview":
        player.engage()  # nothing moves: play at once
    elif engage_after is not None:
        timer = threading.Timer(engage_after, player.engage)
        timer.daemon = True  # a replay stopped before it fires must not wait for it to exit
        timer.start()
    robot = load_robot(rig.rig.robot)
    robot_view = RobotView(robot, view, ROBOT_BOUNDS.get(view))
    p = player.p

    def frame():
        k = player.state.index
        joints = dict(zip(p.arm_names, p.arm[k]))
        if p.effector_names[0] in robot.joint_index:
            joints.update(zip(p.effector_names, p.effector[k]))
        banner = {
            "preview": ("REPLAY: PREVIEW (the robot holds; space to engage)", "bold black on yellow"),
            "ramp": ("REPLAY: moving to the start", "bold white on red"),
            "playing": ("REPLAY: PLAYING", "bold white on red"),
            "done": ("REPLAY: done", "bold"),
        }[player.state.mode]
        info = Text(
            f"{session.name}  step {k + 1}/{len(p.t_ns)}  {(p.t_ns[k] - p.t_ns[0]) / 1e9:6.2f} s  speed "
            f"{player.speed:.2f}x  "
            f"({p.source}; {p.adjusted} steps adjusted by the guards)"
        )
        size = console.size
        picture = robot_view.render(
            [Layer(robot.vector(joints), "cyan")], max(size.width - 2, 20), max(size.height - 5, 6)
        )
        return Group(Text(banner[0], style=banner[1], justify="center"), info, Text(message, style="yellow"), picture)

    with KeyReader(lambda key: player.engage() if key == " " else player.stop() if key in ("q", "\x1b") else None):
        if show:
            with Live(console=console, auto_refresh=False) as live:
                while thread.is_alive():
                    live.update(frame(), refresh=True)
                    time.sleep(0.04)
                live.update(frame(), refresh=True)
        else:
            thread.join()


def _finish(player: Player, thread: threading.Thread, runners, live_view, recording, console: Console, out) -> None:
    """Stop the player and the robot's devices, then close the recording."""
    player.stop()
    if thread.is_alive():
        thread.join(2.0)
    for r in runners:
        r.stop()
    if recording is not None and recording.carry is not None:
        recording.carry.stop()  # the frames of the instants played are in, before the file closes
    if live_view is not None:
        live_view[1].set()
        live_view[2].join(2.0)
        live_view[0].close()
    if recording is not None:
        recording.close()  # after the robot has its last command: a failed recording never stops it early
        if not recording.error:
            console.print(f"replay recorded in {out}", highlight=False, soft_wrap=True)
