"""Stopping on a signal the way Ctrl-C stops: SIGTERM (`systemd stop`, `docker stop`, `kill`) and SIGHUP
(a closed SSH session) raise KeyboardInterrupt in the main thread like SIGINT does, so the command's
clean-up runs (the session file is finalized, a staging folder removed).

Only the first signal interrupts. Once it has, or once the command has begun finishing on its own
(`finishing()`), later signals are noted and nothing more: a second Ctrl-C 20 ms after the first can
no longer cut the clean-up short and leave a half-written file. (SIGKILL still can; what it leaves is
what `teleprev recover` is for.)
"""

from __future__ import annotations

import signal
from contextlib import contextmanager

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class StopSignals:
    def __init__(self, signals=STOP_SIGNALS):
        self.signals = signals
        self.received: int | None = None  # the first signal that arrived
        self.later = 0  # signals that arrived after it (or while finishing), and were only noted
        self._finishing = False
        self._previous: dict[int, object] = {}

    def __enter__(self) -> StopSignals:
        for sig in self.signals:
            self._previous[sig] = signal.signal(sig, self._handle)
        return self

    def __exit__(self, *exc) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)

    def _handle(self, signum, frame) -> None:
        if self.received is None and not self._finishing:
            self.received = signum
            self._finishing = True
            raise KeyboardInterrupt
        if self.received is None:
            self.received = signum
        else:
            self.later += 1

    @contextmanager
    def finishing(self):
        """The clean-up: signals arriving inside it are noted, never raised."""
        self._finishing = True
        yield

    @property
    def name(self) -> str:
        return signal.Signals(self.received).name if self.received is not None else ""

    @property
    def exit_code(self) -> int:
        """128 + the signal's number, as a shell reports a command a signal stopped; 0 without one."""
        return 128 + self.received if self.received is not None else 0
