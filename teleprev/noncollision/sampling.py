"""Configurations labelled by the exact checker: uniform in the joint limits, and near the collision boundary.

Uniform samples are mostly in collision for the LEAP Hand (about 85 %), and most of those are deep in
collision, so they say little about where the boundary is. Boundary samples do: take a collision-free and
a colliding configuration, bisect the segment between them down to a contact boundary, keep both ends of
the last bracket (one free, one colliding, both within |segment| / 2**steps of the boundary), and add
jittered copies at a log-uniform range of distances so the band around the boundary is covered too.

Each sample keeps its m per-link labels and, for the record, which checked link pairs collide (the
link labels are the OR of those). Every configuration is rounded to float32 before it is labelled, so the stored
(float32) values carry
exactly the labels the checker gave them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from teleprev.robot.collision import SelfCollisionChecker
from teleprev.robot.model import RobotModel

SOURCES = ("uniform", "boundary", "jitter")


def as_stored(q: np.ndarray, model: RobotModel) -> np.ndarray:
    """Round to float32 (the stored precision) and back, so labels match the stored values; a value that
    rounds past a joint limit moves to the float32 value just inside it."""
    q32 = np.asarray(q, dtype=np.float32)
    lo, hi = model.lower.astype(np.float32), model.upper.astype(np.float32)
    lo = np.where(lo < model.lower, np.nextafter(lo, np.float32(np.inf)), lo)
    hi = np.where(hi > model.upper, np.nextafter(hi, np.float32(-np.inf)), hi)
    return np.clip(q32, lo, hi).astype(np.float64)


@dataclass(frozen=True)
class BoundarySettings:
    steps: int = 8  # bisection steps: bracket width is the segment length / 2**steps
    jitter_per_pair: int = 2  # jittered copies per boundary point
    jitter_min: float = 0.005  # rad, per-joint standard deviation of the jitter (log-uniform)
    jitter_max: float = 0.1


@dataclass(frozen=True)
class Samples:
    q: np.ndarray  # (N, n_joints) float64 with float32 values
    labels: np.ndarray  # (N, m) bool, per checked link (checker.link_names)
    pairs: np.ndarray  # (N, P) bool, per checked link pair (checker.link_pairs)
    source: np.ndarray  # (N,) uint8 index into SOURCES

    def __len__(self) -> int:
        return len(self.q)

    def take(self, index) -> Samples:
        return Samples(self.q[index], self.labels[index], self.pairs[index], self.source[index])

    @staticmethod
    def concat(parts: list[Samples]) -> Samples:
        return Samples(*(np.concatenate([getattr(p, f) for p in parts]) for f in ("q", "labels", "pairs", "source")))


CHUNK = 5000  # configurations per batched check: the checker's temporaries grow with the batch


def pair_matrix(checker: SelfCollisionChecker, q: np.ndarray) -> np.ndarray:
    """checker.pair_matrix in chunks, so that memory stays bounded for any number of configurations."""
    q = np.atleast_2d(q)
    if len(q) <= CHUNK:
        return checker.pair_matrix(q)
    return np.concatenate([checker.pair_matrix(q[i:i + CHUNK]) for i in range(0, len(q), CHUNK)])


def colliding(checker: SelfCollisionChecker, q: np.ndarray) -> np.ndarray:
    """(N,) bool: which configurations are in self-collision (exact, batched)."""
    return pair_matrix(checker, q).any(axis=1)


def label(checker: SelfCollisionChecker, q: np.ndarray, source: int) -> Samples:
    pairs = pair_matrix(checker, q)
    return Samples(q, checker.labels_from_pairs(pairs), pairs, np.full(len(q), source, np.uint8))


def uniform(model: RobotModel, checker: SelfCollisionChecker, n: int, rng: np.random.Generator) -> Samples:
    return label(checker, as_stored(model.sample_uniform(n, rng), model), 0)


def boundary(
    model: RobotModel,
    checker: SelfCollisionChecker,
    pool: Samples,
    n: int,
    rng: np.random.Generator,
    settings: BoundarySettings = BoundarySettings(),
) -> Samples:
    """n samples near the collision boundary, from segments between free and colliding members of `pool`."""
    colliding = pool.labels.any(axis=1)
    free_idx, hit_idx = np.flatnonzero(~colliding), np.flatnonzero(colliding)
    if len(free_idx) == 0 or len(hit_idx) == 0:
        raise ValueError("boundary sampling needs both free and colliding configurations in the pool")
    per_pair = 2 + settings.jitter_per_pair
    pairs = -(-n // per_pair)
    lo = pool.q[rng.choice(free_idx, pairs)]
    hi = pool.take(rng.choice(hit_idx, pairs))
    hi = Samples(hi.q.copy(), hi.labels.copy(), hi.pairs.copy(), np.full(pairs, 1, np.uint8))
    for _ in range(settings.steps):
        mid = label(checker, as_stored(0.5 * (lo + hi.q), model), 1)
        hit = mid.pairs.any(axis=1)
        hi.q[hit], hi.labels[hit], hi.pairs[hit] = mid.q[hit], mid.labels[hit], mid.pairs[hit]
        lo[~hit] = mid.q[~hit]
    parts = [Samples(lo, np.zeros_like(hi.labels), np.zeros_like(hi.pairs), hi.source), hi]
    if settings.jitter_per_pair:
        k = settings.jitter_per_pair
        centre = np.repeat(0.5 * (lo + hi.q), k, axis=0)
        sigma = np.exp(rng.uniform(np.log(settings.jitter_min), np.log(settings.jitter_max), size=(len(centre), 1)))
        parts.append(label(checker, as_stored(centre + sigma * rng.standard_normal(centre.shape), model), 2))
    out = Samples.concat(parts)
    return out.take(rng.permutation(len(out))[:n])
