"""Imported first by the fork server of local workers (its preload list): the kernel kills the server
when the driver that started it dies, even while it is still importing the rest of its preload (lerobot
takes seconds), and the workers it forked die with it (teleprev/corpus/executor.py _die_with)."""

import signal
import sys

if sys.platform.startswith("linux"):
    try:
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass
