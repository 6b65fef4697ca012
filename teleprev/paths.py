"""Where the shipped data folders (urdf/, models/, rigs/, datasets/recipes/) are.

In a source checkout (the README's install) they sit beside the package; a wheel carries them inside it.
"""

from __future__ import annotations

from pathlib import Path

from teleprev.errors import ConfigError

_PACKAGE = Path(__file__).resolve().parent


def data_dir(name: str) -> Path:
    beside = _PACKAGE.parent / name
    return beside if beside.is_dir() else _PACKAGE / "_data" / name


def inside(folder: Path, relative: str, what: str, where: str) -> Path:
    """`relative` under `folder`, refused (ConfigError naming `what` and `where`) when it is absolute or
    leads out of the folder (through "..", or a symbolic link). For paths taken from file contents: a
    file must never direct teleprev to read or write outside its own folder."""
    folder = Path(folder).resolve()
    p = Path(relative)
    target = (folder / p).resolve()
    if p.is_absolute() or (target != folder and folder not in target.parents):
        raise ConfigError(f"{what} {relative!r} leads out of {folder}; only paths inside that folder are followed",
                          where)
    return target
