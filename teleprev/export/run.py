"""An export from start to end: check every session and the target first, build the dataset in a
staging folder (in this process, or as one task per session whose parts are merged), finalize, move it
into place.

In this process, any failure, Ctrl-C included, removes the staging folder: the target is either the
complete new (or appended) dataset or exactly what it was before. With workers (`workers` > 1 or
`ray`), each session is a task of its own: one that fails, or whose worker dies twice, is listed in the
report's `failed` and the others are merged; only when every session fails does the export fail.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

from teleprev.errors import ConfigError, SessionError, out_of_space
from teleprev.export import dataset as D
from teleprev.export.episode_meta import rows_for, write_columns
from teleprev.export.recipe import Recipe
from teleprev.export.repo_id import check_repo_id
from teleprev.export.report import ExportReport, SessionReport, folder_size
from teleprev.export.selection import episode_facts
from teleprev.export.session import ExportSettings, Progress, Reporter, SessionSource, export_session, no_progress
from teleprev.export.space import space_error
from teleprev.export.swap import clean_stale
from teleprev.export.video import VideoSettings


@dataclass
class ExportOptions:
    sessions: list[Path]
    repo_id: str
    root: Path
    recipe: Recipe
    fps: int = 0  # 0: the recipe's, else the reference camera's rate (appending: the dataset's)
    append: bool = False
    include_discarded: bool = False
    workers: int = 1
    video: VideoSettings | None = None  # None: the recipe's
    ray: str | None = None  # run the sessions on Ray: "local" (a new local instance), "auto", "HOST:PORT"
    open_reader: Callable | None = None  # files that are not teleprev sessions (teleprev/export/foreign/); one process
    selected: dict[str, frozenset[int]] | None = None  # session -> its episodes to export (None: all; selection.py)

    def __post_init__(self):
        check_repo_id(self.repo_id)


def export(options: ExportOptions, report: Reporter = no_progress) -> ExportReport:
    started = time.perf_counter()
    os.environ.setdefault("HF_HUB_OFFLINE", "1")  # an export is local: lerobot must never reach for the Hub
    target = Path(options.root)
    video = options.video or options.recipe.video
    if not options.sessions:
        raise ConfigError("no session files given")
    cleaned = clean_stale(target.resolve())  # first: a swap a kill interrupted puts the old dataset back
    for line in cleaned:
        report(Progress("note", line))
    if target.exists() and not options.append and (not target.is_dir() or any(target.iterdir())):
        raise ConfigError(
            "already exists; pass --append to add these sessions to it, or choose another --root", str(target)
        )
    info = None
    fps = options.fps
    if options.append:
        if not target.exists():
            raise ConfigError("--append: there is no dataset here to append to", str(target))
        info = D.read_info(target)
        D.check_files(target, info)
        fps = fps or int(info.get("fps", 0))

    parallel = options.open_reader is None and (
        options.ray is not None or (options.workers > 1 and len(options.sessions) > 1)
    )
    executor = (
        _local_workers(options) if parallel else None
    )  # started now: lerobot loads while the sessions are checked
    sources, skipped = _open_all(options, fps)
    facts = [f for s in sources for f in episode_facts(s.reader, s.path)]  # before workers: the readers close
    first_episode = int(info.get("total_episodes", 0)) if info is not None else 0
    if skipped:
        options = replace(options, sessions=[p for p in options.sessions if str(p) not in skipped])
    try:
        first = sources[0]
        fps = first.dataset_fps()
        features = first.lerobot_features()
        robot = first.robot_type
        for s in sources[1:]:
            _check_same(s, first, features, fps, robot)
        if info is not None:
            D.check_compatible(info, features, fps, robot, video, str(target))
    except BaseException:
        for s in sources:
            s.close()
        raise

    settings = ExportSettings(fps, options.include_discarded, options.selected)
    staging = D.Staging(target)
    try:
        failed: dict[str, str] = {}
        startup = 0.0
        if parallel:
            for s in sources:
                s.close()  # workers open their own readers (and import lerobot themselves, once each)
            reports = _parallel(options, staging, features, robot, fps, settings, video, report, failed, executor)
        else:
            startup = time.perf_counter()  # after the checks, so bad input is refused without waiting for it
            report(Progress("phase", "loading lerobot"))
            import lerobot.datasets.lerobot_dataset  # noqa: F401  (seconds, once per process: reported apart)

            report(Progress("phase", ""))
            startup = time.perf_counter() - startup
            reports = _sequential(options, sources, staging, features, robot, fps, settings, video, report)
        _refuse_empty(reports)
        write_columns(staging.dataset, first_episode, rows_for(reports, facts))
        totals = D.read_info(staging.dataset)
        staging.commit()
    except BaseException as exc:
        staging.abort()
        what = out_of_space(exc) if isinstance(exc, Exception) else ""
        if what:
            raise space_error(what, target, options.sessions, options.append) from None
        raise
    finally:
        for s in sources:
            s.close()
    out = ExportReport(target, options.repo_id, fps, reports, failed=failed, cleaned=cleaned, skipped=skipped)
    out.total_episodes = int(totals.get("total_episodes", 0))
    out.total_frames = int(totals.get("total_frames", 0))
    out.size_bytes = folder_size(target)
    out.wall_s = time.perf_counter() - started
    out.startup_s = startup
    return out


def _open_all(options: ExportOptions, fps: int) -> tuple[list[SessionSource], dict[str, str]]:
    """Every session opened for export; of several, one recorded in preview only (it has no commands for
    the recipe's actions) is left out and listed (session -> why) rather than stopping the others."""
    sources: list[SessionSource] = []
    skipped: dict[str, str] = {}
    try:
        for path in options.sessions:
            try:
                sources.append(SessionSource(Path(path), options.recipe, fps, options.open_reader))
            except SessionError:
                if len(options.sessions) > 1 and options.open_reader is None and _preview_only(Path(path)):
                    skipped[str(path)] = "recorded in preview only: no commands to export"
                    continue
                raise
        if not sources:  # every one of them: the first says why
            SessionSource(Path(options.sessions[0]), options.recipe, fps).close()
    except BaseException:
        for s in sources:
            s.close()
        raise
    return sources, skipped


def _preview_only(path: Path) -> bool:
    from teleprev.session.reader import SessionReader
    from teleprev.session.summary import is_preview_only

    with SessionReader(path) as reader:
        return is_preview_only(reader.schemas)


def _check_same(s: SessionSource, first: SessionSource, features: dict, fps: int, robot: str) -> None:
    where = str(s.path)
    if s.robot_type != robot:
        raise SessionError(f"recorded with robot {s.robot_type!r}, but {first.path.name} with {robot!r}: one dataset "
                           "holds one robot", where)
    theirs = s.lerobot_features()
    for name, spec in features.items():
        other = theirs.get(name)
        if other != spec:
            got = "nothing" if other is None else f"{other['dtype']} {list(other['shape'])} {other['names']}"
            raise SessionError(f"feature {name!r} would be {got}, but {first.path.name} gives "
                               f"{spec['dtype']} {list(spec['shape'])} {spec['names']}", where)
    extra = sorted(set(theirs) - set(features))
    if extra:
        raise SessionError(f"has features {extra} that {first.path.name} lacks", where)
    s.fps = s.fps or fps
    if s.dataset_fps() != fps:
        raise SessionError(f"would export at {s.dataset_fps()} fps, {first.path.name} at {fps}; pass --fps", where)


def _sequential(options, sources, staging, features, robot, fps, settings, video, report) -> list[SessionReport]:
    ds = None
    try:
        report(Progress("phase", "opening the dataset"))
        if options.append:
            D.stage_copy(Path(options.root), staging.dataset)
            ds = D.resume(options.repo_id, staging.dataset, video)
        else:
            ds = D.create(options.repo_id, staging.dataset, fps, features, robot, video)
        report(Progress("phase", ""))
        reports = [export_session(s, ds, settings, report) for s in sources]
        _refuse_empty(reports)
        report(Progress("phase", "finalizing"))
        ds.finalize()
        report(Progress("phase", ""))
        return reports
    except BaseException:
        D.close_failed(ds)
        raise


def _local_workers(options: ExportOptions):
    """The local workers' executor with its fork server started (None for Ray, which starts in
    _parallel, after the checks: a cluster is not joined for input that is then refused)."""
    if options.ray is not None:
        return None
    from teleprev.corpus.executor import LocalExecutor
    from teleprev.export.parallel import PRELOAD

    executor = LocalExecutor(options.workers, PRELOAD)
    executor.start()
    return executor


def _parallel(
    options, staging, features, robot, fps, settings, video, report, failed, executor=None
) -> list[SessionReport]:
    from teleprev.corpus.executor import make_executor
    from teleprev.export.parallel import PRELOAD, Job, export_parallel, merge

    paths = [Path(p) for p in options.sessions]
    parts = [staging.part(i) for i in range(len(paths))]
    job = Job(options.repo_id, options.recipe, fps, features, robot, settings, video)
    where = "a Ray cluster" if options.ray is not None else f"{min(options.workers, len(paths))} workers"
    report(Progress("phase", f"starting {where} (lerobot loads once per worker)"))
    if executor is None:
        executor = make_executor(options.workers, options.ray, PRELOAD)
    try:
        outcomes = export_parallel(paths, parts, job, executor, report)
        reports = [o.value for o in outcomes if o.ok]
        if not reports:
            raise next(o for o in outcomes if not o.ok).exception()  # nothing to merge: the first failure says why
        failed.update({str(paths[o.index]): _failure(o) for o in outcomes if not o.ok})
        _refuse_empty(reports)
        used = [parts[o.index] for o in outcomes if o.ok and o.value.lerobot_episodes]
        report(Progress("phase", f"merging {len(used)} parts with lerobot's aggregate_datasets"))
        merge(executor, used, options.repo_id, staging.dataset, Path(options.root) if options.append else None)
        report(Progress("phase", ""))
    finally:
        executor.close()
    return reports


def _failure(outcome) -> str:
    return str(outcome.exception())


def _refuse_empty(reports: list[SessionReport]) -> None:
    if any(r.lerobot_episodes for r in reports):
        return
    why = [f"{Path(r.session).name} episode {e.index}: {e.dropped}" for r in reports for e in r.episodes if e.dropped]
    why += [f"{Path(r.session).name}: {n}" for r in reports for n in r.notes]
    raise SessionError("no episode could be exported" + (": " + "; ".join(why) if why else ""))


def with_video(recipe: Recipe, **changes) -> VideoSettings:
    """The recipe's video settings with the given fields replaced (None values are ignored); a new
    codec without a preset or crf gets that codec's defaults."""
    from teleprev.export.video import CODEC_DEFAULTS

    changes = {k: v for k, v in changes.items() if v is not None}
    codec = changes.get("codec")
    if codec in CODEC_DEFAULTS and codec != recipe.video.codec:
        preset, crf, threads = CODEC_DEFAULTS[codec]
        changes.setdefault("preset", preset)
        changes.setdefault("crf", crf)
        changes.setdefault("threads", threads)
    try:
        return replace(recipe.video, **changes)
    except ValueError as exc:
        raise ConfigError(str(exc), "video settings") from None

