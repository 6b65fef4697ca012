"""Driving a LiveSession: from the keyboard with the terminal preview, or from a script (unattended).

The preview redraws on the main thread while the session loop runs on its own; the redraw rate is
measured and kept in `PreviewStats` so the pipeline benchmark can report it. The commands never wait for
the preview (the paced sender has a process of its own), and the preview gives up frame rate before the
session loop falls behind: `PreviewPacer` keeps drawing to at most half a core and waits longer
while the loop has a backlog.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from rich.console import Console
from rich.live import Live

from teleprev.preview.dashboard import Dashboard
from teleprev.preview.keys import KeyReader
from teleprev.preview.robot_view import RobotView
from teleprev.robot.model import load_robot
from teleprev.live.session import LiveSession
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
    hand_view = None
    if recording.rig.effector.hand_urdf:
        hand_view = RobotView(load_robot(recording.rig.effector.hand_urdf), "side")
    return Dashboard(
        RobotView(recording.robot, view, ROBOT_BOUNDS.get(view)), hand_view,
        recording.pipeline.arm_names, recording.pipeline.effector_names, recording.robot,
    )


def handle_key(recording: LiveSession, key: str, quit_flag: list) -> None:
    loop = recording.loop
    if key == " ":
        loop.control("mode", mode="preview" if loop.snapshot.mode == "execute" else "execute")
    elif key == "x":  # e-stop: teleprev sends nothing more at once; the controller stops the robot itself
        loop.control("mode", mode="estop", reason="estop")
    elif key == "s":
        loop.control("start", task=recording.task)
    elif key == "n":
        loop.control("mode", mode="preview")
        loop.control("start", task=recording.task)
    elif key == "d":
        loop.control("discard")
    elif key in ("y", "f"):
        loop.control("outcome", success=key == "y")
    elif key == "r":
        loop.control("operator", event="ready")
    elif key in ("q", "\x1b"):
        loop.control("mode", mode="preview")
        quit_flag.append(True)


def _frame(dashboard: Dashboard, recording: LiveSession, console: Console):
    size = console.size
    snap = recording.loop.snapshot
    return dashboard.render(snap, recording.device_rows(), size.width, size.height, recording.clock.now_ns(),
                            camera=snap.camera)


def run_interactive(recording: LiveSession, console: Console, view: str, fps: float, show: bool = True) -> PreviewStats:
    stats = PreviewStats()
    quit_flag: list = []
    dashboard = make_dashboard(recording, view) if show else None
    with KeyReader(lambda k: handle_key(recording, k, quit_flag)):
        if dashboard is None:
            while not quit_flag and not recording.failure:  # nobody watches a screen: end at once
                time.sleep(0.1)
            return stats
        pacer = PreviewPacer(fps, recording.loop.backlog)
        with Live(console=console, auto_refresh=False, screen=console.is_terminal, transient=False) as live:
            while not quit_flag:
                t = time.perf_counter()
                live.update(_frame(dashboard, recording, console), refresh=True)
                stats.frames += 1
                stats.render_s.append(time.perf_counter() - t)
                time.sleep(pacer.wait_after(time.perf_counter() - t))
    return stats


ENGAGE_RETRY_S = 0.25


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
    plan = []  # (time offset, action, kwargs)
    for k in range(max(episodes, 1)):
        t0 = k * length
        plan.append((t0, "start", {"task": recording.task}))
        if engage_after is not None and engage_after < length:
            plan.append((t0 + engage_after, "mode", {"mode": "execute", "reason": "script"}))
        plan.append((t0 + length - 1e-3, "mode", {"mode": "preview", "reason": "script"}))
        plan.append((t0 + length - 1e-3, "stop", {}))
    if live:
        live.start()
    # an engage the pipeline refused (e.g. nothing previewed yet) is asked again, until one is accepted
    engage_until, asked, engaged_before = None, 0.0, 0
    try:
        while True:
            elapsed = time.perf_counter() - start
            while plan and plan[0][0] <= elapsed:
                _, action, kwargs = plan.pop(0)
                loop.control(action, **kwargs)
                if action == "mode":
                    engage_until = plan[0][0] if kwargs["mode"] == "execute" and plan else None
                    asked, engaged_before = elapsed, loop.stats.engages
            if engage_until is not None and loop.stats.engages > engaged_before:
                engage_until = None  # engaged: this episode asks no more
            if engage_until is not None and elapsed < engage_until and elapsed - asked >= ENGAGE_RETRY_S:
                loop.control("mode", mode="execute", reason="script")
                asked = elapsed
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
        f"episodes: {recording.loop.episodes.index + 1}   commands sent: {sum(recording.loop.stats.commands_sent.values())}"
        f"   lost before recording: {sum(lost.values())}{f' ({detail})' if detail else ''}   file: {recording.options.out}"
    )
    if not sum(recording.loop.stats.commands_sent.values()):
        console.print(f"[yellow]preview only:[/] {PREVIEW_ONLY}", highlight=False)
    for name, n in sorted(recording.loop.stats.device_failures.items()):
        last = recording.runners[name].stats().last_error if name in recording.runners else ""
        console.print(f"[bold red]device {name} failed[/] {n} time(s) (last: {last}); "
                      "see `teleprev info` for when", highlight=False)
