"""Cues at the boundaries of timed episodes: the terminal bell, and the words spoken where a speech
command is installed (spd-say, espeak or macOS's say).

Speaking takes a second or more and may block, so a thread of its own runs the command; `cue` only
queues the words and returns at once. Cues that pile up behind a slow speech command are dropped:
one spoken late says the wrong thing.
"""

from __future__ import annotations

import queue
import shutil
import subprocess
import threading
from typing import TextIO

SPEECH_COMMANDS = ("spd-say", "espeak", "say")
BACKLOG = 2


def speech_command() -> str | None:
    """The first speech command on PATH, or None."""
    for name in SPEECH_COMMANDS:
        found = shutil.which(name)
        if found:
            return found
    return None


class Cues:
    """`bell`: where the bell character goes (a terminal; None: no bell); `speech`: the command that
    speaks its argument (None: none)."""

    def __init__(self, bell: TextIO | None, speech: str | None):
        self.bell = bell
        self.speech = speech
        self.spoken: list[str] = []  # what was handed to the speech command, for the session's caller
        self._queue: queue.Queue = queue.Queue(maxsize=BACKLOG)
        self._thread: threading.Thread | None = None

    @classmethod
    def for_terminal(cls, stream: TextIO | None) -> Cues:
        """The bell on `stream` when it is a terminal (never into a log file), and speech when installed."""
        try:
            bell = stream if stream is not None and stream.isatty() else None
        except (AttributeError, ValueError):
            bell = None
        return cls(bell, speech_command())

    def cue(self, words: str) -> None:
        """Ring the bell and say `words`; never waits for either."""
        if self.bell is not None:
            try:
                self.bell.write("\a")
                self.bell.flush()
            except (OSError, ValueError):  # the terminal went away: the session goes on without its bell
                self.bell = None
        if self.speech is None:
            return
        if self._thread is None:
            self._thread = threading.Thread(target=self._speak, name="cues", daemon=True)
            self._thread.start()
        try:
            self._queue.put_nowait(words)
        except queue.Full:
            pass

    def close(self, timeout_s: float = 0.5) -> None:
        """Let what is queued be said (up to timeout_s), then stop the thread."""
        if self._thread is not None:
            try:
                self._queue.put(None, timeout=timeout_s)
            except queue.Full:
                pass
            self._thread.join(timeout_s)
            self._thread = None

    def _speak(self) -> None:
        while True:
            words = self._queue.get()
            if words is None:
                return
            try:
                self.spoken.append(words)
                subprocess.run([self.speech, words], stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL, timeout=10, check=False)
            except (OSError, subprocess.SubprocessError):  # a broken speech command costs the cue, nothing else
                pass
