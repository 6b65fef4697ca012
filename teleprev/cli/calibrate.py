"""`teleprev calibrate`: guided open hand, fist and neutral wrist; writes the calibration a rig references."""

from __future__ import annotations

from pathlib import Path

import typer

from teleprev.cli.record import WEBXR_HOST_HELP

STEPS = (
    ("open", "Open your hand flat, fingers together, and hold it still."),
    ("fist", "Make a firm fist, thumb over the fingers, and hold it."),
    ("neutral", "Relax your hand and point your fingers straight forward, towards the robot's front."),
)


def calibrate(
    rig: Path | None = typer.Argument(
        None, help="Rig file (TOML) whose glove and suit to read. Default: the all-simulated rig."
    ),
    out: Path = typer.Option(Path("calibration.toml"), "--out", "-o", help="Calibration file to write."),
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
    from teleprev.errors import DeviceError
    from teleprev.human.smplx import hand_pose_from_values
    from teleprev.retarget.calibration import write_calibration
    from teleprev.retarget.calibration_fit import calibrate as compute
    from teleprev.rig import load_rig

    console = Console()
    _check_before_the_first_pose(out, hold, seconds)
    r = load_rig(rig)
    if webxr_host:
        r = r.with_device_settings("webxr", "--webxr-host", host=webxr_host)
    r.require("glove", "suit")
    clock = SessionClock()
    context = r.device_context(clock)
    glove, suit = r.of_kind("glove")[0], r.of_kind("suit")[0]
    devices = [e.cls(e.name, e.settings, context) for e in (glove, suit)]
    hand_topic, wrist_topic = devices[0].topic("hand"), devices[1].topic("wrist")
    samples: dict[str, list] = {"hand": [], "wrist": []}
    collecting = [False]

    def sink(sample, receive_ns: int) -> None:
        if not collecting[0]:
            return
        if sample.topic == hand_topic:
            samples["hand"].append(hand_pose_from_values(sample.payload.names, sample.payload.positions))
        elif sample.topic == wrist_topic:  # (a suit may stream more poses: an XR headset's head)
            samples["wrist"].append(sample.payload.matrix()[:3, :3])

    runners = [DeviceRunner(d, sink, clock) for d in devices]
    for runner in runners:
        runner.start()
    held: dict[str, dict[str, list]] = {}
    try:
        _refuse_what_cannot_start(runners, {e.name: e.plugin for e in (glove, suit)})
        announce_pages(console, devices)
        for pose, instruction in STEPS:
            for listener in context.task_listeners:  # a simulated operator takes the pose when asked
                listener(f"calibration:{pose}")
            console.print(f"[bold]{pose}[/]: {instruction}")
            if hold is None:
                console.input("  press Enter when you are holding it ")
            else:
                time.sleep(hold)
            for key in samples:
                samples[key].clear()
            collecting[0] = True
            time.sleep(seconds)
            collecting[0] = False
            if not samples["hand"] or not samples["wrist"]:
                _refuse_what_cannot_start(runners, {e.name: e.plugin for e in (glove, suit)}, wait_s=0.0)
                raise DeviceError(
                    f"no glove or suit data arrived while holding '{pose}'; check `teleprev devices check`", str(r.path)
                )
            held[pose] = {k: list(v) for k, v in samples.items()}
            console.print(
                f"  [green]ok[/]: {len(held[pose]['hand'])} glove and {len(held[pose]['wrist'])} suit samples"
            )
    finally:
        for listener in context.task_listeners:
            listener("calibration:done")
        for runner in runners:
            runner.stop()
    cal = compute(
        np.array(held["open"]["hand"]), np.array(held["fist"]["hand"]), np.array(held["neutral"]["wrist"]), operator
    )
    try:
        path = write_calibration(cal, out)
    except OSError as exc:  # the folder went away or filled up since the check: the poses are not lost
        from teleprev.errors import ConfigError
        from teleprev.retarget.calibration import calibration_toml

        print(calibration_toml(cal))
        raise ConfigError(f"could not write the calibration ({exc.strerror or exc}); it is printed above: save it "
                          "as a .toml file", str(out)) from None
    console.print(f"wrote {path}: suit yaw {np.degrees(cal.calibration.suit_yaw):.1f} deg; "
                  f"reference it from the rig with \\[rig] calibration = \"{path}\"")


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
