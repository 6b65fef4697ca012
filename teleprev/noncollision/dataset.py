"""Collision datasets on disk: a folder of parquet shards, generated in parallel and resumable.

    <out>/dataset.json         the settings (robot, URDF sha256, sizes, seed, boundary sampling)
    <out>/shard-00000.parquet  columns q (float32[n_joints]), labels (bool[m], per link),
                               pairs (bool[P], per checked link pair), source (uniform|boundary|jitter)

Every shard also carries the settings, URDF hash, joint and link names in its parquet metadata, so a
shard copied on its own still says what it is. Shard k draws from its own seed (seed, k), so the data do
not depend on how many workers made them or in which order; a shard is written to a temporary name and
renamed when complete, so after an interruption the same command generates only the shards missing.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from teleprev.errors import ModelError
from teleprev.noncollision.sampling import SOURCES, BoundarySettings, Samples

FORMAT = "teleprev-collision-dataset/2"
SETTINGS_FILE = "dataset.json"
META_KEY = b"teleprev"


@dataclass(frozen=True)
class DatasetSettings:
    robot: str
    urdf_sha256: str
    uniform: int
    boundary: int
    seed: int = 0
    shard_size: int = 20_000
    sampling: BoundarySettings = field(default_factory=BoundarySettings)

    @property
    def n_shards(self) -> int:
        return max(1, -(-(self.uniform + self.boundary) // self.shard_size))

    def shard_sizes(self, k: int) -> tuple[int, int]:
        """(uniform, boundary) samples in shard k: both spread evenly over the shards."""
        n = self.n_shards
        return self.uniform // n + (k < self.uniform % n), self.boundary // n + (k < self.boundary % n)

    def to_json(self) -> dict:
        return {"format": FORMAT, **asdict(self)}

    def command(self, out: Path) -> str:
        """The `teleprev collision dataset` command that makes this dataset."""
        s = self.sampling
        return (
            f"teleprev collision dataset {out} --robot {self.robot} --uniform {self.uniform} --boundary "
            f"{self.boundary} "
            f"--seed {self.seed} --shard-size {self.shard_size} --bisection-steps {s.steps} "
            f"--jitter-per-pair {s.jitter_per_pair} --jitter-min {s.jitter_min} --jitter-max {s.jitter_max}"
        )

    @staticmethod
    def from_json(data: dict, where: str) -> DatasetSettings:
        if data.get("format") != FORMAT:
            raise ModelError(
                f"not a teleprev collision dataset (format {data.get('format')!r}, expected {FORMAT!r})", where
            )
        try:
            body = {k: v for k, v in data.items() if k != "format"}
            body["sampling"] = BoundarySettings(**body.get("sampling", {}))
            return DatasetSettings(**body)
        except TypeError as exc:
            raise ModelError(f"malformed dataset settings ({exc})", where) from None


def shard_path(out: Path, k: int) -> Path:
    return out / f"shard-{k:05d}.parquet"


# ---- generation (runs in worker processes) --------------------------------------------------------
_worker: dict = {}


def _init_worker(robot: str) -> None:
    from teleprev.robot.collision import SelfCollisionChecker
    from teleprev.robot.model import load_robot

    if _worker.get("robot") != robot:
        model = load_robot(robot)
        _worker.update(robot=robot, model=model, checker=SelfCollisionChecker(model))


def generate_shard(settings: DatasetSettings, k: int) -> Samples:
    from teleprev.noncollision import sampling

    _init_worker(settings.robot)
    model, checker = _worker["model"], _worker["checker"]
    rng = np.random.default_rng([settings.seed, k])
    n_uniform, n_boundary = settings.shard_sizes(k)
    parts = [sampling.uniform(model, checker, n_uniform, rng)] if n_uniform else []
    if n_boundary:
        pool = parts[0] if parts else sampling.uniform(model, checker, 0, rng)
        # Enough free configurations to start segments from (about 15 % of uniform samples are free).
        while (~pool.labels.any(axis=1)).sum() < 64 or pool.labels.any(axis=1).sum() < 64:
            pool = Samples.concat([pool, sampling.uniform(model, checker, 2000, rng)])
        parts.append(sampling.boundary(model, checker, pool, n_boundary, rng, settings.sampling))
    return Samples.concat(parts)


def _table(samples: Samples, settings: DatasetSettings, k: int):
    import pyarrow as pa

    checker = _worker["checker"]
    q = pa.FixedSizeListArray.from_arrays(pa.array(samples.q.astype(np.float32).ravel()), samples.q.shape[1])
    labels = pa.FixedSizeListArray.from_arrays(pa.array(samples.labels.ravel()), samples.labels.shape[1])
    pairs = pa.FixedSizeListArray.from_arrays(pa.array(samples.pairs.ravel()), samples.pairs.shape[1])
    source = pa.DictionaryArray.from_arrays(pa.array(samples.source.astype(np.int8)), pa.array(list(SOURCES)))
    meta = {**settings.to_json(), "shard": k, "joint_names": list(_worker["model"].joint_names),
            "link_names": list(checker.link_names), "link_pairs": [list(p) for p in checker.link_pairs]}
    table = pa.table({"q": q, "labels": labels, "pairs": pairs, "source": source})
    return table.replace_schema_metadata({META_KEY: json.dumps(meta).encode()})


def _write_shard(settings: DatasetSettings, out: str, k: int) -> int:
    import pyarrow.parquet as pq

    samples = generate_shard(settings, k)
    path = shard_path(Path(out), k)
    tmp = path.with_suffix(f".tmp{os.getpid()}")
    pq.write_table(_table(samples, settings, k), tmp, compression="zstd")
    os.replace(tmp, path)
    return len(samples)


# ---- driver ------------------------------------------------------------------------------------
def _shard_complete(path: Path, settings: DatasetSettings) -> bool:
    """A shard counts as done when it is readable parquet written with these settings."""
    import pyarrow.parquet as pq

    if not path.is_file():
        return False
    try:
        meta = json.loads(pq.read_schema(path).metadata[META_KEY])
    except Exception:
        return False
    body = {k: v for k, v in meta.items() if k not in ("shard", "joint_names", "link_names", "link_pairs")}
    return body == settings.to_json()


def pending_shards(out: Path, settings: DatasetSettings) -> list[int]:
    return [k for k in range(settings.n_shards) if not _shard_complete(shard_path(out, k), settings)]


def prepare(out: Path, settings: DatasetSettings) -> None:
    """Create the folder and its settings file, or check that an existing one was made with the same settings."""
    out.mkdir(parents=True, exist_ok=True)
    path = out / SETTINGS_FILE
    if path.exists():
        try:
            existing = json.loads(path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError):
            raise ModelError("unreadable dataset settings; delete the folder or choose another", str(path)) from None
        if existing != settings.to_json():
            diff = sorted(
                k for k in set(existing) | set(settings.to_json()) if existing.get(k) != settings.to_json().get(k)
            )
            raise ModelError(
                f"this folder holds a dataset made with other settings (differs in: {', '.join(diff)}); "
                "use the same settings to resume, or another folder", str(path)
            )
    else:
        path.write_text(json.dumps(settings.to_json(), indent=2) + "\n")


def generate(
    out: Path,
    settings: DatasetSettings,
    workers: int = 1,
    progress: Callable[[int], None] | None = None,
) -> int:
    """Write the missing shards; returns how many samples were generated now (0 if already complete)."""
    prepare(out, settings)
    todo = pending_shards(out, settings)
    for stale in out.glob("shard-*.tmp*"):  # left by an interrupted run
        stale.unlink()
    done = 0
    if workers <= 1 or len(todo) <= 1:
        for k in todo:
            n = _write_shard(settings, str(out), k)
            done += n
            if progress:
                progress(n)
        return done
    import multiprocessing

    ctx = multiprocessing.get_context("spawn")  # workers import only numpy and fcl; no inherited threads
    with ProcessPoolExecutor(
        min(workers, len(todo)), mp_context=ctx, initializer=_init_worker, initargs=(settings.robot,)
    ) as pool:
        futures = [pool.submit(_write_shard, settings, str(out), k) for k in todo]
        try:
            for fut in as_completed(futures):
                n = fut.result()
                done += n
                if progress:
                    progress(n)
        except BaseException:
            for fut in futures:
                fut.cancel()
            raise
    return done


# ---- reading -------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CollisionDataset:
    settings: DatasetSettings
    joint_names: tuple[str, ...]
    link_names: tuple[str, ...]
    link_pairs: tuple[tuple[str, str], ...]
    samples: Samples
    path: Path


def load_settings(path: Path) -> DatasetSettings:
    path = Path(path)
    settings_path = path / SETTINGS_FILE
    if not settings_path.is_file():
        raise ModelError(
            f"no {SETTINGS_FILE}: not a collision dataset folder (make one with `teleprev collision dataset`)",
            str(path),
        )
    try:
        return DatasetSettings.from_json(json.loads(settings_path.read_text()), str(settings_path))
    except (json.JSONDecodeError, UnicodeDecodeError):
        raise ModelError("unreadable dataset settings", str(settings_path)) from None


def load_dataset(path: Path, urdf_sha256: str | None = None) -> CollisionDataset:
    """All shards of a dataset folder, checked against its settings (and the robot's URDF hash if given)."""
    import pyarrow.parquet as pq

    path = Path(path)
    settings = load_settings(path)
    if urdf_sha256 is not None and settings.urdf_sha256 != urdf_sha256:
        raise ModelError(
            f"generated for a different URDF (sha256 {settings.urdf_sha256[:12]}…, the robot's is "
            f"{urdf_sha256[:12]}…); "
            "generate the dataset again",
            str(path),
        )
    missing = pending_shards(path, settings)
    if missing:
        raise ModelError(
            f"incomplete: {len(missing)} of {settings.n_shards} shards missing or unreadable (first: "
            f"{shard_path(path, missing[0]).name}); "
            "rerun the same `teleprev collision dataset` command to finish it",
            str(path),
        )
    parts, names = [], None
    for k in range(settings.n_shards):
        table = pq.read_table(shard_path(path, k))
        meta = json.loads(table.schema.metadata[META_KEY])
        shard_names = (
            tuple(meta["joint_names"]),
            tuple(meta["link_names"]),
            tuple(tuple(p) for p in meta["link_pairs"]),
        )
        if names is not None and shard_names != names:
            raise ModelError("joint, link or pair names differ from the first shard's", str(shard_path(path, k)))
        names = shard_names

        def column(name: str, width: int) -> np.ndarray:
            flat = table.column(name).combine_chunks().flatten().to_numpy(zero_copy_only=False)
            return flat.reshape(len(table), width)

        parts.append(Samples(
            column("q", len(names[0])).astype(np.float64), column("labels", len(names[1])).astype(bool),
            column("pairs", len(names[2])).astype(bool),
            table.column("source").combine_chunks().indices.to_numpy().astype(np.uint8),
        ))
    return CollisionDataset(settings, *names, Samples.concat(parts), path)
