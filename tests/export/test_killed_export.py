"""A killed export: the target is the old dataset byte for byte or the whole new one, never neither; the
next export to it cleans up (and says so); with -j 2 the workers die with their parent."""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from teleprev.export.dataset import Staging
from teleprev.export.swap import FAULT_ENV, clean_stale
from teleprev.export.synthetic import EpisodeSpec, SyntheticSession, write_session
from tests.helpers.cli import teleprev
from tests.helpers.faults import ROOT, has_traceback, start_cli, survivors, workers_of
from tests.helpers.wait import wait_until


def tree(root: Path) -> dict[str, str]:
    """Every file under root, by relative path, with its sha256."""
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def make_dataset(folder: Path, seed: int) -> None:
    for rel in ("meta/info.json", "data/chunk-000/file-000.parquet", "videos/cam/chunk-000/file-000.mp4"):
        p = folder / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(os.urandom(1000 + seed))


COMMIT = textwrap.dedent("""
    import sys
    from pathlib import Path
    from teleprev.export.dataset import Staging
    sys.path.insert(0, sys.argv[3])
    from tests.export.test_killed_export import make_dataset

    staging = Staging(Path(sys.argv[1]))
    make_dataset(staging.dataset, int(sys.argv[2]))
    staging.commit()
""")


@pytest.mark.parametrize("scheme", ["exchange", "journal"])
def test_a_kill_inside_the_swap_leaves_old_or_new_whole_and_the_next_export_cleans_up(tmp_path, scheme):
    root = tmp_path / "ds"
    make_dataset(root, 1)
    old = tree(root)
    new_dir = tmp_path / "expected_new"
    run = subprocess.run([sys.executable, "-c", COMMIT, str(root), "2", str(ROOT)], cwd=ROOT, capture_output=True,
                         text=True, env={**os.environ, FAULT_ENV: scheme, "PYTHONPATH": str(ROOT)}, timeout=60)
    assert run.returncode == -signal.SIGKILL, run.stderr  # killed at the scheme's riskiest point
    leftovers = list(tmp_path.glob(".ds.export-*"))
    assert len(leftovers) == 1
    if scheme == "exchange":  # the new dataset is in place, whole; the old one waits in the leftover
        assert root.is_dir() and tree(root) != old and len(tree(root)) == 3
        new = tree(root)
    else:  # between the journal's two renames: the old dataset is in the leftover, the journal says where
        assert not root.exists() and (leftovers[0] / "journal").exists()
    alive_staging = Staging(root if root.exists() else new_dir)  # a running export's folder is left alone
    done = clean_stale(root)
    assert any("left by a killed export" in line for line in done)
    assert not leftovers[0].exists()
    if scheme == "exchange":
        assert tree(root) == new
    else:
        assert tree(root) == old  # byte for byte
        assert any("put the dataset back" in line for line in done)
    assert alive_staging.dir.exists()
    alive_staging.abort()


@pytest.fixture(scope="module")
def sessions(tmp_path_factory):
    d = tmp_path_factory.mktemp("killed_sessions")
    return [write_session(d / f"{name}.mcap", SyntheticSession((EpisodeSpec("pour", 6.0),), seed=k + 30))
            for k, name in enumerate("ab")]


def test_workers_die_with_a_killed_export_and_the_next_export_cleans_up(sessions, tmp_path):
    root = tmp_path / "killed"
    proc = start_cli(["export", *sessions, "--repo-id", "lab/killed", "--root", root, "-j", "2"])
    workers: set[int] = set()
    try:

        def both_writing() -> bool:
            parts = [p for s in tmp_path.glob(".killed.export-*") for p in s.glob("part-*")]
            workers.update(workers_of(proc.pid))
            assert len(parts) == 2 or proc.poll() is None, proc.communicate()
            return len(parts) == 2

        wait_until(both_writing, 240, what="both workers writing their parts", poll_s=0.05)
        workers |= workers_of(proc.pid)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert workers and not survivors(workers), "a worker outlived its parent"  # one left alone would go on for seconds
    assert not root.exists() and len(list(tmp_path.glob(".killed.export-*"))) == 1

    run = teleprev("export", sessions[0], "--repo-id", "lab/killed", "--root", root)  # here: no second lerobot import
    assert run.returncode == 0 and not has_traceback(run.stdout + run.stderr), run.stderr
    assert "left by a killed export" in run.stdout
    assert not list(tmp_path.glob(".killed.export-*")) and (root / "meta" / "info.json").is_file()


def test_sigterm_or_sighup_stop_an_append_and_leave_the_dataset_as_it_was(sessions, tmp_path):
    root = tmp_path / "kept"
    run = teleprev("export", sessions[0], "--repo-id", "lab/kept", "--root", root)
    assert run.returncode == 0, run.stderr
    before = tree(root)
    for sig in (signal.SIGTERM, signal.SIGHUP):
        proc = start_cli(["export", sessions[1], "--repo-id", "lab/kept", "--root", root, "--append"])
        try:

            def copied() -> list[Path]:
                found = list(tmp_path.glob(".kept.export-*/dataset"))
                assert found or proc.poll() is None, proc.communicate()
                return found

            wait_until(copied, 240, what="the append's working copy", poll_s=0.02)
            proc.send_signal(sig)
            stdout, stderr = proc.communicate(timeout=120)
        finally:
            if proc.poll() is None:
                proc.kill()
        assert proc.returncode == 128 + sig, stderr
        assert not has_traceback(stdout + stderr) and f"stopped by {signal.Signals(sig).name}" in stderr
        assert tree(root) == before and not list(tmp_path.glob(".kept.export-*"))
