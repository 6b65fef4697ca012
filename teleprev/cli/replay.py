"""`teleprev replay` and `teleprev eval`: show a session again, and re-run it to measure the pipeline."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer


def replay(
    session: Path = typer.Argument(..., help="Session file (.mcap)."),
    episode: Optional[int] = typer.Option(None, "--episode", "-e", help="Play one episode (default: the whole session)."),
    speed: float = typer.Option(1.0, "--speed", "-x", min=0.01, help="Playback speed multiple (capped so no joint exceeds its limit)."),
    to: str = typer.Option("preview", "--to", help="preview (screen only), sim (the simulated robot) or arm (the rig's robot)."),
    rig: Optional[Path] = typer.Option(None, "--rig", help="Rig whose robot receives the commands with --to arm (default: the recorded rig)."),
    engage_after: Optional[float] = typer.Option(None, "--engage-after", help="Engage automatically after this many seconds (else press space)."),
    view: str = typer.Option("side", "--view", help="Robot view: front, side or top."),
    preview: bool = typer.Option(True, "--preview/--no-preview", help="Show the terminal preview."),
) -> None:
    """Play a session's commands back, on screen and optionally to the simulated or a real robot."""
    from rich.console import Console

    from teleprev.live.playback import play

    if to not in ("preview", "sim", "arm"):
        raise typer.BadParameter("--to must be preview, sim or arm")
    play(session, episode, speed, to, rig, engage_after, Console(), view, preview)


def eval_(
    sessions: list[Path] = typer.Argument(..., help="Session files (.mcap)."),
    models: Optional[Path] = typer.Option(None, "--models", help="CPN/CCN weights to evaluate (default: the shipped models)."),
    config: Optional[Path] = typer.Option(None, "--config", help="Rig file to evaluate with (default: the rig recorded in each session)."),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="Write the report as JSON here (for CI and as a later baseline)."),
    baseline: Optional[Path] = typer.Option(None, "--baseline", help="An earlier report: exit 1 if a metric regressed past its tolerance."),
    tolerances: Optional[Path] = typer.Option(None, "--tolerances", help="Tolerances TOML (default: teleprev/evaluation/tolerances.toml)."),
    plots: Optional[Path] = typer.Option(None, "--plots", help="Write a PNG per episode (recorded vs re-run joints) into this folder."),
) -> None:
    """Re-run the pipeline on recorded raw streams, measure it, and catch regressions."""
    from rich.console import Console

    from teleprev.evaluation.evaluate import evaluate
    from teleprev.evaluation.report import load_tolerances, print_report, read_report, write_report

    console = Console()
    result = evaluate(
        sessions, models, config,
        baseline=read_report(baseline) if baseline else None,
        tolerances=load_tolerances(tolerances) if tolerances else None,
    )
    print_report(console, result.report, result.regressions)
    if out:
        write_report(result.report, out)
        console.print(f"report written to {out}")
    if plots:
        from teleprev.evaluation.plots import plot_episodes

        written = [p for r in result.reruns for p in plot_episodes(r, plots)]
        console.print(f"{len(written)} plot(s) written to {plots}")
    if result.regressions:
        raise typer.Exit(1)


def audit(
    sessions: list[Path] = typer.Argument(..., help="Session files (.mcap)."),
    config: Optional[Path] = typer.Option(None, "--config", help="Rig whose limits apply (default: the rig recorded in each session)."),
    json_out: Optional[Path] = typer.Option(None, "--json", help="Write the audit as JSON here."),
) -> None:
    """Check every command stream against the robot's limits: position, speed, acceleration, jerk, and
    (for a hand) end-point and swept self-collision. Exits 1 on any violation."""
    from rich.console import Console

    from teleprev.evaluation.audit import audit_session, print_report, write_json

    console = Console()
    reports = [audit_session(s, config) for s in sessions]
    for r in reports:
        print_report(r, console)
    if json_out:
        write_json(reports, json_out)
        console.print(f"audit written to {json_out}")
    if not all(r.ok for r in reports):
        raise typer.Exit(1)
