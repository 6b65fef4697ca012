"""Sessions exported in parallel worker processes, one part dataset per session, merged at the end
with lerobot's own aggregation (lerobot.datasets.aggregate.aggregate_datasets), in session order.

Workers come from a fork server that has imported lerobot once (so a worker starts in milliseconds,
not the ~10 s lerobot's import takes) and is itself single-threaded (so forking is safe while the
parent draws its progress bars). A worker takes the next session from a queue, so a long session does
not hold up the others; its progress and its result come back through a second queue. The first
failure stops every worker; the staging folder then goes away with the parts.
"""

from __future__ import annotations

import multiprocessing as mp
import queue
import signal
from dataclasses import dataclass
from pathlib import Path

from teleprev.errors import SessionError, TeleprevError
from teleprev.export.recipe import Recipe
from teleprev.export.report import SessionReport
from teleprev.export.session import ExportSettings, Progress, Reporter
from teleprev.export.video import VideoSettings

_PRELOAD = ["lerobot.datasets.lerobot_dataset", "lerobot.datasets.video_utils", "lerobot.datasets.aggregate",
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


def _worker(job: Job, tasks, events) -> None:
    from teleprev.export import dataset as D
    from teleprev.export.session import SessionSource, export_session

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C and stops the workers
    while True:
        item = tasks.get()
        if item is None:
            return
        i, path, part = item
        ds = source = None
        try:
            source = SessionSource(Path(path), job.recipe, job.ask_fps)
            if source.lerobot_features() != job.features:
                raise SessionError("its features changed since it was checked", path)
            ds = D.create(job.repo_id, Path(part), job.settings.fps, job.features, job.robot_type, job.video)
            rep = export_session(source, ds, job.settings, events.put)
            ds.finalize()
            events.put(("done", i, rep))
        except TeleprevError as exc:
            D.close_failed(ds)
            events.put(("error", i, type(exc).__name__, exc.message, exc.where))
            return
        except BaseException as exc:  # anything else still ends the export with a message
            D.close_failed(ds)
            events.put(("error", i, "", f"{type(exc).__name__}: {exc}", path))
            return
        finally:
            if source is not None:
                source.close()


def _context():
    ctx = mp.get_context("forkserver")
    ctx.set_forkserver_preload(_PRELOAD)
    return ctx


def export_parallel(paths: list[Path], parts: list[Path], job: Job, workers: int, report: Reporter) -> list[SessionReport]:
    """Export each session into its part dataset (parts[i], which must not exist); returns the reports
    in session order. Raises the first worker's error."""
    ctx = _context()
    tasks, events = ctx.Queue(), ctx.Queue()
    for i, (path, part) in enumerate(zip(paths, parts)):
        tasks.put((i, str(path), str(part)))
    n = min(workers, len(paths))
    for _ in range(n):
        tasks.put(None)
    procs = [ctx.Process(target=_worker, args=(job, tasks, events), name=f"export-worker-{k}") for k in range(n)]
    for p in procs:
        p.start()
    results: dict[int, SessionReport] = {}
    try:
        while len(results) < len(paths):
            try:
                event = events.get(timeout=0.5)
            except queue.Empty:
                dead = [p for p in procs if p.exitcode not in (None, 0)]
                if dead:
                    raise SessionError(f"an export worker died (exit code {dead[0].exitcode}) before finishing its "
                                       "session", str(paths[0].parent))
                continue
            if isinstance(event, Progress):
                if len(results) == 0 and event.kind == "session":
                    report(Progress("phase", ""))
                report(event)
            elif event[0] == "done":
                results[event[1]] = event[2]
            else:
                _, i, kind, message, where = event
                raise _error(kind, message, where)
        for p in procs:
            p.join()
    finally:
        for p in procs:
            if p.is_alive():
                p.terminate()
        for p in procs:
            p.join(timeout=10)
    return [results[i] for i in range(len(paths))]


def _error(kind: str, message: str, where: str | None) -> Exception:
    from teleprev import errors

    cls = getattr(errors, kind, None)
    if isinstance(cls, type) and issubclass(cls, TeleprevError):
        return cls(message, where)
    return SessionError(f"an export worker failed: {message}", where)


def merge(parts: list[Path], repo_id: str, root: Path, existing: Path | None = None) -> None:
    """Aggregate the part datasets (after the existing dataset, when appending) into `root`, in a
    process from the fork server, which has lerobot imported already (this process has not)."""
    ctx = _context()
    results = ctx.Queue()
    proc = ctx.Process(target=_merge_worker, args=([str(p) for p in parts], repo_id, str(root),
                                                    str(existing) if existing else None, results), name="export-merge")
    proc.start()
    try:
        while True:
            try:
                outcome = results.get(timeout=0.5)
                break
            except queue.Empty:
                if proc.exitcode is not None:
                    raise SessionError(f"merging the parts failed (the process exited with {proc.exitcode})", str(root))
        if outcome is not None:
            raise SessionError(f"merging the parts with lerobot's aggregate_datasets failed: {outcome}", str(root))
        proc.join()
    finally:
        if proc.is_alive():
            proc.terminate()
        proc.join(timeout=10)


def _merge_worker(parts: list[str], repo_id: str, root: str, existing: str | None, results) -> None:
    import contextlib
    import os

    from lerobot.datasets.aggregate import aggregate_datasets

    from teleprev.export.dataset import prepare_lerobot

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        prepare_lerobot()
        roots = [Path(p) for p in ([existing] if existing else []) + parts]
        with open(os.devnull, "w") as devnull, contextlib.redirect_stderr(devnull):  # its tqdm bars would cut through ours
            aggregate_datasets(repo_ids=[repo_id] * len(roots), aggr_repo_id=repo_id, roots=roots, aggr_root=Path(root))
        results.put(None)
    except BaseException as exc:
        results.put(f"{type(exc).__name__}: {exc}")
