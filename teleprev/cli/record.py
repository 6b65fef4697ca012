"""`teleprev record`: collect a session with the terminal preview, or unattended from a script."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

import typer

WEBXR_HOST_HELP = ("Where the XR page (webxr.* devices) listens, over the rig's host: 0.0.0.0 opens it to the "
                   "network, and its URL then carries a pairing token.")
TASKS_HELP = (
    "Task label of the episodes (the sim operator performs it): pick_place, hang, pour, box_rotation, cup_stack."
)
View = Literal["front", "side", "top"]  # the robot views of the terminal preview


def record(
    rig: Path | None = typer.Argument(None, help="Rig file (TOML). Default: the all-simulated rig."),
    out: Path | None = typer.Option(
        None, "--out", "-o", help="Session file to write (default: sessions/<time>_<task>.mcap)."
    ),
    task: str = typer.Option("", "--task", "-t", help=TASKS_HELP),
    task_text: str = typer.Option(
        "",
        "--task-text",
        help="The task as an instruction in words, e.g. 'pick up the cube and "
        "place it in the bowl' (default: the rig's \\[tasks] entry); exports give it to the "
        "policy, the id stays in the session.",
    ),
    duration: float | None = typer.Option(None, "--duration", help="Run unattended for this many seconds, then stop."),
    episodes: int = typer.Option(
        1,
        "--episodes",
        min=1,
        help="With --duration: split it into this many episodes; with --episode-time: record this many timed episodes.",
    ),
    episode_time: float | None = typer.Option(
        None,
        "--episode-time",
        help="Timed episodes of this many seconds each (instead of --duration), with "
        "--reset-time between them; keys n, d, a still work.",
    ),
    reset_time: float | None = typer.Option(
        None,
        "--reset-time",
        help="With --episode-time: seconds of reset between episodes, the robot in preview (default 0).",
    ),
    marks: str | None = typer.Option(
        None,
        "--marks",
        help="With --episode-time: mark the episodes success (y), failure (f) or not (-) in turn, "
        "one character per episode, cycling (e.g. yf-).",
    ),
    cues: bool = typer.Option(
        True,
        "--cues/--no-cues",
        help="With --episode-time: the terminal bell, and spoken "
        "words where spd-say, espeak or say is installed, at each boundary.",
    ),
    engage_after: float | None = typer.Option(
        None,
        "--engage-after",
        help="Unattended: switch to execute this many seconds into each episode (default: stay in preview).",
    ),
    preview: bool = typer.Option(
        True, "--preview/--no-preview", help="Show the terminal preview (--no-preview runs headless)."
    ),
    view: View = typer.Option("side", "--view", help="Robot view."),
    fps: float = typer.Option(25.0, "--fps", help="Terminal preview redraws per second."),
    models: Path | None = typer.Option(
        None, "--models", help="Folder with CPN/CCN weights (default: the rig's, else models/)."
    ),
    operator: str = typer.Option("", "--operator", help="Operator name, stored with the session."),
    participant: str = typer.Option("", "--participant", help="User-study participant id."),
    condition: str = typer.Option("", "--condition", help="User-study condition, e.g. 'w/ preview'."),
    practice: bool = typer.Option(False, "--practice", help="Mark the session as practice; press r when ready."),
    connect_timeout: float = typer.Option(
        5.0,
        "--connect-timeout",
        help="Unattended or headless: fail unless every device has sent something within this many seconds.",
    ),
    webxr_host: str = typer.Option("", "--webxr-host", help=WEBXR_HOST_HELP),
    foxglove: int | None = typer.Option(
        None,
        "--foxglove",
        metavar="[PORT]",
        min=0,
        max=65535,
        help="Also show the session live in Foxglove: a WebSocket server on "
        "127.0.0.1:PORT (default 8765) with the file's topics.",
        show_default=False,
    ),
) -> None:
    """Record a session: devices, pipeline, preview and execute, episodes, all into one MCAP file."""
    from rich.console import Console
    from rich.markup import escape

    from teleprev import topics
    from teleprev.cli.outputs import check_output
    from teleprev.cli.pages import announce_pages
    from teleprev.cli.signals import StopSignals
    from teleprev.live.record.bimanual_session import open_session
    from teleprev.live.record.cues import Cues
    from teleprev.live.record.run import print_summary, run_interactive, run_script, run_timed
    from teleprev.live.record.session import RecordOptions, default_session_path

    plan = check_options(rig, task, duration, engage_after, connect_timeout, episodes, episode_time, reset_time, marks)
    check_fps(fps)
    out = out or default_session_path(task)
    check_output(out, "--out", overwrite=False, make_parents=True)
    console = Console()
    preview = preview and console.is_terminal  # a redrawn screen in a log file is noise: headless there
    options = RecordOptions(
        out=out, rig=rig, models=models, task=task, task_text=task_text,
        operator=operator, participant=participant, condition=condition, practice=practice,
        connect_timeout_s=connect_timeout, foxglove=foxglove, episode_plan=plan, webxr_host=webxr_host,
    )
    unconnected: list[str] = []
    with StopSignals() as signals:
        with signals.deferred():  # the session file opened whole (a signal now is raised in the try below)
            recording = open_session(options)
        if recording.view is not None:
            console.print(f"Foxglove: open connection {recording.view.url}", highlight=False)
        if plan is not None and plan.engage_after_s is not None and \
                plan.engage_after_s + recording.preview_lead_s >= plan.episode_s:
            console.print(f"[yellow]warning:[/] episodes of {plan.episode_s:g} s leave no time to engage after "
                          f"{plan.engage_after_s:g} s: the robot is back in preview {recording.preview_lead_s:.2f} s "
                          "before each end, so it stays in preview", highlight=False)
        try:
            signals.check()
            with signals.deferred():
                recording.start()
            signals.check()  # also a Ctrl-C whose KeyboardInterrupt start-up lost: it must not go on to engage
            announce_pages(console, recording.devices.values())
            if duration is not None or plan is not None or not preview:  # nobody watches the device table, or
                unconnected = recording.wait_connected()  # the clock runs: a dead rig must fail
            signals.check()
            if not unconnected and plan is not None:
                run_timed(recording, plan, console if preview else None, view, fps,
                          cues=Cues.for_terminal(console.file) if cues else Cues(None, None))
            elif not unconnected and duration is not None:
                run_script(recording, duration, episodes, engage_after, console if preview else None, view, fps)
            elif not unconnected:
                run_interactive(recording, console, view, fps, show=preview)
                unconnected = recording.start_failures()  # what ended it at once, if a device cannot start
        except KeyboardInterrupt:
            pass  # Ctrl-C, SIGTERM or SIGHUP: the session is finalized below all the same
        finally:
            with signals.finishing():  # a second signal must not cut the file's finalization short
                summary = recording.stop()  # raises SessionError if the recording failed (exit 2)
    try:
        if not recording.cannot_start:  # else nothing ran: the one line below says why
            print_summary(console, recording, summary)
    except OSError:  # the terminal went away with the SIGHUP; the file is complete all the same
        pass
    signals.exit_if_stopped(console, options.out)
    if unconnected:
        errors = Console(stderr=True)
        for line in unconnected:
            errors.print(f"[bold red]error:[/] {escape(line)}", highlight=False, soft_wrap=True)
        raise typer.Exit(1)
    if recording.loop.failure:
        Console(stderr=True).print(f"[bold red]error:[/] {escape(recording.loop.failure)} (the robot was braked to "
                                   f"rest; the traceback is in {escape(str(options.out))}, {topics.OPERATOR})",
                                   highlight=False, soft_wrap=True)
        raise typer.Exit(1)
    if recording.loop.stats.device_failures:
        raise typer.Exit(1)  # a device failed during the session: the summary above says which
    unattended = duration is not None or plan is not None
    missed = never_engaged(recording.loop, engage_after if unattended else None)
    if missed:
        Console(stderr=True).print(f"[bold red]error:[/] {escape(missed)}", highlight=False, soft_wrap=True)
        raise typer.Exit(1)


def never_engaged(loop, engage_after: float | None) -> str:
    """One line saying why, when an unattended session (record or rollout) was asked to engage
    `engage_after` s into its episodes and never did; "" when it engaged or was not asked to."""
    if engage_after is None or loop.stats.engages:
        return ""
    last = loop.snapshot.message  # the loop's last word to the operator: a refused engage, as a rule
    why = last.removeprefix("cannot switch to execute: ") or "no episode lasted until then"
    return f"never engaged (--engage-after {engage_after:g} s): {why}; the session is recorded, all in preview"


def check_options(rig: Path | None, task: str, duration: float | None, engage_after: float | None,
                  connect_timeout: float, episodes: int = 1, episode_time: float | None = None,
                  reset_time: float | None = None, marks: str | None = None):
    """The values no device has to be opened to refuse: one line each (teleprev.errors.ConfigError).
    Returns the plan of timed episodes (--episode-time), or None."""
    from teleprev.errors import ConfigError
    from teleprev.live.record.schedule import EpisodeTimes
    from teleprev.rig import load_rig

    plan = None
    if episode_time is not None:
        if duration is not None:
            raise ConfigError("--episode-time and --duration both set how long the session runs: pass one "
                              "(--duration splits itself evenly into --episodes)")
        plan = EpisodeTimes(episodes, episode_time, 0.0 if reset_time is None else reset_time, engage_after,
                            marks or "").check()
    else:
        for name, value in (("--reset-time", reset_time), ("--marks", marks)):
            if value is not None:
                raise ConfigError(f"{name} goes with --episode-time (timed episodes)")

    for name, value in (("--duration", duration), ("--connect-timeout", connect_timeout)):
        if value is not None and not 0 < value < float("inf"):
            raise ConfigError(f"{name} must be a positive number of seconds, got {value:g}")
    if engage_after is not None and not 0 <= engage_after < float("inf"):
        raise ConfigError(f"--engage-after must be 0 or more seconds, got {engage_after:g}")
    if task:
        load_rig(rig).check_task(task, "--task")
    return plan


MAX_FPS = 120.0  # terminal preview redraws per second: more than a terminal shows


def check_fps(fps: float) -> None:
    """--fps (the terminal preview's redraws per second), refused before anything opens."""
    from teleprev.errors import ConfigError

    if not 0 < fps <= MAX_FPS:
        raise ConfigError(f"--fps must be more than 0 and at most {MAX_FPS:g} redraws per second, got {fps:g}")
