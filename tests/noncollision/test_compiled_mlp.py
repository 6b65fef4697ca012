"""Compiled CPN / CCN inference (teleprev/kernels/mlp.py): agrees with the numpy networks to float32
rounding, answers a row the same bits whatever batch it is in, and the Corrector on them keeps every
guarantee of the numpy one (NumpyCorrector, formats 1 and 2) (every answer passes the exact checker;
prepare-then-correct == correct)."""

import numpy as np
import pytest

from teleprev.noncollision.compiled import CompiledCCN, CompiledCPN, CompiledMLP, CompiledNets
from teleprev.noncollision.corrector import Corrector
from teleprev.noncollision.mlp import CCN, CPN
from teleprev.pipeline.older_formats import NumpyCorrector
from tests.noncollision.test_mlp import _random_net


@pytest.fixture(scope="module")
def shipped(hand, hand_checker):
    return NumpyCorrector.load(None, hand, hand_checker)


@pytest.fixture(scope="module")
def compiled_corrector(hand, hand_checker):
    return Corrector.load(None, hand, hand_checker)


@pytest.fixture(scope="module")
def colliding(hand, hand_checker):
    q = hand.sample_uniform(3000, np.random.default_rng(31))
    return q[hand_checker.pair_matrix(q).any(axis=1)][:800]


def _close(a, b, rel=1e-5):
    scale = np.abs(a).max(axis=-1, keepdims=True) + 1e-6  # per row: relative to the row's largest output
    return np.max(np.abs(a - b) / scale) < rel


@pytest.mark.parametrize("activation", ["relu", "silu", "tanh"])
def test_compiled_forward_matches_numpy(hand, hand_checker, activation):
    rng = np.random.default_rng(3)
    q = np.concatenate([hand.sample_uniform(300, rng), hand.sample_uniform(20, rng) * 0.0])
    for kind in ("cpn", "ccn"):
        net = _random_net(hand, hand_checker, kind, activation, rng)
        assert _close(net.slots(q), CompiledMLP(net).slots(q))
        assert _close(net.slots(q[7]), CompiledMLP(net).slots(q[7]))
    ccn = CCN(net, hand.lower, hand.upper)
    assert np.max(np.abs(ccn(q) - CompiledCCN(ccn)(q))) < 1e-5


def test_shipped_networks_match_numpy(hand, shipped, colliding):
    rng = np.random.default_rng(4)
    q = np.concatenate([hand.sample_uniform(1000, rng), colliding])
    cpn, ccn = CompiledCPN(shipped.cpn), CompiledCCN(shipped.ccn)
    assert _close(shipped.cpn.net.slots(q), cpn.mlp.slots(q))
    assert _close(shipped.ccn.net.slots(q), ccn.mlp.slots(q))
    assert np.max(np.abs(shipped.ccn(q) - ccn(q))) < 1e-5
    assert np.allclose(shipped.cpn.prob(q), cpn.prob(q), atol=1e-5)
    # the decision differs only where the numpy score is within float32 rounding of the threshold
    score = shipped.cpn.score(q).astype(np.float64)
    differ = shipped.cpn.predicts_free(q) != cpn.predicts_free(q)
    assert np.all(np.abs(score[differ] - shipped.cpn.free_below) < 1e-4 * (1.0 + abs(shipped.cpn.free_below)))


def test_batch_rows_equal_single_rows_bitwise(hand, shipped, colliding):
    nets = CompiledNets(shipped.cpn, shipped.ccn, 2)
    q = np.concatenate([colliding[:150], hand.sample_uniform(50, np.random.default_rng(5))])
    slots = nets.cpn.mlp.slots(q)
    free = nets.cpn.predicts_free(q)
    proposals = nets.ccn(q)
    batch = nets.propose_shorten(q)
    for k, x in enumerate(q):
        assert np.array_equal(nets.cpn.mlp.slots(x), slots[k])
        assert nets.cpn.predicts_free(x) == free[k]
        assert np.array_equal(nets.ccn(x), proposals[k])
        single = nets.propose_shorten(x[None])
        for a, b in zip(single, batch):
            assert np.array_equal(a[0], b[k])
    # and the same bits every time
    again = nets.propose_shorten(q)
    assert all(np.array_equal(a, b) for a, b in zip(again, batch))


@pytest.mark.parametrize("activation", ["relu", "silu", "tanh"])
def test_every_batch_width_answers_as_a_single_row(hand, hand_checker, activation):
    """Batches run four rows per pass over a layer, the rest one row at a time, a pass adding the inputs nonzero
    in any of its rows (a zero product where a row's own input is zero): batches of every size up to two
    blocks, rows with zero joints and ReLU's zero units among them, give each row the bits it has alone."""
    rng = np.random.default_rng(12)
    q = hand.sample_uniform(17, rng)
    q[::3] = 0.0  # whole rows of zero inputs next to rows without
    q[1::4, :5] = 0.0
    cpn = CPN(_random_net(hand, hand_checker, "cpn", activation, rng))
    ccn = CCN(_random_net(hand, hand_checker, "ccn", activation, rng), hand.lower, hand.upper)
    nets = CompiledNets(cpn, ccn, 2)
    alone = [(nets.cpn.mlp.slots(x), nets.cpn.predicts_free(x), nets.ccn(x), nets.propose_shorten(x[None]))
             for x in q]
    for size in range(2, 18):
        x = q[:size]
        slots, free, proposals, batch = (
            nets.cpn.mlp.slots(x),
            nets.cpn.predicts_free(x),
            nets.ccn(x),
            nets.propose_shorten(x),
        )
        for k in range(size):
            assert np.array_equal(slots[k], alone[k][0]) and free[k] == alone[k][1]
            assert proposals[k].tobytes() == alone[k][2].tobytes()
            assert all(a[k].tobytes() == b[0].tobytes() for a, b in zip(batch, alone[k][3]))


def test_fused_step_bisects_as_the_numpy_corrector_would(shipped, colliding):
    """propose_shorten picks the fraction that _shortest_predicted_free picks, asking the compiled CPN."""
    nets = CompiledNets(shipped.cpn, shipped.ccn, 2)
    proposals, shortened, his = nets.propose_shorten(colliding[:200])
    probe = NumpyCorrector(shipped.model, shipped.checker, nets.cpn, shipped.ccn)  # bisection with the compiled CPN
    for q0, p, s, hi in zip(colliding[:200], proposals, shortened, his):
        expected = probe._shortest_predicted_free(q0, p)
        if expected is None:
            assert hi == nets.steps
        else:
            assert hi < nets.steps and np.array_equal(s, expected)


def test_compiled_corrector_answers_pass_the_exact_checker(compiled_corrector, hand, hand_checker, colliding):
    rng = np.random.default_rng(6)
    inputs = np.concatenate([colliding, hand.clip(hand.neutral() + rng.normal(0, 0.6, (400, 16)))])
    outs, actions = [], []
    previous = None
    for k, q in enumerate(inputs):
        r = compiled_corrector.correct(q, previous if k % 2 else None)
        outs.append(r.q)
        actions.append(r.action)
        previous = r.q
    outs = np.array(outs)
    assert np.all(outs >= hand.lower) and np.all(outs <= hand.upper)
    assert not hand_checker.pair_matrix(outs).any()
    assert actions.count("ccn") > 0.9 * len(colliding)


def test_compiled_fallback_never_collides(hand, hand_checker, shipped, colliding):
    from teleprev.noncollision.mlp import MLP
    from tests.noncollision.test_corrector import _assert_valid

    net = shipped.ccn.net
    zero = MLP(net.info, net.w[:-1] + [np.zeros_like(net.w[-1])],
               [b[:, 0, :] for b in net.b[:-1]] + [np.zeros_like(net.b[-1][:, 0, :])])
    forced = Corrector(hand, hand_checker, shipped.cpn, CCN(zero, hand.lower, hand.upper))
    outs = [forced.correct(q) for q in colliding[:100]]
    assert all(r.action == "fallback" for r in outs)
    _assert_valid(hand, hand_checker, np.array([r.q for r in outs]))


def test_compiled_prepare_then_correct_equals_correct(compiled_corrector, hand, colliding):
    rng = np.random.default_rng(8)
    q = np.concatenate([colliding[:200], hand.sample_uniform(100, rng)])
    q[::7, 3] = hand.upper[3] + 0.2  # some outside the limits
    prepared = compiled_corrector.prepare(q)
    previous = hand.neutral()
    for x, p in zip(q, prepared):
        a = compiled_corrector.correct(x, previous, p)
        b = compiled_corrector.correct(x, previous)
        assert a.action == b.action and a.colliding_links == b.colliding_links and a.deviation == b.deviation
        assert np.array_equal(a.q, b.q)


def test_compiled_cpn_decides_as_the_cpn(hand, shipped):
    """The fallback's projection asks the compiled CPN for its decision: a bool for one configuration,
    one per row for many, the numpy CPN's answers (these samples are not within rounding of the threshold)."""
    cpn = CompiledCPN(shipped.cpn)
    q = hand.sample_uniform(200, np.random.default_rng(9))
    assert isinstance(cpn.predicts_free(q[0]), bool) and cpn.predicts_free(q).shape == (200,)
    assert cpn.predicts_free(q).tolist() == shipped.cpn.predicts_free(q).tolist()
    assert 0 < cpn.predicts_free(q).sum() < 200  # both answers occur
