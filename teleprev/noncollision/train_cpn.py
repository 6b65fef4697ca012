"""Self-Collision Prediction Network training (appendix A.1): configuration -> per-link collision probability.

Architecture: "grouped" (default) is one small MLP per group of joints that can collide with each other
(two fingers), each link's probability the noisy-OR of its pairs' outputs (groups.py); "plain" is one
MLP from all joints to all links' logits, as in the paper.
Loss: the mean over links of the binary cross-entropy (equation 5), each link's positive term weighted by
`pos_weight` times that link's negative/positive ratio in the training set, so that rare link collisions
weigh as much as common ones and a missed collision costs more than a false alarm. The grouped network's
output slots are single link pairs, so the dataset's per-pair labels also supervise them directly (an
auxiliary per-pair BCE, weight `pair_weight`), which tells each slot which pair a link's collision came
from instead of leaving the noisy-OR to work it out. Adam with a cosine
learning-rate decay; the weights of the epoch with the best validation loss are kept. The operating
threshold is then picked on the validation set: the largest probability at which the target recall of
colliding link labels, and the target rate of colliding configurations flagged somewhere, are met.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from teleprev.errors import ModelError
from teleprev.noncollision.dataset import load_dataset
from teleprev.noncollision.groups import collision_groups, single_group
from teleprev.noncollision.metrics import cpn_figures, recall_threshold
from teleprev.noncollision.mlp import MLP, ModelInfo
from teleprev.robot.collision import SelfCollisionChecker
from teleprev.robot.model import RobotModel


@dataclass(frozen=True)
class CPNSettings:
    architecture: str = "grouped"  # or "plain"
    hidden: tuple[int, ...] = (128, 128, 128)
    activation: str = "relu"
    epochs: int = 24
    batch_size: int = 1024
    lr: float = 2e-3
    pos_weight: float = 2.0  # on top of each link's negative/positive ratio
    pair_weight: float = 1.0  # grouped: weight of the auxiliary per-pair BCE on the output slots
    val_frac: float = 0.05
    target_recall: float = 0.998  # on the validation set, with a margin over the 0.995 asked of held-out data
    target_config_fnr: float = 0.002
    seed: int = 0
    device: str = "auto"


@dataclass(frozen=True)
class EpochLog:
    epoch: int
    train_loss: float
    val_loss: float
    val_auc_min_link: float
    val_recall_at_half: float
    seconds: float


@dataclass
class CPNResult:
    net: MLP
    settings: CPNSettings
    history: list[EpochLog] = field(default_factory=list)
    best_epoch: int = 0
    val_figures: dict = field(default_factory=dict)
    dataset: dict = field(default_factory=dict)
    device: str = "cpu"
    seconds: float = 0.0


def normalisation(model: RobotModel) -> tuple[np.ndarray, np.ndarray]:
    """Joint-space features in [-1, 1]: offset = middle of the limits, scale = half the range."""
    return 0.5 * (model.lower + model.upper), 0.5 * (model.upper - model.lower)


def split(n: int, val_frac: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    order = np.random.default_rng(seed).permutation(n)
    n_val = max(1, int(round(n * val_frac)))
    return order[n_val:], order[:n_val]


def train_cpn(
    dataset_path: Path,
    model: RobotModel,
    checker: SelfCollisionChecker,
    settings: CPNSettings = CPNSettings(),
    log: Callable[[EpochLog], None] | None = None,
) -> CPNResult:
    import torch

    from teleprev.noncollision.torch_util import TorchMLP, pick_device, seed_everything

    t_start = time.perf_counter()
    link_names = checker.link_names
    if settings.architecture not in ("grouped", "plain"):
        raise ValueError(f"unknown CPN architecture {settings.architecture!r} (grouped or plain)")
    data = load_dataset(dataset_path, model.urdf_sha256)
    if data.link_names != tuple(link_names):
        raise ModelError(
            f"dataset links {list(data.link_names)} differ from the checker's {list(link_names)}", str(dataset_path)
        )
    if data.joint_names != tuple(model.joint_names):
        raise ModelError(f"dataset joints {list(data.joint_names)} differ from the robot's", str(dataset_path))
    device = pick_device(settings.device)
    gen = seed_everything(settings.seed)
    train_idx, val_idx = split(len(data.samples), settings.val_frac, settings.seed)
    q = torch.as_tensor(data.samples.q, dtype=torch.float32)
    y = torch.as_tensor(data.samples.labels, dtype=torch.float32)
    q_train, y_train = q[train_idx].to(device), y[train_idx].to(device)
    q_val, y_val = q[val_idx].to(device), y[val_idx].to(device)
    del q, y

    pos = y_train.mean(0).clamp(1e-4, 1 - 1e-4)
    pos_weight = (settings.pos_weight * (1 - pos) / pos).clamp(min=1.0)  # never weigh collisions below free
    offset, scale = normalisation(model)
    grouped = settings.architecture == "grouped"
    info = ModelInfo(
        kind="cpn", robot=model.name, urdf_sha256=model.urdf_sha256, joint_names=tuple(model.joint_names),
        link_names=tuple(link_names),
        groups=collision_groups(model, checker) if grouped else single_group(model.joint_names, link_names),
        combine="noisy_or" if grouped else "identity", hidden=tuple(settings.hidden), activation=settings.activation,
        input_offset=offset, input_scale=scale, threshold=0.5,
    )
    net = TorchMLP(info)
    if grouped:
        with torch.no_grad():  # start each pair at a small probability, not at the noisy-OR of many halves
            net.biases[-1].fill_(-4.0)
    net = net.to(device)
    # grouped: output slot k is link pair slot_pair[k] (padding slots are left out of the pair loss)
    pair_index = {p: i for i, p in enumerate(data.link_pairs)}
    slot_pair = [(g * info.width_out + k, pair_index[tuple(o)]) for g, grp in enumerate(info.groups)
                 for k, o in enumerate(grp.outputs)] if grouped else []
    use_pairs = bool(slot_pair) and settings.pair_weight > 0
    if use_pairs:
        slots_idx = torch.as_tensor([s for s, _ in slot_pair], device=device)
        pairs_idx = torch.as_tensor([p for _, p in slot_pair])
        yp_all = torch.as_tensor(data.samples.pairs[:, pairs_idx.numpy()], dtype=torch.float32)
        yp_train, yp_val = yp_all[train_idx].to(device), yp_all[val_idx].to(device)
        del yp_all
        pos_p = yp_train.mean(0).clamp(1e-4, 1 - 1e-4)
        pair_pos_weight = (settings.pos_weight * (1 - pos_p) / pos_p).clamp(1.0, 100.0)
    else:
        yp_train = yp_val = torch.zeros(len(q_train), 0)
    opt = torch.optim.Adam(net.parameters(), lr=settings.lr)
    steps_per_epoch = -(-len(q_train) // settings.batch_size)
    sched = torch.optim.lr_scheduler.OneCycleLR(
        opt, max_lr=settings.lr, total_steps=settings.epochs * steps_per_epoch, pct_start=0.05
    )

    def losses(q, target, target_pairs):
        """Equation 5 (mean per-link BCE, positives weighted) and the auxiliary per-pair BCE."""
        slots = net.slots(q)
        log_p, log_not_p = net.cpn_log_probs(q, slots)
        link = -(pos_weight * target * log_p + (1.0 - target) * log_not_p).mean()
        if not use_pairs:
            return link, link
        pair = torch.nn.functional.binary_cross_entropy_with_logits(
            slots[:, slots_idx], target_pairs, pos_weight=pair_pos_weight)
        return link, link + settings.pair_weight * pair

    def evaluate() -> tuple[float, np.ndarray]:
        with torch.no_grad():
            loss, probs = 0.0, []
            for i in range(0, len(q_val), 65536):
                sl = slice(i, i + 65536)
                loss += float(losses(q_val[sl], y_val[sl], yp_val[sl])[0]) * len(q_val[sl])
                probs.append(net.cpn_prob(q_val[sl]))
        return loss / len(q_val), torch.cat(probs).cpu().numpy()

    result = CPNResult(net=None, settings=settings, device=str(device))  # type: ignore[arg-type]
    best_loss, best_state = float("inf"), None
    val_labels = data.samples.labels[val_idx]
    for epoch in range(1, settings.epochs + 1):
        t0 = time.perf_counter()
        perm = torch.randperm(len(q_train), generator=gen).to(device)
        total = 0.0
        for i in range(0, len(perm), settings.batch_size):
            b = perm[i:i + settings.batch_size]
            link_loss, loss = losses(q_train[b], y_train[b], yp_train[b])
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            sched.step()
            total += link_loss.item() * len(b)
        val_loss, prob = evaluate()
        fig = cpn_figures(prob, val_labels, 0.5)
        entry = EpochLog(epoch, total / len(perm), val_loss, fig.auc_min_link, fig.recall, time.perf_counter() - t0)
        result.history.append(entry)
        if log:
            log(entry)
        if val_loss < best_loss:
            best_loss, result.best_epoch = val_loss, epoch
            best_state = {k: v.detach().clone() for k, v in net.state_dict().items()}
    net.load_state_dict(best_state)
    _, prob = evaluate()
    threshold = recall_threshold(prob, val_labels, settings.target_recall, settings.target_config_fnr)
    info = ModelInfo(**{**info.__dict__, "threshold": threshold})
    fig = cpn_figures(prob, val_labels, threshold)
    result.val_figures = {"threshold": threshold, **fig.as_dict(prefix=""), "n": fig.n,
                          "auc_per_link": dict(zip(link_names, (round(float(a), 5) for a in fig.auc_per_link)))}
    result.dataset = {
        "path": str(dataset_path),
        "samples": len(data.samples),
        "train": len(train_idx),
        "val": len(val_idx),
        **{k: v for k, v in data.settings.to_json().items() if k not in ("format",)},
    }
    result.seconds = time.perf_counter() - t_start
    training = {
        "settings": {**asdict(settings), "hidden": list(settings.hidden)},
        "best_epoch": result.best_epoch,
        "history": [
            {k: round(v, 5) if isinstance(v, float) else v for k, v in asdict(h).items()} for h in result.history
        ],
        "val": {k: v for k, v in result.val_figures.items() if k != "auc_per_link"},
        "dataset": result.dataset,
        "device": result.device,
        "seconds": round(result.seconds, 1),
    }
    info = ModelInfo(**{**info.__dict__, "training": training})
    result.net = net.cpu().to_numpy(info)
    return result
