"""Finding the link pairs a self-collision check should leave out: adjacent ones, and ones in contact in
every sampled configuration (`teleprev robot exclusions` writes them next to the URDF with exclusions.py)."""

from __future__ import annotations

import numpy as np

from teleprev.robot.collision import SelfCollisionChecker
from teleprev.robot.exclusions import ExcludedPair, Exclusions, adjacent_pairs
from teleprev.robot.model import RobotModel


def compute_exclusions(model: RobotModel, samples: int, seed: int = 0, progress=None) -> Exclusions:
    """Adjacent pairs, plus pairs found in contact in every one of `samples` uniform configurations."""
    adjacent = adjacent_pairs(model)
    checker = SelfCollisionChecker(model, Exclusions(tuple(ExcludedPair(p, "adjacent") for p in adjacent)))
    rng = np.random.default_rng(seed)
    always = np.ones(len(checker.link_pairs), dtype=bool)
    done = 0
    while done < samples:
        n = min(2000, samples - done)
        always &= checker.pair_matrix(model.sample_uniform(n, rng)).all(axis=0)
        done += n
        if progress:
            progress(n)
    pairs = [ExcludedPair(p, "adjacent") for p in adjacent]
    pairs += [ExcludedPair(p, "always") for p, a in zip(checker.link_pairs, always) if a and samples > 0]
    return Exclusions(tuple(pairs), model.urdf_sha256, samples)
