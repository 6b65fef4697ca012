"""Export of a corpus in worker processes when one session's worker dies: retried once, then left out
and named, the other sessions merged in session order into a dataset that lerobot loads back."""


import pytest

from teleprev.corpus.executor import FAULT_ENV
from teleprev.errors import SessionError
from teleprev.export.recipe import load_recipe
from teleprev.export.run import ExportOptions, export
from teleprev.export.synthetic import EpisodeSpec, SyntheticSession, write_session

pytestmark = pytest.mark.usefixtures("forkserver")  # workers fork with lerobot and eval imported


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    d = tmp_path_factory.mktemp("corpus")
    tasks = {"a": ("pick_place", "pour"), "b": ("hang",), "c": ("cup_stack",)}
    return [write_session(d / f"{name}.mcap", SyntheticSession(tuple(EpisodeSpec(t, 1.0) for t in ts), seed=k + 10))
            for k, (name, ts) in enumerate(tasks.items())]


def test_a_dying_worker_leaves_its_session_out_and_the_rest_is_merged_in_order(corpus, tmp_path, monkeypatch):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    monkeypatch.setenv(FAULT_ENV, "b.mcap")
    root = tmp_path / "ds"
    report = export(ExportOptions(corpus, "lab/corpus", root, load_recipe(), workers=2))
    assert list(report.failed) == [str(corpus[1])]
    assert "its worker died on each of 2 attempts" in report.failed[str(corpus[1])]
    assert [s.session for s in report.sessions] == [str(corpus[0]), str(corpus[2])]
    ds = LeRobotDataset("lab/corpus", root=root, video_backend="pyav")
    assert ds.num_episodes == report.total_episodes == 3
    tasks = [t[0] for t in ds.meta.episodes["tasks"]]
    assert tasks == ["pick_place", "pour", "cup_stack"]  # a's episodes, then c's: session order
    assert ds[len(ds) - 1]["observation.images.cam_front"].shape[0] == 3  # the last part's video decodes

    # every session's worker dies: nothing to merge, and the first failure says why
    monkeypatch.setenv(FAULT_ENV, "a.mcap,b.mcap,c.mcap")
    with pytest.raises(SessionError, match=r"a\.mcap: its worker died on each of 2 attempts"):
        export(ExportOptions(corpus, "lab/none", tmp_path / "none", load_recipe(), workers=2))
    assert not (tmp_path / "none").exists() and not list(tmp_path.glob(".none.export-*"))
