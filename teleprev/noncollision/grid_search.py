"""The alpha/beta grid for the CCN loss (appendix A.3): validity against deviation, and the pair chosen.

Each pair trains a short CCN on a subset of the invalid configurations and is scored on held-out invalid
configurations with the exact checker. The chosen pair is the one with the smallest mean joint deviation
among those reaching `min_valid`; if none does, the most valid one. With Adam only the ratio beta/alpha
really matters (the optimiser is invariant to the loss scale), so pairs with equal ratios score alike.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path

from teleprev.noncollision.train_ccn import CCNSettings, invalid_configurations, train_ccn
from teleprev.robot.collision import SelfCollisionChecker
from teleprev.robot.model import RobotModel


@dataclass(frozen=True)
class GridPoint:
    alpha: float
    beta: float
    valid_frac: float
    mean_dev_rad: float
    best_epoch: int
    seconds: float


@dataclass(frozen=True)
class GridResult:
    points: tuple[GridPoint, ...]
    chosen: GridPoint
    min_valid: float
    settings: CCNSettings

    def to_json(self) -> dict:
        return {
            "min_valid": self.min_valid,
            "chosen": asdict(self.chosen),
            "points": [asdict(p) for p in self.points],
            "settings": {**asdict(self.settings), "hidden": list(self.settings.hidden)},
        }

    def markdown(self) -> str:
        lines = [
            "| alpha | beta | beta/alpha | valid (exact) | mean joint deviation (rad) | |",
            "|---:|---:|---:|---:|---:|---|",
        ]
        for p in self.points:
            mark = "**chosen**" if p == self.chosen else ""
            lines.append(
                f"| {p.alpha:g} | {p.beta:g} | {p.beta / p.alpha:.3g} | {p.valid_frac:.4f} | {p.mean_dev_rad:.4f} | "
                f"{mark} |"
            )
        return "\n".join(lines)


def choose(points: list[GridPoint], min_valid: float) -> GridPoint:
    ok = [p for p in points if p.valid_frac >= min_valid]
    if ok:
        return min(ok, key=lambda p: (p.mean_dev_rad, -p.valid_frac))
    return max(points, key=lambda p: (p.valid_frac, -p.mean_dev_rad))


def grid_search(
    dataset_path: Path,
    cpn_path: Path,
    model: RobotModel,
    checker: SelfCollisionChecker,
    alphas: tuple[float, ...],
    betas: tuple[float, ...],
    settings: CCNSettings,
    min_valid: float = 0.95,
    log: Callable[[GridPoint], None] | None = None,
) -> GridResult:
    invalid = invalid_configurations(dataset_path, model, checker.link_names)
    points = []
    for alpha in alphas:
        for beta in betas:
            r = train_ccn(
                dataset_path, cpn_path, model, checker, replace(settings, alpha=alpha, beta=beta), invalid=invalid
            )
            point = GridPoint(
                alpha,
                beta,
                r.val_figures["valid_frac"],
                r.val_figures["mean_dev_rad"],
                r.best_epoch,
                round(r.seconds, 1),
            )
            points.append(point)
            if log:
                log(point)
    return GridResult(tuple(points), choose(points, min_valid), min_valid, settings)


def write_grid(result: GridResult, out: Path) -> tuple[Path, Path]:
    """<out>.json (every point and the chosen pair) and <out>.md (the table)."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    js, md = out.with_suffix(".json"), out.with_suffix(".md")
    js.write_text(json.dumps(result.to_json(), indent=2) + "\n")
    c = result.chosen
    md.write_text(
        "# CCN loss weights: grid search\n\n"
        f"Validity is the exact (fcl) collision-free fraction of CCN outputs on {result.settings.val_exact} "
        "held-out invalid "
        f"configurations; each point trained {result.settings.epochs} epochs on at most "
        f"{result.settings.max_train or 'all'} "
        "invalid configurations.\n\n"
        + result.markdown()
        + f"\n\nChosen: alpha = {c.alpha:g}, beta = {c.beta:g} "
        + (
            f"(smallest deviation with validity >= {result.min_valid:g}).\n"
            if c.valid_frac >= result.min_valid
            else f"(no pair reached validity {result.min_valid:g}: the most valid one).\n"
        )
    )
    return js, md


def read_chosen(path: Path) -> tuple[float, float]:
    from teleprev.errors import ConfigError

    path = Path(path)
    try:
        chosen = json.loads(path.read_text())["chosen"]
        return float(chosen["alpha"]), float(chosen["beta"])
    except FileNotFoundError:
        raise ConfigError("no such grid-search result", str(path)) from None
    except (json.JSONDecodeError, KeyError, TypeError, ValueError):
        raise ConfigError(
            "not a grid-search result (expected the .json that `teleprev collision grid-search` writes)", str(path)
        ) from None
