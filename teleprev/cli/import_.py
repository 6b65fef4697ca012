"""`teleprev import FILE... --recipe R.toml --repo-id NAME`: robot recordings teleprev did not make (ROS 2
MCAP, rosbag2 folders, Foxglove-schema MCAP) into a LeRobot dataset, through the export's machinery.

Only typer and the standard library at import time (see cli/export.py)."""

from __future__ import annotations

from pathlib import Path

import typer

from teleprev.cli.export import DATASET_ROOT, DEFAULT_ROOT, FPS, REPO_ID, Codec, print_report, run_stoppable


def import_(
    files: list[Path] = typer.Argument(
        ...,
        help="ROS 2 .mcap files, rosbag2 folders (sqlite3 or mcap) or Foxglove-schema "
        ".mcap files, imported in this order.",
        show_default=False,
    ),
    recipe: str = typer.Option(
        ...,
        "--recipe",
        help="Import recipe: which topics become which features, how episodes "
        "are cut: a file, or the name of one in datasets/imports/ (ros2_arm).",
        show_default=False,
    ),
    repo_id: str = REPO_ID,
    root: Path | None = DATASET_ROOT,
    fps: int = FPS,
    append: bool = typer.Option(False, "--append", help="Add the files to an existing dataset."),
    codec: Codec | None = typer.Option(
        None, "--codec", help="Video codec (default: the recipe's).", show_default=False
    ),
    as_json: bool = typer.Option(False, "--json", help="Print the summary as one JSON object instead of a table."),
) -> None:
    """Import robot recordings (ROS 2 MCAP, rosbag2, Foxglove MCAP) into a LeRobot dataset."""
    from rich.console import Console

    from teleprev.export.foreign.config import load_import_recipe
    from teleprev.export.foreign.run import import_files
    from teleprev.export.run import with_video

    the_recipe = load_import_recipe(recipe)
    video = with_video(the_recipe.recipe, codec=codec)
    target = root if root is not None else DEFAULT_ROOT / repo_id
    console = Console(stderr=as_json)
    report = run_stoppable("import", target, lambda bars: import_files(
        files, the_recipe, repo_id, target, fps=fps, append=append, video=video, report=bars), console)
    print_report(console, report, as_json, f"robot {the_recipe.robot_type}, video: {video.describe()}")
