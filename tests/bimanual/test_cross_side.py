"""The two sides kept apart: the cross-robot contact check against FCL on every shape pair, and a scripted
episode driving the two hands through each other, with and without the guard."""

from __future__ import annotations

from pathlib import Path

import fcl
import numpy as np
import pytest

from teleprev.bimanual import build_guard, build_side_pipelines
from teleprev.rig import load_rig
from tests.helpers.bimanual_drive import HOME, drive_through

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def rig():
    return load_rig(ROOT / "rigs" / "sim_bimanual.toml")


@pytest.fixture(scope="module")
def guard(rig):
    return build_guard(rig, build_side_pipelines(rig))


def _reference(checker, q_a, q_b) -> set[tuple[str, str]]:
    """Every shape pair of the two robots put to FCL, no filter: collide, or closer than the clearance."""
    a, b = checker.robots
    sa, sb = a.shapes(q_a), b.shapes(q_b)
    out = set()
    for i, oa in enumerate(a.objects):
        oa.setTransform(fcl.Transform(sa[i, :3, :3], sa[i, :3, 3]))
        for j, ob in enumerate(b.objects):
            ob.setTransform(fcl.Transform(sb[j, :3, :3], sb[j, :3, 3]))
            if fcl.collide(oa, ob, fcl.CollisionRequest(), fcl.CollisionResult()) or \
                    fcl.distance(oa, ob, fcl.DistanceRequest(), fcl.DistanceResult()) < checker.clearance_m:
                out.add((a.link_of[i], b.link_of[j]))
    return out


def test_contacts_are_fcls_on_every_pair(guard, rng):
    checker, joints = guard.checker, guard.joints
    hand = np.zeros(16)
    seen = 0
    for turn in np.linspace(0.0, 1.2, 9):  # the two arms swung towards each other, fingers bent at random
        left, right = HOME.copy(), HOME.copy()
        left[0], right[0] = -turn, turn
        q_l = joints["left"].full(left, rng.uniform(0, 1.2, 16) * (rng.random(16) < 0.5))
        q_r = joints["right"].full(right, hand)
        got = checker.contacts(q_l, q_r)
        assert set(got) == _reference(checker, q_l, q_r), turn
        seen += bool(got)
    assert 3 <= seen < 9  # both answers occur, and apart at rest


def test_driving_the_hands_through_each_other_is_held(rig):
    unguarded = drive_through(rig, guard=False)
    assert unguarded.colliding_commands > 20  # the script does bring the robots into contact
    guarded = drive_through(rig, guard=True)
    assert guarded.ticks > 300
    assert guarded.colliding_commands == 0, guarded.contacts
    assert guarded.held >= 1 and guarded.flagged == guarded.held  # each held target says so in its report


def test_preview_is_not_guarded(rig, guard):
    """In preview nothing is commanded: targets pass as they are, and nothing is held."""
    from teleprev.pipeline.planner import TargetUpdate

    update = TargetUpdate(1, 0, HOME.copy(), np.zeros(6), 0, np.zeros(16), np.zeros(16))
    assert guard.guard("left", update, executing=False) == (update, [])
    assert guard.held == 0
