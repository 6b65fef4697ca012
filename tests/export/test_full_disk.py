"""An export that runs out of disk space: one line naming where and how much space it needs, the old
dataset untouched, nothing left behind."""

from __future__ import annotations

import os

from teleprev.export.synthetic import EpisodeSpec, SyntheticSession, write_session
from tests.export.test_killed_export import tree
from tests.helpers.cli import teleprev
from tests.helpers.faults import fsize_limit, has_traceback, run_cli, small_disk


def test_append_on_a_full_disk_leaves_the_dataset_as_it_was(tmp_path):
    a = write_session(tmp_path / "a.mcap", SyntheticSession((EpisodeSpec("pour", 2.0),), seed=51))
    b = write_session(tmp_path / "b.mcap", SyntheticSession((EpisodeSpec("pour", 6.0),), seed=52))
    with small_disk(tmp_path, 6_000_000) as (disk, preexec):
        root = disk / "ds"
        run = teleprev("export", a, "--repo-id", "lab/full", "--root", root)  # the dataset to append to
        assert run.returncode == 0, run.stderr
        before = tree(root)
        if preexec is None:  # a real small file system: fill it up to leave 150 kB
            free = os.statvfs(disk).f_bavail * os.statvfs(disk).f_frsize
            (disk / "filler").write_bytes(b"\0" * max(0, free - 150_000))
        else:  # no mount here: a file-size limit instead
            preexec = fsize_limit(150_000)
        run = run_cli(
            ["export", b, "--repo-id", "lab/full", "--root", root, "--append"], preexec_fn=preexec, timeout=300
        )
        assert run.returncode == 2 and not has_traceback(run.stdout + run.stderr), run.stderr
        lines = [line for line in run.stderr.splitlines() if line.strip()]
        assert len(lines) == 1, run.stderr
        assert (
            ("no space left" in lines[0] or "size limit" in lines[0])
            and "MB free" in lines[0]
            and "needs about" in lines[0]
            and str(root) in lines[0]
        )
        assert tree(root) == before  # byte for byte
        assert not list(disk.glob(".ds.export-*"))  # the partial export is gone


def test_the_video_encoder_failing_on_a_full_disk_says_nothing_of_its_own(tmp_path):
    """The encoder thread's failure (here the file-size limit hits the video first) reaches the user as the
    export's one line, without the thread's own log line before it."""
    b = write_session(tmp_path / "b.mcap", SyntheticSession((EpisodeSpec("pour", 6.0),), seed=52))
    run = run_cli(["export", b, "--repo-id", "lab/full", "--root", tmp_path / "ds"], preexec_fn=fsize_limit(400_000),
                  timeout=300)
    lines = [line for line in run.stderr.splitlines() if line.strip()]
    assert run.returncode == 2 and len(lines) == 1 and "size limit" in lines[0], run.stderr
