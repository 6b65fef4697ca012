"""The LeRobot dataset being written, and the staging that keeps a failed export from leaving anything.

Everything is built inside a temporary folder beside the target (same file system, so the final move
is a rename) and moved into place only after lerobot's finalize(). Appending stages a copy of the
existing dataset (files lerobot never rewrites are hard links, the rest copies), resumes it there with
lerobot's resume(), and swaps it in at the end; the original stays untouched until that swap.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path

from teleprev.errors import ConfigError
from teleprev.export.swap import claim, replace_dir, staging_prefix
from teleprev.export.video import VideoSettings

INFO = Path("meta") / "info.json"


class Staging:
    """A temporary folder beside `target`, marked as this process's; `commit` moves the built dataset
    into place atomically (swap.py)."""

    def __init__(self, target: Path):
        self.target = Path(target).resolve()
        try:
            self.target.parent.mkdir(parents=True, exist_ok=True)
            self.dir = Path(tempfile.mkdtemp(prefix=staging_prefix(self.target), dir=self.target.parent))
            claim(self.dir)
        except OSError as exc:
            raise ConfigError(f"cannot create the export's working folder here: {exc.strerror}",
                              str(self.target.parent)) from None
        self.dataset = self.dir / "dataset"

    def part(self, i: int) -> Path:
        return self.dir / f"part-{i:04d}"

    def commit(self) -> None:
        """Move the built dataset to the target; an existing target (appending, or an empty folder) is
        replaced in one step."""
        usual_modes(self.dataset)
        if self.target.exists():
            replace_dir(self.dataset, self.target, self.dir)
        else:
            os.rename(self.dataset, self.target)
        shutil.rmtree(self.dir, ignore_errors=True)

    def abort(self) -> None:
        shutil.rmtree(self.dir, ignore_errors=True)


def usual_modes(root: Path) -> None:
    """Give every file and folder under root the mode the user's umask gives new ones: lerobot writes the
    videos it concatenates through tempfile, whose files are private (0600), so a dataset of several
    episodes had videos nobody else could read."""
    umask = os.umask(0o022)  # reading the umask means setting it: set it straight back
    os.umask(umask)
    for path in [root, *root.rglob("*")]:
        wanted = (0o777 if path.is_dir() else 0o666) & ~umask
        if not path.is_symlink() and path.stat().st_mode & 0o777 != wanted:
            path.chmod(wanted)


def read_info(root: Path) -> dict:
    """An existing dataset's meta/info.json (without importing lerobot)."""
    path = Path(root) / INFO
    if not path.is_file():
        raise ConfigError(f"not a LeRobot dataset (no {INFO})", str(root))
    try:
        return json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{INFO} is not valid JSON ({exc})", str(root)) from None


EPISODES_META = Path("meta") / "episodes"


def check_files(root: Path, info: dict) -> None:
    """Refuse to append to a dataset a file of which is missing: every data and video file its episodes'
    metadata names (info.json's data_path and video_path filled in), and the episodes' metadata itself.
    Appending would otherwise write new episodes beside a hole that training fails on later."""
    import pyarrow.parquet as pq

    root = Path(root)
    tables = sorted((root / EPISODES_META).rglob("*.parquet"))
    if not tables and int(info.get("total_episodes", 0)):
        raise ConfigError(f"the dataset's episode metadata ({EPISODES_META}/) is missing: it cannot be appended to",
                          str(root))
    videos = [k for k, f in info.get("features", {}).items() if f.get("dtype") == "video"]
    wanted: dict[Path, None] = {}
    for table in tables:
        try:
            columns = pq.read_table(table).to_pydict()
        except Exception as exc:  # pyarrow's errors have no common base below Exception
            raise ConfigError(f"{table.relative_to(root)} cannot be read ({exc})", str(root)) from None
        templates = [("data", info.get("data_path"), {})] + [(f"videos/{k}", info.get("video_path"), {"video_key": k})
                                                             for k in videos]
        for prefix, template, fields in templates:
            chunks, files = columns.get(f"{prefix}/chunk_index"), columns.get(f"{prefix}/file_index")
            if not template or chunks is None or files is None:
                continue
            for chunk, file in zip(chunks, files):
                wanted[Path(template.format(chunk_index=chunk, file_index=file, **fields))] = None
    for rel in wanted:
        if not (root / rel).is_file():
            raise ConfigError(f"{rel} is missing (the dataset's episodes name it): appending to a damaged dataset "
                              "is refused; restore the file, or export into a new --root", str(root))


def check_compatible(info: dict, features: dict, fps: int, robot_type: str, video: VideoSettings, where: str) -> None:
    """Refuse to append sessions whose features, fps, robot or codec differ from the dataset's."""
    if info.get("fps") != fps:
        raise ConfigError(f"the dataset is at {info.get('fps')} fps, these sessions would export at {fps} "
                          f"(pass --fps {info.get('fps')})", where)
    if (info.get("robot_type") or "unknown") != robot_type:
        raise ConfigError(f"the dataset's robot is {info.get('robot_type')!r}, the sessions' is {robot_type!r}", where)
    theirs = {k: v for k, v in info.get("features", {}).items()
              if k not in ("timestamp", "frame_index", "episode_index", "index", "task_index")}
    if set(theirs) != set(features):
        raise ConfigError(f"the dataset's features ({', '.join(sorted(theirs))}) differ from the recipe's "
                          f"({', '.join(sorted(features))})", where)
    for name, ours in features.items():
        t = theirs[name]
        if (
            t.get("dtype") != ours["dtype"]
            or tuple(t.get("shape", ())) != tuple(ours["shape"])
            or t.get("names") != ours["names"]
        ):
            raise ConfigError(f"feature {name!r} differs: dataset {t.get('dtype')} {t.get('shape')} {t.get('names')}, "
                              f"sessions {ours['dtype']} {list(ours['shape'])} {ours['names']}", where)
        codec = (t.get("info") or {}).get("video.codec")
        if ours["dtype"] == "video" and codec and codec != video.codec:
            raise ConfigError(f"the dataset's videos are {codec}; pass --codec {codec} to append to it", where)


def stage_copy(existing: Path, dest: Path) -> None:
    """A copy of a dataset that resume() can write to without touching the original: meta/ and the
    newest file of every data/video folder are copied; older data and video files, which lerobot
    never rewrites, are hard-linked (copied where links are not possible)."""
    existing = Path(existing)
    newest: set[Path] = set()
    for folder in ("data", "videos"):
        groups: dict[Path, list[Path]] = {}
        for p in (existing / folder).rglob("*"):
            if p.is_file():
                groups.setdefault(p.parent.parent, []).append(p)
        newest.update(max(files) for files in groups.values())

    def place(src: str, dst: str) -> str:
        s = Path(src)
        rel = s.relative_to(existing)
        if rel.parts[0] in ("data", "videos") and s not in newest:
            try:
                os.link(src, dst)
                return dst
            except OSError:
                pass
        return shutil.copy2(src, dst)

    shutil.copytree(existing, dest, copy_function=place)


def prepare_lerobot() -> None:
    """Before writing: FFmpeg's encoder chatter and the datasets library's progress bars would bury the
    export's own; and lerobot's per-episode embed_images step is skipped where it does nothing."""
    import av
    from lerobot.datasets import dataset_writer

    import datasets

    av.logging.set_libav_level(av.logging.ERROR)
    datasets.disable_progress_bars()
    if not getattr(dataset_writer.embed_images, "teleprev_skips_noop", False):
        dataset_writer.embed_images = _embed_images_unless_noop(dataset_writer.embed_images)


def _embed_images_unless_noop(embed):
    """lerobot's save_episode runs embed_images (a row-by-row datasets.map of embed_table_storage,
    ~1.2 ms per frame) on every episode; it embeds image files into the table, so with no image
    column (cameras stored as video) it returns the table unchanged. This wrapper returns the dataset
    as it is in that case and calls lerobot's function otherwise (tests/test_export_dataset.py checks
    that the two give the same table)."""
    import datasets

    def embeddable(feature) -> bool:
        if isinstance(feature, (datasets.Image, datasets.Audio)) or type(feature).__name__ in ("Video", "Pdf"):
            return True
        if isinstance(feature, dict):
            return any(embeddable(f) for f in feature.values())
        inner = getattr(feature, "feature", None)
        return inner is not None and embeddable(inner)

    def embed_images(dataset):
        if any(embeddable(f) for f in dataset.features.values()):
            return embed(dataset)
        return dataset

    embed_images.teleprev_skips_noop = True
    embed_images.lerobot_embed_images = embed
    return embed_images


def create(repo_id: str, root: Path, fps: int, features: dict, robot_type: str, video: VideoSettings):
    """A new dataset in write mode at `root` (which must not exist)."""
    from teleprev.export.lerobot_video import TeleprevDataset, encoder_config

    prepare_lerobot()
    return TeleprevDataset.for_settings(video).create(
        repo_id=repo_id, fps=fps, features=features, root=root, robot_type=robot_type, use_videos=True,
        video_backend="pyav", streaming_encoding=video.streaming, rgb_encoder=encoder_config(video),
        encoder_threads=video.encoder_threads, encoder_queue_maxsize=video.queue,
    )


def resume(repo_id: str, root: Path, video: VideoSettings):
    """An existing dataset at `root`, in write mode for more episodes."""
    from teleprev.export.lerobot_video import TeleprevDataset, encoder_config

    prepare_lerobot()
    return TeleprevDataset.for_settings(video).resume(
        repo_id, root=root, video_backend="pyav", streaming_encoding=video.streaming,
        rgb_encoder=encoder_config(video), encoder_threads=video.encoder_threads, encoder_queue_maxsize=video.queue,
    )


def close_failed(dataset) -> None:
    """Stop a dataset's encoders and writers after a failure, so nothing writes into the staging folder
    while it is removed (lerobot's writers would finalize themselves when garbage-collected)."""
    if dataset is None:
        return
    for step in (lambda: dataset.writer.cancel_pending_videos(), dataset.finalize):
        try:
            step()
        except Exception:  # the export is failing already
            pass
