"""Imported by the fork server of eval's local workers (corpus.PRELOAD), never by teleprev itself: it loads
the compiled kernels from numba's cache once, so that every worker forked from the server starts with
them instead of paying numba's first-call start (about 0.4 s) in its first session."""

from teleprev.kernels import warm

warm()
