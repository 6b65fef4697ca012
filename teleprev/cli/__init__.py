"""The `teleprev` command line: one small module per command group, registered in app.py.

A Ctrl-C while the command's modules are still being imported (the first second of every command, longer on
a busy machine) stops it with one line and exit status 130, as one during the command does (app.main), not a
traceback through the import machinery: this package is imported before any of them. SIGTERM and SIGHUP
then say "stopped by SIGTERM" and exit 128 + the signal, not die without a word: nothing has begun yet, so
there is nothing to clean up (app.main raises them as interrupts once the command runs).
"""

import os
import signal
import sys
import threading

INTERRUPTED = "interrupted"  # what a command stopped by Ctrl-C says on stderr
INTERRUPTED_EXIT = 130  # 128 + SIGINT, as a shell reports it


def _say_and_exit(line: str, code: int):
    """Flush what was printed, say `line` on stderr and exit `code` at once, from anywhere (inside an import
    too: nothing is left to clean up there)."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    try:
        sys.stderr.write(f"{line}\n")
        sys.stderr.flush()
    except (OSError, ValueError):
        pass
    os._exit(code)


def interrupted_exit():
    """Say one line and exit 130."""
    _say_and_exit(INTERRUPTED, INTERRUPTED_EXIT)


def stopped_exit(signum: int, frame=None):
    """Say which signal stopped the command and exit 128 + it."""
    _say_and_exit(f"stopped by {signal.Signals(signum).name}", 128 + signum)


def _quiet_interrupt(kind, value, tb, previous=sys.excepthook):
    if issubclass(kind, KeyboardInterrupt):
        interrupted_exit()
    previous(kind, value, tb)


if sys.excepthook is sys.__excepthook__:  # not in a host that has its own (an IDE, a test runner's)
    sys.excepthook = _quiet_interrupt
    if threading.current_thread() is threading.main_thread():  # (handlers are set from the main thread only)
        for _sig in (signal.SIGTERM, signal.SIGHUP):
            if signal.getsignal(_sig) is signal.SIG_DFL:  # as the default would, but in a line
                signal.signal(_sig, stopped_exit)
