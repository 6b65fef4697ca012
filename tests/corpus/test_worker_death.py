"""Local workers never outlive the process that started them, even in the middle of a long task."""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap
import time

from tests.helpers.faults import ROOT, survivors, workers_of
from tests.helpers.wait import wait_until

DRIVER = textwrap.dedent("""
    import sys, time
    from teleprev.corpus.executor import LocalExecutor

    def nap(context, item, emit):  # a long task that says nothing (as lerobot's merge or finalize)
        time.sleep(120)
        return item

    if __name__ == "__main__":
        print("starting", flush=True)
        LocalExecutor(2).map(nap, None, [1, 2])
""")


def test_workers_die_with_their_parent(tmp_path):
    script = tmp_path / "driver.py"
    script.write_text(DRIVER)
    proc = subprocess.Popen([sys.executable, str(script)], cwd=ROOT, stdout=subprocess.PIPE, text=True,
                            env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    try:
        assert proc.stdout.readline().strip() == "starting"

        def started() -> set[int]:
            found = workers_of(proc.pid)
            return found if len(found) >= 3 else set()

        workers = wait_until(started, 60, what="the fork server and its two workers", poll_s=0.05)
        time.sleep(0.5)  # inside their tasks
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
    left = survivors(workers)  # left alone they would nap for 2 minutes
    for p in left:  # do not leave them behind on a shared machine
        try:
            import os

            os.kill(p, signal.SIGKILL)
        except ProcessLookupError:
            pass
    assert not left, "a worker outlived its parent"
