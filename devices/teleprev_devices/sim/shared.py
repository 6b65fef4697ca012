"""One object per rig shared by the sim devices (the operator, the world, the truth log), kept in
DeviceContext.shared and created by whichever device asks first."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

_LOCK = threading.Lock()  # devices may be opened on different threads


def get_or_create(shared: dict, key: str, factory: Callable[[], Any]) -> Any:
    with _LOCK:
        if key not in shared:
            shared[key] = factory()
        return shared[key]
