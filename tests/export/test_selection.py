"""`teleprev export --only/--task/--participant/--condition` and `--holdout`: real MCAP sessions with
marked episodes (written with the session writer) exported through the CLI, the datasets loaded back
with lerobot's own LeRobotDataset and its metadata API: which episodes, where each came from, and the
per-frame next.done / next.success marks."""

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from teleprev.export.selection import Selection, read_facts, select, split
from teleprev.export.synthetic import EpisodeSpec, SyntheticSession, write_session
from tests.helpers.cli import teleprev


def _session(path, participant, condition, episodes, seed):
    meta = {"session": {"task": "pick_place", "operator": "synthetic", "end_effector": "leap_hand",
                        "participant": participant, "condition": condition}}
    return write_session(path, SyntheticSession(episodes, width=160, height=120, pause_s=0.5, metadata=meta, seed=seed))


@pytest.fixture(scope="module")
def marked(tmp_path_factory):
    """Two sessions, five episodes (one discarded): y marks on a0, a2 and b1."""
    d = tmp_path_factory.mktemp("marked")
    a = _session(d / "a.mcap", "p1", "vr", (EpisodeSpec("pick_place", 1.0, outcome="success"),
                                            EpisodeSpec("pick_place", 1.0, outcome="failure"),
                                            EpisodeSpec("pour", 1.0, outcome="success")), seed=11)
    b = _session(
        d / "b.mcap",
        "p2",
        "screen",
        (
            EpisodeSpec("pour", 1.0),
            EpisodeSpec("pick_place", 1.0, outcome="success"),
            EpisodeSpec("pick_place", 1.0, outcome="success", discarded=True),
        ),
        seed=12,
    )
    return SimpleNamespace(dir=d, a=a, b=b)


def load(repo_id, root):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    return LeRobotDataset(repo_id, root=root, video_backend="pyav")


def episodes_of(ds) -> list[dict]:
    cols = ("source_session", "source_episode", "outcome", "participant", "condition")
    meta = ds.meta.episodes
    return [{c: meta[c][i] for c in cols} for i in range(len(meta))]


def marks(ds) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    table = ds.hf_dataset.with_format("numpy")
    return (np.asarray(table["episode_index"]), np.asarray(table["next.done"]).reshape(-1),
            np.asarray(table["next.success"]).reshape(-1))


def test_only_success_exports_exactly_the_episodes_marked_y_with_their_marks(marked, tmp_path):
    root = tmp_path / "succ"
    ran = teleprev("export", marked.a, marked.b, "--repo-id", "t/succ", "--root", root, "--only", "success")
    assert ran.returncode == 0, ran.stderr + ran.stdout
    assert "selected: recorded 5; --only success kept 3" in ran.stdout
    ds = load("t/succ", root)
    assert ds.num_episodes == 3
    assert episodes_of(ds) == [
        {"source_session": "a.mcap", "source_episode": 0, "outcome": "success", "participant": "p1", "condition": "vr"},
        {"source_session": "a.mcap", "source_episode": 2, "outcome": "success", "participant": "p1", "condition": "vr"},
        {
            "source_session": "b.mcap",
            "source_episode": 1,
            "outcome": "success",
            "participant": "p2",
            "condition": "screen",
        },
    ]
    episode, done, success = marks(ds)
    last = np.r_[episode[1:] != episode[:-1], True]  # the last frame of each episode
    assert done.dtype == bool and (done == last).all() and (success == last).all()
    assert not bool(ds[0]["next.done"])  # a frame reads back through lerobot too
    assert bool(ds[ds.num_frames - 1]["next.success"])


def test_filters_combine_and_unmarked_episodes_get_no_success_mark(marked, tmp_path):
    root = tmp_path / "mixed"
    ran = teleprev("export", marked.a, marked.b, "--repo-id", "t/mixed", "--root", root, "--participant", "p2",
                   "--task", "pour", "--json")
    assert ran.returncode == 0, ran.stderr
    summary = json.loads(ran.stdout.strip().splitlines()[-1])
    assert summary["selection"] == {"recorded": 5, "--task pour": 2, "--participant p2": 1}
    ds = load("t/mixed", root)
    assert [(e["source_session"], e["source_episode"], e["outcome"]) for e in episodes_of(ds)] == [("b.mcap", 0, "")]
    _, done, success = marks(ds)
    assert done[-1] and done.sum() == 1 and not success.any()


def test_a_selection_that_matches_nothing_is_one_line_and_writes_nothing(marked, tmp_path):
    root = tmp_path / "none"
    ran = teleprev("export", marked.a, marked.b, "--repo-id", "t/none", "--root", root, "--only", "failure",
                   "--condition", "screen")
    assert ran.returncode == 2
    assert ran.stderr.strip() == ("error: --condition screen matches no episode of the 5 recorded "
                                  "(--condition values there: screen, vr)")
    assert not root.exists() and not list(tmp_path.glob(".none*"))
    bad = teleprev("export", marked.a, "--repo-id", "t/none", "--root", root, "--only", "great")
    assert bad.returncode == 2 and bad.stderr.strip() == "error: --only must be success, failure, unmarked, got 'great'"
    by = teleprev("export", marked.a, "--repo-id", "t/none", "--root", root, "--holdout", "0.5", "--split-by", "file")
    assert by.returncode == 2 and by.stderr.strip() == "error: --split-by must be session or episode, got 'file'"
    assert not root.exists()


def test_holdout_writes_a_second_dataset_deterministic_for_a_seed(marked, tmp_path):
    root = tmp_path / "train"
    ran = teleprev("export", marked.a, marked.b, "--repo-id", "t/train", "--root", root, "--holdout", "0.25",
                   "--split-by", "episode", "--seed", "7", "--json")
    assert ran.returncode == 0, ran.stderr + ran.stdout
    summary = json.loads(ran.stdout.strip().splitlines()[-1])
    assert (summary["total_episodes"], summary["holdout"]["total_episodes"]) == (4, 1)
    assert summary["holdout"]["root"] == str(tmp_path / "train_holdout")
    train, held = load("t/train", root), load("t/train_holdout", tmp_path / "train_holdout")
    def keys(ds):
        return [(e["source_session"], e["source_episode"]) for e in episodes_of(ds)]
    assert len(keys(held)) == 1 and len(keys(train)) == 4  # round(0.25 x 5)
    assert sorted(keys(train) + keys(held)) == [
        ("a.mcap", 0),
        ("a.mcap", 1),
        ("a.mcap", 2),
        ("b.mcap", 0),
        ("b.mcap", 1),
    ]
    kept = select(read_facts([marked.a, marked.b]), Selection()).kept
    for seed in (7, 8, 9):  # the same seed, the same split; the draw depends on it
        assert split(kept, 0.25, "episode", seed) == split(kept, 0.25, "episode", seed)
    held_again = split(kept, 0.25, "episode", 7)[1]
    assert [(Path(f.session).name, f.index) for f in held_again] == keys(held)
    by_session = split(kept, 0.5, "session", 7)
    assert {f.session for f in by_session[0]}.isdisjoint({f.session for f in by_session[1]})

    # --append needs both targets: with one missing, neither is written
    lone = tmp_path / "lone"
    before = sorted(p.name for p in root.rglob("*"))
    again = teleprev("export", marked.a, marked.b, "--repo-id", "t/train", "--root", root, "--holdout", "0.25",
                     "--split-by", "episode", "--seed", "7", "--append", "--root", lone)
    assert again.returncode == 2 and "there is no dataset here to append to (neither is written)" in again.stderr
    assert not lone.exists() and sorted(p.name for p in root.rglob("*")) == before
    split_empty = teleprev("export", marked.a, "--repo-id", "t/x", "--root", tmp_path / "x", "--holdout", "0.5")
    assert split_empty.returncode == 2 and "--holdout 0.5 of 1 sessions holds out" in split_empty.stderr
