"""`export --append` onto a dataset a file of which was deleted (a video, a data file) said nothing and
appended beside the hole; now it refuses in one line naming the missing file, before any work, and the
dataset is left exactly as it was."""

from __future__ import annotations

import shutil

import pytest

from tests.helpers.cli import teleprev


def listing(root):
    return sorted((p.relative_to(root), p.stat().st_size) for p in root.rglob("*") if p.is_file())


@pytest.mark.parametrize("missing", ["videos/observation.images.cam_front/chunk-000/file-000.mp4",
                                     "data/chunk-000/file-000.parquet"], ids=["video", "data"])
def test_append_onto_a_dataset_with_a_missing_file_is_refused(sim_dataset, sim_session, tmp_path, missing):
    root = tmp_path / "ds"
    shutil.copytree(sim_dataset, root)
    (root / missing).unlink()
    before = listing(root)
    ran = teleprev("export", sim_session, "--repo-id", "lab/sim", "--root", root, "--append")
    assert ran.returncode == 2, ran.stdout + ran.stderr
    assert ran.stderr.strip() == (f"error: {root}: {missing} is missing (the dataset's episodes name it): appending to "
                                  "a damaged dataset is refused; restore the file, or export into a new --root")
    assert listing(root) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]  # no staging folder was made


def test_append_onto_a_whole_dataset_still_works(sim_dataset, sim_session, tmp_path):
    root = tmp_path / "ds"
    shutil.copytree(sim_dataset, root)
    ran = teleprev("export", sim_session, "--repo-id", "lab/sim", "--root", root, "--append", "--json")
    assert ran.returncode == 0, ran.stdout + ran.stderr
    assert '"total_episodes": 2' in ran.stdout
