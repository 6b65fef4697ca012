"""The record screen of a live bimanual session draws both robots, left first, at 80x24 and 120x45 (and both
hands where there is room), each from its own side's step and measured joints, and nothing runs past the
terminal."""

from __future__ import annotations

import io
from pathlib import Path

import pytest
from rich.console import Console

from teleprev.live.record.bimanual_session import open_session
from teleprev.live.record.run import _frame, make_dashboard
from teleprev.live.record.session import RecordOptions
from teleprev.preview.dashboard import KEYS
from tests.helpers.wait import wait_until

RIG = Path(__file__).resolve().parents[2] / "rigs" / "sim_bimanual.toml"


@pytest.fixture(scope="module")
def screens(tmp_path_factory) -> dict[tuple[int, int], list[str]]:
    rec = open_session(RecordOptions(rig=RIG, out=tmp_path_factory.mktemp("preview") / "s.mcap"))
    rec.start()
    try:
        def both_stepped():
            views = rec.loop.snapshot.sides
            return len(views) == 2 and all(v.step is not None and v.measured_arm is not None for v in views)
        wait_until(both_stepped, 30, what="both sides stepped and measured in the preview's snapshot")
        views = {v.side: v for v in rec.loop.snapshot.sides}
        assert [v.side for v in rec.loop.snapshot.sides] == ["left", "right"]
        assert views["left"].step is not views["right"].step
        dashboard = make_dashboard(rec, "side")
        out = {}
        for width, height in ((80, 24), (120, 45)):
            console = Console(file=io.StringIO(), width=width, height=height, record=True, color_system="truecolor")
            console.print(_frame(dashboard, rec, console))
            out[(width, height)] = console.export_text().rstrip("\n").splitlines()
    finally:
        rec.stop()
    return out


def panel(lines: list[str], title: str) -> list[str]:
    """The inside of the panel titled `title`: its rows, cut to its columns."""
    top = next(n for n, line in enumerate(lines) if title in line)
    line = lines[top]
    start = line.rindex("╭", 0, line.index(title))
    end = line.index("╮", line.index(title))
    bottom = next(n for n in range(top + 1, len(lines)) if lines[n][start:start + 1] == "╰")
    return [row[start + 1:end] for row in lines[top + 1:bottom]]


def braille(rows: list[str]) -> int:
    return sum(0x2801 <= ord(c) <= 0x28FF for c in "".join(rows))


@pytest.mark.parametrize("width, height", [(80, 24), (120, 45)])
def test_both_robots_are_drawn_side_by_side_and_fit(screens, width, height):
    lines = screens[(width, height)]
    assert len(lines) <= height and max(len(line) for line in lines) <= width, "\n".join(lines)
    text = " ".join(" ".join(lines).split())
    for key, what in KEYS:
        assert f"{key} {what}" in text, key
    top = next(line for line in lines if "left robot (side)" in line)
    assert top.index("left robot (side)") < top.index("right robot (side)")  # left on the left
    for side in ("left", "right"):
        rows = panel(lines, f"{side} robot (side)")
        assert len(rows[0]) >= 30 and len(rows) >= 8, side
        assert braille(rows) > 20, f"{side} robot not drawn:\n" + "\n".join(rows)


def test_at_120x45_both_hands_are_drawn_too(screens):
    lines = screens[(120, 45)]
    for side in ("left", "right"):
        rows = panel(lines, f"{side} hand")
        assert len(rows[0]) >= 18, side
        assert braille(rows) > 30, f"{side} hand not drawn:\n" + "\n".join(rows)

