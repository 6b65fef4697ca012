"""Where a command will write, checked before it does any work: one line naming the option and the path,
exit 2 (ConfigError), instead of a traceback or a refusal after minutes of work.

`check_output` for every output option of every command (--out, --json, --plots, study --out, a survey's
sidecar): what is there already (a folder where a file goes, a file where a folder goes, a file that
must not be overwritten), the folder it goes in (missing, a file, not writable) and, for the options
whose folders the command makes, the nearest folder that exists. `check_input` for a file a command
reads back (eval --baseline).
"""

from __future__ import annotations

import errno
import os
import tempfile
from pathlib import Path
from typing import Literal

from teleprev.errors import ConfigError


def check_output(path: Path | None, option: str, kind: Literal["file", "folder"] = "file", *,
                 overwrite: bool = True, make_parents: bool = False) -> None:
    """Refuse (ConfigError naming `option`) a path the command could not write `kind` at. `overwrite`:
    an existing file may be replaced; `make_parents`: missing folders above it are made by the command."""
    if path is None:
        return
    path = Path(path)
    where = f"{option} {path}"
    if path.is_dir() and kind == "file":
        raise ConfigError("is a folder; this option names a file to write", where)
    if path.exists() and not path.is_dir() and kind == "folder":
        raise ConfigError("is a file; this option names a folder to write into", where)
    if path.is_file() and not overwrite:
        raise ConfigError("already exists; teleprev does not overwrite it (choose another name)", where)
    if path.is_dir():
        _writable(path, where)
        return
    parent = path.parent
    if not parent.is_dir():
        existing = next((p for p in parent.parents if p.exists()), Path("."))
        if parent.exists() or not existing.is_dir():
            blocker = parent if parent.exists() else existing
            raise ConfigError(f"{blocker} is a file, not a folder", where)
        if not make_parents:
            raise ConfigError(f"the folder {parent} does not exist", where)
        parent = existing
    _writable(parent, where)


def check_input(path: Path | None, option: str, what: str = "file", *, folder: bool = False) -> None:
    """Refuse a path to read that is missing, or a folder (with `folder`: a file)."""
    if path is None:
        return
    path = Path(path)
    if not path.exists():
        raise ConfigError(f"no such {what}", f"{option} {path}")
    if path.is_dir() and not folder:
        raise ConfigError(f"is a folder; this option names a {what} to read", f"{option} {path}")
    if folder and not path.is_dir():
        raise ConfigError(f"is a file; this names a {what} to read", f"{option} {path}")


def _writable(folder: Path, where: str) -> None:
    """Whether a file can be made in `folder`: by trying (permissions say nothing for root, and a read-only
    mount shows only when written)."""
    try:
        fd, probe = tempfile.mkstemp(prefix=".teleprev-probe-", dir=folder)
    except OSError as exc:
        reason = (
            "is read-only"
            if exc.errno in (errno.EROFS, errno.EACCES, errno.EPERM)
            else (exc.strerror or str(exc)).lower()
        )
        raise ConfigError(f"cannot write in {folder}: it {reason}" if reason == "is read-only"
                          else f"cannot write in {folder}: {reason}", where) from None
    os.close(fd)
    os.unlink(probe)
