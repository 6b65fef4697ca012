"""Driving a LiveSession: from the keyboard with the terminal preview, from a script (unattended), or
through a plan of timed episodes (run_timed: the keys still work, and so does an unattended run).

The preview redraws on the main thread while the session loop runs on its own; the redraw rate is
measured and kept in `PreviewStats` so the pipeline benchmark can report it. The commands never wait for
the preview (the paced sender has a process of its own), and the preview gives up frame rate before the
session loop falls behind: `PreviewPacer` keeps drawing to at most half a core and waits longer
while the loop has a backlog.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass, field

from rich.console import Console
from rich.live import Live

from teleprev.live.core.controls import UNATTENDED, Control, Engage, StartEpisode, StopEpisode, ToPreview
from teleprev.live.record.cues import Cues
from teleprev.live.record.operator_actions import handle_key
from teleprev.live.record.schedule import EpisodeTimes, Period, Schedule
from teleprev.live.record.session import LiveSession
from teleprev.preview.dashboard import CAMERA_KEY, Dashboard, RobotSide
from teleprev.preview.keys import KeyReader
from teleprev.preview.robot_view import RobotView
from teleprev.robot.model import load_robot
from teleprev.session.summary import PREVIEW_ONLY, device_lost

# Fixed view bounds (metres) that hold an xArm's workspace, so the picture does not rescale.
ROBOT_BOUNDS = {"front": (-0.75, 0.75, -0.1, 1.0), "side": (-0.35, 0.95, -0.1, 1.0), "top": (-0.75, 0.75, -0.35, 0.95)}


@dataclass
class PreviewStats:
    frames: int = 0
    started: float = field(default_factory=time.perf_counter)
    render_s: list[float] = field(default_factory=list)

    def fps(self) -> float:
        elapsed = time.perf_counter() - self.started
        return self.frames / elapsed if elapsed > 0 else 0.0


class PreviewPacer:
    """When to draw the next frame: at `fps` at most, drawing at most RENDER_SHARE of the time, and slower
    (doubling the interval, up to MAX_INTERVAL_S) while the session loop has more than BACKLOG waiting;
    back to `fps` as it catches up."""

    RENDER_SHARE = 0.5
    BACKLOG = 32
    MAX_INTERVAL_S = 1.0

    def __init__(self, fps: float, backlog=lambda: 0):
        self.base = 1.0 / fps
        self.interval = self.base
        self.backlog = backlog

    def wait_after(self, render_s: float) -> float:
        """Seconds to wait after a frame that took render_s to draw."""
        if self.backlog() > self.BACKLOG:
            self.interval = min(self.MAX_INTERVAL_S, 2.0 * self.interval)
        else:
            self.interval = max(self.base, 0.5 * self.interval)
        return max(0.0, max(self.interval, render_s / self.RENDER_SHARE) - render_s)


def make_dashboard(recording: LiveSession, view: str) -> Dashboard:
    robots = getattr(recording, "robots", None)  # a bimanual session: a robot per side
    if robots is not None:
        return Dashboard.bimanual(tuple(
            RobotSide(side, RobotView(robots[side], view, ROBOT_BOUNDS.get(view)),
                      RobotView(load_robot(s.effector.hand_urdf), "side") if s.effector.hand_urdf else None,
                      recording.pipelines[side].arm_names, recording.pipelines[side].effector_names, robots[side])
            for side, s in recording.rig.sides.items()))
    hand_view = None
    if recording.rig.effector.hand_urdf:
        hand_view = RobotView(load_robot(recording.rig.effector.hand_urdf), "side")
    return Dashboard(
        RobotView(recording.robot, view, ROBOT_BOUNDS.get(view)), hand_view,
        recording.pipeline.arm_names, recording.pipeline.effector_names, recording.robot,
    )


def with_camera_key(dashboard: Dashboard | None, then):
    """A key handler: the camera key switches what the dashboard's camera panel shows (nothing the recording
    does), every other key goes on to `then`."""
    def press(key: str):
        if key == CAMERA_KEY[0] and dashboard is not None:
            dashboard.next_camera_mode()
            return None
        return then(key)
    return press


def _frame(dashboard: Dashboard, recording: LiveSession, console: Console, countdown=None):
    size = console.size
    snap = recording.loop.snapshot
    return dashboard.render(snap, recording.device_rows(), size.width, size.height, recording.clock.now_ns(),
                            camera=snap.camera, countdown=countdown, depth=snap.depth)


def run_interactive(recording: LiveSession, console: Console, view: str, fps: float, show: bool = True) -> PreviewStats:
    stats = PreviewStats()
    quit_flag: list = []
    dashboard = make_dashboard(recording, view) if show else None
    press = with_camera_key(dashboard, lambda k: handle_key(recording, k, quit_flag))
    with KeyReader(press), recording.pressing(press):
        if dashboard is None:
            while not quit_flag and not recording.failure and not recording.start_failures():  # nobody watches
                time.sleep(0.1)
            return stats
        pacer = PreviewPacer(fps, recording.loop.backlog)
        with Live(console=console, auto_refresh=False, screen=console.is_terminal, transient=False) as live:
            while not quit_flag and not recording.start_failures():  # (the caller says why, in one line)
                t = time.perf_counter()
                live.update(_frame(dashboard, recording, console), refresh=True)
                stats.frames += 1
                stats.render_s.append(time.perf_counter() - t)
                time.sleep(pacer.wait_after(time.perf_counter() - t))
    return stats


ENGAGE_RETRY_S = 0.25


class Engager:
    """An unattended engage: execute asked for (reason "script", which the loop refuses after a fault
    until the operator engages with a key), and asked again every ENGAGE_RETRY_S while the pipeline
    refuses (e.g. nothing previewed yet), until one is accepted or the window closes. So an episode
    engages once. Times are seconds on any clock the caller keeps to."""

    def __init__(self, loop):
        self.loop = loop
        self.until: float | None = None
        self._asked = 0.0
        self._before = 0

    def open(self, now: float, until: float) -> None:
        self._before = self.loop.stats.engages
        self.loop.engage(unattended=True)
        self.until, self._asked = until, now

    def close(self) -> None:
        self.until = None

    def poll(self, now: float) -> None:
        if self.until is None:
            return
        if self.loop.stats.engages > self._before or now >= self.until:
            self.until = None  # engaged (this episode asks no more), or its window is over
        elif now - self._asked >= ENGAGE_RETRY_S:
            self.loop.engage(unattended=True)
            self._asked = now

    def next_s(self) -> float | None:
        """When poll has something to do next (None: nothing)."""
        return None if self.until is None else min(self._asked + ENGAGE_RETRY_S, self.until)


def run_script(recording: LiveSession, duration: float, episodes: int, engage_after: float | None,
               console: Console | None = None, view: str = "side", fps: float = 25.0) -> PreviewStats:
    """Unattended: `episodes` episodes filling `duration` seconds, each engaging after `engage_after` s (asked
    again every ENGAGE_RETRY_S while the pipeline refuses, until the episode's end). An episode engages once:
    after a fault has sent it back to preview it stays there (the loop refuses an unattended engage after
    a fault until the operator engages with a key)."""
    stats = PreviewStats()
    loop = recording.loop
    dashboard = make_dashboard(recording, view) if console is not None else None
    live = Live(console=console, auto_refresh=False, transient=False) if dashboard is not None else None
    length = duration / max(episodes, 1)
    pacer = PreviewPacer(fps, loop.backlog)
    start = time.perf_counter()
    plan: list[tuple[float, Control]] = []  # (time offset, control)
    engager = Engager(loop)
    for k in range(max(episodes, 1)):
        t0 = k * length
        plan.append((t0, StartEpisode(recording.task)))
        if engage_after is not None and engage_after < length:
            plan.append((t0 + engage_after, Engage(UNATTENDED, unattended=True)))
        plan.append((t0 + length - 1e-3, ToPreview(UNATTENDED)))
        plan.append((t0 + length - 1e-3, StopEpisode()))
    if live:
        live.start()
    try:
        while True:
            elapsed = time.perf_counter() - start
            while plan and plan[0][0] <= elapsed:
                _, control = plan.pop(0)
                if isinstance(control, Engage):
                    engager.open(elapsed, plan[0][0] if plan else elapsed)
                    continue
                if isinstance(control, ToPreview):
                    engager.close()
                loop.send(control)
            engager.poll(elapsed)
            if (elapsed >= duration and not plan) or recording.failure:
                break
            if live:
                t = time.perf_counter()
                live.update(_frame(dashboard, recording, console), refresh=True)
                stats.frames += 1
                stats.render_s.append(time.perf_counter() - t)
                time.sleep(min(pacer.wait_after(time.perf_counter() - t), ENGAGE_RETRY_S))
            else:
                time.sleep(0.01)
    finally:
        if live:
            live.stop()
    return stats


class TimedKeys:
    """The operator's keys during timed episodes, each stamped on the session clock as it arrives (an
    episode that `n` ends stops then, not when the runner gets round to it)."""

    def __init__(self, clock):
        self.clock = clock
        self._keys: deque[tuple[int, str]] = deque()
        self._arrived = threading.Event()

    def press(self, key: str) -> int:
        """For any thread (the terminal's key reader, a test); returns the key's stamp."""
        t = self.clock.now_ns()
        self._keys.append((t, key))
        self._arrived.set()
        return t

    def wait(self, timeout_s: float) -> None:
        """Until a key arrives, or at most timeout_s."""
        self._arrived.wait(max(0.0, timeout_s))

    def take(self) -> list[tuple[int, str]]:
        """(stamp, key) of the keys pressed since the last take, in order."""
        self._arrived.clear()
        got = []
        while self._keys:
            got.append(self._keys.popleft())
        return got


RESTING = "the robot rests between timed episodes (n: start the next one now)"  # why execute is refused
SCHEDULE = "schedule"  # who holds execute back between timed episodes (and the reason the switch records)


class TimedRun:
    """run_timed's state: the schedule, the current period's engage and preview instants, the keys."""

    def __init__(self, recording: LiveSession, plan: EpisodeTimes, cues: Cues, keys: TimedKeys):
        self.recording, self.plan, self.cues, self.keys = recording, plan, cues, keys
        self.loop = recording.loop
        self.lead_ns = round(recording.preview_lead_s * 1e9)
        self.engager = Engager(self.loop)
        self.schedule = Schedule(plan, recording.clock.now_ns())
        self.quit = False
        self.unattended = plan.engage_after_s is not None  # False after an e-stop: the operator engages
        self.engage_ns: int | None = None  # when the current episode asks to engage (None: not, or asked)
        self.rest_ns: int | None = None  # when it switches to preview, so that the robot rests by its end
        self.begin(self.schedule.current)

    @property
    def period(self) -> Period | None:
        return self.schedule.current

    def begin(self, period: Period | None) -> None:
        """Start a period at its planned start (the previous one ended there)."""
        if period is None:
            self.cues.cue("done")
            return
        if period.kind == "reset":
            self.cues.cue("reset")
            return
        self.loop.release(SCHEDULE)
        self.loop.start_episode(self.recording.task, at_ns=period.start_ns)
        self.cues.cue(f"episode {period.number + 1}")
        after = self.plan.engage_after_s
        self.rest_ns = period.end_ns - self.lead_ns
        engage_ns = period.start_ns + round(after * 1e9) if self.unattended else None
        self.engage_ns = engage_ns if engage_ns is not None and engage_ns < self.rest_ns else None

    def rest(self) -> None:
        """Back to preview and refuse execute until the next episode (the robot brakes to rest)."""
        self.engager.close()
        self.engage_ns = self.rest_ns = None
        self.loop.hold(SCHEDULE, RESTING, reason=SCHEDULE)

    def end(self, at_ns: int | None = None, discard: bool = False) -> None:
        """End the current period at its planned end or early at at_ns; the next one begins."""
        period = self.period
        at = period.end_ns if at_ns is None else at_ns
        if period.kind == "episode":
            self.rest()
            if discard:
                self.loop.discard_episode(at_ns=at)
            else:
                self.loop.stop_episode(at_ns=at)
            mark = None if discard else self.plan.mark(period.number)
            if mark is not None:
                self.loop.mark_outcome(mark)
        self.begin(self.schedule.advance(at_ns))

    def key(self, t_ns: int, key: str) -> None:
        period = self.period
        if key in ("n", "e") or (key == "s" and period.kind == "reset"):
            self.end(t_ns)
        elif key in ("d", "a"):
            if key == "a":
                self.schedule.redo()
            if period.kind == "episode":
                self.end(t_ns, discard=True)
            else:
                self.loop.discard_episode(at_ns=t_ns)  # the last episode (its reset goes on)
        elif key in ("q", "\x1b"):
            if period.kind == "episode":
                self.rest()
                self.loop.stop_episode(at_ns=t_ns)
            self.quit = True
        elif key != "s":  # (s during an episode: it is running already)
            if key == "x":  # an e-stop: no episode engages by itself any more
                self.unattended, self.engage_ns = False, None
                self.engager.close()
            handle_key(self.recording, key, [])

    def _catch_up(self, t_ns: int) -> None:
        """End every period that ended by t_ns, at its planned end."""
        while not self.done and t_ns >= self.period.end_ns:
            self.end()

    def step(self, now_ns: int) -> int:
        """Do what is due at now_ns; the next instant something will be (ns)."""
        for t, key in self.keys.take():  # each key in the period it was pressed in, however late seen
            self._catch_up(t)
            if not self.done:
                self.key(t, key)
        self._catch_up(now_ns)
        period = self.period
        if period is None or self.quit:
            return now_ns
        if self.engage_ns is not None and now_ns >= self.engage_ns:
            self.engager.open(now_ns / 1e9, self.rest_ns / 1e9)
            self.engage_ns = None
        if self.rest_ns is not None and now_ns >= self.rest_ns:
            self.rest()
        self.engager.poll(now_ns / 1e9)
        due = [period.end_ns] + [t for t in (self.engage_ns, self.rest_ns) if t is not None]
        retry = self.engager.next_s()
        if retry is not None:
            due.append(round(retry * 1e9))
        return min(due)

    @property
    def done(self) -> bool:
        return self.period is None or self.quit

    def countdown(self, now_ns: int) -> tuple[str, float] | None:
        period = self.period
        return None if period is None else (self.schedule.label, period.left_s(now_ns))


def run_timed(recording: LiveSession, plan: EpisodeTimes, console: Console | None = None, view: str = "side",
              fps: float = 25.0, cues: Cues | None = None, keys: TimedKeys | None = None) -> PreviewStats:
    """Timed episodes on a started LiveSession (opened with RecordOptions(episode_plan=plan), so that the
    file keeps the plan): `plan.episodes` episodes of `plan.episode_s` seconds with `plan.reset_s` seconds
    of reset between them, every boundary planned from the plan's start. Each episode engages
    `plan.engage_after_s` into it as run_script's do (once; never after a fault), switches back to
    preview `recording.preview_lead_s` before its end so that the robot rests by then, and stays in
    preview through the reset (execute is refused there). Cues (bell, spoken words) at each boundary.
    Keys (from the terminal, or pressed on `keys`): n ends the current period, d discards the running
    (or last) episode, a discards it and records it again, the others as in run_interactive. `console`:
    the terminal preview with a countdown (None: headless). Returns when the plan is done, q is pressed
    or the session fails."""
    if recording.options.episode_plan != plan:
        raise ValueError("run_timed: open the LiveSession with RecordOptions(episode_plan=plan), so that the "
                         "session keeps the plan it was recorded to")
    plan.check()
    stats = PreviewStats()
    clock = recording.clock
    keys = keys or TimedKeys(clock)
    cues = cues or Cues.for_terminal(console.file if console is not None else None)
    dashboard = make_dashboard(recording, view) if console is not None else None
    live = Live(console=console, auto_refresh=False, transient=False) if dashboard is not None else None
    pacer = PreviewPacer(fps, recording.loop.backlog)
    run = TimedRun(recording, plan, cues, keys)
    next_frame = 0.0
    press = with_camera_key(dashboard, keys.press)
    with KeyReader(press), recording.pressing(press):
        if live:
            live.start()
        try:
            while not run.done and not recording.failure:
                due_ns = run.step(clock.now_ns())
                if run.done:
                    break
                if live and time.perf_counter() >= next_frame:
                    t = time.perf_counter()
                    live.update(_frame(dashboard, recording, console, run.countdown(clock.now_ns())), refresh=True)
                    stats.frames += 1
                    stats.render_s.append(time.perf_counter() - t)
                    next_frame = time.perf_counter() + pacer.wait_after(time.perf_counter() - t)
                wait_s = (due_ns - clock.now_ns()) / 1e9
                if live:
                    wait_s = min(wait_s, next_frame - time.perf_counter())
                keys.wait(min(wait_s, 0.1))  # a key wakes the run at once
        finally:
            if live:
                live.stop()
            run.engager.close()
            recording.loop.release(SCHEDULE)
            cues.close()
    return stats


def print_summary(console: Console, recording: LiveSession, summary) -> None:
    from rich.table import Table

    table = Table(title=f"session {recording.options.out}", title_justify="left")
    table.add_column("stream")
    table.add_column("written", justify="right")
    table.add_column("dropped", justify="right")
    for topic, s in sorted(summary.streams.items()):
        table.add_row(topic, str(s.written), str(s.dropped))
    console.print(table)
    counts = recording.device_counts()
    lost = {name: device_lost(c) for name, c in counts.items()}
    detail = ", ".join(f"{name} {n}" for name, n in sorted(lost.items()) if n)
    console.print(
        f"episodes: {recording.loop.episodes.index + 1}   commands sent: "
        f"{sum(recording.loop.stats.commands_sent.values())}"
        f"   lost before recording: {sum(lost.values())}{f' ({detail})' if detail else ''}   file: "
        f"{recording.options.out}"
    )
    if not sum(recording.loop.stats.commands_sent.values()):
        console.print(f"[yellow]preview only:[/] {PREVIEW_ONLY}", highlight=False)
    for name, n in sorted(recording.loop.stats.device_failures.items()):
        last = recording.runners[name].stats().last_error if name in recording.runners else ""
        console.print(f"[bold red]device {name} failed[/] {n} time(s) (last: {last}); "
                      "see `teleprev info` for when", highlight=False)
