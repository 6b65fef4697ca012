"""The shipped CPN and CCN on freshly generated held-out data: the issue's figures, on smaller samples and
with slightly looser thresholds (bench/collision_model.py prints the full figures)."""

import pytest

from teleprev.noncollision import evaluate
from teleprev.noncollision.corrector import Corrector

SEED = 31_337  # not a training or bench seed


@pytest.fixture(scope="module")
def exact(hand):
    """The pipeline's exact check: FCL's answers bit for bit (tests/robot/test_compiled_collision.py), at
    50x its speed, which the 20,000 held-out labels need (8 s with FCL itself)."""
    from teleprev.robot.collision import SelfCollisionChecker

    return SelfCollisionChecker(hand)


@pytest.fixture(scope="module")
def corrector(hand, exact):
    return Corrector.load(None, hand, exact)


def test_cpn_heldout(corrector, hand, exact):
    figs = evaluate.cpn_heldout(hand, exact, corrector.cpn, n_uniform=20_000, n_boundary=0, seed=SEED)
    assert figs["cpn_auc_min_link"] >= 0.99, figs["cpn_auc_per_link"]
    assert figs["cpn_recall"] >= 0.99
    assert figs["cpn_config_fnr"] <= 0.01


def test_ccn_heldout(corrector, hand, exact):
    invalid = evaluate.invalid_set(hand, exact, n_uniform=3000, n_trajectory=1000, seed=SEED)
    figs = evaluate.ccn_heldout(exact, corrector.ccn, invalid)
    assert figs["ccn_valid_frac"] >= 0.93
    assert figs["ccn_valid_frac_trajectory"] >= 0.9
    # corrections stay local (the shipped card: about 0.11 rad mean absolute joint deviation, mostly deep
    # uniform collisions; trajectory frames need much less)
    assert figs["ccn_mean_dev_rad"] < 0.15
    assert figs["ccn_mean_dev_rad_trajectory"] < 0.1
