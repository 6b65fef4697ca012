"""`teleprev calibrate`: guided open hand, fist and neutral wrist; writes the calibration a rig references.

A bimanual rig is calibrated in one go: the operator holds each pose with both hands, each side's glove and suit
are averaged on their own, and each side gets its own file (`--out` with `_left` / `_right` before its suffix),
referenced by `[sides.<side>] calibration`. The left glove's pose is mirrored into the right hand's terms first,
as the bimanual pipeline mirrors it before retargeting (teleprev/human/mirror.py), so that the file's joint
scales apply to what the left side's retargeting reads.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import typer

from teleprev.cli.record import WEBXR_HOST_HELP

STEPS = (
    ("open", "Open your hand flat, fingers together, and hold it still."),
    ("fist", "Make a firm fist, thumb over the fingers, and hold it."),
    ("neutral", "Relax your hand and point your fingers straight forward, towards the robot's front."),
)


@dataclass
class Reading:
    """One side's glove and suit as calibrate reads them (side "": a single-arm rig)."""

    side: str
    hand_topic: str
    wrist_topic: str
    out: Path
    mirrored: bool = False  # the operator's left hand: its pose mirrored into the right hand's terms
    samples: dict[str, list] = field(default_factory=lambda: {"hand": [], "wrist": []})

    @property
    def where(self) -> str:
        return f" on the {self.side} side" if self.side else ""


def side_out(out: Path, side: str) -> Path:
    """The file a side's calibration goes to: `out` with _<side> before its suffix (calib/ada_left.toml)."""
    return out.with_name(f"{out.stem}_{side}{out.suffix or '.toml'}")


def calibrate(
    rig: Path | None = typer.Argument(
        None, help="Rig file (TOML) whose glove and suit to read. Default: the all-simulated rig."
    ),
    out: Path = typer.Option(Path("calibration.toml"), "--out", "-o",
                             help="Calibration file to write (a bimanual rig: one per side, _left and _right added)."),
    seconds: float = typer.Option(1.5, "--seconds", help="How long each pose is averaged."),
    hold: float | None = typer.Option(
        None, "--hold", help="Unattended: wait this long for each pose instead of asking for Enter."
    ),
    operator: str = typer.Option("", "--operator", help="Operator name, stored in the file."),
    webxr_host: str = typer.Option("", "--webxr-host", help=WEBXR_HOST_HELP),
) -> None:
    """Guided calibration: open hand, fist and neutral wrist, averaged from the live glove and suit."""
    import time

    import numpy as np
    from rich.console import Console

    from teleprev.cli.pages import announce_pages
    from teleprev.clock import SessionClock
    from teleprev.devices.runner import DeviceRunner
    from teleprev.errors import ConfigError, DeviceError
    from teleprev.human.mirror import mirror_hand_pose
    from teleprev.human.smplx import hand_pose_from_values
    from teleprev.retarget.calibration import write_calibration
    from teleprev.retarget.calibration_fit import calibrate as compute
    from teleprev.rig import load_rig

    console = Console()
    _check_before_the_first_pose(out, hold, seconds)
    r = load_rig(rig)
    if webxr_host:
        r = r.with_device_settings("webxr", "--webxr-host", host=webxr_host)
    clock = SessionClock()
    context = r.device_context(clock)
    contexts = [context]
    if r.bimanual:
        by_side = r.side_contexts(context)
        contexts += by_side.values()
        for side, s in r.sides.items():
            if not s.devices.get("glove") or not s.devices.get("suit"):
                raise ConfigError("calibrate reads each side's glove and suit: name both", f"{r.path} [sides.{side}]")
        names = {side: (s.devices["glove"], s.devices["suit"]) for side, s in r.sides.items()}
        opened = r.open_devices([n for pair in names.values() for n in pair], context, by_side)
        pairs = {side: (opened[g], opened[su]) for side, (g, su) in names.items()}
    else:
        r.require("glove", "suit")
        glove, suit = r.of_kind("glove")[0], r.of_kind("suit")[0]
        pairs = {"": tuple(e.cls(e.name, e.settings, context) for e in (glove, suit))}
    readings = [Reading(side, g.topic("hand"), su.topic("wrist"), side_out(out, side) if side else out,
                        mirrored=side == "left") for side, (g, su) in pairs.items()]
    devices = [d for pair in pairs.values() for d in pair]
    by_topic = {t: (reading, key) for reading in readings
                for t, key in ((reading.hand_topic, "hand"), (reading.wrist_topic, "wrist"))}
    collecting = [False]

    def sink(sample, receive_ns: int) -> None:
        if not collecting[0] or sample.topic not in by_topic:  # (a suit may stream more poses: an XR headset's head)
            return
        reading, key = by_topic[sample.topic]
        if key == "hand":
            values = sample.payload.positions
            if reading.mirrored:
                values = mirror_hand_pose(values, sample.payload.names)
            reading.samples["hand"].append(hand_pose_from_values(sample.payload.names, values))
        else:
            reading.samples["wrist"].append(sample.payload.matrix()[:3, :3])

    runners = [DeviceRunner(d, sink, clock) for d in devices]
    for runner in runners:
        runner.start()
    held: dict[tuple[str, str], dict[str, list]] = {}  # (side, pose) -> samples
    both = "With both hands: " if r.bimanual else ""
    plugins = {runner.name: r.devices[runner.name].plugin for runner in runners}
    try:
        _refuse_what_cannot_start(runners, plugins)
        announce_pages(console, devices)
        for pose, instruction in STEPS:
            for c in contexts:  # a simulated operator takes the pose when asked
                for listener in c.task_listeners:
                    listener(f"calibration:{pose}")
            console.print(f"[bold]{pose}[/]: {both}{instruction}")
            if hold is None:
                console.input("  press Enter when you are holding it ")
            else:
                time.sleep(hold)
            for reading in readings:
                for key in reading.samples:
                    reading.samples[key].clear()
            collecting[0] = True
            time.sleep(seconds)
            collecting[0] = False
            for reading in readings:
                if not reading.samples["hand"] or not reading.samples["wrist"]:
                    _refuse_what_cannot_start(runners, plugins, wait_s=0.0)
                    raise DeviceError(f"no glove or suit data arrived{reading.where} while holding '{pose}'; check "
                                      "`teleprev devices check`", str(r.path))
                held[reading.side, pose] = {k: list(v) for k, v in reading.samples.items()}
                console.print(f"  [green]ok[/]{reading.where}: {len(reading.samples['hand'])} glove and "
                              f"{len(reading.samples['wrist'])} suit samples")
    finally:
        for c in contexts:
            for listener in c.task_listeners:
                listener("calibration:done")
        for runner in runners:
            runner.stop()
    for reading in readings:
        side = reading.side
        cal = compute(np.array(held[side, "open"]["hand"]), np.array(held[side, "fist"]["hand"]),
                      np.array(held[side, "neutral"]["wrist"]), operator)
        try:
            path = write_calibration(cal, reading.out)
        except OSError as exc:  # the folder went away or filled up since the check: the poses are not lost
            from teleprev.retarget.calibration import calibration_toml

            print(calibration_toml(cal))
            raise ConfigError(f"could not write the calibration ({exc.strerror or exc}); it is printed above: save "
                              "it as a .toml file", str(reading.out)) from None
        table = f"\\[sides.{side}]" if side else "\\[rig]"
        console.print(f"wrote {path}{reading.where}: suit yaw {np.degrees(cal.calibration.suit_yaw):.1f} deg; "
                      f"reference it from the rig with {table} calibration = \"{path}\"")


START_WAIT_S = 2.0  # how long the devices' first connect may take before the first pose is asked for anyway


def _refuse_what_cannot_start(runners, plugins: dict[str, str], wait_s: float = START_WAIT_S) -> None:
    """A device that cannot start at all (its port taken, its certificate folder not writable) fails at once,
    in the line `record` says, instead of "no data arrived" after the operator held a pose. Waits up to
    wait_s for the devices' first connect to end (a slower one is asked about no further)."""
    import time

    from teleprev.devices.runner import cannot_start_lines
    from teleprev.errors import DeviceError

    deadline = time.monotonic() + wait_s
    while time.monotonic() < deadline and any(r.stats().state == "connecting" for r in runners):
        time.sleep(0.02)
    lines = cannot_start_lines({r.name: r.stats() for r in runners}, plugins)
    if lines:
        raise DeviceError("; ".join(lines))


def _check_before_the_first_pose(out: Path, hold: float | None, seconds: float) -> None:
    """What would lose the operator's three poses, refused before the first: no terminal to press Enter in,
    or an --out that cannot be written (cli/outputs.py: a read-only folder too, which root's permissions hide)."""
    from teleprev.cli.outputs import check_output
    from teleprev.errors import ConfigError
    from teleprev.preview.keys import KeyReader

    if hold is None and not KeyReader(print).is_terminal:
        raise ConfigError("calibrate asks you to press Enter at each pose, and there is no terminal to press it in: "
                          "run it in a terminal, or pass --hold SECONDS")
    if hold is not None and not 0 <= hold < float("inf"):
        raise ConfigError(f"--hold must be 0 or more seconds, got {hold:g}")
    if not 0 < seconds < float("inf"):
        raise ConfigError(f"--seconds must be a positive number of seconds, got {seconds:g}")
    check_output(out, "--out", make_parents=True)  # (write_calibration makes the folders)
