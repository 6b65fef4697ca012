"""`teleprev rollout`: a policy trained with lerobot-train drives the robot, previewed, limited and recorded."""

from __future__ import annotations

from pathlib import Path

import typer


def rollout(
    policy: Path = typer.Option(
        ...,
        "--policy",
        help="A policy saved by lerobot-train: its pretrained_model folder "
        "(e.g. outputs/train/act/checkpoints/last/pretrained_model).",
    ),
    config: Path | None = typer.Option(None, "--config", help="Rig file (TOML). Default: the all-simulated rig."),
    episodes: int = typer.Option(1, "--episodes", help="How many episodes to run."),
    episode_time: float = typer.Option(
        10.0, "--episode-time", help="Seconds per episode (preview first, then execute)."
    ),
    engage_after: float = typer.Option(
        1.0,
        "--engage-after",
        help="Seconds of preview at the start of each episode before the robot executes the policy's actions.",
    ),
    reset_time: float = typer.Option(
        0.0, "--reset-time", help="Seconds between episodes, the robot in preview (to reset the scene)."
    ),
    out: Path | None = typer.Option(
        None, "--out", "-o", help="Session file to write (default: sessions/<time>_rollout.mcap)."
    ),
    recipe: str | None = typer.Option(
        None,
        "--recipe",
        help="The export recipe the policy's dataset was made with "
        "(a name in datasets/recipes/ or a file; default: default).",
    ),
    models: Path | None = typer.Option(
        None, "--models", help="Folder with CPN/CCN weights (default: the rig's, else models/)."
    ),
    task: str = typer.Option("", "--task", "-t", help="Task id of the episodes (the policy reads its instruction)."),
) -> None:
    """Run a trained LeRobot policy on the rig: each episode previewed, then executed through the same
    limits, Corrector and paced sender as the operator's targets; recorded as a session."""
    from rich.console import Console
    from rich.markup import escape

    from teleprev.cli.outputs import check_output
    from teleprev.cli.record import never_engaged
    from teleprev.cli.signals import StopSignals
    from teleprev.live.record.run import print_summary
    from teleprev.live.record.session import default_session_path
    from teleprev.live.rollout.rollout import Rollout, RolloutOptions, check_rollout

    options = RolloutOptions(policy=policy, out=out or default_session_path("rollout"), rig=config, episodes=episodes,
                             episode_time_s=episode_time, engage_after_s=engage_after, reset_time_s=reset_time,
                             recipe=recipe, models=models, task=task)
    check_output(options.out, "--out", overwrite=False, make_parents=True)
    plan = check_rollout(options)  # bad input: one line, exit 2, before anything opens
    console = Console()
    console.print(f"loading {plan.card.type} policy from {escape(str(policy))} ...", highlight=False)
    run = result = None
    with StopSignals() as signals:  # SIGTERM, SIGHUP as Ctrl-C: the robot stops, the recording is finalized
        try:
            from teleprev.live.rollout.lerobot_policy import LeRobotPolicy

            loaded = LeRobotPolicy.load(policy)
            with signals.deferred():  # the session file opened whole (a signal now is raised below)
                run = Rollout(options, plan, loaded)
            signals.check()
            result = run.run(signals)
        except KeyboardInterrupt:
            if run is not None and run.recording.summary is None:  # stopped before the run began
                with signals.finishing():
                    run.recording.stop()
    if run is None:  # (only a signal leaves it so) stopped while the policy loaded: nothing was recorded
        signals.exit_if_stopped(console)
    recording = run.recording
    try:
        if recording.summary is not None:
            print_summary(console, recording, recording.summary)
        stats = run.runner.stats
        console.print(f"policy: {stats.inferences} inferences ({stats.policy_hz():.1f} Hz while inferring), "
                      f"{stats.handed} actions handed on at {plan.fps:g} fps, {stats.starved} frames without one",
                      highlight=False)
        if recording.summary is not None:
            print_success(console, recording.options.out)
    except OSError:  # the terminal went away with the SIGHUP; the file is complete all the same
        pass
    signals.exit_if_stopped(console, options.out)
    errors = Console(stderr=True)
    if result is not None and result.unconnected:
        for line in result.unconnected:
            errors.print(f"[bold red]error:[/] {escape(line)}", highlight=False, soft_wrap=True)
        raise typer.Exit(1)
    failure = stats.failure or recording.loop.failure
    if failure:
        errors.print(f"[bold red]error:[/] {escape(failure)} (the robot was braked to rest)", highlight=False,
                     soft_wrap=True)
        raise typer.Exit(1)
    if recording.loop.stats.device_failures:
        raise typer.Exit(1)
    missed = never_engaged(recording.loop, engage_after) if result is not None else ""
    if missed:
        errors.print(f"[bold red]error:[/] {escape(missed)}", highlight=False, soft_wrap=True)
        raise typer.Exit(1)


def print_success(console, session: Path) -> None:
    """Each task's success rate over the session's episodes (lerobot-eval's pc_success), from the marks the
    session recorded: the physics world's on a physics rig; nothing where no episode has an outcome."""
    from teleprev.session.episodes import success_by_task
    from teleprev.session.reader import SessionReader

    with SessionReader(session) as reader:
        rates = success_by_task(reader.episodes())
    for rate in rates.values():
        if rate.pc_success is not None:
            console.print(f"success {rate.task or '(no task)'}: {rate.successes} of {rate.judged} episodes "
                          f"(pc_success {rate.pc_success:.1f})", highlight=False)
