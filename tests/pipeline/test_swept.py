"""The swept self-collision check of hand commands: the link-motion bound holds, a segment that passes
through a collision between two free end points is caught, and the clearance margin is real distance."""

import numpy as np
import pytest

from teleprev.pipeline.older_formats import NumpySweptCheck
from teleprev.pipeline.swept import SweptCheck
from teleprev.robot.collision import SelfCollisionChecker
from teleprev.robot.model import load_robot
from tests.helpers.hand_segments import random_segments


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
        moved = max(
            np.linalg.norm(_corners(swept, q0 + s * (q1 - q0)) - start, axis=1).max() for s in np.linspace(0, 1, 11)
        )
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
            nearest = min(
                nearest, fcl.distance(plain._objects[a], plain._objects[b], fcl.DistanceRequest(), fcl.DistanceResult())
            )
        assert nearest < 0.003 + 1e-9
        checked += 1
        if checked >= 5:
            break
    assert checked


# ---- the compiled check (SweptCheck, teleprev/kernels/swept.py) gives the numpy check's answers (NumpySweptCheck)
@pytest.fixture(scope="module")
def pair():
    hand = load_robot("leap_hand_right")
    plain = SelfCollisionChecker(hand)
    return NumpySweptCheck(hand, plain, 0.003), SweptCheck(hand, plain, 0.003)


def _agree(numpy_swept, compiled_swept, segments, monkeypatch):
    """The compiled check answers as the numpy one, with the same clearance cache; returns how often it
    handed a segment to the numpy check, and how many bisections the kernel finished alone (a kernel that
    never decides would agree too, through those fallbacks)."""
    handed, bisected = [0], [0]
    numpy_check, kernel_bisection = compiled_swept._segment_free_numpy, compiled_swept._last_free_compiled

    def to_numpy(q0, q1):
        handed[0] += 1
        return numpy_check(q0, q1)

    def bisection(q0, q1, steps):
        lo = kernel_bisection(q0, q1, steps)
        bisected[0] += lo is not None
        return lo

    monkeypatch.setattr(compiled_swept, "_segment_free_numpy", to_numpy)
    monkeypatch.setattr(compiled_swept, "_last_free_compiled", bisection)
    for q0, q1 in segments:
        numpy_swept._clear_cache = compiled_swept._clear_cache = (b"", False)
        assert numpy_swept.segment_free(q0, q1) == compiled_swept.segment_free(q0, q1)
        assert numpy_swept._clear_cache == compiled_swept._clear_cache
        assert numpy_swept.segment_free(q1, q0) == compiled_swept.segment_free(q1, q0)  # with a cache hit at q0 maybe
        assert numpy_swept._clear_cache == compiled_swept._clear_cache
    for q0, q1 in segments[::5]:
        a, b = numpy_swept.last_free_on_segment(q0, q1), compiled_swept.last_free_on_segment(q0, q1)
        assert a.tobytes() == b.tobytes()
        assert numpy_swept._clear_cache == compiled_swept._clear_cache
    return handed[0], bisected[0]


def test_compiled_segment_checks_agree_with_numpy(pair, monkeypatch):
    numpy_swept, compiled_swept = pair
    assert compiled_swept._kernel_args is not None  # LEAP Hand: boxes, so the kernels run
    segments = random_segments(numpy_swept.model, 1200, np.random.default_rng(3))
    free = sum(numpy_swept.segment_free(*s) for s in segments)
    assert 0.2 * len(segments) < free < 0.9 * len(segments)  # both answers are well represented
    handed, bisected = _agree(numpy_swept, compiled_swept, segments, monkeypatch)
    assert handed == 0 and bisected > 0.9 * len(segments[::5])  # the kernels decided


def test_compiled_check_asks_fcl_within_the_margin(pair, monkeypatch):
    """With the tight margin pushed far out, every contact the loose test finds is left to FCL (the
    kernel's UNSURE answers): the answers stay the numpy check's."""
    from teleprev.robot.collision import FclSelfCollisionChecker

    numpy_swept, compiled_swept = pair
    hand = numpy_swept.model
    unsure = SweptCheck(hand, numpy_swept.checker, 0.003)
    args = list(unsure._kernel_args)
    args[-2] = -1.0  # the tight test's margin: no contact is ever certain
    unsure._kernel_args = tuple(args)
    asked = [0]
    fcl = FclSelfCollisionChecker.collides

    def ask_fcl(checker, q):
        asked[0] += 1
        return fcl(checker, q)

    monkeypatch.setattr(FclSelfCollisionChecker, "collides", ask_fcl)
    handed, _ = _agree(numpy_swept, unsure, random_segments(hand, 300, np.random.default_rng(4)), monkeypatch)
    assert handed == 0 and asked[0] > 50  # the kernel's UNSURE answers went to FCL, not to the numpy check


def test_compiled_command_check_is_both_segment_checks(pair):
    """command_free: segment_free(q0, q1) and segment_free(q1, the stop point), as Motion.hand_step makes
    them, with the same clearance cache afterwards."""
    from teleprev.pipeline.trajectory import HandLimiter

    numpy_swept, compiled_swept = pair
    hand = numpy_swept.model
    limiter = HandLimiter(hand.lower, hand.upper, hand.velocity_limit, np.full(len(hand.lower), 40.0))
    rng = np.random.default_rng(5)
    decided = 0
    for q0, q1 in random_segments(hand, 600, rng):
        v1 = rng.normal(0, 1.0, q0.shape) * (rng.random() < 0.8)
        stop = np.minimum(np.maximum(q1 + v1 * np.abs(v1) / (2.0 * limiter.acceleration), limiter.lower), limiter.upper)
        for cache in ((b"", False), (q0.tobytes(), True), (q1.tobytes(), False)):
            numpy_swept._clear_cache = compiled_swept._clear_cache = cache
            expected = numpy_swept.segment_free(q0, q1) and numpy_swept.segment_free(q1, stop)
            got = compiled_swept.command_free(q0, q1, v1, limiter.acceleration, limiter.lower, limiter.upper)
            if got is None:  # within the margin somewhere: the caller makes the two calls
                continue
            decided += 1
            assert got == expected
            assert numpy_swept._clear_cache == compiled_swept._clear_cache
    assert decided > 1000


def test_a_chain_of_commands_checks_each_start_once(pair, monkeypatch):
    """Consecutive commands (each starting where the last one ended, as the planner sends them) answer as
    the two numpy segment checks do, and the kernel is told each start's clearance, found by the check
    of the command before (without that, every command checked its start again: a fifth of the points)."""
    from teleprev.kernels import swept as swept_kernels
    from teleprev.pipeline.trajectory import HandLimiter

    numpy_swept, compiled_swept = pair
    hand = numpy_swept.model
    limiter = HandLimiter(hand.lower, hand.upper, hand.velocity_limit, np.full(len(hand.lower), 40.0))
    told, kernel = [], swept_kernels.swept_command

    def swept_command(q0, q1, v1, acceleration, lower, upper, q0_clear, *rest):
        told.append(q0_clear)
        return kernel(q0, q1, v1, acceleration, lower, upper, q0_clear, *rest)

    monkeypatch.setattr(swept_kernels, "swept_command", swept_command)
    rng = np.random.default_rng(6)
    compiled_swept._clear_cache = compiled_swept._command_end = (b"", False)
    q, decided = hand.neutral(), 0
    for _ in range(400):
        step = rng.normal(0, 0.004, q.shape)
        q1 = np.clip(q + step, hand.lower, hand.upper)
        v1 = step / 0.01
        stop = np.minimum(np.maximum(q1 + v1 * np.abs(v1) / (2.0 * limiter.acceleration), limiter.lower), limiter.upper)
        numpy_swept._clear_cache = (b"", False)
        expected = numpy_swept.segment_free(q, q1) and numpy_swept.segment_free(q1, stop)
        got = compiled_swept.command_free(q, q1, v1, limiter.acceleration, limiter.lower, limiter.upper)
        if got is not None:
            decided += 1
            assert got == expected
        q = q1 if expected else q
    assert decided > 390
    known = sum(c >= 0 for c in told[1:])
    assert known > 0.95 * (len(told) - 1), known
