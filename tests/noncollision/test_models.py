"""The shipped CPN and CCN on freshly generated held-out data: the issue's figures, on smaller samples and
with slightly looser thresholds (bench/collision_model.py prints the full figures)."""

import pytest

from teleprev.noncollision import evaluate
from teleprev.noncollision.corrector import Corrector

SEED = 31_337  # not a training or bench seed


@pytest.fixture(scope="module")
def corrector(hand, hand_checker):
    return Corrector.load(None, hand, hand_checker)


def test_cpn_heldout(corrector, hand, hand_checker):
    figs = evaluate.cpn_heldout(hand, hand_checker, corrector.cpn, n_uniform=20_000, n_boundary=0, seed=SEED)
    assert figs["cpn_auc_min_link"] >= 0.99, figs["cpn_auc_per_link"]
    assert figs["cpn_recall"] >= 0.99
    assert figs["cpn_config_fnr"] <= 0.01


def test_ccn_heldout(corrector, hand, hand_checker):
    invalid = evaluate.invalid_set(hand, hand_checker, n_uniform=3000, n_trajectory=1000, seed=SEED)
    figs = evaluate.ccn_heldout(hand_checker, corrector.ccn, invalid)
    assert figs["ccn_valid_frac"] >= 0.93
    assert figs["ccn_valid_frac_trajectory"] >= 0.9
    # corrections stay local (the shipped card: about 0.11 rad mean absolute joint deviation, mostly deep
    # uniform collisions; trajectory frames need much less)
    assert figs["ccn_mean_dev_rad"] < 0.15
    assert figs["ccn_mean_dev_rad_trajectory"] < 0.1
