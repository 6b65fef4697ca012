"""The simulated operator's demonstrations through the real path into the physics world
(teleprev/evaluation/demos.py): its glove and suit samples through the rig's pipeline (retarget, Corrector),
the driver's updates through the command planner, each tick's commands into the world's drives."""

from __future__ import annotations

from pathlib import Path

import pytest

from teleprev.evaluation.demos import run_demo
from teleprev.rig import load_rig

ROOT = Path(__file__).resolve().parents[2]
POUR_SEED = 0


@pytest.fixture(scope="module")
def rig():
    return load_rig(ROOT / "rigs" / "sim_physics.toml")


def test_a_pick_and_place_by_the_watching_operator_succeeds(rig):
    result = run_demo(rig, "pick_place", seed=0)
    assert result.outcome.success, result.outcome.reason
    assert "let go and at rest" in result.outcome.reason
    # The Corrector did work on the way (the tight grasp retargets into self-collision), and every tick
    # commanded the world.
    assert result.actions.get("ccn", 0) > 0 and result.ticks > 100 * result.sim_s


def test_a_pour_by_the_watching_operator_succeeds(rig):
    # The operator turns the hand towards the bowl and points the fingers down before it rolls the cup
    # past 110 degrees: with the roll alone the xArm's last joint stops at about 90 and nothing pours.
    result = run_demo(rig, "pour", seed=POUR_SEED)
    assert result.outcome.success, result.outcome.reason
    assert "balls in the bowl" in result.outcome.reason and "let go and at rest" in result.outcome.reason
    # The firm pour grip squeezes into self-collision while the cup is upside down: the Corrector works.
    assert result.actions.get("ccn", 0) > 0


def test_without_the_corrector_the_hand_holds_where_the_glove_collides(rig):
    result = run_demo(rig, "pick_place", seed=0, hand="no_corrector")
    assert "ccn" not in result.actions and result.actions.get("held", 0) > 0


def test_an_unknown_hand_side_is_refused(rig):
    with pytest.raises(ValueError, match="hand must be one of"):
        run_demo(rig, "pick_place", seed=0, hand="none")


def test_a_mug_hung_on_the_peg_by_the_watching_operator_succeeds(rig):
    # The operator picks the mug by its body, pushes its handle's hole along the peg (seen where the mug's
    # base and yaw put it) and lets go: the mug hangs from the peg, clear of the table, at rest.
    result = run_demo(rig, "hang", seed=0)
    assert result.outcome.success, result.outcome.reason
    assert "the peg through the mug's handle" in result.outcome.reason
    assert "let go and at rest" in result.outcome.reason
