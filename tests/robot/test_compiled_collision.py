"""The compiled self-collision check and FK against FCL and the numpy FK.

FCL (through FclSelfCollisionChecker, itself checked against brute-force FCL in test_collision.py) is the
independent reference. The compiled check errs towards "colliding" by at most its margin, so its answer
is bracketed: every pair FCL reports, the compiled check reports; every pair the compiled check reports
with the margin turned negative (deeper than 1 nm only), FCL reports.
"""

import subprocess
import sys

import fcl
import numpy as np
import pytest

from teleprev.errors import UrdfError
from teleprev.kernels import boxes as boxes_kernels
from teleprev.kernels import collision as collision_kernels
from teleprev.robot.collision import SelfCollisionChecker
from teleprev.robot.compiled_collision import CompiledSelfCollisionChecker
from teleprev.robot.compiled_kinematics import CompiledKinematics
from teleprev.robot.exclusions import Exclusions
from teleprev.robot.model import load_robot
from teleprev.transforms import make_transform, rpy_to_matrix


@pytest.fixture(scope="module")
def compiled(hand):
    return CompiledSelfCollisionChecker(hand)


@pytest.fixture(scope="module")
def strict(hand):
    """Reports only pairs that overlap by more than the margin: a lower bracket on FCL's answer."""
    return CompiledSelfCollisionChecker(hand, margin=-boxes_kernels.MARGIN)


def _assert_bracketed(fcl_pairs, loose, tight):
    assert not (fcl_pairs & ~loose).any(), "the compiled check missed a contact FCL found"
    assert not (tight & ~fcl_pairs).any(), "the compiled check found an overlap deeper than its margin that FCL did not"


def test_same_links_pairs_and_order_as_the_fcl_checker(compiled, hand_checker):
    assert compiled.link_names == hand_checker.link_names
    assert compiled.link_pairs == hand_checker.link_pairs


def test_open_hand_is_free(hand, compiled):
    report = compiled.check(hand.neutral())
    assert not report.colliding and not report.labels.any() and report.pairs == ()
    assert not compiled.collides(hand.neutral())


def test_agrees_with_fcl_on_uniform_configurations(hand, hand_checker, compiled, strict, rng):
    q = hand.sample_uniform(6_000, rng)
    expected = hand_checker.pair_matrix(q)
    ours = compiled.pair_matrix(q)
    _assert_bracketed(expected, ours, strict.pair_matrix(q))
    # the margin is 1 nm: a uniform sample lands inside it about never
    assert (ours != expected).any(axis=1).sum() <= 2
    assert 0.75 < ours.any(axis=1).mean() < 0.92
    np.testing.assert_array_equal(compiled.labels(q), hand_checker.labels_from_pairs(ours))
    np.testing.assert_array_equal(compiled.pair_matrix(q, hand.fk(q).world), ours)


def test_single_configuration_api_matches_the_batch_and_fcl(hand, hand_checker, compiled, rng):
    q = hand.sample_uniform(400, rng)
    batch = compiled.pair_matrix(q)
    labels = compiled.labels_from_pairs(batch)
    for i in range(len(q)):
        report = compiled.check(q[i])
        expected = hand_checker.check(q[i])
        assert report.pairs == expected.pairs == tuple(compiled.link_pairs[k] for k in np.flatnonzero(batch[i]))
        np.testing.assert_array_equal(report.labels, expected.labels)
        np.testing.assert_array_equal(report.labels, labels[i])
        assert compiled.collides(q[i]) == report.colliding


def test_named_poses_report_the_same_links_as_fcl(hand, hand_checker, compiled):
    for pose in ({"1": 1.6, "2": 1.88, "3": 2.0}, {"0": 0.3}, {"12": 2.0, "13": 0.5, "14": 1.0, "15": 1.2}):
        q = hand.vector(pose)
        report, expected = compiled.check(q), hand_checker.check(q)
        assert report.pairs == expected.pairs and report.colliding
        np.testing.assert_array_equal(report.labels, expected.labels)


def test_near_contact_configurations_differ_only_inside_the_margin(hand, hand_checker, compiled, strict, rng):
    """Bisect FCL's contact boundary between a free and a colliding configuration to the last bit."""
    pool = hand.sample_uniform(400, rng)
    colliding = hand_checker.pair_matrix(pool).any(axis=1)
    free, hit = pool[~colliding][:40], pool[colliding][:40]
    margin_side = 0
    for q0, q1 in zip(free, hit):
        lo, hi = 0.0, 1.0  # FCL: free at lo, colliding at hi
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            if hand_checker.collides(q0 + mid * (q1 - q0)):
                hi = mid
            else:
                lo = mid
        q_free, q_hit = q0 + lo * (q1 - q0), q0 + hi * (q1 - q0)
        for q in (q_free, q_hit):
            expected = np.isin(np.arange(len(compiled.link_pairs)),
                               [compiled.link_pairs.index(p) for p in hand_checker.check(q).pairs])
            _assert_bracketed(expected[None], compiled.pair_matrix(q), strict.pair_matrix(q))
        assert compiled.collides(q_hit) and not strict.collides(q_free)
        margin_side += compiled.collides(q_free)
    # within 1e-16 rad of FCL's boundary, the boxes are within the margin: "colliding" on both sides
    assert margin_side >= 30


def test_the_pipeline_checker_gives_fcls_answers_bit_for_bit(hand, hand_checker, rng):
    """SelfCollisionChecker decides with the compiled check and asks FCL inside the margin, so its answers
    are FCL's everywhere, including configurations a last bit away from FCL's contact boundary."""
    checker = SelfCollisionChecker(hand)
    q = hand.sample_uniform(5000, rng)
    np.testing.assert_array_equal(checker.pair_matrix(q), hand_checker.pair_matrix(q))
    pool = hand.sample_uniform(200, rng)
    colliding = hand_checker.pair_matrix(pool).any(axis=1)
    band = 0
    for q0, q1 in zip(pool[~colliding][:15], pool[colliding][:15]):
        lo, hi = 0.0, 1.0
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if hand_checker.collides(q0 + mid * (q1 - q0)) else (mid, hi)
        for q in (q0 + lo * (q1 - q0), q0 + hi * (q1 - q0)):
            expected = hand_checker.check(q)
            report = checker.check(q)
            assert report.pairs == expected.pairs and checker.collides(q) == expected.colliding
            np.testing.assert_array_equal(report.labels, expected.labels)
            np.testing.assert_array_equal(checker.pair_matrix(q[None])[0], hand_checker.pair_matrix(q[None])[0])
        band += CompiledSelfCollisionChecker(hand).collides(q0 + lo * (q1 - q0))  # free for FCL, in the margin
    assert band >= 8, "the near-contact sample should exercise the FCL side"


def test_first_collision_of_a_batch_is_fcls(hand, hand_checker, rng):
    """A segment's points in order, through the boundary: the first FCL finds colliding, even when the
    compiled check is unsure of an earlier one (within its margin, free for FCL)."""
    checker = SelfCollisionChecker(hand)
    pool = hand.sample_uniform(300, rng)
    colliding = hand_checker.pair_matrix(pool).any(axis=1)
    for q0, q1 in zip(pool[~colliding][:10], pool[colliding][:10]):
        lo, hi = 0.0, 1.0
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if hand_checker.collides(q0 + mid * (q1 - q0)) else (mid, hi)
        points = q0 + np.array([0.0, 0.5 * lo, lo, hi, 1.0])[:, None] * (q1 - q0)
        expected = next(i for i, q in enumerate(points) if hand_checker.collides(q))
        assert checker.first_collision(points) == expected
        assert hand_checker.first_collision(points) == expected
        assert checker.first_collision(points[:expected]) is None
    assert CompiledSelfCollisionChecker(hand).first_collision(pool) == int(np.argmax(colliding))


# ---- the box-box test itself -------------------------------------------------------------------
def _boxes(*placed):
    """(S, 3, 4) poses and (S, 4) sizes for boxes_kernels.boxes_apart from (size, xyz, rpy) triples."""
    poses = np.array([make_transform(rpy_to_matrix(*rpy), xyz)[:3] for _, xyz, rpy in placed])
    sizes = np.array([[*(np.array(s) / 2), np.linalg.norm(s) / 2] for s, _, _ in placed])
    return poses, sizes


def _fcl_collide(placed) -> bool:
    (sa, xa, ra), (sb, xb, rb) = placed
    a = fcl.CollisionObject(fcl.Box(*sa), fcl.Transform(rpy_to_matrix(*ra), np.array(xa, dtype=float)))
    b = fcl.CollisionObject(fcl.Box(*sb), fcl.Transform(rpy_to_matrix(*rb), np.array(xb, dtype=float)))
    return bool(fcl.collide(a, b, fcl.CollisionRequest(), fcl.CollisionResult()))


def _apart(placed, margin=boxes_kernels.MARGIN) -> bool:
    poses, sizes = _boxes(*placed)
    return bool(boxes_kernels.boxes_apart(poses, 0, 1, sizes, margin))


def test_face_contact_is_decided_at_the_margin():
    cube = (1.0, 1.0, 1.0)
    for gap, apart in ((1e-3, True), (2e-9, True), (0.5e-9, False), (0.0, False), (-1e-3, False)):
        placed = [(cube, (0, 0, 0), (0, 0, 0)), (cube, (1.0 + gap, 0.2, -0.3), (0, 0, 0))]
        assert _apart(placed) == apart
        assert _fcl_collide(placed) == (gap <= 0)


def test_crossed_edges_are_separated_by_an_edge_axis_alone():
    """A's vertical edge faces B's horizontal edge: only the axis a_z x b_y separates them (at 2 * 0.5 * sqrt 2)."""
    cube = (1.0, 1.0, 1.0)
    edge = np.sqrt(2.0)
    for d, apart in ((1.6, True), (edge + 1e-6, True), (edge - 1e-6, False), (1.3, False)):
        placed = [(cube, (0, 0, 0), (0, 0, np.pi / 4)), (cube, (d, 0, 0), (0, np.pi / 4, 0))]
        assert _apart(placed) == apart
        assert _fcl_collide(placed) == (not apart)
    # face axes alone do not separate at d = 1.6 (they would from about 1.915)
    placed = [(cube, (0, 0, 0), (0, 0, np.pi / 4)), (cube, (1.6, 0, 0), (0, np.pi / 4, 0))]
    assert not _apart(placed, margin=1.0) and _apart(placed, margin=0.1)


@pytest.mark.parametrize("tilt", [0.0, 1e-15, 1e-12, 1e-9, 1e-6])
def test_nearly_parallel_edges_never_separate_overlapping_boxes(tilt):
    """The cross product of (nearly) parallel edges is about the zero vector; rounding must not make it separate."""
    size = (0.02, 0.006, 0.034)
    for overlap in (1e-7, 1e-4):
        placed = [(size, (0, 0, 0), (0, 0, 0)), (size, (0.02 - overlap, 0.003, 0.01), (tilt, 0, tilt))]
        assert not _apart(placed) and _fcl_collide(placed)
    placed = [(size, (0, 0, 0), (0, 0, 0)), (size, (0.0201, 0.003, 0.01), (tilt, 0, tilt))]
    assert _apart(placed) and not _fcl_collide(placed)


def test_other_geometry_is_refused(xarm6):
    with pytest.raises(UrdfError, match="boxes only"):
        CompiledSelfCollisionChecker(xarm6, Exclusions(()))


# ---- compiled FK ---------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["leap_hand_right", "xarm6", "xarm7", "xarm6_leap_hand"])
def test_compiled_fk_matches_the_numpy_fk(name, rng):
    model = load_robot(name)
    kin = CompiledKinematics(model)
    q = model.sample_uniform(2000, rng)
    expected = model.fk(q)
    assert np.abs(kin.world(q) - expected.world).max() < 1e-12
    for i in range(0, 2000, 101):
        assert np.abs(kin.world(q[i]) - expected.world[i]).max() < 1e-12
    tips = [n for n in model.link_names if n.endswith("tip_head")] or [model.link_names[-1]]
    for tip in tips:
        assert np.abs(kin.fk(q[:50]).position(tip) - expected.position(tip)[:50]).max() < 1e-12


# ---- compile cost stays off the start-up path ---------------------------------------------------
def test_importing_compiles_nothing_and_needs_no_fcl():
    code = (
        "import sys\n"
        "import teleprev.robot.compiled_collision\n"
        "from numba.core.registry import CPUDispatcher\n"
        "import importlib, pkgutil, teleprev.kernels\n"
        "mods = [importlib.import_module('teleprev.kernels.' + m.name) for m in "
        "pkgutil.iter_modules(teleprev.kernels.__path__)]\n"
        "print(sorted(n for k in mods for n, f in vars(k).items() if isinstance(f, CPUDispatcher) and "
        "f.signatures), 'fcl' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "[] False"


# ---- both margins in one pass (SelfCollisionChecker's kernels) ------------------------------------
def _near_contact(checker, hand, rng, n: int) -> np.ndarray:
    """Configurations a last bit either side of the contact boundary of `checker` (bisected 60 times
    between a free and a colliding configuration): where the two margins disagree."""
    pool = hand.sample_uniform(10 * n, rng)
    colliding = checker.pair_matrix(pool).any(axis=1)
    out = []
    for q0, q1 in zip(pool[~colliding][:n], pool[colliding][:n]):
        lo, hi = 0.0, 1.0
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if checker.collides(q0 + mid * (q1 - q0)) else (mid, hi)
        out += [q0 + lo * (q1 - q0), q0 + hi * (q1 - q0)]
    return np.array(out)


@pytest.fixture(scope="module", params=["plain", "grown"])
def margins(request, hand):
    """SelfCollisionChecker (its kernels' arguments: both margins) and its two single-margin checkers,
    for the hand's shapes and for them grown as the swept check grows them."""
    from teleprev.pipeline.swept import inflated_model

    model = hand if request.param == "plain" else inflated_model(hand, 0.0015)
    checker = SelfCollisionChecker(model)
    return model, checker, checker._loose, CompiledSelfCollisionChecker(model, checker.exclusions,
                                                                        margin=-boxes_kernels.MARGIN)


def test_both_margins_in_one_pass_equal_the_two_separate_calls(hand, margins, rng):
    model, checker, loose, tight = margins
    q = np.concatenate([hand.sample_uniform(3000, rng), _near_contact(loose, hand, rng, 25),
                        _near_contact(tight, hand, rng, 25)])
    lo, ti = loose.pair_matrix(q), tight.pair_matrix(q)
    differ = (lo != ti).any(axis=1)
    assert not (ti & ~lo).any()  # the tight margin's pairs are among the loose one's
    assert differ.sum() >= 15, "the near-contact sample should have configurations within the margin"

    hits, unsure = collision_kernels.pair_matrix_margins_world(loose.kinematics.world(q), *checker._args[3:])
    np.testing.assert_array_equal(unsure, differ)
    np.testing.assert_array_equal(hits[~differ], lo[~differ])

    n_pairs, n_links = len(checker.link_pairs), len(checker.link_names)
    for i in np.r_[np.flatnonzero(differ), np.arange(0, len(q), 7)]:
        labels, index = np.zeros(n_links, dtype=bool), np.empty(n_pairs, dtype=np.int64)
        n = collision_kernels.check_margins(q[i], *checker._args, False, labels, index)
        a, b = loose.check(q[i]), tight.check(q[i])
        if differ[i]:
            assert n == collision_kernels.MARGINS_UNSURE
        else:
            assert n == len(a.pairs) and tuple(checker.link_pairs[k] for k in index[:n]) == a.pairs == b.pairs
            np.testing.assert_array_equal(labels, a.labels)
        expected = 0 if not loose.collides(q[i]) else 1 if tight.collides(q[i]) else collision_kernels.MARGINS_UNSURE
        assert collision_kernels.collides_margins(q[i], *checker._args) == expected
        labels = np.zeros(n_links, dtype=bool)
        assert collision_kernels.check_margins(q[i], *checker._args, True, labels, index) == expected


def test_first_colliding_with_both_margins_is_the_loose_ones_with_the_tight_answer(hand, margins, rng):
    model, checker, loose, tight = margins
    near = _near_contact(loose, hand, rng, 10)
    free = hand.sample_uniform(400, rng)
    free = free[~loose.pair_matrix(free).any(axis=1)][:20]
    for q in (np.concatenate([free[:5], near[k:k + 1], free[5:]]) for k in range(len(near))):
        for start in (0, 3, 6, len(q)):
            k, state = collision_kernels.first_colliding_margins(q, start, *checker._args)
            expected = loose.first_collision(q, start)
            assert k == (-1 if expected is None else expected)
            if k >= 0:
                assert state == (1 if tight.collides(q[k]) else collision_kernels.MARGINS_UNSURE)
            else:
                assert state == 0


def test_box_state_is_the_two_single_margin_answers(rng):
    """boxes_state against boxes_apart with either margin, on box pairs apart, touching and overlapping
    by amounts around the margin (face, edge and random contacts, random orientations)."""
    sizes = rng.uniform(0.005, 0.05, (400, 2, 3))
    states = set()
    for k in range(400):
        (sa, sb) = sizes[k]
        rpy = rng.uniform(-np.pi, np.pi, 3) if k % 3 else rng.normal(0, 1e-9, 3) * (k % 2)
        # push b along a's x axis until its face touches, then by a gap around the margin
        placed = [(tuple(sa), (0, 0, 0), (0, 0, 0)), (tuple(sb), (0, 0, 0), tuple(rpy))]
        poses, size = _boxes(*placed)
        extent = sb @ np.abs(poses[1, :3, :3][0]) / 2 + sa[0] / 2
        gap = rng.choice([-3e-9, -1.5e-9, -1e-9, -5e-10, 0.0, 5e-10, 1e-9, 1.5e-9, 3e-9, 1e-3, -1e-3])
        poses[1, :, 3] = (extent + gap, rng.uniform(-0.3, 0.3) * sa[1], rng.uniform(-0.3, 0.3) * sa[2])
        for a, b in ((0, 1), (1, 0)):
            loose = boxes_kernels.boxes_apart(poses, a, b, size, boxes_kernels.MARGIN)
            tight = boxes_kernels.boxes_apart(poses, a, b, size, -boxes_kernels.MARGIN)
            state = boxes_kernels.boxes_state(poses, a, b, size, boxes_kernels.MARGIN, -boxes_kernels.MARGIN)
            expected = (
                boxes_kernels.BOX_APART if loose else boxes_kernels.BOX_LOOSE if tight else boxes_kernels.BOX_BOTH
            )
            assert state == expected
            states.add(state)
    assert states == {boxes_kernels.BOX_APART, boxes_kernels.BOX_LOOSE, boxes_kernels.BOX_BOTH}
