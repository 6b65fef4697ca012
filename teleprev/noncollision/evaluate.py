"""Held-out figures of the CPN and CCN on freshly generated data (for the model cards and the benchmark).

    CPN: uniform samples (the paper's distribution) and boundary samples, labelled exactly; per-link ROC AUC,
         recall at the operating threshold, colliding configurations predicted entirely free.
    CCN: invalid configurations from uniform samples and from retargeted human hand trajectories; the exact
         collision-free fraction of the CCN's outputs and the mean absolute joint deviation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from teleprev.noncollision import sampling
from teleprev.noncollision.metrics import cpn_figures
from teleprev.noncollision.mlp import CCN, CPN
from teleprev.noncollision.trajectories import retargeted_trajectories
from teleprev.robot.collision import SelfCollisionChecker
from teleprev.robot.model import RobotModel

EVAL_SEED = 20_241_217  # held-out data never share the training seed's streams


def _prob(cpn: CPN, q: np.ndarray, chunk: int = 20_000) -> np.ndarray:
    return np.concatenate([cpn.prob(q[i:i + chunk]) for i in range(0, len(q), chunk)])


def cpn_heldout(model: RobotModel, checker: SelfCollisionChecker, cpn: CPN, n_uniform: int, n_boundary: int,
                seed: int = EVAL_SEED) -> dict:
    rng = np.random.default_rng([seed, 1])
    uni = sampling.uniform(model, checker, n_uniform, rng)
    out = {
        "cpn_threshold": cpn.threshold,
        "cpn_heldout_uniform": n_uniform,
        "cpn_heldout_boundary": n_boundary,
        "cpn_heldout_seed": seed,
    }
    fig = cpn_figures(_prob(cpn, uni.q), uni.labels, cpn.threshold)
    out.update(fig.as_dict())
    out["cpn_auc_per_link"] = {n: round(float(a), 5) for n, a in zip(checker.link_names, fig.auc_per_link)}
    if n_boundary:
        bnd = sampling.boundary(model, checker, uni, n_boundary, rng)
        out.update(cpn_figures(_prob(cpn, bnd.q), bnd.labels, cpn.threshold).as_dict(prefix="cpn_boundary_"))
    return out


@dataclass(frozen=True)
class InvalidSet:
    q: np.ndarray  # (N, n) colliding configurations
    source: np.ndarray  # (N,) "uniform" | "trajectory"
    trajectories: list[np.ndarray]  # the full trajectories the trajectory part came from


def invalid_set(model: RobotModel, checker: SelfCollisionChecker, n_uniform: int, n_trajectory: int,
                seed: int = EVAL_SEED) -> InvalidSet:
    """At least `n_uniform` colliding uniform samples (the first n_uniform) and the colliding frames of
    retargeted trajectories, generated until there are n_trajectory of them."""
    rng = np.random.default_rng([seed, 2])
    parts = []
    have = 0
    while have < n_uniform:
        q = sampling.as_stored(model.sample_uniform(max(1000, int(1.25 * (n_uniform - have))), rng), model)
        q = q[sampling.colliding(checker, q)][: n_uniform - have]
        parts.append(q)
        have += len(q)
    uni = np.concatenate(parts) if parts else np.zeros((0, len(model.lower)))
    trajs, frames, have, k = [], [], 0, 0
    while have < n_trajectory:
        traj = retargeted_trajectories(model, 1, seconds=10.0, seed=seed * 1000 + k)[0]
        k += 1
        hit = sampling.colliding(checker, traj)
        trajs.append(traj)
        frames.append(traj[hit][: n_trajectory - have])
        have += len(frames[-1])
    traj_q = np.concatenate(frames) if frames else np.zeros((0, len(model.lower)))
    source = np.array(["uniform"] * len(uni) + ["trajectory"] * len(traj_q))
    return InvalidSet(np.concatenate([uni, traj_q]), source, trajs)


def ccn_heldout(checker: SelfCollisionChecker, ccn: CCN, invalid: InvalidSet) -> dict:
    out_q = ccn(invalid.q)
    valid = ~sampling.colliding(checker, out_q)
    dev = np.abs(out_q - invalid.q).mean(axis=1)
    fig = {
        "ccn_valid_frac": float(valid.mean()),
        "ccn_mean_dev_rad": float(dev.mean()),
        "ccn_n_invalid": int(len(valid)),
    }
    for src in ("uniform", "trajectory"):
        sel = invalid.source == src
        if sel.any():
            fig[f"ccn_valid_frac_{src}"] = float(valid[sel].mean())
            fig[f"ccn_mean_dev_rad_{src}"] = float(dev[sel].mean())
    return fig
