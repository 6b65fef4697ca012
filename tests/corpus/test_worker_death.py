"""Local workers never outlive the process that started them, even in the middle of a long task."""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap
import time

from tests.helpers.faults import ROOT, alive, workers_of

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
        deadline = time.monotonic() + 60
        workers: set[int] = set()
        while time.monotonic() < deadline:  # the fork server and its two workers
            workers = workers_of(proc.pid)
            if len(workers) >= 3:
                break
            time.sleep(0.05)
        assert len(workers) >= 3, workers
        time.sleep(0.5)  # inside their tasks
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
    deadline = time.monotonic() + 3  # the kernel ends them at once; left alone they would nap for 2 minutes
    while any(alive(p) for p in workers) and time.monotonic() < deadline:
        time.sleep(0.05)
    survivors = [p for p in workers if alive(p)]
    for p in survivors:  # do not leave them behind on a shared machine
        try:
            import os

            os.kill(p, signal.SIGKILL)
        except ProcessLookupError:
            pass
    assert not survivors, "a worker outlived its parent"
