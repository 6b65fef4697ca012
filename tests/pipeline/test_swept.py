"""The swept self-collision check of hand commands: the link-motion bound holds, a segment that passes
through a collision between two free end points is caught, and the clearance margin is real distance."""

import numpy as np
import pytest

from teleprev.pipeline.swept import SweptCheck
from teleprev.robot.collision import SelfCollisionChecker
from teleprev.robot.model import load_robot


@pytest.fixture(scope="module")
def swept():
    hand = load_robot("leap_hand_right")
    return SweptCheck(hand, SelfCollisionChecker(hand), 0.003)


def _corners(swept, q):
    """World positions of every collision box's corners, (shapes * 8, 3)."""
    model = swept.model
    poses = model.fk(q)
    points = []
    for name in swept.checker.link_names:
        world = poses.matrix(name)
        for shape in model.links[name].collisions:
            half = np.array(shape.size[:3]) / 2 if shape.kind == "box" else np.zeros(3)
            for sx in (-1, 1):
                for sy in (-1, 1):
                    for sz in (-1, 1):
                        p = shape.origin @ np.r_[half * (sx, sy, sz), 1.0]
                        points.append((world @ p)[:3])
    return np.array(points)


def test_no_point_moves_further_than_the_bound(swept):
    rng = np.random.default_rng(0)
    m = swept.model
    for _ in range(20):
        q0 = m.sample_uniform(1, rng)[0]
        q1 = np.clip(q0 + rng.normal(0, 0.2, q0.shape), m.lower, m.upper)
        start = _corners(swept, q0)
        moved = max(np.linalg.norm(_corners(swept, q0 + s * (q1 - q0)) - start, axis=1).max() for s in np.linspace(0, 1, 11))
        assert moved <= swept.motion_bound(q0, q1) + 1e-12


def test_a_segment_through_a_collision_between_free_end_points_is_caught(swept):
    m, plain = swept.model, swept.checker
    rng = np.random.default_rng(1)
    found = 0
    for _ in range(4000):
        q0, q1 = m.sample_uniform(2, rng)
        q1 = q0 + 0.3 * (q1 - q0)
        if not (swept.clear(q0) and swept.clear(q1)):
            continue
        middle = any(plain.collides(q0 + s * (q1 - q0)) for s in np.linspace(0, 1, 41)[1:-1])
        if middle:
            found += 1
            assert not swept.segment_free(q0, q1)
        if found >= 3:
            break
    assert found >= 1, "no free-ends-but-colliding segment in the sample"
    open_hand = m.neutral()
    assert swept.segment_free(open_hand, open_hand + 0.05)  # a small motion of the open hand is free


def test_the_clearance_is_distance_between_links(swept):
    import fcl

    m, plain = swept.model, swept.checker
    rng = np.random.default_rng(2)
    checked = 0
    for q in m.sample_uniform(3000, rng):
        if plain.collides(q) or swept.clear(q):
            continue
        # free, but not clear: some checked pair of shapes is nearer than the margin
        shapes = plain._shape_world(m.fk(q).world)
        nearest = np.inf
        for a, b in zip(plain._si.tolist(), plain._sj.tolist()):
            for s in (a, b):
                plain._objects[s].setRotation(shapes[s, :3, :3])
                plain._objects[s].setTranslation(shapes[s, :3, 3])
            nearest = min(nearest, fcl.distance(plain._objects[a], plain._objects[b], fcl.DistanceRequest(), fcl.DistanceResult()))
        assert nearest < 0.003 + 1e-9
        checked += 1
        if checked >= 5:
            break
    assert checked
