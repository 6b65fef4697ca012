"""The `teleprev` command run inside the test process, through its real entry point (teleprev.cli.app.main,
with its one-line errors and exit codes), for tests whose subject is what a command does and says rather
than the process: no interpreter to start and nothing to import again (a fresh `teleprev export` spends
about 10 s importing lerobot before it starts).

Tests of signals, kills, resource limits, start-up time or what a fresh process imports run the command in
a child process instead (tests.helpers.faults.run_cli / start_cli).
"""

from __future__ import annotations

import io
import logging
import os
import sys
import warnings
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


@dataclass(frozen=True)
class Ran:
    returncode: int
    stdout: str
    stderr: str


# Python's warning filters in a process started without -W options: what a child would print
_CHILD_FILTERS = (
    ("default", DeprecationWarning, "__main__"),
    ("ignore", DeprecationWarning, ""),
    ("ignore", PendingDeprecationWarning, ""),
    ("ignore", ImportWarning, ""),
    ("ignore", ResourceWarning, ""),
)


def teleprev(*args, stdin: str = "", cwd: Path = ROOT, columns: int = 200) -> Ran:
    """Run `teleprev ARGS...` here, as a shell would from `cwd` with no terminal: stdout and stderr
    captured, `stdin` as its input, tables `columns` wide (the child processes' COLUMNS). What a child
    would print on stderr besides the command's own output is in `stderr` too: log records of WARNING
    and above (Python's last-resort handler) and warnings under the default filters."""
    from teleprev.cli.app import main

    out, err = io.StringIO(), io.StringIO()
    saved = sys.argv, sys.stdin, os.getcwd(), os.environ.get("COLUMNS")
    logged = logging.StreamHandler(err)
    logged.setLevel(logging.WARNING)
    code = 0
    try:
        sys.argv = ["teleprev", *map(str, args)]
        sys.stdin = io.StringIO(stdin)
        os.chdir(cwd)
        os.environ["COLUMNS"] = str(columns)
        logging.getLogger().addHandler(logged)
        with redirect_stdout(out), redirect_stderr(err), warnings.catch_warnings(record=True) as caught:
            warnings.resetwarnings()
            for action, category, module in _CHILD_FILTERS:
                warnings.filterwarnings(action, category=category, module=module, append=True)
            try:
                main()
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    finally:
        logging.getLogger().removeHandler(logged)
        sys.argv, sys.stdin = saved[0], saved[1]
        os.chdir(saved[2])
        if saved[3] is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = saved[3]
    for w in caught:
        err.write(warnings.formatwarning(w.message, w.category, w.filename, w.lineno, w.line))
    return Ran(code, out.getvalue(), err.getvalue())
