"""Stopping on a signal the way Ctrl-C stops: SIGTERM (`systemd stop`, `docker stop`, `kill`) and SIGHUP
(a closed SSH session) raise KeyboardInterrupt in the main thread like SIGINT does, so the command's
clean-up runs (the session file is finalized, a staging folder removed).

A signal stays pending until the command acts on it, which it shows by entering `finishing()` (its
clean-up). `check()` raises for one that arrived but whose KeyboardInterrupt was lost: Python drops an
exception raised inside a callback it cannot propagate from (a `__del__`, a weakref or ctypes callback, as
numba's loading of its runtime has), and a Ctrl-C lost that way must not let start-up go on to engage the
robot. For the same reason a signal LOST_AFTER_S or more after the one that raised, the command still not
finishing, raises again; one sooner (a burst, a double Ctrl-C) is the same stop and is only noted. Inside `deferred()`
(building what a clean-up
needs to exist whole: the session file, the devices) a signal is only noted, for the `check()` after it.

Once the command is finishing, later signals are noted and nothing more: a second Ctrl-C 20 ms after the
first can no longer cut the clean-up short and leave a half-written file. (SIGKILL still can; what it
leaves is what `teleprev recover` is for.)
"""

from __future__ import annotations

import signal
import time
from contextlib import contextmanager

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
LOST_AFTER_S = 0.5  # a raised interrupt that has not led to finishing by then was lost


class StopSignals:
    def __init__(self, signals=STOP_SIGNALS):
        self.signals = signals
        self.received: int | None = None  # the first signal that arrived
        self.later = 0  # signals that arrived after it
        self._finishing = False
        self._deferring = False
        self._raised_at: float | None = None  # monotonic time of the last KeyboardInterrupt raised
        self._previous: dict[int, object] = {}

    def __enter__(self) -> StopSignals:
        for sig in self.signals:
            self._previous[sig] = signal.signal(sig, self._handle)
        return self

    def __exit__(self, *exc) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)

    def _handle(self, signum, frame) -> None:
        if self.received is None:
            self.received = signum
        else:
            self.later += 1
        if self._finishing or self._deferring:
            return
        now = time.monotonic()
        if self._raised_at is None or now - self._raised_at >= LOST_AFTER_S:
            self._raised_at = now
            raise KeyboardInterrupt

    @property
    def pending(self) -> bool:
        """A signal arrived and the command has not begun finishing."""
        return self.received is not None and not self._finishing

    def check(self) -> None:
        """Raise KeyboardInterrupt for a signal that arrived and has not been acted on (its own
        KeyboardInterrupt was lost, or came inside `deferred()`)."""
        if self.pending and not self._deferring:
            self._raised_at = time.monotonic()
            raise KeyboardInterrupt

    @contextmanager
    def deferred(self):
        """A block that a signal must not cut in half: one arriving inside it is only noted; the `check()`
        after the block raises it, where the command's clean-up catches it."""
        self._deferring = True
        try:
            yield
        finally:
            self._deferring = False

    @contextmanager
    def finishing(self):
        """The clean-up: signals arriving inside it are noted, never raised."""
        self._finishing = True
        yield

    @property
    def name(self) -> str:
        return signal.Signals(self.received).name if self.received is not None else ""

    def exit_if_stopped(self, console, finalized=None) -> None:
        """After the command's clean-up: one line saying which signal stopped it (and that `finalized`, the
        file it wrote, is complete), then exit 128 + the signal. Nothing when no signal came."""
        if self.received is None:
            return
        import typer

        try:
            console.print(f"stopped by {self.name}" + (f"; {finalized} is complete" if finalized else ""),
                          highlight=False, soft_wrap=True)
        except OSError:  # the terminal went away with the SIGHUP; the file is complete all the same
            pass
        raise typer.Exit(self.exit_code)

    @property
    def exit_code(self) -> int:
        """128 + the signal's number, as a shell reports a command a signal stopped; 0 without one."""
        return 128 + self.received if self.received is not None else 0
