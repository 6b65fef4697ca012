"""Where the shipped data folders (urdf/, models/, rigs/, datasets/recipes/) are.

In a source checkout (the README's install) they sit beside the package; a wheel carries them inside it.
"""

from __future__ import annotations

from pathlib import Path

_PACKAGE = Path(__file__).resolve().parent


def data_dir(name: str) -> Path:
    beside = _PACKAGE.parent / name
    return beside if beside.is_dir() else _PACKAGE / "_data" / name
