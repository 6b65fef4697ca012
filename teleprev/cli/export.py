"""`teleprev export SESSION... --repo-id NAME`: recorded sessions into a LeRobot dataset (v3.0).

Only typer and the standard library at import time: lerobot (about 10 s to import) and numpy load inside
the command.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

import typer

from teleprev.cli.tables import print_table

DEFAULT_ROOT = Path("datasets") / "out"  # beside sessions/, where `teleprev record` writes by default
Codec = Literal["h264", "hevc", "av1"]
# Options of more than one command (import takes the dataset's, eval the Ray one), declared once.
REPO_ID = typer.Option(..., "--repo-id", help="Dataset name, e.g. lab/pick_place.", show_default=False)
DATASET_ROOT = typer.Option(None, "--root", help="Dataset folder (default: ./datasets/out/<repo-id>).",
                            show_default=False)
FPS = typer.Option(0, "--fps", min=0, show_default=False,
                   help="Frames per second (default: the recipe's, else the reference camera's rate).")
RAY = typer.Option(None, "--ray", metavar="[ADDRESS]", show_default=False,
                   help="Run the sessions on Ray: alone, start a local instance (with -j CPUs, default all); auto, "
                   "HOST:PORT or ray://HOST:PORT: join that cluster. Needs `uv sync --extra ray`.")


def export(
    sessions: list[str] = typer.Argument(
        ...,
        help="Session files (.mcap), folders of them or globs ('sessions/*.mcap'), exported in this order.",
        show_default=False,
    ),
    repo_id: str = REPO_ID,
    root: Path | None = DATASET_ROOT,
    fps: int = FPS,
    recipe: str = typer.Option(
        "default", "--recipe", help="Recipe file, or the name of one in datasets/recipes/ (default, with_glove)."
    ),
    append: bool = typer.Option(False, "--append", help="Add the sessions to an existing dataset (LeRobot's resume)."),
    include_discarded: bool = typer.Option(
        False, "--include-discarded", help="Export episodes the operator discarded too."
    ),
    workers: int = typer.Option(1, "--workers", "-j", help="Export sessions in this many processes, then merge them."),
    ray: str | None = RAY,
    codec: Codec | None = typer.Option(
        None, "--codec", help="Video codec (default: the recipe's, h264).", show_default=False
    ),
    crf: int | None = typer.Option(
        None, "--crf", help="Video quality: lower is better and larger (h264 default 23).", show_default=False
    ),
    preset: str | None = typer.Option(
        None, "--preset", help="Encoder preset (x264: ultrafast..veryslow; av1: 0..13).", show_default=False
    ),
    gop: int | None = typer.Option(
        None, "--gop", help="Keyframe interval (default 2: fast random access in training).", show_default=False
    ),
    streaming: bool | None = typer.Option(
        None,
        "--streaming/--no-streaming",
        help="Encode while frames arrive (default), or write PNGs and encode after.",
        show_default=False,
    ),
    encoder: str | None = typer.Option(
        None, "--encoder", help="Streaming encoder: teleprev (fast, default) or lerobot.", show_default=False
    ),
    on_gap: str | None = typer.Option(
        None, "--on-gap", help="A stream gap inside an episode: split it, drop it, or fail.", show_default=False
    ),
    max_gap_ms: float | None = typer.Option(
        None, "--max-gap-ms", help="Longest silence of a stream that is not a gap.", show_default=False
    ),
    only: str | None = typer.Option(
        None, "--only", help="Only episodes marked success (y), failure (f), or unmarked.", show_default=False
    ),
    task: str | None = typer.Option(
        None, "--task", help="Only episodes of this task (its id or instruction).", show_default=False
    ),
    participant: str | None = typer.Option(
        None, "--participant", help="Only sessions of this study participant.", show_default=False
    ),
    condition: str | None = typer.Option(
        None, "--condition", help="Only sessions of this study condition.", show_default=False
    ),
    holdout: float | None = typer.Option(
        None,
        "--holdout",
        help="Hold this fraction out as a second dataset, <repo-id>_holdout, beside the first.",
        show_default=False,
    ),
    split_by: str = typer.Option("session", "--split-by", help="Hold out whole sessions, or single episodes."),
    seed: int = typer.Option(
        0, "--seed", min=0, help="Seed of the held-out draw (the same seed gives the same split)."
    ),
    as_json: bool = typer.Option(False, "--json", help="Print the summary as one JSON object instead of a table."),
) -> None:
    """Export recorded sessions to a LeRobot dataset, one LeRobot episode per recorded episode."""
    from dataclasses import replace

    from rich.console import Console

    from teleprev.corpus.sessions import resolve_sessions
    from teleprev.errors import ConfigError
    from teleprev.export.recipe import load_recipe
    from teleprev.export.run import ExportOptions, with_video
    from teleprev.export.run import export as run_export
    from teleprev.export.selection import SPLITS, Selection, plan_exports

    if workers < 1:
        raise ConfigError(f"--workers must be at least 1, got {workers}")
    paths = resolve_sessions(sessions)
    the_recipe = load_recipe(recipe)
    overrides = {k: v for k, v in (("on_gap", on_gap), ("max_gap_ms", max_gap_ms)) if v is not None}
    if overrides:
        if on_gap is not None and on_gap not in ("split", "drop", "fail"):
            raise ConfigError(f"--on-gap must be split, drop or fail, got {on_gap!r}")
        try:
            the_recipe = replace(the_recipe, export=replace(the_recipe.export, **overrides))
        except ValueError as exc:
            raise ConfigError(str(exc), "--max-gap-ms") from None
    video = with_video(the_recipe, codec=codec, crf=crf, preset=preset, gop=gop, streaming=streaming, encoder=encoder)
    target = root if root is not None else DEFAULT_ROOT / repo_id
    options = ExportOptions(paths, repo_id, target, the_recipe, fps=fps, append=append,
                            include_discarded=include_discarded, workers=workers, video=video, ray=ray)
    selection = Selection(only, task, participant, condition)
    if split_by not in SPLITS:
        raise ConfigError(f"--split-by must be {' or '.join(SPLITS)}, got {split_by!r}")
    exports, counts = [options], {}
    if selection.filters() or holdout is not None:
        exports, counts = plan_exports(options, selection, holdout, split_by, seed)
    console = Console(stderr=as_json)
    reports = []
    for opts in exports:
        report = run_stoppable("export", opts.root, lambda bars: run_export(opts, bars), console)
        report.selection = counts
        reports.append(report)
        if not as_json:
            print_report(console, report, as_json, f"video: {video.describe()}")
    if as_json:  # one JSON object, the held-out dataset's summary inside it
        import json

        typer.echo(
            json.dumps({**_as_json(reports[0]), **({"holdout": _as_json(reports[1])} if len(reports) > 1 else {})})
        )
    if any(r.failed for r in reports):
        raise typer.Exit(1)  # the rest is in the dataset; a script must still notice


class _Bars:
    """Rich progress bars: one per session (episodes) and one for the episode being written (frames)."""

    def __init__(self, console):
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

        self.progress = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                                 TimeElapsedColumn(), TimeRemainingColumn(), console=console, transient=False)
        self.sessions: dict[str, int] = {}
        self.totals: dict[str, int] = {}
        self.episodes: dict[str, int] = {}
        self.phase: tuple[int, str] | None = None

    def __enter__(self):
        self.progress.__enter__()
        return self

    def __exit__(self, *exc):
        self.progress.__exit__(*exc)

    def __call__(self, ev) -> None:
        p = self.progress
        name = Path(ev.session).name
        if ev.kind == "note":
            p.console.print(ev.session, highlight=False, soft_wrap=True)
        elif ev.kind == "phase":
            if self.phase is not None:
                p.update(self.phase[0], completed=1, description=f"{self.phase[1]}: done")
            self.phase = (p.add_task(f"{ev.session}...", total=1), ev.session) if ev.session else None
        elif ev.kind == "session":
            self.sessions[ev.session] = p.add_task(f"[bold]{name}[/] episodes", total=max(1, ev.total))
            self.totals[ev.session] = max(1, ev.total)
        elif ev.kind == "episode":
            self._end_episode(ev.session)
            self.episodes[ev.session] = p.add_task(f"  {name} episode {ev.episode} frames", total=ev.total)
        elif ev.kind == "frames" and ev.session in self.episodes:
            p.advance(self.episodes[ev.session], ev.count)
        elif ev.kind == "episode_done":
            self._end_episode(ev.session)
            p.advance(self.sessions[ev.session], 1)
        elif ev.kind == "session_done" and ev.session in self.sessions:
            p.update(self.sessions[ev.session], completed=self.totals[ev.session])

    def _end_episode(self, session: str) -> None:
        task = self.episodes.pop(session, None)
        if task is not None:
            self.progress.remove_task(task)


def _as_json(report) -> dict:
    return {
        "root": str(report.root),
        "repo_id": report.repo_id,
        "fps": report.fps,
        "episodes": report.episodes,
        "frames": report.frames,
        "duration_s": round(report.duration_s, 3),
        "total_episodes": report.total_episodes,
        "total_frames": report.total_frames,
        "wall_s": round(report.wall_s, 3),
        "startup_s": round(report.startup_s, 3),
        "realtime_x": round(report.realtime_x, 2),
        "max_align_err_ms": round(report.align_err_ms, 3),
        "size_bytes": report.size_bytes,
        "failed": report.failed,
        "skipped": report.skipped,
        "cleaned": report.cleaned,
        "selection": report.selection,
        "sessions": [
            {
                "session": s.session,
                "source_episodes": s.source_episodes,
                "episodes": s.lerobot_episodes,
                "frames": s.frames,
                "duration_s": round(s.duration_s, 3),
                "notes": s.notes,
                "dropped": {e.index: e.dropped for e in s.episodes if e.dropped},
                "split": {e.index: e.gaps for e in s.episodes if e.pieces > 1},
                "align_err_ms": round(s.align_err_ms, 3),
                "image_err_ms": round(s.image_err_ms, 3),
                "held_frames": sum(e.held_frames for e in s.episodes),
            }
            for s in report.sessions
        ],
    }


def run_stoppable(verb: str, target: Path, job, console):
    """job(bars) with progress bars, stopped by SIGTERM / SIGHUP as by Ctrl-C (its staging folder goes):
    then one line saying the target is as it was, and exit 128 + the signal."""
    from rich.console import Console

    from teleprev.cli.signals import StopSignals

    with StopSignals() as signals:
        try:
            with _Bars(console) as bars:
                return job(bars)
        except KeyboardInterrupt:
            Console(stderr=True).print(f"{verb} stopped by {signals.name or 'SIGINT'}; {target} is as it was",
                                       highlight=False, soft_wrap=True)
            raise typer.Exit(signals.exit_code or 130) from None


def print_report(console, report, as_json: bool, details: str) -> None:
    """The export's summary table and notes (or its JSON), and the closing line with `details`."""
    if as_json:
        import json

        typer.echo(json.dumps(_as_json(report)))
        return
    from teleprev.export.report import export_notes, summary_table

    print_table(console, summary_table(report))
    for line in export_notes(report):  # soft_wrap: a path stays whole, to be copied
        console.print(line, highlight=False, soft_wrap=True)
    console.print(f"[green]done:[/] {report.total_episodes} episodes, {report.total_frames} frames in {report.root} "
                  f"({details})", highlight=False, soft_wrap=True)
