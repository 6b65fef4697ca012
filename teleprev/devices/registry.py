"""Device plugins by name, from the `teleprev.devices` entry-point group (third-party plugins included)."""

from __future__ import annotations

import sys
from functools import lru_cache
from importlib.metadata import EntryPoint, entry_points

from teleprev.errors import ConfigError

GROUP = "teleprev.devices"


def available() -> dict[str, EntryPoint]:
    """The installed plugins by name. Finding entry points reads every installed distribution's
    metadata (about 15 ms), and a rig names several plugins: they are read once per sys.path."""
    return dict(_entry_points(tuple(sys.path)))


@lru_cache(maxsize=4)
def _entry_points(_path: tuple[str, ...]) -> tuple[tuple[str, EntryPoint], ...]:
    return tuple((ep.name, ep) for ep in entry_points(group=GROUP))


def load_plugin(name: str, where: str = ""):
    """The Device class registered as `name` (e.g. "sim.glove")."""
    eps = available()
    if name not in eps:
        known = ", ".join(sorted(eps)) or "none"
        raise ConfigError(f"unknown device plugin {name!r} (installed: {known})", where or None)
    try:
        return eps[name].load()
    except ImportError as exc:
        raise ConfigError(
            f"device plugin {name!r} cannot be loaded ({exc}); is its optional extra installed "
            f"(e.g. `uv sync --extra xarm`)?",
            where or None,
        ) from None
