"""The runtime Corrector with the shipped models: never a colliding or out-of-limits output, untouched when
free, continuous along smooth input, and the fallback path holding the guarantee on its own."""

import numpy as np
import pytest

from teleprev.noncollision.corrector import Corrector
from teleprev.noncollision.mlp import CCN, MLP
from teleprev.noncollision.trajectories import retargeted_trajectories


@pytest.fixture(scope="module")
def corrector(hand, hand_checker):
    return Corrector.load(None, hand, hand_checker)


@pytest.fixture(scope="module")
def invalid(hand, hand_checker):
    q = hand.sample_uniform(1500, np.random.default_rng(4242))
    return q[hand_checker.pair_matrix(q).any(axis=1)][:600]


def _assert_valid(hand, checker, outputs):
    outputs = np.atleast_2d(outputs)
    assert np.all(outputs >= hand.lower) and np.all(outputs <= hand.upper)
    colliding = checker.pair_matrix(outputs).any(axis=1)  # the batched path: independent of the single check
    assert not colliding.any(), f"{colliding.sum()} colliding outputs"


def test_invalid_inputs_corrected(corrector, hand, hand_checker, invalid):
    results = [corrector.correct(q) for q in invalid]
    _assert_valid(hand, hand_checker, np.array([r.q for r in results]))
    actions = [r.action for r in results]
    assert "untouched" not in actions
    assert actions.count("ccn") > 0.9 * len(actions)  # the CCN does the work; fallback is the exception
    for q, r in zip(invalid, results):
        assert set(r.colliding_links) == set(hand_checker.check(q).colliding_links(hand_checker.link_names))
        assert r.deviation == pytest.approx(np.max(np.abs(r.q - q)))


def test_free_inputs_untouched(corrector, hand, hand_checker):
    q = hand.sample_uniform(2000, np.random.default_rng(7))
    free = q[~hand_checker.pair_matrix(q).any(axis=1)][:100]
    assert len(free) > 50
    for qf in free:
        r = corrector.correct(qf)
        assert r.action == "untouched" and r.colliding_links == () and r.deviation == 0.0
        assert np.array_equal(r.q, qf)


def test_out_of_limits_input_clamped(corrector, hand, hand_checker):
    q = hand.neutral() + 0.0
    q[1] = hand.upper[1] + 0.5
    r = corrector.correct(q)
    _assert_valid(hand, hand_checker, r.q)
    assert r.deviation >= 0.5 - 1e-12
    with pytest.raises(ValueError, match="finite"):
        corrector.correct(np.full(16, np.nan))
    with pytest.raises(ValueError, match="16"):
        corrector.correct(np.zeros(5))


@pytest.fixture(scope="module")
def forced_fallback(hand, hand_checker, corrector):
    """The shipped CPN with a CCN that proposes its input unchanged: every invalid input falls back."""
    net = corrector.ccn.net
    zero = MLP(
        net.info,
        net.w[:-1] + [np.zeros_like(net.w[-1])],
        [b[:, 0, :] for b in net.b[:-1]] + [np.zeros_like(net.b[-1][:, 0, :])],
    )
    return Corrector(hand, hand_checker, corrector.cpn, CCN(zero, hand.lower, hand.upper))


def test_fallback_alone_never_collides(forced_fallback, hand, hand_checker, invalid):
    rng = np.random.default_rng(5)
    outs, anchored = [], 0
    free_pool = hand.sample_uniform(3000, rng)
    free_pool = free_pool[~hand_checker.pair_matrix(free_pool).any(axis=1)]
    for k, q in enumerate(invalid[:300]):
        previous = (
            free_pool[k] if k % 3 == 1 else (q if k % 3 == 2 else None)
        )  # free, colliding (must be ignored), none
        r = forced_fallback.correct(q, previous)
        assert r.action == "fallback"
        outs.append(r.q)
        anchored += np.array_equal(r.q, hand.neutral()) or (previous is not None and np.array_equal(r.q, previous))
    _assert_valid(hand, hand_checker, np.array(outs))
    assert anchored < 0.5 * len(outs)  # most answers come from projection or the segment, not the anchor


def test_continuous_along_retargeted_trajectories(corrector, hand, hand_checker):
    trajs = retargeted_trajectories(hand, 3, seconds=8.0, seed=99)
    worst_ratio, corrected = 0.0, 0
    for traj in trajs:
        previous, prev_in = None, None
        outs = []
        for q in traj:
            r = corrector.correct(q, previous)
            corrected += r.action != "untouched"
            if previous is not None:
                step_in = np.max(np.abs(q - prev_in))
                step_out = np.max(np.abs(r.q - previous))
                # a step may not exceed the input's step by more than the CCN's margin at the boundary
                assert step_out <= 3.0 * step_in + 0.15, (step_in, step_out, r.action)
                worst_ratio = max(worst_ratio, step_out / max(step_in, 1e-3))
            previous, prev_in = r.q, q
            outs.append(r.q)
        _assert_valid(hand, hand_checker, np.array(outs))
        # total motion stays comparable to the input's: no chattering between corrections
        path_in = np.abs(np.diff(traj, axis=0)).sum()
        path_out = np.abs(np.diff(np.array(outs), axis=0)).sum()
        assert path_out < 1.5 * path_in
    assert corrected > 100  # the trajectories do go through self-collision
