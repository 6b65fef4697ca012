"""An export that ran out of disk space, told in one line: where, how much is free, about how much it needs."""

from __future__ import annotations

import shutil
from pathlib import Path

from teleprev.errors import ConfigError

_MB = 1e6


def space_error(what: str, target: Path, sessions: list[Path], append: bool) -> ConfigError:
    """`what` ran out (errors.out_of_space). After the staging folder is gone: the free space left where the
    dataset is written, and what the
    export needs, estimated as the sessions' size (their video and joint streams; the dataset comes out
    smaller) plus, when appending, the dataset's newest files that are copied."""
    parent = Path(target).resolve().parent
    try:
        free = shutil.disk_usage(parent).free
    except OSError:
        free = None
    need = sum(Path(s).stat().st_size for s in sessions if Path(s).is_file())
    if append and Path(target).is_dir():
        need += sum(p.stat().st_size for p in (Path(target) / "meta").rglob("*") if p.is_file())
    have = "unknown" if free is None else f"{free / _MB:.1f} MB"
    return ConfigError(f"{what}: {have} free here, the export needs about {need / _MB:.1f} MB; "
                       f"{target} was left as it was and the partial export removed", str(parent))
