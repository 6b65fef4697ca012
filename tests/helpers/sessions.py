"""LiveSession real sim sessions for tests (the whole path: sim devices, loop, pipeline, recorder)."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

from teleprev.live.record.session import LiveSession, RecordOptions
from teleprev.rig import default_rig_path
from tests.helpers.wait import WaitTimeout, wait_until

RIGS = default_rig_path().parent


def record_sim(
    out: Path,
    rig: str = "sim.toml",
    seconds: float = 3.0,
    episodes: int = 1,
    engage_after: float | None = 1.0,
    task: str = "pick_place",
    **options,
) -> LiveSession:
    """Record `episodes` episodes of `seconds` each; engage `engage_after` s into each (None: preview only)."""
    rec = LiveSession(RecordOptions(out=out, rig=RIGS / rig, task=task, **options))
    rec.start()
    try:
        for _ in range(episodes):
            rec.loop.start_episode(task)
            if engage_after is not None:
                time.sleep(engage_after)
                end = time.monotonic() + seconds - engage_after
                engaged = rec.loop.stats.engages
                rec.loop.engage(unattended=True)
                while time.monotonic() < end:  # refused (e.g. nothing previewed yet under load): ask again
                    time.sleep(min(0.25, max(0.0, end - time.monotonic())))  # until engaged, as `record` does
                    if rec.loop.stats.engages == engaged and time.monotonic() < end:
                        rec.loop.engage(unattended=True)
            else:
                time.sleep(seconds)
            rec.loop.to_preview("test")
            rec.loop.stop_episode()
    finally:
        rec.stop()
    return rec


def engage_until_accepted(rec: LiveSession, timeout_s: float = 10.0, unattended: bool = False, every_s: float = 0.25,
                          ask: Callable[[], object] | None = None) -> None:
    """Ask to engage every `every_s` until the pipeline accepts (it refuses while nothing is previewed yet, or
    while the sim hand stands inside its clearance margin); fails naming the last refusal after timeout_s.
    `ask` sends one request instead of the loop's engage (the XR page's toggle, say): as a toggle, only
    while the loop shows preview."""
    before = rec.loop.stats.engages

    def engaged():
        if rec.loop.stats.engages > before:
            return True
        if ask is None:
            rec.loop.engage(unattended=unattended)
        elif rec.loop.snapshot.mode == "preview":
            ask()
        return False

    try:
        wait_until(engaged, timeout_s, what="an accepted engage", poll_s=every_s)
    except WaitTimeout as e:
        raise WaitTimeout(f"{e}; the last refusal: {rec.loop.snapshot.message!r}") from None


def record_corpus(folder: Path, names: str = "abc", seconds: float = 2.0) -> Path:
    """A folder of short sim sessions (one episode each, engaged half a second in), named <name>.mcap."""
    folder.mkdir(parents=True, exist_ok=True)
    for name in names:
        record_sim(folder / f"{name}.mcap", seconds=seconds, engage_after=0.5)
    return folder


class RecordingPort:
    """A test double at the ActuatorPort interface: keeps (monotonic time, command) of what the loop
    sends, and passes it on."""

    def __init__(self, port):
        self.port, self.sent = port, []

    def send(self, command):
        self.sent.append((time.monotonic(), command))
        return self.port.send(command)


def record_what_is_sent(rec: LiveSession) -> dict[str, RecordingPort]:
    """Put a RecordingPort between the session loop and each actuator."""
    doubles = {k: RecordingPort(p) for k, p in rec.actuators.items()}
    rec.actuators.update(doubles)  # the very dict the loop sends through
    return doubles


def wait_opened(rec: LiveSession, timeout_s: float = 10.0) -> None:
    """Wait until every device runner of a started session has opened its device: a datagram sent to a
    VMC receiver before its socket is bound is lost where nothing can count it."""
    try:
        wait_until(lambda: all(r.connected for r in rec.runners.values()), timeout_s, what="devices opened")
    except WaitTimeout as e:
        closed = [n for n, r in rec.runners.items() if not r.connected]
        raise WaitTimeout(f"{e}; not opened: {closed}") from None


# A LEAP Hand spread into itself: index and middle fingers abducted towards each other (self-collision).
COLLIDING_LEAP_HOME = [0.6, 0.0, 0.0, 0.0, -0.6] + [0.0] * 11


def colliding_hand_rig(folder: Path) -> Path:
    """The default sim rig with its hand starting in self-collision, written to `folder`: every engage is
    refused (no valid command to start from), whatever the timing."""
    text = (RIGS / "sim.toml").read_text()
    start = text.index("[devices.hand]")
    line = text.index("home = []", start)
    end = text.index("\n", line)
    path = folder / "colliding_hand.toml"
    path.write_text(text[:line] + f"home = {COLLIDING_LEAP_HOME}" + text[end:])
    return path
