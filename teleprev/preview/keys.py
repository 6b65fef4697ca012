"""Single keys from the terminal, without Enter, on a background thread.

The terminal goes into cbreak mode (keys arrive one by one, Ctrl-C still works) for the life of the
context and is restored afterwards, also when the program fails. Without a terminal, nothing is read.
"""

from __future__ import annotations

import os
import select
import sys
import threading
from collections.abc import Callable


class KeyReader:
    def __init__(self, on_key: Callable[[str], None], stream=None):
        self.on_key = on_key
        self.stream = stream if stream is not None else sys.stdin
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._saved = None

    @property
    def is_terminal(self) -> bool:
        """Whether keys can be read: the stream is a terminal (not a pipe, a file, or no file at all)."""
        try:
            return os.isatty(self.stream.fileno())
        except (AttributeError, OSError, ValueError):  # no fileno (io.UnsupportedOperation is both), or closed
            return False

    def __enter__(self) -> KeyReader:
        if not self.is_terminal:
            return self
        import termios
        import tty

        fd = self.stream.fileno()
        self._saved = termios.tcgetattr(fd)
        tty.setcbreak(fd)
        self._thread = threading.Thread(target=self._run, name="keys", daemon=True)
        self._thread.start()
        return self

    def _run(self) -> None:
        fd = self.stream.fileno()
        while not self._stop.is_set():
            ready, _, _ = select.select([fd], [], [], 0.1)
            if ready:
                ch = os.read(fd, 1).decode(errors="ignore")
                if ch:
                    self.on_key(ch)

    def __exit__(self, *exc) -> None:
        self._stop.set()
        if self._thread:
            self._thread.join(1.0)
        if self._saved is not None:
            import termios

            termios.tcsetattr(self.stream.fileno(), termios.TCSADRAIN, self._saved)
