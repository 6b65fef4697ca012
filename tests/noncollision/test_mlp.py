"""The numpy networks used at runtime agree with the torch ones they were trained as, and their gradient is right."""

import numpy as np
import pytest

from teleprev.noncollision.groups import collision_groups, single_group
from teleprev.noncollision.mlp import CCN, CPN, MLP, ModelInfo, load_model, save_model


def _random_net(hand, checker, kind, activation, rng):
    if kind == "cpn":
        groups, combine = collision_groups(hand, checker), "noisy_or"
    else:
        groups, combine = single_group(hand.joint_names, hand.joint_names), "identity"
    info = ModelInfo(
        kind,
        hand.name,
        hand.urdf_sha256,
        hand.joint_names,
        checker.link_names,
        groups,
        combine,
        (32, 24),
        activation,
        0.5 * (hand.lower + hand.upper),
        0.5 * (hand.upper - hand.lower),
        threshold=0.3 if kind == "cpn" else None,
        output_scale=0.5 * (hand.upper - hand.lower) if kind == "ccn" else None,
    )
    shapes = info.layer_shapes()
    return MLP(info, [rng.standard_normal(s).astype(np.float32) * 0.5 for s in shapes],
               [rng.standard_normal((s[0], s[2])).astype(np.float32) * 0.5 for s in shapes])


def test_groups_cover_every_checked_pair_once(hand, hand_checker):
    groups = collision_groups(hand, hand_checker)
    slots = [tuple(o) for g in groups for o in g.outputs]
    assert sorted(slots) == sorted(hand_checker.link_pairs)
    assert len(groups) == 6 and all(len(g.inputs) == 8 for g in groups)  # the six pairs of fingers


@pytest.mark.parametrize("activation", ["relu", "silu", "tanh"])
def test_numpy_matches_torch_and_file_roundtrip(tmp_path, hand, hand_checker, activation):
    import torch

    from teleprev.noncollision.torch_util import TorchMLP

    rng = np.random.default_rng(0)
    q = hand.sample_uniform(64, rng)
    cpn_net = _random_net(hand, hand_checker, "cpn", activation, rng)
    path = save_model(tmp_path / "cpn_x.safetensors", cpn_net)
    cpn = CPN(load_model(path, "cpn", hand, hand_checker.link_names))
    with torch.no_grad():
        expected = TorchMLP.from_numpy(cpn_net).cpn_prob(torch.as_tensor(q, dtype=torch.float32)).numpy()
    assert np.allclose(cpn.prob(q), expected, atol=2e-5)
    assert np.allclose(cpn.prob(q[5]), expected[5], atol=2e-5)  # the single-configuration path

    ccn_net = _random_net(hand, hand_checker, "ccn", activation, rng)
    ccn = CCN(load_model(save_model(tmp_path / "ccn_x.safetensors", ccn_net), "ccn", hand), hand.lower, hand.upper)
    with torch.no_grad():
        t = TorchMLP.from_numpy(ccn_net)
        qt = torch.as_tensor(q, dtype=torch.float32)
        delta = t.outputs(qt).numpy()
    assert np.allclose(ccn(q), np.clip(q + ccn.output_scale * delta, hand.lower, hand.upper), atol=2e-5)
    assert np.all(ccn(q) >= hand.lower) and np.all(ccn(q) <= hand.upper)


@pytest.mark.parametrize("activation", ["silu", "tanh"])
def test_mean_probability_gradient(hand, hand_checker, activation):
    rng = np.random.default_rng(1)
    cpn = CPN(_random_net(hand, hand_checker, "cpn", activation, rng))
    q = hand.sample_uniform(4, rng)
    _, grad = cpn.mean_prob_grad(q)
    eps = 1e-3
    numeric = np.stack(
        [(cpn.prob(q + eps * e).mean(1) - cpn.prob(q - eps * e).mean(1)) / (2 * eps) for e in np.eye(16)], axis=1
    )
    assert np.allclose(grad, numeric, atol=2e-3 * np.abs(numeric).max())


def test_batched_scores_stay_far_inside_the_band_of_single_ones(hand, rng):
    """Corrector.prepare trusts a batched CPN score's side of the threshold unless it is within SCORE_BAND
    of it: batched and single float32 sums must differ by far less than that (the shipped CPN)."""
    from teleprev.noncollision.corrector import Corrector
    from teleprev.noncollision.mlp import SCORE_BAND

    cpn = Corrector.load(None, hand).cpn
    q = np.concatenate([hand.sample_uniform(1500, rng), hand.clip(hand.neutral() + rng.normal(0, 0.3, (1500, 16)))])
    batch = cpn.score(q).astype(np.float64)
    single = np.array([float(cpn.score(x)) for x in q])
    assert np.max(np.abs(batch - single) / (1.0 + np.abs(single))) < SCORE_BAND / 100
    assert np.array_equal(single < cpn.free_below, np.array([cpn.predicts_free(x) for x in q]))
