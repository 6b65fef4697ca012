"""Collision datasets: exact labels, metadata, resuming after an interruption, refusing mismatches."""

import json

import numpy as np
import pyarrow.parquet as pq
import pytest

from teleprev.errors import ModelError
from teleprev.noncollision.dataset import (
    DatasetSettings,
    generate,
    load_dataset,
    pending_shards,
    shard_path,
)


@pytest.fixture
def settings(hand):
    return DatasetSettings("leap_hand_right", hand.urdf_sha256, uniform=1200, boundary=800, seed=3, shard_size=500)


def test_labels_are_exact_and_metadata_complete(tmp_path, hand, hand_checker, settings):
    n = generate(tmp_path, settings, workers=1)
    assert n == 2000 and settings.n_shards == 4
    data = load_dataset(tmp_path, hand.urdf_sha256)
    s = data.samples
    assert s.q.shape == (2000, 16) and s.labels.shape == (2000, 17)
    assert np.all(s.q >= hand.lower) and np.all(s.q <= hand.upper)
    # every stored configuration carries exactly the checker's labels (float32 values, labelled as stored)
    for i in np.random.default_rng(0).choice(len(s.q), 150, replace=False):
        report = hand_checker.check(s.q[i])
        assert np.array_equal(report.labels, s.labels[i])
        assert {p for p, hit in zip(hand_checker.link_pairs, s.pairs[i]) if hit} == set(report.pairs)
    assert np.array_equal(hand_checker.labels_from_pairs(s.pairs), s.labels)
    assert data.link_pairs == hand_checker.link_pairs
    uniform, boundary = s.source == 0, s.source != 0
    assert uniform.sum() == 1200 and boundary.sum() == 800
    # uniform samples are mostly colliding; boundary samples are balanced around the boundary
    assert s.labels[uniform].any(axis=1).mean() > 0.7
    assert 0.3 < s.labels[boundary].any(axis=1).mean() < 0.7
    meta = json.loads(pq.read_schema(shard_path(tmp_path, 0)).metadata[b"teleprev"])
    assert meta["urdf_sha256"] == hand.urdf_sha256
    assert meta["link_names"] == list(hand_checker.link_names)
    assert meta["uniform"] == 1200 and meta["sampling"]["steps"] == settings.sampling.steps


def test_boundary_samples_are_near_the_boundary(tmp_path, hand, hand_checker, settings):
    generate(tmp_path, settings)
    s = load_dataset(tmp_path).samples
    bnd = s.q[s.source == 1]  # bisection ends: a small step along a random direction flips many of them
    rng = np.random.default_rng(1)
    d = rng.standard_normal(bnd.shape)
    d *= 0.05 / np.linalg.norm(d, axis=1, keepdims=True)
    before = hand_checker.pair_matrix(bnd).any(axis=1)
    after = hand_checker.pair_matrix(hand.clip(bnd + d)).any(axis=1)
    assert (before != after).mean() > 0.2


def test_interrupted_run_resumes_with_identical_shards(tmp_path, hand, hand_checker, settings):
    generate(tmp_path, settings, workers=2)
    original = pq.read_table(shard_path(tmp_path, 2))
    kept = shard_path(tmp_path, 1).stat().st_mtime_ns
    # simulate an interruption: one shard never finished, another half-written, a temp file left behind
    shard_path(tmp_path, 2).unlink()
    shard_path(tmp_path, 3).write_bytes(shard_path(tmp_path, 3).read_bytes()[:200])
    (tmp_path / "shard-00003.tmp999").write_bytes(b"partial")
    assert pending_shards(tmp_path, settings) == [2, 3]
    with pytest.raises(ModelError, match="incomplete: 2 of 4 shards"):
        load_dataset(tmp_path)
    n = generate(tmp_path, settings, workers=1)
    assert n == sum(settings.shard_sizes(2)) + sum(settings.shard_sizes(3))
    assert shard_path(tmp_path, 1).stat().st_mtime_ns == kept  # finished shards were not redone
    assert pq.read_table(shard_path(tmp_path, 2)).equals(original)  # same seed per shard: same data
    assert not list(tmp_path.glob("*.tmp*"))
    assert len(load_dataset(tmp_path).samples) == 2000
    assert generate(tmp_path, settings) == 0


def test_other_settings_or_urdf_refused(tmp_path, hand, hand_checker, settings):
    generate(tmp_path, settings)
    other = DatasetSettings("leap_hand_right", hand.urdf_sha256, uniform=1200, boundary=800, seed=4, shard_size=500)
    with pytest.raises(ModelError, match="other settings .*seed"):
        generate(tmp_path, other)
    with pytest.raises(ModelError, match="different URDF"):
        load_dataset(tmp_path, urdf_sha256="0" * 64)
    with pytest.raises(ModelError, match="not a collision dataset folder"):
        load_dataset(tmp_path / "nothing")
