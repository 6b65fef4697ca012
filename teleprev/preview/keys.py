"""Single keys from the terminal, without Enter, on a background thread.

The terminal goes into cbreak mode (keys arrive one by one, Ctrl-C still works) for the life of the
context and is restored afterwards, also when the program fails. Without a terminal, nothing is read.

Keys that the terminal sends as escape sequences (arrows, Page Up/Down, F-keys) arrive whole, so a lone Esc
(quit) is never read out of one. Page Down and Page Up are a foot pedal's: a USB pedal is a keyboard, and
"page turner" pedals send these two (most others can be set to). With both hands driving a bimanual rig
the left hand's pinches on the XR page are gone, and the pedal takes over what they did: Page Down is space
(preview/execute), Page Up is n (next episode: back to preview, the next one starts). Other sequences are
dropped. The decision and its reasons: docs/rigs-and-devices.md#bimanual-rigs.
"""

from __future__ import annotations

import os
import select
import sys
import threading
from collections.abc import Callable

ESC = "\x1b"
PEDAL_KEYS = {"\x1b[6~": " ", "\x1b[5~": "n"}  # Page Down, Page Up (a foot pedal's) -> the key they press
ESC_WAIT_S = 0.03  # after a lone Esc, how long the rest of an escape sequence may take to arrive


def keys_of(data: str) -> list[str]:
    """The keys in what the terminal sent: one per character, an escape sequence (ESC [ ... final byte, or
    ESC O x) as a whole, given as PEDAL_KEYS' key where it is one of those and dropped otherwise."""
    out, i = [], 0
    while i < len(data):
        ch = data[i]
        if ch != ESC or i + 1 >= len(data) or data[i + 1] not in "[O":
            out.append(ch)
            i += 1
            continue
        j = i + 2
        if data[i + 1] == "[":
            while j < len(data) and not "\x40" <= data[j] <= "\x7e":  # parameters, up to the final byte
                j += 1
        sequence = data[i:j + 1]
        if sequence in PEDAL_KEYS:
            out.append(PEDAL_KEYS[sequence])
        i = j + 1
    return out


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
                data = os.read(fd, 64).decode(errors="ignore")
                if data.endswith(ESC) and select.select([fd], [], [], ESC_WAIT_S)[0]:  # a sequence, split
                    data += os.read(fd, 64).decode(errors="ignore")
                for key in keys_of(data):
                    self.on_key(key)

    def __exit__(self, *exc) -> None:
        self._stop.set()
        if self._thread:
            self._thread.join(1.0)
        if self._saved is not None:
            import termios

            termios.tcsetattr(self.stream.fileno(), termios.TCSADRAIN, self._saved)
