"""Local workers' fork server starts before the command's own work (export: opening and checking every
session; eval: the corpus run), so that its preload (lerobot's import, seconds; eval's kernels) runs on
another core meanwhile instead of after it. A sequential run starts no server."""

from __future__ import annotations

import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from tests.helpers.faults import ROOT

FIXTURE = Path(__file__).parents[1] / "fixtures" / "sim_v2.mcap"

# Replaces the first thing each command does after choosing its workers, and says whether a fork server
# was running by then. Fork servers are per process: a fresh interpreter for each case.
DRIVER = textwrap.dedent("""
    import os
    import signal
    import sys
    from multiprocessing import forkserver

    import teleprev.evaluation.corpus as corpus
    import teleprev.export.run as run

    def first_work(*args, **kwargs):
        pid = forkserver._forkserver._forkserver_pid
        print("server running:", pid is not None, flush=True)
        if pid is not None:  # a server still in its preload would hold the test's pipe until lerobot's import is done
            os.kill(pid, signal.SIGKILL)
        raise SystemExit(3)

    run._open_all = first_work
    corpus.evaluate_corpus = first_work
    from teleprev.cli.app import main

    sys.argv = ["teleprev", *sys.argv[1:]]
    main()
""")


@pytest.mark.parametrize("command,workers,running", [("export", 2, True), ("export", 1, False),
                                                     ("eval", 2, True), ("eval", 1, False)])
def test_the_fork_server_starts_before_the_work(tmp_path, command, workers, running):
    sessions = [tmp_path / "a.mcap", tmp_path / "b.mcap"]
    for s in sessions:
        shutil.copyfile(FIXTURE, s)  # two files (links to one are one session)
    args = [*map(str, sessions), "-j", str(workers)]
    if command == "export":
        args += ["--repo-id", "lab/x", "--root", str(tmp_path / "out")]
    script = tmp_path / "driver.py"
    script.write_text(DRIVER)
    run = subprocess.run([sys.executable, str(script), command, *args], cwd=ROOT, capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 3, run.stdout + run.stderr
    assert f"server running: {running}" in run.stdout, run.stdout + run.stderr
