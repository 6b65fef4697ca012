"""Invalid Configuration Correction Network training (appendix A.2): invalid configuration -> corrected one.

    q_hat = clip(q + scale * net(q), lower, upper)          (scale: half of each joint's range)
    L = alpha * mean((q_hat - q)^2) + beta * mean_links(CPN(q_hat))      (equations 6-8), CPN frozen

The last layer starts at zero, so training starts from the identity. Adam with a cosine learning-rate
decay. Convergence is monitored by the exact collision rate of the outputs on held-out invalid
configurations (fcl, every epoch); the epoch with the lowest rate is kept (ties: the smaller deviation).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from teleprev.errors import ModelError
from teleprev.noncollision.dataset import load_dataset
from teleprev.noncollision.groups import single_group
from teleprev.noncollision.mlp import CCN, MLP, ModelInfo, file_sha256, load_model
from teleprev.noncollision.sampling import colliding
from teleprev.noncollision.train_cpn import normalisation, split
from teleprev.robot.collision import SelfCollisionChecker
from teleprev.robot.model import RobotModel


@dataclass(frozen=True)
class CCNSettings:
    alpha: float = 1.0
    beta: float = 1.0
    hidden: tuple[int, ...] = (256, 256, 256)
    activation: str = "silu"
    epochs: int = 12
    batch_size: int = 1024
    lr: float = 1e-3
    val_frac: float = 0.05
    val_exact: int = 3000  # held-out invalid configurations checked exactly every epoch
    max_train: int = 0  # 0: every invalid configuration of the dataset
    seed: int = 0
    device: str = "auto"


@dataclass(frozen=True)
class CCNEpochLog:
    epoch: int
    loss: float
    mse: float
    collision: float
    val_valid_frac: float  # exact check
    val_mean_dev_rad: float
    seconds: float


@dataclass
class CCNResult:
    net: MLP
    settings: CCNSettings
    history: list[CCNEpochLog] = field(default_factory=list)
    best_epoch: int = 0
    val_figures: dict = field(default_factory=dict)
    dataset: dict = field(default_factory=dict)
    device: str = "cpu"
    seconds: float = 0.0


def exact_validity(checker: SelfCollisionChecker, q_in: np.ndarray, q_out: np.ndarray) -> tuple[float, float]:
    """Fraction of outputs collision-free (exact) and the mean absolute joint deviation (rad)."""
    valid = ~colliding(checker, q_out)
    return float(valid.mean()), float(np.abs(q_out - q_in).mean())


def invalid_configurations(dataset_path: Path, model: RobotModel, link_names) -> tuple[np.ndarray, dict]:
    data = load_dataset(dataset_path, model.urdf_sha256)
    if data.link_names != tuple(link_names) or data.joint_names != tuple(model.joint_names):
        raise ModelError("dataset joints or links differ from the robot's and checker's", str(dataset_path))
    q = data.samples.q[data.samples.labels.any(axis=1)]
    info = {"path": str(dataset_path), "samples": len(data.samples), "invalid": len(q),
            **{k: v for k, v in data.settings.to_json().items() if k != "format"}}
    return q, info


def train_ccn(
    dataset_path: Path,
    cpn_path: Path,
    model: RobotModel,
    checker: SelfCollisionChecker,
    settings: CCNSettings = CCNSettings(),
    log: Callable[[CCNEpochLog], None] | None = None,
    invalid: tuple[np.ndarray, dict] | None = None,
) -> CCNResult:
    """`invalid` may pass (configurations, dataset info) already loaded, as the grid search does."""
    import torch

    from teleprev.noncollision.torch_util import TorchMLP, pick_device, seed_everything

    t_start = time.perf_counter()
    q_all, data_info = (
        invalid if invalid is not None else invalid_configurations(dataset_path, model, checker.link_names)
    )
    cpn_np = load_model(cpn_path, "cpn", model, checker.link_names)
    device = pick_device(settings.device)
    gen = seed_everything(settings.seed)
    train_idx, val_idx = split(len(q_all), settings.val_frac, settings.seed)
    if settings.max_train:
        train_idx = train_idx[: settings.max_train]
    q_train = torch.as_tensor(q_all[train_idx], dtype=torch.float32, device=device)
    q_val = q_all[val_idx[: settings.val_exact]]

    cpn = TorchMLP.from_numpy(cpn_np).to(device).eval()
    for p in cpn.parameters():
        p.requires_grad_(False)
    offset, scale = normalisation(model)
    info = ModelInfo(
        kind="ccn", robot=model.name, urdf_sha256=model.urdf_sha256, joint_names=tuple(model.joint_names),
        link_names=tuple(checker.link_names), groups=single_group(model.joint_names, model.joint_names),
        combine="identity", hidden=tuple(settings.hidden), activation=settings.activation,
        input_offset=offset, input_scale=scale, output_scale=scale,
    )
    net = TorchMLP(info).to(device)
    with torch.no_grad():
        net.weights[-1].zero_()
        net.biases[-1].zero_()
    out_scale = torch.as_tensor(scale, dtype=torch.float32, device=device)
    lower = torch.as_tensor(model.lower, dtype=torch.float32, device=device)
    upper = torch.as_tensor(model.upper, dtype=torch.float32, device=device)

    def corrected(q):
        return torch.clamp(q + out_scale * net.outputs(q), lower, upper)

    opt = torch.optim.Adam(net.parameters(), lr=settings.lr)
    steps = settings.epochs * -(-len(q_train) // settings.batch_size)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=settings.lr, total_steps=steps, pct_start=0.05)

    def validate() -> tuple[float, float]:
        ccn = CCN(_to_numpy(net, info), model.lower, model.upper)
        return exact_validity(checker, q_val, ccn(q_val))

    result = CCNResult(net=None, settings=settings, device=str(device))  # type: ignore[arg-type]
    best, best_state = (-1.0, float("inf")), None
    for epoch in range(1, settings.epochs + 1):
        t0 = time.perf_counter()
        perm = torch.randperm(len(q_train), generator=gen).to(device)
        sums = np.zeros(3)
        for i in range(0, len(perm), settings.batch_size):
            q = q_train[perm[i:i + settings.batch_size]]
            q_hat = corrected(q)
            mse = ((q_hat - q) ** 2).mean()
            collision = cpn.cpn_prob(q_hat).mean()
            loss = settings.alpha * mse + settings.beta * collision
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            sched.step()
            sums += np.array([loss.item(), mse.item(), collision.item()]) * len(q)
        valid, dev = validate()
        sums /= len(perm)
        entry = CCNEpochLog(epoch, float(sums[0]), float(sums[1]), float(sums[2]), valid, dev, time.perf_counter() - t0)
        result.history.append(entry)
        if log:
            log(entry)
        if (valid, -dev) > (best[0], -best[1]):
            best, result.best_epoch = (valid, dev), epoch
            best_state = {k: v.detach().clone() for k, v in net.state_dict().items()}
    net.load_state_dict(best_state)
    result.val_figures = {"valid_frac": best[0], "mean_dev_rad": best[1], "n": len(q_val)}
    result.dataset = {**data_info, "train": len(train_idx), "val": len(val_idx)}
    result.seconds = time.perf_counter() - t_start
    training = {
        "settings": {**asdict(settings), "hidden": list(settings.hidden)},
        "best_epoch": result.best_epoch,
        "history": [
            {k: round(v, 5) if isinstance(v, float) else v for k, v in asdict(h).items()} for h in result.history
        ],
        "val": result.val_figures,
        "dataset": result.dataset,
        "device": result.device,
        "seconds": round(result.seconds, 1),
        "cpn": {"file": Path(cpn_path).name, "sha256": file_sha256(cpn_path)},
    }
    info = ModelInfo(**{**info.__dict__, "training": training})
    result.net = _to_numpy(net, info)
    return result


def _to_numpy(net, info: ModelInfo) -> MLP:
    import copy

    return copy.deepcopy(net).cpu().to_numpy(info)
