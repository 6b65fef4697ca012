"""The record screen: mode banner, robot views, the hand close-up, the camera, device health, and the keys.

Built fresh from a LoopSnapshot and the device rows on every redraw. What fits is chosen by priority:
the banner (with timed episodes' countdown of the current period), the keys (every one of them, on as
many lines as the width needs), the episode line and the device table always; the pictures share what is left, the
robot first, then the hand, then the camera,
each only where it has room to be read (at 80x24: robot, hand and camera side by side).
A bimanual rig's screen has a robot panel per side, left first, before any hand or camera (at 80x24: the two
robots; at 120x45: the two robots and both hands).

With a depth camera the camera panel shows colour, depth (colour-mapped) or both side by side: `c` switches
(CAMERA_MODES), and the key shows only where there is depth to switch to.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from rich.console import Group, RenderableType
from rich.panel import Panel
from rich.table import Table
from rich.text import Text

from teleprev.preview.camera_view import CameraView, DepthView
from teleprev.preview.robot_view import Layer, RobotView
from teleprev.status import DeviceRow, LoopSnapshot, SideView  # what the live session hands the preview to draw

KEYS = (("space", "preview/execute"), ("x", "e-stop"), ("s/e", "start/end episode"),
        ("n", "next episode"),
        ("d", "discard"), ("a", "discard, again"), ("y/f", "success/failure"), ("r", "ready"), ("q", "quit"))
CAMERA_KEY = ("c", "colour/depth")  # shown with a depth camera only: the camera panel's CAMERA_MODES in turn
CAMERA_MODES = ("colour", "depth", "both")
PREVIEW_STYLE = "bold black on yellow"
EXECUTE_STYLE = "bold white on red"
REAL_STYLE = "grey70"
PREVIEW_ROBOT_STYLE = "cyan"
FIXED_STYLE = "bold magenta"
EPISODE_STYLE = "bold white on blue"
COUNTDOWN_HINT = "(n: end it) "


def mode_banner(mode: str, width: int, countdown: tuple[str, float] | None = None) -> Text:
    """The mode across the top line; timed episodes' countdown (period, seconds left) at its right end,
    on the same line (the pictures keep their rows)."""
    label = "  EXECUTE: the robot follows you  " if mode == "execute" else "  PREVIEW: the robot holds still  "
    style = EXECUTE_STYLE if mode == "execute" else PREVIEW_STYLE
    if countdown is None:
        return Text(label.center(max(width, len(label))), style=style, justify="center")
    period, left_s = countdown
    clock = f" {period}: {left_s:4.1f} s left "
    if len(label) + len(clock) + len(COUNTDOWN_HINT) <= width:
        clock += COUNTDOWN_HINT
    if len(label) + len(clock) > width:
        label = f" {mode.upper()} "
    text = Text(no_wrap=True, overflow="crop")
    text.append(label.center(max(width - len(clock), len(label))), style=style)
    text.append(clock, style=EPISODE_STYLE if period.startswith("episode") else PREVIEW_STYLE)
    return text


def key_lines(width: int, keys: tuple[tuple[str, str], ...] = KEYS) -> Text:
    """Every key and what it does, centred, on as many lines as `width` needs (none is ever cut off)."""
    lines: list[list[tuple[str, str]]] = [[]]
    used = 0
    for key, what in keys:
        size = len(key) + 1 + len(what) + (3 if lines[-1] else 0)
        if lines[-1] and used + size > width:
            lines.append([])
            used, size = 0, size - 3
        lines[-1].append((key, what))
        used += size
    text = Text(justify="center")
    for n, line in enumerate(lines):
        for k, (key, what) in enumerate(line):
            text.append("   " if k else "")
            text.append(key, style="bold")
            text.append(f" {what}")
        if n < len(lines) - 1:
            text.append("\n")
    return text


def episode_line(snap: LoopSnapshot, now_ns: int, hints: tuple[str, ...] = ()) -> Text:
    session_s = (now_ns - snap.session_started_ns) / 1e9
    if snap.episode_active:
        ep = f"episode {snap.episode}  [{snap.task}]  {(now_ns - snap.episode_started_ns) / 1e9:6.1f} s"
    elif snap.episode >= 0:
        ep = f"episode {snap.episode} stopped  (s: start the next)"
    else:
        ep = "no episode yet  (s: start)"
    line = Text(f"{ep}    session {session_s:7.1f} s    commands sent {snap.commands_sent}")
    if snap.dropped:
        line.append(f"    dropped {snap.dropped}", style="bold red")
    if snap.input_old:
        stale = snap.input_age_ms > snap.stale_ms
        line.append(f"\ninput {snap.input_age_ms:.0f} ms old when stepped "
                    + ("(stale: the robot holds)" if stale else f"(the robot holds at {snap.stale_ms:.0f} ms)")
                    + ": the machine is busy or the link slow", style="bold red" if stale else "yellow")
    if snap.message:
        line.append(f"\n{snap.message}", style="yellow")
    for hint in hints:  # a device waiting for the operator (the XR page's URL until the page streams)
        line.append(f"\n{hint}", style="bold cyan")
    return line


def device_table(rows: list[DeviceRow]) -> Table:
    table = Table(expand=True, box=None, padding=(0, 1))
    for col, just in (
        ("device", "left"),
        ("kind", "left"),
        ("state", "left"),
        ("rate", "right"),
        ("latency", "right"),
        ("drops", "right"),
        ("lost", "right"),
        ("errors", "right"),
    ):
        table.add_column(col, justify=just, no_wrap=True)
    for r in rows:
        state_style = {"ok": "green", "gap": "bold yellow", "error": "bold red"}.get(r.state, "dim")
        slow = r.nominal_hz > 0 and r.rate_hz < 0.8 * r.nominal_hz
        table.add_row(
            r.name, r.kind, Text(r.state, style=state_style),
            Text(f"{r.rate_hz:6.1f}/{r.nominal_hz:g} Hz", style="yellow" if slow else ""),
            f"{r.latency_ms:5.1f} ms", Text(str(r.dropped), style="red" if r.dropped else ""),
            Text(str(r.lost + r.lost_input), style="red" if r.lost + r.lost_input else ""),
            Text(str(r.errors), style="red" if r.errors else ""),
        )
    return table


@dataclass
class RobotSide:
    """One robot the dashboard draws: its views (the arm with its end effector, the hand alone) and joint names.
    A single-arm rig has one, named ""; a bimanual rig one per side, left first."""

    name: str
    robot_view: RobotView
    hand_view: RobotView | None
    arm_names: tuple[str, ...]
    effector_names: tuple[str, ...]
    model: object  # RobotModel of robot_view

    def q(self, arm: np.ndarray | None, effector: np.ndarray | None) -> np.ndarray | None:
        if arm is None:
            return None
        joints = dict(zip(self.arm_names, arm))
        if effector is not None and self.effector_names[0] in self.model.joint_index:
            joints.update(zip(self.effector_names, effector))
        return self.model.vector(joints)

    def title(self, what: str) -> str:
        return f"{self.name} {what}" if self.name else what


class Dashboard:
    """Holds the views (their scale stays fixed between frames) and renders a screen for a given size."""

    MIN_ROBOT = (30, 8)  # cols, rows of a robot view that still reads as a robot (inside its panel)
    MIN_SIDE = (18, 6)  # the same for the hand and the camera

    def __init__(self, robot_view: RobotView, hand_view: RobotView | None, arm_names, effector_names, robot_model):
        self.robots = (RobotSide("", robot_view, hand_view, tuple(arm_names), tuple(effector_names), robot_model),)
        self.camera_view = CameraView()
        self.depth_view = DepthView()
        self.camera_mode = CAMERA_MODES[0]

    @classmethod
    def bimanual(cls, sides: tuple[RobotSide, ...]) -> Dashboard:
        """A robot panel (and a hand panel where there is room) per side, in the order given (left first), each
        drawing its side of the snapshot (LoopSnapshot.sides)."""
        first = sides[0]
        dashboard = cls(first.robot_view, first.hand_view, first.arm_names, first.effector_names, first.model)
        dashboard.robots = tuple(sides)
        return dashboard

    @property
    def robot_view(self) -> RobotView:
        return self.robots[0].robot_view

    @property
    def hand_view(self) -> RobotView | None:
        return self.robots[0].hand_view

    def next_camera_mode(self) -> str:
        """The camera panel's next mode (the `c` key): colour, depth, both, colour, ..."""
        self.camera_mode = CAMERA_MODES[(CAMERA_MODES.index(self.camera_mode) + 1) % len(CAMERA_MODES)]
        return self.camera_mode

    def camera_panels(self, camera, depth) -> list:
        """(title, draw(cols, rows)) of the camera's panels in the current mode: colour without depth."""
        colour = ("camera", lambda c, r: self.camera_view.render(camera, c, r))
        mapped = ("depth", lambda c, r: self.depth_view.render(depth, c, r))
        if depth is None or self.camera_mode == "colour":
            return [colour] if camera is not None else []
        if self.camera_mode == "depth" or camera is None:
            return [mapped]
        return [mapped, colour]  # beside each other where both fit; colour is dropped first (at 80x24)

    def _shown(self, snap: LoopSnapshot) -> list[tuple[RobotSide, SideView]]:
        """Each robot with what the snapshot says of it: a bimanual snapshot's sides by name, else the snapshot."""
        if len(self.robots) == 1:
            return [(self.robots[0], SideView("", snap.step, snap.measured_arm, snap.measured_effector))]
        by_name = {view.side: view for view in snap.sides}
        return [(robot, by_name.get(robot.name, SideView(robot.name))) for robot in self.robots]

    def robot_panel(self, robot: RobotSide, view: SideView, cols: int, rows: int) -> RenderableType:
        step = view.step
        layers = []
        real = robot.q(view.measured_arm, view.measured_effector)
        if real is not None:
            layers.append(Layer(real, REAL_STYLE))
        fixed = frozenset(step.report.get("colliding_links", ())) if step is not None else frozenset()
        if step is not None and step.state.arm_q is not None:
            preview = robot.q(step.state.arm_q, step.state.effector_q)
            layers.append(Layer(preview, PREVIEW_ROBOT_STYLE, fixed, FIXED_STYLE))
        if not layers:
            return Text("waiting for the arm's state ...", style="dim")
        title = Text.assemble(
            ("real", REAL_STYLE), "  ", ("preview", PREVIEW_ROBOT_STYLE), "  ", ("fixed", FIXED_STYLE)
        )
        if step is not None and "cross_side_held" in step.report.get("flags", ()):
            title.append("  held: would touch the other side", style=FIXED_STYLE)
        title.truncate(cols)
        return Group(title, robot.robot_view.render(layers, cols, rows - 1))

    def hand_panel(self, robot: RobotSide, view: SideView, cols: int, rows: int) -> RenderableType:
        step = view.step
        if robot.hand_view is None or step is None or step.corrected is None:
            return Text("")
        fixed = frozenset(step.report.get("colliding_links", ()))
        layers = [Layer(step.corrected, PREVIEW_ROBOT_STYLE)]
        if fixed:
            # what retargeting asked for, with the links that collided, over what the hand will do
            layers.insert(0, Layer(step.retargeted, "dim", fixed, FIXED_STYLE))
        action = step.report.get("corrector", "")
        caption = Text(
            f"hand: {action}" + (f" ({', '.join(sorted(fixed))})" if fixed else ""), style=FIXED_STYLE if fixed else ""
        )
        return Group(caption, robot.hand_view.render(layers, cols, rows - 1))

    def render(self, snap: LoopSnapshot, devices: list[DeviceRow], width: int, height: int, now_ns: int,
               camera=None, countdown: tuple[str, float] | None = None, depth=None) -> RenderableType:
        """The screen for a terminal of width x height; `camera` is the latest frame (an ImageSample) of the
        camera to show, or None; `depth` the latest depth frame (a DepthSample), or None; `countdown`: timed
        episodes' current period and its seconds left, or None."""
        episode = episode_line(snap, now_ns, tuple(dict.fromkeys(r.hint for r in devices if r.hint)))
        keys = key_lines(width, KEYS if depth is None else (*KEYS[:-1], CAMERA_KEY, KEYS[-1]))
        table = device_table(devices)
        fixed = 1 + len(episode.plain.splitlines()) + len(keys.plain.splitlines()) + len(devices) + 1
        body_rows = height - fixed
        rows, cols = body_rows - 2, width  # inside the panels' borders (their widths include theirs)
        shown = self._shown(snap)
        n = len(shown)  # robot panels: each wants two shares of the width and at least MIN_ROBOT
        if rows < self.MIN_ROBOT[1] or cols < n * (self.MIN_ROBOT[0] + 2):  # too small for pictures: status only
            return Group(mode_banner(snap.mode, width, countdown), episode, table, keys)
        sides = [(robot.title("hand"), lambda c, r, robot=robot, view=view: self.hand_panel(robot, view, c, r))
                 for robot, view in shown if robot.hand_view is not None]
        sides += self.camera_panels(camera, depth)
        # each robot gets two shares of the width, each side panel one (at least its minimum), while the robots
        # still have their own minimum; the camera goes first, then the hands (the right's before the left's)
        while sides:
            side = max(self.MIN_SIDE[0] + 2, cols // (len(sides) + 2 * n))
            if cols - len(sides) * side >= n * (self.MIN_ROBOT[0] + 2) and rows >= self.MIN_SIDE[1]:
                break
            sides.pop()
        side = max(self.MIN_SIDE[0] + 2, cols // (len(sides) + 2 * n)) if sides else 0
        robot_cols = [(cols - len(sides) * side) // n] * n
        robot_cols[-1] += cols - len(sides) * side - sum(robot_cols)
        body = Table.grid(padding=0)
        for c in robot_cols:
            body.add_column(width=c)
        for _ in sides:
            body.add_column(width=side)
        body.add_row(
            *(Panel(self.robot_panel(robot, view, c - 2, rows), title=robot.title(f"robot ({robot.robot_view.view})"),
                    padding=0, height=body_rows) for (robot, view), c in zip(shown, robot_cols)),
            *(Panel(draw(side - 2, rows), title=title, padding=0, height=body_rows) for title, draw in sides))
        return Group(mode_banner(snap.mode, width, countdown), episode, body, table, keys)
