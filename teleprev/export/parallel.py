"""Sessions exported as independent tasks (teleprev.corpus.executor: local worker processes or a Ray
cluster), one part dataset per session, merged at the end with lerobot's own aggregation
(lerobot.datasets.aggregate.aggregate_datasets), in session order.

Local workers come from a fork server that has imported lerobot once (a worker starts in milliseconds,
not the seconds lerobot's import takes) and is itself single-threaded (so forking is safe while the
parent draws its progress bars); a worker takes the next session as soon as it is free, so a long
session does not hold up the others. A session that fails, or whose worker dies twice, is reported
and left out; the others are exported and merged. The merge runs as one more task, where lerobot is
imported already (the parent never imports it on this path).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from teleprev.corpus.executor import Outcome
from teleprev.errors import SessionError
from teleprev.export.recipe import Recipe
from teleprev.export.report import SessionReport
from teleprev.export.session import ExportSettings, Reporter
from teleprev.export.video import VideoSettings

PRELOAD = ["lerobot.datasets.lerobot_dataset", "lerobot.datasets.video_utils", "lerobot.datasets.aggregate",
           "teleprev.export.session", "teleprev.export.dataset", "teleprev.export.lerobot_video", "cv2"]


@dataclass(frozen=True)
class Job:
    repo_id: str
    recipe: Recipe
    ask_fps: int
    features: dict
    robot_type: str
    settings: ExportSettings
    video: VideoSettings


def export_one(job: Job, item: tuple[str, str], emit) -> SessionReport:
    """A task: one session (item: its path, the part folder to create) into a part dataset."""
    from teleprev.export import dataset as D
    from teleprev.export.session import SessionSource, export_session

    os.environ.setdefault("HF_HUB_OFFLINE", "1")  # a worker on another machine has not had the driver's setting
    path, part = item
    ds = source = None
    try:
        source = SessionSource(Path(path), job.recipe, job.ask_fps)
        if source.lerobot_features() != job.features:
            raise SessionError("its features changed since it was checked", path)
        ds = D.create(job.repo_id, Path(part), job.settings.fps, job.features, job.robot_type, job.video)
        rep = export_session(source, ds, job.settings, emit)
        ds.finalize()
        return rep
    except BaseException:
        D.close_failed(ds)
        raise
    finally:
        if source is not None:
            source.close()


def export_parallel(paths: list[Path], parts: list[Path], job: Job, executor, report: Reporter) -> list[Outcome]:
    """Export each session into its part dataset (parts[i], which must not exist); the outcomes in
    session order, each holding a SessionReport or why the session failed."""
    items = [(str(Path(p).resolve()), str(Path(part).resolve())) for p, part in zip(paths, parts)]
    return executor.map(export_one, job, items, labels=[str(p) for p in paths], on_event=report)


def merge(executor, parts: list[Path], repo_id: str, root: Path, existing: Path | None = None) -> None:
    """Aggregate the part datasets (after the existing dataset, when appending) into `root`, as a task
    of the executor (its workers have lerobot imported; this process has not)."""
    item = (
        [str(Path(p).resolve()) for p in parts],
        str(Path(root).resolve()),
        str(Path(existing).resolve()) if existing else None,
    )
    outcome = executor.map(merge_parts, repo_id, [item], labels=[str(root)])[0]
    if not outcome.ok:
        raise SessionError(f"merging the parts with lerobot's aggregate_datasets failed: {outcome.error}", str(root))


def merge_parts(repo_id: str, item: tuple[list[str], str, str | None], emit) -> None:
    import contextlib

    from lerobot.datasets.aggregate import aggregate_datasets

    from teleprev.export.dataset import prepare_lerobot

    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    parts, root, existing = item
    prepare_lerobot()
    roots = [Path(p) for p in ([existing] if existing else []) + parts]
    with open(os.devnull, "w") as devnull, contextlib.redirect_stderr(devnull):  # its tqdm bars would cut through ours
        aggregate_datasets(repo_ids=[repo_id] * len(roots), aggr_repo_id=repo_id, roots=roots, aggr_root=Path(root))
