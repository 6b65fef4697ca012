"""A corpus on a real local Ray instance with 2 CPUs: sim sessions exported into one dataset (loaded
back with lerobot) and evaluated into one report; a worker killed under Ray is retried on a fresh
worker, and a session whose worker dies twice is reported failed while the others finish.

Ray is an optional extra of teleprev, but not of its tests (scripts/test.sh installs it): without it the
corpus test fails, naming the extra to install, rather than skipping.
"""

import sys
from pathlib import Path

import pytest

from teleprev.corpus.executor import FAULT_ENV, RAY_MISSING, RayExecutor, make_executor
from teleprev.errors import ConfigError

try:
    import ray
except ImportError:
    ray = None


@pytest.fixture(scope="module")
def cluster():
    assert ray is not None, RAY_MISSING
    ray.init(num_cpus=2, include_dashboard=False, logging_level="ERROR", log_to_driver=False)
    yield ray
    ray.shutdown()


@pytest.fixture
def corpus(sim_corpus):
    return sim_corpus


def test_a_corpus_exported_and_evaluated_on_ray(cluster, corpus, tmp_path, monkeypatch):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from teleprev.corpus.sessions import resolve_sessions
    from teleprev.evaluation.corpus import evaluate_corpus
    from teleprev.export.recipe import load_recipe
    from teleprev.export.run import ExportOptions, export

    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    paths = resolve_sessions([corpus])
    assert cluster.cluster_resources()["CPU"] == 2

    monkeypatch.setenv(FAULT_ENV, "b.mcap@1")  # b's worker is killed once: Ray runs b again on a fresh worker
    root = tmp_path / "ds"
    report = export(ExportOptions(paths, "lab/ray", root, load_recipe(), ray="auto"))  # joins the instance above
    assert report.failed == {} and [Path(s.session).name for s in report.sessions] == ["a.mcap", "b.mcap", "c.mcap"]
    ds = LeRobotDataset("lab/ray", root=root, video_backend="pyav")
    assert ds.num_episodes == 3 and ds.num_frames == report.total_frames == sum(s.frames for s in report.sessions)
    assert [int(n) for n in ds.meta.episodes["length"]] == [s.frames for s in report.sessions]  # in session order
    assert ds[0]["observation.images.cam_front"].ndim == 3 and ds[len(ds) - 1]["action"].shape == (22,)

    monkeypatch.setenv(FAULT_ENV, "c.mcap")  # c's worker dies on both attempts
    executor = RayExecutor("auto")
    result = evaluate_corpus(paths, executor=executor)
    executor.close()
    assert not executor.owned and cluster.is_initialized()  # an instance it did not start is left running
    assert list(result.failed) == [str(paths[2])] and "died on each of 2 attempts" in result.failed[str(paths[2])]
    assert sorted(Path(s["session"]).name for s in result.report["sessions"]) == ["a.mcap", "b.mcap"]
    assert all(s["bit_identical"] for s in result.report["sessions"])
    assert result.report["corpus"]["executor"] == "ray" and result.report["corpus"]["workers"] == 2


def test_without_ray_the_error_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` raises ImportError
    with pytest.raises(ConfigError, match=r"uv sync --extra ray"):
        make_executor(2, "local")
