"""`teleprev replay` of a bimanual session or dataset: one Player per side, each as a single-arm replay of that
side (its commands, or its left_/right_ columns of a dataset's action; its own guards, limits, generator
and simulated robot), played at one speed from one recorded instant, starting together once both sides are at rest on
their first commands. A sequence that would bring the two robots into contact (every link of one against
every link of the other at their mounts, as the live cross-side guard checks) is refused before anything
moves. A side that stops (a fault, a robot that went away) stops the other: one side may be
holding what the other needs, as in a live bimanual session.

Not yet for two sides: --to arm (the paced actuator processes per side), the terminal preview of the robots
(a line per side instead) and --foxglove.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.live import Live
from rich.text import Text

from teleprev.assembly import build_pipeline, motion_limits
from teleprev.bimanual import build_guard, side_calibration
from teleprev.clock import SessionClock
from teleprev.errors import ConfigError, DeviceError
from teleprev.export.actions import is_dataset
from teleprev.live.replay.player import (
    ROUNDING,
    Player,
    StartTogether,
    load_dataset_playback,
    load_playback,
    safe_speed,
    smooth,
    validate,
)
from teleprev.preview.keys import KeyReader
from teleprev.rig import Rig, side_rig
from teleprev.sides import SIDES


@dataclass
class SidePlayer:
    side: str
    player: Player
    runners: list
    tap: object  # state_tap.StateTap: the latest state this side's actuators report


@dataclass
class BimanualReplay:
    sides: list[SidePlayer]
    message: str  # why the speed is lower than asked ("" when it is not)
    recording: object | None  # a ReplayRecording of both sides, or None

    @property
    def players(self) -> list[Player]:
        return [s.player for s in self.sides]

    def stop(self) -> None:
        for p in self.players:
            p.stop()


def build_bimanual_replay(session: Path, episode, speed: float, to: str, rig: Rig, rig_given: bool,
                          smoothed: bool = False, out: Path | None = None) -> BimanualReplay:
    """Both sides' players of `rig` (bimanual), what they drive and the recording; `rig_given`: the rig came
    from --rig (its calibration applies) rather than from the session."""
    from teleprev.devices.registry import load_plugin
    from teleprev.devices.runner import DeviceRunner
    from teleprev.live.replay.replay_recording import ReplayRecording
    from teleprev.live.replay.state_tap import StateTap

    dataset = is_dataset(session)
    if to == "arm":  # (a replay to the arms writes through their paced actuator processes: not yet per side)
        raise ConfigError("replay --to arm is not built for a bimanual rig yet: --to sim or preview",
                          str(rig.path or session))
    if out is not None and to == "preview":
        raise ConfigError("--out records what the robots are sent: add --to sim")
    if to == "sim" and not dataset and not smoothed:
        # Played exactly, a side's hand measured up to 1.09x its acceleration limit around the start of play in
        # 2 of 4 runs (the recorded commands within it); the smoothed replay keeps every limit.
        raise ConfigError("replaying a bimanual session's commands exactly is not built yet (a hand can pass its "
                          "acceleration limit as play starts): add --smooth", str(session))
    built = {}
    for side in SIDES:
        srig = side_rig(rig, side)
        pipeline = build_pipeline(srig, calibration=side_calibration(rig, side) if rig_given else None)
        loaded = (load_dataset_playback(session, episode, motion_limits(srig), side) if dataset
                  else load_playback(session, episode, side))
        playback = validate(loaded, pipeline.arm_guard, pipeline.effector.guard)
        if smoothed:
            if pipeline.motion is None:
                raise ConfigError("--smooth needs the rig's motion limits, and this side has none",
                                  f"{rig.path or session} [sides.{side}]")
            playback = smooth(playback, pipeline.motion, pipeline.effector.guard, speed)
        built[side] = (srig, pipeline, playback)
    effective = speed if smoothed else min(
        safe_speed(p, pl.arm_guard.speed, pl.effector.guard.speed, speed, pl.motion) for _, pl, p in built.values())
    if to != "preview" and not smoothed and effective < min(speed, 1.0) - ROUNDING:
        what = "the dataset's actions" if dataset else "the recorded commands"
        raise ConfigError(f"{what} exceed a side's acceleration or jerk limit at {min(speed, 1.0):g}x, and slower "
                          "than 1x a servo arm would stop between them: add --smooth to re-command them through "
                          "the jerk-limited generator", str(session))
    contact = first_contact(build_guard(rig, {side: pl for side, (_, pl, _) in built.items()}),
                            {side: p for side, (_, _, p) in built.items()})
    if contact:
        raise ConfigError(f"not replaying: {contact}", str(session))
    message = "" if effective >= speed else (f"playing at {effective:.2f}x: {speed:g}x would exceed a joint's "
                                             "speed, acceleration or jerk limit")
    clock = SessionClock()
    recording = ReplayRecording(out, rig, session, episode, clock) if out is not None else None
    together = StartTogether(len(SIDES))
    t0 = min(int(p.t_ns[0]) for _, _, p in built.values())  # one recorded instant for both sides
    sides = []
    for side, (srig, pipeline, playback) in built.items():
        actuators, runners, tap = {}, [], StateTap()
        if to != "preview":
            context = srig.device_context(clock)
            names = rig.sides[side].devices  # the sim stands in for this side's arm and hand, under their names
            devices = {kind: load_plugin(f"sim.{kind}") for kind in ("arm", "hand")}
            devices = {kind: cls(names[kind], cls.Settings(), context) for kind, cls in devices.items()}
            actuators = recording.actuators(devices, side) if recording else devices
            sink = recording.sink(tap.sink) if recording else tap.sink
            runners = [DeviceRunner(dev, sink, clock) for dev in devices.values()]
        player = Player(playback, effective, actuators, pipeline.arm_guard, pipeline.effector.guard,
                        _measured(tap, playback), srig.pipeline.engage_speed_frac, motion=pipeline.motion,
                        clock=clock, together=together if actuators else None, t0_ns=t0)
        sides.append(SidePlayer(side, player, runners, tap))
    replay = BimanualReplay(sides, message, recording)
    if recording is not None:
        recording.playing = lambda: any(p.state.mode == "playing" for p in replay.players)
        from teleprev.live.replay.camera_carry import CameraCarry, dataset_depth_frames, session_frames

        # the source's camera frames as the instants are played (both sides play them together; the left's clock)
        frames = dataset_depth_frames(session, episode) if dataset else session_frames(session)
        recording.carry = CameraCarry(frames, recording, replay.players[0]) if frames is not None else None
    return replay


def first_contact(guard, playbacks: dict) -> str:
    """Where the two sides' played commands first touch, each side at its last command at every step of
    either (its values held between its own steps), in words; "" when they never do."""
    left, right = (playbacks[s] for s in SIDES)
    t = np.union1d(left.t_ns, right.t_ns)
    t0 = int(t[0])
    at = {s: np.clip(np.searchsorted(playbacks[s].t_ns, t, side="right") - 1, 0, None) for s in SIDES}
    last = None
    for k in range(len(t)):
        pair = (int(at["left"][k]), int(at["right"][k]))
        if pair == last:
            continue
        last = pair
        q = {s: guard.joints[s].full(playbacks[s].arm[i], playbacks[s].effector[i]) for s, i in zip(SIDES, pair)}
        found = guard.checker.contacts(q["left"], q["right"])
        if found:
            return (f"the two sides' commands touch {(int(t[k]) - t0) / 1e9:.3f} s in ({found[0][0]} of the left, "
                    f"{found[0][1]} of the right)")
    return ""


def _measured(tap, playback):
    """The robot's (arm, effector) joints as this side's actuators last reported them, or None yet."""
    def measured():
        arm = next((s for t, s in tap.latest.items() if t.startswith("/arm/")), None)
        hand = next((s for t, s in tap.latest.items() if t.startswith("/hand/")), None)
        if arm is None or hand is None:
            return None
        return (np.array([arm.positions[arm.names.index(n)] for n in playback.arm_names]),
                np.array([hand.positions[hand.names.index(n)] for n in playback.effector_names]))
    return measured


def play_bimanual(session: Path, episode, speed: float, to: str, rig: Rig, rig_given: bool, engage_after,
                  console: Console, show: bool, smoothed: bool, out: Path | None, signals) -> None:
    with signals.deferred():
        replay = build_bimanual_replay(session, episode, speed, to, rig, rig_given, smoothed, out)
    threads = [threading.Thread(target=p.run, daemon=True, name=f"replay-{s.side}") for s, p in
               zip(replay.sides, replay.players)]
    runners = [r for s in replay.sides for r in s.runners]
    try:
        signals.check()
        for r in runners:
            r.start()
        if replay.recording is not None and replay.recording.carry is not None:
            replay.recording.carry.start()
        for t in threads:
            t.start()
        _show(session, replay, threads, to, engage_after, console, show)
    finally:
        with signals.finishing():
            _finish(replay, threads, runners, console, out)
    for s in replay.sides:
        sent = sum(1 for phase, _, _ in s.player.state.sent if phase == "playing")
        console.print(f"{s.side}: played {len(s.player.p.t_ns)} steps at {s.player.speed:.2f}x to {to}; {sent} "
                      "commands sent")
    if replay.message:
        console.print(replay.message)
    stopped = [f"{s.side}: {s.player.state.message}" for s in replay.sides if s.player.state.message]
    if stopped:
        raise DeviceError(f"playback stopped: {'; '.join(stopped)}")
    if replay.recording is not None:
        replay.recording.check()


def _show(session: Path, replay: BimanualReplay, threads, to: str, engage_after, console: Console,
          show: bool) -> None:
    """Engage both sides (at once for the screen, after `engage_after` or on space otherwise) and watch:
    a side that stopped with a message stops the other."""
    def engage():
        for p in replay.players:
            p.engage()

    if to == "preview":
        engage()
    elif engage_after is not None:
        timer = threading.Timer(engage_after, engage)
        timer.daemon = True
        timer.start()

    def frame() -> Text:
        lines = [f"{session.name}  REPLAY of both sides to {to}"]
        for s in replay.sides:
            p, k = s.player, s.player.state.index
            lines.append(f"{s.side:>5}: {p.state.mode:8} step {k + 1}/{len(p.p.t_ns)}  "
                         f"({p.p.source}; {p.p.adjusted} steps adjusted by the guards)")
        return Text("\n".join(lines + ([replay.message] if replay.message else [])))

    def key(k: str) -> None:
        if k == " ":
            engage()
        elif k in ("q", "\x1b"):
            replay.stop()

    with KeyReader(key):
        live = Live(console=console, auto_refresh=False) if show else None
        with live if live is not None else _Nothing():
            while any(t.is_alive() for t in threads):
                if any(p.state.message for p in replay.players):
                    replay.stop()  # one side faulted: both stop
                if live is not None:
                    live.update(frame(), refresh=True)
                time.sleep(0.02)
            if live is not None:
                live.update(frame(), refresh=True)


class _Nothing:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def _finish(replay: BimanualReplay, threads, runners, console: Console, out) -> None:
    replay.stop()
    for t in threads:
        if t.is_alive():
            t.join(2.0)
    for r in runners:
        r.stop()
    recording = replay.recording
    if recording is not None:
        if recording.carry is not None:
            recording.carry.stop()
        recording.close()
        if not recording.error:
            console.print(f"replay recorded in {out}", highlight=False, soft_wrap=True)
