"""The session files a command was given: files, globs and folders, resolved in one place.

    a file      that file (any name: the reader says whether it is a session)
    a folder    every *.mcap directly inside it, sorted by name
    a glob      (a quoted `sessions/*.mcap`, or `**` for sub-folders) its matches, sorted by name

The order is the order given, each argument expanded in place; a file reached twice (a folder and a
glob over it) is kept at its first place only, so no session is exported or evaluated twice.
"""

from __future__ import annotations

import glob
from pathlib import Path

from teleprev.errors import ConfigError

_GLOB_CHARS = set("*?[")


def is_glob(arg: str) -> bool:
    return bool(_GLOB_CHARS & set(arg))


def resolve_sessions(args: list[str | Path]) -> list[Path]:
    """The session files named by `args`, in order; a ConfigError names an argument that gives none."""
    if not args:
        raise ConfigError("no sessions given: name session files, folders of them, or a glob such as 'sessions/*.mcap'")
    out: list[Path] = []
    seen: set[Path] = set()
    for arg in args:
        text = str(arg)
        path = Path(text).expanduser()
        if path.is_dir():
            found = sorted(p for p in path.glob("*.mcap") if p.is_file())
            if not found:
                raise ConfigError("a folder with no session (*.mcap) directly inside it", text)
        elif path.is_file():
            found = [path]
        elif is_glob(text):
            found = sorted(Path(p) for p in glob.glob(str(path), recursive=True) if Path(p).is_file())
            if not found:
                raise ConfigError("no file matches this pattern", text)
        else:
            raise ConfigError("no such session file or folder", text)
        for p in found:
            key = p.resolve()
            if key not in seen:
                seen.add(key)
                out.append(p)
    return out

