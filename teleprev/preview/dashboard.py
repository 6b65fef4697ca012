"""The record screen: mode banner, robot views, the hand close-up, device health, and the keys.

Built fresh from a LoopSnapshot and the device rows on every redraw. In a small terminal the robot views
shrink, then go, and the banner, episode and device table stay.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from rich.console import Group, RenderableType
from rich.layout import Layout
from rich.panel import Panel
from rich.table import Table
from rich.text import Text

from teleprev.preview.robot_view import Layer, RobotView

if TYPE_CHECKING:  # the preview renders what the live session hands it; it never imports the live session
    from teleprev.live.device_rows import DeviceRow
    from teleprev.live.loop import LoopSnapshot

KEYS = "[b]space[/] preview/execute   [b]x[/] e-stop   [b]s[/] start episode   [b]n[/] next episode   [b]d[/] discard   [b]y[/]/[b]f[/] success/failure   [b]r[/] ready   [b]q[/] quit"
PREVIEW_STYLE = "bold black on yellow"
EXECUTE_STYLE = "bold white on red"
REAL_STYLE = "grey70"
PREVIEW_ROBOT_STYLE = "cyan"
FIXED_STYLE = "bold magenta"


def mode_banner(mode: str, width: int) -> Text:
    label = "  EXECUTE: the robot follows you  " if mode == "execute" else "  PREVIEW: the robot holds still  "
    text = Text(label.center(max(width, len(label))), style=EXECUTE_STYLE if mode == "execute" else PREVIEW_STYLE, justify="center")
    return text


def episode_line(snap: LoopSnapshot, now_ns: int) -> Text:
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
    if snap.message:
        line.append(f"\n{snap.message}", style="yellow")
    return line


def device_table(rows: list[DeviceRow]) -> Table:
    table = Table(expand=True, box=None, padding=(0, 1))
    for col, just in (("device", "left"), ("kind", "left"), ("state", "left"), ("rate", "right"), ("latency", "right"), ("drops", "right"), ("lost", "right"), ("errors", "right")):
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


class Dashboard:
    """Holds the views (their scale stays fixed between frames) and renders a screen for a given size."""

    def __init__(self, robot_view: RobotView, hand_view: RobotView | None, arm_names, effector_names, robot_model):
        self.robot_view = robot_view
        self.hand_view = hand_view
        self.arm_names = tuple(arm_names)
        self.effector_names = tuple(effector_names)
        self.model = robot_model

    def _robot_q(self, arm: np.ndarray | None, effector: np.ndarray | None) -> np.ndarray | None:
        if arm is None:
            return None
        joints = dict(zip(self.arm_names, arm))
        if effector is not None and self.effector_names[0] in self.model.joint_index:
            joints.update(zip(self.effector_names, effector))
        return self.model.vector(joints)

    def robot_panel(self, snap: LoopSnapshot, cols: int, rows: int) -> RenderableType:
        step = snap.step
        layers = []
        real = self._robot_q(snap.measured_arm, snap.measured_effector)
        if real is not None:
            layers.append(Layer(real, REAL_STYLE))
        fixed = frozenset(step.report.get("colliding_links", ())) if step is not None else frozenset()
        if step is not None and step.state.arm_q is not None:
            preview = self._robot_q(step.state.arm_q, step.state.effector_q)
            layers.append(Layer(preview, PREVIEW_ROBOT_STYLE, fixed, FIXED_STYLE))
        if not layers:
            return Text("waiting for the arm's state ...", style="dim")
        title = Text.assemble(("real", REAL_STYLE), "  ", ("preview", PREVIEW_ROBOT_STYLE), "  ", ("fixed", FIXED_STYLE))
        return Group(title, self.robot_view.render(layers, cols, rows - 1))

    def hand_panel(self, snap: LoopSnapshot, cols: int, rows: int) -> RenderableType:
        step = snap.step
        if self.hand_view is None or step is None or step.corrected is None:
            return Text("")
        fixed = frozenset(step.report.get("colliding_links", ()))
        layers = [Layer(step.corrected, PREVIEW_ROBOT_STYLE)]
        if fixed:
            # what retargeting asked for, with the links that collided, over what the hand will do
            layers.insert(0, Layer(step.retargeted, "dim", fixed, FIXED_STYLE))
        action = step.report.get("corrector", "")
        caption = Text(f"hand: {action}" + (f" ({', '.join(sorted(fixed))})" if fixed else ""), style=FIXED_STYLE if fixed else "")
        return Group(caption, self.hand_view.render(layers, cols, rows - 1))

    def render(self, snap: LoopSnapshot, devices: list[DeviceRow], width: int, height: int, now_ns: int) -> RenderableType:
        top = Group(mode_banner(snap.mode, width - 2), episode_line(snap, now_ns))
        table = device_table(devices)
        keys = Text.from_markup(KEYS, justify="center")
        view_rows = height - 9 - len(devices)
        if width < 60 or view_rows < 8:  # too small for pictures: status only
            return Group(top, table, keys)
        layout = Layout()
        layout.split_column(Layout(top, name="top", size=3), Layout(name="body"), Layout(keys, name="keys", size=1))
        if self.hand_view is not None and width >= 100:
            robot_cols, hand_cols = int((width - 6) * 0.62), int((width - 6) * 0.38)
            body = Layout()
            body.split_row(
                Layout(Panel(self.robot_panel(snap, robot_cols, view_rows), title=f"robot ({self.robot_view.view})")),
                Layout(Panel(self.hand_panel(snap, hand_cols, view_rows), title="hand")),
            )
        else:
            body = Layout(Panel(self.robot_panel(snap, width - 4, view_rows), title=f"robot ({self.robot_view.view})"))
        layout["body"].split_column(Layout(body), Layout(table, size=len(devices) + 1))
        return layout
