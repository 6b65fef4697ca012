"""`teleprev replay` and `teleprev eval`: show a session again, and re-run it to measure the pipeline."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

import typer

from teleprev.cli.export import RAY
from teleprev.cli.record import View


def replay(
    session: Path = typer.Argument(
        ...,
        help="Session file (.mcap), or a LeRobot dataset folder (its `action` column; with --episode and --config).",
    ),
    episode: int | None = typer.Option(None, "--episode", "-e", help="Play one episode (default: the whole session)."),
    speed: float = typer.Option(
        1.0, "--speed", "-x", min=0.01, help="Playback speed multiple (capped so no joint exceeds its limit)."
    ),
    to: Literal["preview", "sim", "arm"] = typer.Option(
        "preview", "--to", help="preview (screen only), sim (the simulated robot) or arm (the rig's robot)."
    ),
    rig: Path | None = typer.Option(
        None,
        "--rig",
        "--config",
        help="Rig whose robot receives the commands with --to arm, "
        "and whose limits apply (default: the recorded rig; a dataset needs one).",
    ),
    engage_after: float | None = typer.Option(
        None, "--engage-after", help="Engage automatically after this many seconds (else press space)."
    ),
    view: View = typer.Option("side", "--view", help="Robot view."),
    preview: bool = typer.Option(True, "--preview/--no-preview", help="Show the terminal preview."),
    smooth: bool = typer.Option(
        False,
        "--smooth",
        help="Send the commands as the pipeline's jerk-limited generator re-commands them "
        "(needed with --to arm for a session that fails `teleprev audit`).",
    ),
    foxglove: int | None = typer.Option(
        None,
        "--foxglove",
        metavar="[PORT]",
        min=0,
        max=65535,
        help="Also play the session's topics live to Foxglove: a WebSocket server on 127.0.0.1:PORT (default 8765).",
        show_default=False,
    ),
    out: Path | None = typer.Option(
        None,
        "--out",
        "-o",
        help="Record the replay (what the robot was sent, and its states) as a session here.",
        show_default=False,
    ),
) -> None:
    """Play a session's commands, or a LeRobot dataset episode's actions, back: on screen and optionally to the
    simulated or a real robot.

    A real robot (--to arm) gets only commands that pass `teleprev audit`, or ones played --smooth."""
    from rich.console import Console

    from teleprev.cli.outputs import check_output
    from teleprev.cli.values import check_finite, check_seconds
    from teleprev.errors import ConfigError
    from teleprev.live.replay.playback import play
    from teleprev.preview.keys import KeyReader

    check_finite("--speed", speed, "a finite multiple of the recorded speed (at least 0.01)")
    check_seconds("--engage-after", engage_after, zero_ok=True)
    if not session.exists():
        raise ConfigError("no such session file or dataset folder", str(session))
    from teleprev.export.actions import is_dataset

    if session.is_dir() and not is_dataset(session):
        raise ConfigError("a folder that is not a LeRobot dataset (no meta/info.json)", str(session))
    if session.is_dir() and foxglove is not None:
        raise ConfigError("--foxglove plays a session's recorded topics, and a dataset has none", str(session))
    check_output(out, "--out", overwrite=False)

    waits_for_a_key = to == "sim" or (to == "arm" and rig is not None)  # (--to arm without --rig: refused below)
    if waits_for_a_key and engage_after is None and not KeyReader(print).is_terminal:
        raise ConfigError(f"--to {to} waits for space to engage the robot, and there is no terminal to press it in: "
                          "pass --engage-after SECONDS")
    console = Console()
    if to == "arm" and not smooth:
        from teleprev.evaluation.audit import audit_path

        report = audit_path(session, rig)
        if not report.ok:
            reasons = "; ".join(f"{s.topic}: {v}" for s in report.streams for v in s.violations)
            if report.hand_state_colliding:
                reasons += f"; measured hand state in self-collision {report.hand_state_colliding}x"
            console.print(f"[red]not replaying {session} to the robot: it fails the audit[/] ({reasons}). "
                          "Add --smooth to send it through the jerk-limited generator instead.")
            raise typer.Exit(1)
    from teleprev.cli.signals import StopSignals

    with StopSignals() as signals:  # SIGTERM, SIGHUP as Ctrl-C: the robot stops, the recording is finalized
        try:
            play(session, episode, speed, to, rig, engage_after, console, view, preview, smooth, foxglove, out, signals)
        except KeyboardInterrupt:
            pass
    signals.exit_if_stopped(console)  # (play said "replay recorded in OUT" once the recording was closed whole)


def eval_(
    sessions: list[str] = typer.Argument(
        ..., help="Session files (.mcap), folders of them or globs ('sessions/*.mcap')."
    ),
    models: Path | None = typer.Option(
        None, "--models", help="CPN/CCN weights to evaluate (default: the shipped models)."
    ),
    config: Path | None = typer.Option(
        None, "--config", help="Rig file to evaluate with (default: the rig recorded in each session)."
    ),
    out: Path | None = typer.Option(
        None, "--out", "-o", help="Write the report as JSON here (for CI and as a later baseline)."
    ),
    baseline: Path | None = typer.Option(
        None, "--baseline", help="An earlier report: exit 1 if a metric regressed past its tolerance."
    ),
    tolerances: Path | None = typer.Option(
        None, "--tolerances", help="Tolerances TOML (default: teleprev/evaluation/tolerances.toml)."
    ),
    plots: Path | None = typer.Option(
        None,
        "--plots",
        help="Write a PNG per episode (recorded vs re-run joints), and corpus.png for many sessions, into this folder.",
    ),
    workers: int = typer.Option(1, "--workers", "-j", min=1, help="Re-run sessions in this many processes."),
    ray: str | None = RAY,
    rows: int = typer.Option(
        30, "--rows", min=1, help="Sessions shown in the table of a corpus (the worst; the report has all)."
    ),
    physics: bool = typer.Option(
        False, "--physics", help="Also play each session into the physics world from its recorded scenes and "
        "judge every episode's outcome, with the recorded and with the re-computed commands: an episode that "
        "succeeds with the recorded commands and fails with the re-computed ones is a regression.",
    ),
) -> None:
    """Re-run the pipeline on recorded raw streams, measure it, and catch regressions.

    Exits 1 on a regression (with --physics, also an episode the re-computed commands fail) or a session
    that could not be evaluated."""
    from rich.console import Console

    from teleprev.cli.outputs import check_input, check_output
    from teleprev.corpus.sessions import resolve_sessions
    from teleprev.evaluation.report import load_tolerances, print_report, read_report, write_report

    check_output(out, "--out")
    check_output(plots, "--plots", "folder", make_parents=True)
    check_input(baseline, "--baseline", "report")
    check_input(tolerances, "--tolerances", "tolerances file")
    check_input(models, "--models", "folder of CPN/CCN weights", folder=True)
    if models is not None:  # weights that cannot be read fail every session: say so once, before the work
        from teleprev.noncollision.mlp import read_info

        for weights in sorted(models.glob("*.safetensors")):
            read_info(weights)
    paths = resolve_sessions(sessions)
    console = Console()
    executor = None
    if ray is not None or (workers > 1 and len(paths) > 1):
        from teleprev.corpus.executor import make_executor
        from teleprev.evaluation.corpus import PRELOAD

        executor = make_executor(workers, ray, PRELOAD)
        executor.start()  # local workers' fork server: it loads the kernels while this process goes on
    from teleprev.evaluation.corpus import evaluate_corpus, print_corpus

    try:
        with _SessionBar(console, len(paths)) as bar:
            result = evaluate_corpus(
                paths, models, config,
                baseline=read_report(baseline) if baseline else None,
                tolerances=load_tolerances(tolerances) if tolerances else None,
                executor=executor, plots=plots, on_done=bar, physics=physics,
            )
    finally:
        if executor is not None:
            executor.close()
    if len(paths) == 1 and not result.failed:
        print_report(console, result.report, result.regressions)  # one session: every metric, per episode
    else:
        print_corpus(console, result, rows)
    outcome_regressions = result.outcome_regressions
    if physics:
        from teleprev.evaluation.physics import print_physics

        if len(paths) == 1:
            print_physics(console, result.report)
        for why in outcome_regressions:
            console.print(f"[bold red]outcome regression[/] {why}", highlight=False)
    if out:
        write_report(result.report, out)
        console.print(f"report written to {out}")
    if plots:
        console.print(f"{len(result.plots)} plot(s) written to {plots}")
    if result.regressions or result.failed or outcome_regressions:
        raise typer.Exit(1)


def audit(
    sessions: list[Path] = typer.Argument(
        ..., help="Session files (.mcap) or LeRobot dataset folders (their `action` column)."
    ),
    config: Path | None = typer.Option(
        None,
        "--config",
        help="Rig whose limits apply (default: the rig recorded in each session; required for a dataset).",
    ),
    json_out: Path | None = typer.Option(None, "--json", help="Write the audit as JSON here."),
) -> None:
    """Check a session's commands, or a dataset's actions, against the robot's limits.

    Position, speed, acceleration, jerk, and (for a hand) end-point and swept self-collision. Exits 1 on
    any violation."""
    from rich.console import Console

    from teleprev.cli.outputs import check_output
    from teleprev.evaluation.audit import audit_path, print_report, write_json

    check_output(json_out, "--json")
    console = Console()
    reports = [audit_path(s, config) for s in sessions]
    for r in reports:
        print_report(r, console)
    if json_out:
        write_json(reports, json_out)
        console.print(f"audit written to {json_out}")
    if not all(r.ok for r in reports):
        raise typer.Exit(1)


class _SessionBar:
    """Progress of the sessions evaluated (a corpus, or plots, can take a while): a transient bar on a
    terminal (none for one session); elsewhere (piped, a log file) a line as each session is done."""

    def __init__(self, console, total: int):
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

        self.console, self.total, self.done = console, total, 0
        self.lines = not console.is_terminal
        self.progress = Progress(TextColumn("evaluating"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                                 console=console, transient=True, disable=total < 2 or self.lines)
        self.task = None
        self.started = 0.0

    def __enter__(self):
        import time

        self.started = time.perf_counter()
        if self.lines:
            self.console.print(f"evaluating {self.total} session(s)", highlight=False)
        self.progress.__enter__()
        self.task = self.progress.add_task("sessions", total=self.total)
        return self

    def __exit__(self, *exc):
        self.progress.__exit__(*exc)

    def __call__(self, outcome) -> None:
        import time

        self.done += 1
        self.progress.advance(self.task)
        if self.lines:
            how = "done" if outcome.ok else "failed"
            self.console.print(f"  {self.done}/{self.total} {Path(outcome.label).name}: {how} "
                               f"({time.perf_counter() - self.started:.1f} s)", highlight=False)
