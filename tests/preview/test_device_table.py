"""The preview's device table shows every count a device's samples can be lost under."""

import io

from rich.console import Console

from teleprev.preview.dashboard import device_table
from teleprev.status import DeviceRow


def render(rows) -> str:
    console = Console(file=io.StringIO(), width=120, color_system=None)
    console.print(device_table(rows))
    return console.file.getvalue()


def test_samples_lost_in_the_runner_are_shown_next_to_the_queue_drops():
    text = render([DeviceRow("glove", "glove", "ok", 119.0, 120.0, 2.1, dropped=4, lost=7, errors=1)])
    header, row = text.splitlines()[:2]
    assert header.split() == ["device", "kind", "state", "rate", "latency", "drops", "lost", "errors"]
    assert row.split()[-3:] == ["4", "7", "1"]
