"""Gradient projection on the frozen CPN (numpy): the baseline the CCN is compared with, and a fallback step
of the Corrector.

From the start point, step downhill on the mean link probability of the CPN plus a distance term
w/2 * |q - q_in|^2, in steps of fixed length in joint space, clamped to the joint limits. Deep inside
collision the probability saturates and its gradient all but vanishes, so its direction is used at unit
length: the step direction is  grad p / |grad p| + w (q - q_in), which lets the distance term hold q near
the input without stalling it there. The exact checker runs whenever the CPN predicts every link
free, and every `check_every` steps otherwise; the first configuration it passes is the answer.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from teleprev.noncollision.mlp import CPN
from teleprev.robot.collision import SelfCollisionChecker
from teleprev.robot.model import RobotModel


@dataclass(frozen=True)
class ProjectionSettings:
    step: float = 0.02  # rad, length of one step in joint space
    distance_weight: float = 0.05
    max_steps: int = 300
    check_every: int = 10


@dataclass(frozen=True)
class Projection:
    q: np.ndarray
    valid: bool  # the exact checker passed q
    steps: int
    exact_checks: int


def descend(
    cpn: CPN, model: RobotModel, q: np.ndarray, q_in: np.ndarray, settings: ProjectionSettings
) -> tuple[np.ndarray, bool]:
    """One step of the projection; also whether the CPN predicts the new point free."""
    _, grad = cpn.mean_prob_grad(q, scaled=True)
    g = grad[0]
    gn = np.linalg.norm(g)
    if gn > 0:
        g = g / gn
    g = g + settings.distance_weight * (q - q_in)
    norm = np.linalg.norm(g)
    if norm > 0:
        q = model.clip(q - settings.step * g / norm)
    return q, bool(cpn.predicts_free(q))


def project(
    cpn: CPN,
    checker: SelfCollisionChecker,
    model: RobotModel,
    q_in: np.ndarray,
    settings: ProjectionSettings = ProjectionSettings(),
    start: np.ndarray | None = None,
) -> Projection:
    q = model.clip(np.array(q_in if start is None else start, dtype=float))
    checks = 1
    if not checker.collides(q):
        return Projection(q, True, 0, checks)
    for k in range(1, settings.max_steps + 1):
        q, free = descend(cpn, model, q, q_in, settings)
        if free or k % settings.check_every == 0:
            checks += 1
            if not checker.collides(q):
                return Projection(q, True, k, checks)
    return Projection(q, False, settings.max_steps, checks)
